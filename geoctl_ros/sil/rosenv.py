"""The DDS environment of every ROS process this project starts: loopback only, a domain of its
own.

Two settings, both keeping traffic on 127.0.0.1 (docs/interface.md, "DDS transport"):

- ``node_env``: the nodes (and the tests' and tools' own rclpy nodes) use the shipped Fast DDS
  profile ``config/dds/fastdds_loopback.xml``: UDPv4 only, every locator and initial peer on
  127.0.0.1, no shared memory, no multicast. It needs ``ROS_AUTOMATIC_DISCOVERY_RANGE=
  SYSTEM_DEFAULT``, because in LOCALHOST mode rmw_fastrtps replaces the profile's transports
  with its own (shared memory + UDP), and shared memory is what stalls a process for ~333 ms
  whenever a participant (a ``ros2`` command) joins.
- ``cli_env``: what a lab's own shell has for the ``ros2`` command:
  ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` and no profile. It reaches the nodes over UDP on
  loopback.

Both keep the caller's ``ROS_DOMAIN_ID`` or pick a random one (10-99), so that runs side by side
do not hear each other. No rclpy here: this is read before anything creates a node.
"""
import os
import random
import sys

from ament_index_python.packages import get_package_share_directory

PROFILE_VAR = 'FASTRTPS_DEFAULT_PROFILES_FILE'   # Fast DDS 2.x (ROS 2 Jazzy)
RANGE_VAR = 'ROS_AUTOMATIC_DISCOVERY_RANGE'


class NoConfig(SystemExit):
    """The shipped config folder is nowhere to be found: a script stops with the message's one
    line (how to source the workspace), not a traceback.
    """


def config_dir():
    """The shipped config folder: the source tree's, the sourced workspace's share directory
    (the ament index), or the one ``pip install`` put under this Python's prefix. NoConfig, with
    one line saying how to source the workspace, when none has it.
    """
    top = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    candidates = [os.path.join(top, 'config')]
    try:
        candidates.append(os.path.join(get_package_share_directory('geoctl_ros'), 'config'))
    except (LookupError, ValueError, KeyError, OSError):
        pass            # no ament index (AMENT_PREFIX_PATH unset), or not in it
    candidates.append(os.path.join(sys.prefix, 'share', 'geoctl_ros', 'config'))
    for here in candidates:
        if os.path.isdir(here):
            return here
    raise NoConfig('geoctl_ros: the config folder was not found (looked in %s): source the '
                   'workspace first (source install/setup.bash) or run from the source tree'
                   % ', '.join(candidates))


def dds_profile():
    """Path of the shipped Fast DDS loopback profile."""
    return os.path.join(config_dir(), 'dds', 'fastdds_loopback.xml')


def _domain(env):
    return env.get('ROS_DOMAIN_ID') or str(random.SystemRandom().randint(10, 99))


def node_env(env=None):
    """A copy of env (default: os.environ) set up for nodes: the loopback profile, own domain."""
    out = dict(os.environ if env is None else env)
    out[RANGE_VAR] = 'SYSTEM_DEFAULT'
    out[PROFILE_VAR] = dds_profile()
    out['ROS_DOMAIN_ID'] = _domain(out)
    out.setdefault('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp')
    return out


def cli_env(env=None):
    """A copy of env as a lab's shell has it for the ``ros2`` command: LOCALHOST, no profile."""
    out = dict(os.environ if env is None else env)
    out[RANGE_VAR] = 'LOCALHOST'
    out.pop(PROFILE_VAR, None)
    out['ROS_DOMAIN_ID'] = _domain(out)
    return out


def use_node_env():
    """Set this process's environment for nodes (call before rclpy creates a context)."""
    os.environ.update(node_env())
