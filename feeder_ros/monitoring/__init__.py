"""Speed and feed monitoring of a feeder cell (ROS-free)."""
