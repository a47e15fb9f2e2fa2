"""rclpy nodes: thin wrappers over the numerical core."""
