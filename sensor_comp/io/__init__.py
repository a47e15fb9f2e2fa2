"""Bag, message and file input/output; pure Python, no ROS import."""
