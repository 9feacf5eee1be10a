"""Test support (not installed): this package in a colcon workspace of its own, as a lab builds
it (`colcon build` in ~/ws with the package in src/), and `ros2 launch` run on it (the
``installed`` fixture, conftest.py: test_launch and test_runbook share one build).
"""
import os
import shutil
import signal
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BIN = os.path.dirname(sys.executable)       # the venv's: colcon, ros2

try:
    import launch_ros  # noqa: F401
    HAVE_LAUNCH = shutil.which('colcon', path=BIN) is not None
except ImportError:
    HAVE_LAUNCH = False
NO_LAUNCH = ('no `ros2 launch`: install it from ../shared/wheels/launch (./run does when the '
             'folder exists, on Python 3.11)')


class Workspace:
    """A workspace at path holding a copy of this tree (no venvs, builds or git)."""

    def __init__(self, path):
        self.path = path
        # (not the byte code either: ./run's .pycache/ is some 140 MB, whose copy to disk, beside
        # the flights, stalled the sim of one for 0.3 s)
        skip = shutil.ignore_patterns('.venv*', 'build', 'install', 'log', '.git', '__pycache__',
                                      '.pycache', 'out')
        shutil.copytree(ROOT, os.path.join(path, 'src', 'geoctl_ros'), ignore=skip)
        self.env = dict(os.environ, PATH=BIN + os.pathsep + os.environ['PATH'])
        self.prefix = os.path.join(path, 'install', 'geoctl_ros')

    def colcon(self, *args):
        """Run `colcon ARGS` in the workspace; its output (a failure fails the test with it)."""
        r = subprocess.run(['colcon'] + list(args), cwd=self.path, env=self.env,
                           capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, r.stdout + r.stderr
        return r.stdout


class Launch:
    """`ros2 launch geoctl_ros FILE args...` in a process group of its own, in this session (not
    a session of its own: the kernel's autogroup scheduling gives each session an equal share of
    the CPU whatever its nice, so a launch at `nice 19` in a new session took the cores from the
    foreground's flights as if it had nice 0; docs/stacks.md).
    """

    def __init__(self, env, log, *args):
        self.log = open(log, 'w+')
        self.proc = subprocess.Popen([os.path.join(BIN, 'ros2'), 'launch', 'geoctl_ros'] +
                                     list(args), env=env, stdout=self.log,
                                     stderr=subprocess.STDOUT, process_group=0)

    def output(self):
        if not self.log.closed:
            self.log.flush()
        with open(self.log.name) as fh:
            return fh.read()

    def children(self):
        """The pids of the node processes launch started (the direct children of ros2 launch)."""
        r = subprocess.run(['pgrep', '-P', str(self.proc.pid)], capture_output=True, text=True)
        return [int(p) for p in r.stdout.split()]

    def child(self, program):
        """The pid of the one node process whose command line runs a path ending in program."""
        found = []
        for pid in self.children():
            with open('/proc/%d/cmdline' % pid, 'rb') as fh:
                if any(a.endswith(program.encode()) for a in fh.read().split(b'\0')):
                    found.append(pid)
        assert len(found) == 1, (program, found)
        return found[0]

    def stop(self):
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGINT)             # as Ctrl-C in a terminal
            try:
                self.proc.wait(15)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait(5)
        self.log.close()
