"""Test-wide settings: ROS traffic on loopback in a domain of this run's own, Agg plots.

Set before anything imports rclpy: every node of the tests (this process's and the ones it
starts) uses the loopback DDS profile (geoctl_ros.sil.rosenv), so nothing can leave 127.0.0.1.
"""
import os

from geoctl_ros.sil.rosenv import use_node_env

use_node_env()
os.environ['MPLBACKEND'] = 'Agg'
