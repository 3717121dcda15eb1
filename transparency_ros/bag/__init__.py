"""rosbag2 read/write (rosbags, mcap) <-> arrays. No rclpy."""
