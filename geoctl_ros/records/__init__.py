"""Flight records: rosbag2 bags written and read with rosbags (no rclpy)."""
