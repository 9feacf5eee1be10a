"""The paper's law as published (Kulumani, Poole & Lee): the configuration error carries every
cone's log barrier, on the cones as configured (never blind, no brake).
"""
from geoctl_ros.core.law.step_types import Law

PAPER = Law(barrier=True, widened=False)
