"""ROS message builders for the estimator node (estimate arrays -> messages)."""

from __future__ import annotations

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point
from nav_msgs.msg import OccupancyGrid
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker

from .estimator import ShapeEstimator


def surface_marker(est: ShapeEstimator, frame_id: str, stamp: Time) -> Marker:
    """LINE_LIST contour (2D, at plane_z_m) or TRIANGLE_LIST mesh (3D) of the zero level set."""
    ls = est.level_set()
    m = Marker(header=Header(frame_id=frame_id, stamp=stamp), ns="gpis_surface", id=0, action=Marker.ADD)
    m.pose.orientation.w = 1.0
    if est.dim == 2:
        m.type = Marker.LINE_LIST
        m.scale.x = 0.002
        m.color = ColorRGBA(r=0.1, g=0.6, b=1.0, a=1.0)
    else:
        m.type = Marker.TRIANGLE_LIST
        m.scale.x = m.scale.y = m.scale.z = 1.0
        m.color = ColorRGBA(r=0.1, g=0.6, b=1.0, a=0.8)
    xyz = est._to_xyz(ls.vertices)[ls.elements.ravel()] if len(ls.elements) else np.zeros((0, 3))
    m.points = [Point(x=float(x), y=float(y), z=float(z)) for x, y, z in xyz.tolist()]
    return m


def occupancy_grid(est: ShapeEstimator, frame_id: str, stamp: Time) -> OccupancyGrid:
    """2D: P(inside) = Phi(-mu/sigma) x 100 on the lattice (cells centred on lattice
    nodes; row-major with x fastest; resolution = the x spacing)."""
    p = est.occupancy()  # (nx, ny), x slowest
    xs, ys = est.lattice_axes
    res = float(xs[1] - xs[0])
    g = OccupancyGrid(header=Header(frame_id=frame_id, stamp=stamp))
    g.info.map_load_time = stamp
    g.info.resolution = res
    g.info.width, g.info.height = len(xs), len(ys)
    g.info.origin.position.x = float(xs[0] - 0.5 * res)
    g.info.origin.position.y = float(ys[0] - 0.5 * (ys[1] - ys[0]))
    g.info.origin.position.z = est.plane_z_m
    g.info.origin.orientation.w = 1.0
    g.data = np.clip(np.rint(100.0 * p.T), 0, 100).astype(np.int8).ravel().tolist()
    return g
