"""Lee's geometric controller on SO(3), the baseline: the attractive error alone, no barrier, with
the same gains (what the barrier buys). The cones are still evaluated, so margins and violations
are reported.
"""
from geoctl_ros.core.law.step_types import Law

GEOMETRIC = Law(barrier=False, widened=False)
