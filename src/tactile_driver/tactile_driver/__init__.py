"""Tactile sensor protocol and driver node, Pinocchio 7-DOF arm commander node."""
