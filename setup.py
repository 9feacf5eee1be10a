"""ament_python package definition for geoctl_ros.

One package, two parts (docs/stacks.md, "What runs where"):

- the flight package: the controller and the nodes of the flight chain (and the sim that stands in
  for the testbed), with ``scenario`` and ``report``. Its run-time dependencies are
  INSTALL_REQUIRES here and the exec_depends of package.xml (the same list, as rosdep keys, with
  the ROS packages that rosdep and apt bring: rclpy and common_interfaces' messages). Nothing
  else: a vehicle's ``colcon build`` or ``pip install`` needs none of the tools' dependencies;
- the development tools (campaign, tune, falsify, benchmark, soak, and through ``./run`` demo,
  sensors and fuzz): their dependencies are the extra ``tools`` (``pip install -e '.[tools]'``,
  which ``./run`` gives the development stack). Without it their commands say so in one line
  (``geoctl_ros.cli.tools``); ``scenario`` and ``report`` draw their figures with it.
"""
from glob import glob

from setuptools import find_packages, setup

PACKAGE = 'geoctl_ros'

# The flight package's run-time dependencies from the package index, lowest versions as on the
# vehicle (Ubuntu 24.04's numpy, PyYAML and smbus2; pymavlink and rosbags from pip, as rosdep
# installs them). rosbags is the recorder's (``record``, a node of the flight chain that the
# runbook starts before arming). rclpy and the message packages are not here: they come from
# ROS 2 (apt, or the Jazzy wheels of requirements*.txt), not from an index under these names.
INSTALL_REQUIRES = [
    'numpy>=1.26.4',
    'PyYAML>=6.0.1',
    'pymavlink>=2.4.50',
    'smbus2>=0.4.3',
    'rosbags>=0.11.9',
]

# The development tools' dependencies (the extra ``tools``), pinned as requirements.txt pins them
# (test_package.py keeps the two the same).
TOOLS = [
    'matplotlib==3.11.2',       # every figure (plots/): scenario, report, campaign, ...
    'dask==2026.8.0',           # campaigns, studies, tuning, falsification, the benchmark
    'distributed==2026.8.0',
    'optuna==5.1.0',            # tune
    'psy-taliro==3.2.0',        # falsify
    'rtamt==0.4.10',
    'scipy==1.17.1',
    'hypothesis==6.170.17',     # fuzz (and test_fuzz.py)
]

setup(
    name=PACKAGE,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE]),
        ('share/' + PACKAGE, ['package.xml']),
        ('share/' + PACKAGE + '/config', glob('config/*.yaml')),
        ('share/' + PACKAGE + '/config/scenarios', glob('config/scenarios/*.yaml')),
        ('share/' + PACKAGE + '/config/dds', glob('config/dds/*.xml')),
        ('share/' + PACKAGE + '/config/rviz', glob('config/rviz/*.rviz')),
        ('share/' + PACKAGE + '/launch', glob('launch/*.launch.xml')),
    ],
    install_requires=INSTALL_REQUIRES,
    zip_safe=True,
    maintainer='geoctl_ros developers',
    maintainer_email='geoctl-ros@example.com',
    description='Geometric adaptive constrained attitude control on SO(3) for a hexrotor testbed',
    license='BSD-3-Clause',
    extras_require={'tools': TOOLS, 'test': ['pytest']},
    entry_points={
        'console_scripts': [
            # the flight package: the flight chain's nodes, the sim, and the checks of a
            # parameter file and of a recorded flight (figures with the extra tools)
            'controller = geoctl_ros.nodes.controller:main',
            'sim = geoctl_ros.nodes.sim:main',
            'esc_i2c = geoctl_ros.nodes.esc_i2c:main',
            'mavlink_bridge = geoctl_ros.nodes.mavlink_bridge:main',
            'calibrate = geoctl_ros.nodes.calibrate:main',
            'record = geoctl_ros.nodes.recorder:main',
            'view = geoctl_ros.nodes.view:main',
            'setpoint = geoctl_ros.nodes.commands:setpoint',
            'stop = geoctl_ros.nodes.commands:stop',
            'scenario = geoctl_ros.cli.scenario:main',
            'report = geoctl_ros.cli.report:main',
            # the flight chain's launch prefix: SCHED_FIFO where permitted, else one line
            'realtime = geoctl_ros.nodes.realtime:main',
            # the development tools: without the extra tools, one line says so
            'soak = geoctl_ros.cli.tools:soak',
            'campaign = geoctl_ros.cli.tools:campaign',
            'tune = geoctl_ros.cli.tools:tune',
            'falsify = geoctl_ros.cli.tools:falsify',
            'benchmark = geoctl_ros.cli.tools:benchmark',
        ],
    },
)
