"""Simulated rig: objects as signed distance functions, metrics, simulated sensor device, emulated ros2_control controller."""
