"""Models of the sensors a real feeder has: the carrier accelerometer and part-present sensors."""
