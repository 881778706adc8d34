"""Point layouts of the graph's PointCloud2 messages, as numpy structured dtypes.

Every producer and consumer of these clouds uses these dtypes with
:mod:`tactile_common.pointcloud`, so the layout is defined in one place.
"""

import numpy as np

#: Label of a point on ``/tactile/contacts``.
LABEL_FREE_SPACE = 0  # a probe reached its depth without contact: the point is outside
LABEL_CONTACT = 1  # a surface contact: the point is on the surface

#: ``/tactile/contacts``: world frame, metres, unit outward normal, force in newtons.
#: Positions are float64 so that a graph run and an offline run see identical
#: numbers (float32 would quantise contacts to ~0.03 mm and change decisions).
CONTACT_DTYPE = np.dtype(
    [
        ("x", np.float64),
        ("y", np.float64),
        ("z", np.float64),
        ("normal_x", np.float64),
        ("normal_y", np.float64),
        ("normal_z", np.float64),
        ("force", np.float64),
        ("label", np.uint8),
    ]
)

#: Kinds of point on ``/gpis/variance_map``.
KIND_LATTICE = 0  # a node of the estimator's regular evaluation lattice
KIND_CANDIDATE = 1  # a touch candidate on the zero level set of the mean

#: ``/gpis/variance_map``: world frame. Lattice nodes come first, in C order of
#: the lattice (x slowest ... z fastest in 3D; x then y in 2D, with z the fixed
#: height); then the candidates. ``mean``/``variance`` are the GP posterior of
#: f (metres, metres²); ``normal_*`` is grad(mean)/|grad(mean)| (zero where
#: undefined).
VARIANCE_MAP_DTYPE = np.dtype(
    [
        ("x", np.float64),
        ("y", np.float64),
        ("z", np.float64),
        ("mean", np.float64),
        ("variance", np.float64),
        ("normal_x", np.float64),
        ("normal_y", np.float64),
        ("normal_z", np.float64),
        ("kind", np.uint8),
    ]
)


def xyz(points: np.ndarray) -> np.ndarray:
    """(N, 3) float64 array of the x, y, z fields of a structured array."""
    return np.stack([points["x"], points["y"], points["z"]], axis=-1).astype(np.float64)


def normals(points: np.ndarray) -> np.ndarray:
    """(N, 3) float64 array of the normal_x, normal_y, normal_z fields."""
    return np.stack(
        [points["normal_x"], points["normal_y"], points["normal_z"]], axis=-1
    ).astype(np.float64)
