"""Test-wide settings: ROS traffic on loopback in a domain of this run's own, Agg plots."""
import os
import random

# Set before anything imports rclpy, so that no test can multicast off this machine.
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('ROS_DOMAIN_ID', str(random.SystemRandom().randint(10, 99)))
os.environ['MPLBACKEND'] = 'Agg'
