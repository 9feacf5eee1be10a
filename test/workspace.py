"""Test support (not installed): this package in a colcon workspace of its own, as a lab builds
it (`colcon build` in ~/ws with the package in src/).
"""
import os
import shutil
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BIN = os.path.dirname(sys.executable)       # the venv's: colcon, ros2


class Workspace:
    """A workspace at path holding a copy of this tree (no venvs, builds or git)."""

    def __init__(self, path):
        self.path = path
        skip = shutil.ignore_patterns('.venv*', 'build', 'install', 'log', '.git', '__pycache__',
                                      'out')
        shutil.copytree(ROOT, os.path.join(path, 'src', 'geoctl_ros'), ignore=skip)
        self.env = dict(os.environ, PATH=BIN + os.pathsep + os.environ['PATH'])
        self.prefix = os.path.join(path, 'install', 'geoctl_ros')

    def colcon(self, *args):
        """Run `colcon ARGS` in the workspace; its output (a failure fails the test with it)."""
        r = subprocess.run(['colcon'] + list(args), cwd=self.path, env=self.env,
                           capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, r.stdout + r.stderr
        return r.stdout
