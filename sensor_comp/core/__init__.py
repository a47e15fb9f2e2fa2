"""The numerical core: shots, identification, comparison and compensation (no ROS)."""
