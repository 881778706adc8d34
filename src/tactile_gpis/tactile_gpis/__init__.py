"""Gaussian-process implicit surface (ROS-free core) and the GPIS estimator node."""
