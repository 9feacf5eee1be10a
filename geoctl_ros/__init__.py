"""geoctl_ros: geometric adaptive constrained attitude control on SO(3) for a hexrotor testbed."""
