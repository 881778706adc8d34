"""Reading the lattice out of a variance map: the axes found in one pass equal the sorted ones,
and a map whose nodes are not a C-order lattice is refused with the reason."""

import numpy as np
import pytest

from tactile_common.fields import VARIANCE_MAP_DTYPE
from tactile_planner.maps import MapError, parse_variance_map


def _lattice(axes) -> np.ndarray:
    """A variance map holding only the lattice of ``axes`` (x, y, z), nodes in C order."""
    mesh = np.meshgrid(*axes, indexing="ij")
    m = np.zeros(mesh[0].size, VARIANCE_MAP_DTYPE)
    for k, name in enumerate("xyz"):
        m[name] = mesh[k].ravel()
    m["mean"] = np.linalg.norm(np.stack([g.ravel() for g in mesh], axis=1) - 0.5, axis=1) - 0.05
    m["variance"] = 1e-4
    return m


@pytest.mark.parametrize("shape", [(48, 48, 48), (7, 5, 3), (5, 7, 2), (33, 17, 1), (2, 2, 1)])
def test_the_axes_are_the_sorted_unique_coordinates(shape):
    axes = [np.linspace(0.3, 0.3 + 0.01 * (n - 1), n) + 0.1 * k for k, n in enumerate(shape)]
    m = _lattice(axes)
    lattice, _ = parse_variance_map(m)
    want = [np.unique(m[name]) for name in "xyz"]
    got = list(lattice.axes) + ([np.array([lattice.plane_z_m])] if lattice.plane_z_m is not None else [])
    assert all(np.array_equal(g, w) for g, w in zip(got, want))
    assert lattice.mean_m.shape == (shape if shape[2] > 1 else shape[:2])  # one z: a 2D lattice
    np.testing.assert_array_equal(lattice.mean_m.ravel(), m["mean"])


@pytest.mark.parametrize("spoil, reason", [
    (lambda m: m[np.random.default_rng(0).permutation(len(m))], "C order"),
    (lambda m: m[::-1], "C order"),
    (lambda m: m[:-1], "full lattice"),
    (lambda m: np.concatenate([m, m[:1]]), "full lattice"),
])
def test_nodes_out_of_order_or_missing_are_refused_with_the_reason(spoil, reason):
    axes = [np.linspace(0.3, 0.4, 6), np.linspace(-0.1, 0.0, 5), np.linspace(0.0, 0.05, 4)]
    with pytest.raises(MapError, match=reason):
        parse_variance_map(spoil(_lattice(axes)))


@pytest.mark.parametrize("field", ["x", "y", "z"])
def test_one_node_a_micrometre_off_its_place_is_refused(field):
    axes = [np.linspace(0.3, 0.4, 6), np.linspace(-0.1, 0.0, 5), np.linspace(0.0, 0.05, 4)]
    m = _lattice(axes)
    m[field][37] += 1e-6
    with pytest.raises(MapError):
        parse_variance_map(m)
    m[field][37] -= 1e-6 - 5e-10  # within the 1e-9 m tolerance: accepted
    parse_variance_map(m)


def test_an_unevenly_spaced_axis_is_refused():
    axes = [np.array([0.3, 0.31, 0.33, 0.34]), np.linspace(-0.1, 0.0, 5), np.linspace(0.0, 0.05, 4)]
    with pytest.raises(MapError, match="evenly spaced"):
        parse_variance_map(_lattice(axes))
