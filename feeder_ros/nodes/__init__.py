"""ROS 2 nodes: thin shells that translate parameters and messages to and from the pure core."""
