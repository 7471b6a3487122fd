"""Example programs that use feeder_ros only through its public ROS interface."""
