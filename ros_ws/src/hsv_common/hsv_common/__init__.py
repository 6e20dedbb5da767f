"""Shared ROS 2 plumbing of the hsv_* nodes: lockstep, parameters, message conversion."""
