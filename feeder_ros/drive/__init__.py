"""The drive-command interface's ROS-free core: limits, ramps, watchdog, state machine, speed model
and backends (simulated platform, Modbus TCP feeder controller).

The ROS node :mod:`feeder_ros.nodes.drive_interface` only translates messages, parameters and
lifecycle transitions into calls on :class:`~feeder_ros.drive.controller.DriveController`; every
decision about what reaches the feeder is made here and unit-tested without rclpy.
"""
