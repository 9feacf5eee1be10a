"""The vehicle's identity for AUTOPILOT_VERSION: the package's version and the git commit."""
import importlib.metadata
import os
import subprocess


def version():
    """This package's version as (major, minor, patch) (AUTOPILOT_VERSION)."""
    try:
        v = importlib.metadata.version('geoctl_ros')
    except Exception:
        v = '0.0.0'
    parts = (v.split('.') + ['0', '0', '0'])[:3]
    return tuple(int(p) if p.isdigit() else 0 for p in parts)


def git_hash():
    """The source tree's git commit, or '' (AUTOPILOT_VERSION's custom version)."""
    try:
        here = os.path.dirname(os.path.abspath(__file__))
        return subprocess.run(['git', 'rev-parse', 'HEAD'], cwd=here, capture_output=True,
                              text=True, timeout=5).stdout.strip()
    except Exception:
        return ''
