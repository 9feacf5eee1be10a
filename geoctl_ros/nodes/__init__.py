"""The ROS 2 nodes: thin shells over the ROS-free core."""
