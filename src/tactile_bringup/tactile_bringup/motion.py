"""The motion model of a touch: it lives in :mod:`tactile_common.touch_geometry` (one place)."""

from tactile_common.touch_geometry import MotionModel, polyline_length_m

__all__ = ["MotionModel", "polyline_length_m"]
