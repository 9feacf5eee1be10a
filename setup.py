"""ament_python package definition for geoctl_ros."""
from glob import glob

from setuptools import find_packages, setup

PACKAGE = 'geoctl_ros'

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
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='geoctl_ros developers',
    maintainer_email='geoctl-ros@example.com',
    description='Geometric adaptive constrained attitude control on SO(3) for a hexrotor testbed',
    license='BSD-3-Clause',
    extras_require={'test': ['pytest']},
    entry_points={
        'console_scripts': [
            'scenario = geoctl_ros.cli.scenario:main',
            'controller = geoctl_ros.nodes.controller:main',
            'sim = geoctl_ros.nodes.sim:main',
            'soak = geoctl_ros.cli.soak:main',
            'mavlink_bridge = geoctl_ros.nodes.mavlink_bridge:main',
            'campaign = geoctl_ros.cli.campaign:main',
            'tune = geoctl_ros.cli.tune:main',
            'falsify = geoctl_ros.cli.falsify:main',
            'benchmark = geoctl_ros.cli.benchmark:main',
            'record = geoctl_ros.nodes.recorder:main',
            'report = geoctl_ros.cli.report:main',
            'view = geoctl_ros.nodes.view:main',
            'esc_i2c = geoctl_ros.nodes.esc_i2c:main',
            'calibrate = geoctl_ros.nodes.calibrate:main',
        ],
    },
)
