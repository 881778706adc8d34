"""Marching squares / tetrahedra on analytic fields; export files."""

import numpy as np
import pytest

from tactile_gpis.export import contour_loops, export_level_set
from tactile_gpis.levelset import (farthest_point_subsample, lattice_points, marching_squares,
                                   marching_tetrahedra)


def test_marching_squares_circle_is_one_closed_loop_on_the_circle():
    axes = [np.linspace(-1, 1, 41), np.linspace(-1, 1, 41)]
    P = lattice_points(axes)
    f = (np.linalg.norm(P, axis=1) - 0.6).reshape(41, 41)
    ls = marching_squares(f, axes)
    r = np.linalg.norm(ls.vertices, axis=1)
    assert np.abs(r - 0.6).max() < 0.01  # linear interpolation of a smooth field
    loops = contour_loops(ls.elements)
    assert len(loops) == 1 and loops[0][0] == loops[0][-1]
    xy = ls.vertices[loops[0]]
    area = 0.5 * abs(np.sum(xy[:-1, 0] * xy[1:, 1] - xy[1:, 0] * xy[:-1, 1]))
    assert area == pytest.approx(np.pi * 0.36, rel=0.01)


def test_marching_squares_saddle_and_empty():
    axes = [np.arange(2.0), np.arange(2.0)]
    f = np.array([[-1.0, 1.0], [1.0, -1.0]])  # corners c0, c2 inside: case 5
    assert len(marching_squares(f, axes).elements) == 2
    assert len(marching_squares(np.ones((3, 3)), [np.arange(3.0)] * 2).elements) == 0


def test_marching_tetrahedra_sphere_is_closed_outward_and_encloses_its_volume():
    n = 25
    axes = [np.linspace(-1, 1, n)] * 3
    P = lattice_points(axes)
    f = (np.linalg.norm(P, axis=1) - 0.7).reshape(n, n, n)
    ls = marching_tetrahedra(f, axes)
    assert np.abs(np.linalg.norm(ls.vertices, axis=1) - 0.7).max() < 0.02
    tris = ls.elements
    edges = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert (counts == 2).all(), "every edge shared by exactly two triangles (closed)"
    v = ls.vertices[tris]
    volume = np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() / 6
    assert volume == pytest.approx(4 / 3 * np.pi * 0.7**3, rel=0.02)  # > 0: outward normals


def test_farthest_point_subsample_is_deterministic_and_spread():
    rng = np.random.default_rng(0)
    P = rng.uniform(0, 1, (2000, 2))
    a = farthest_point_subsample(P, 50)
    assert len(a) == 50 and len(set(a)) == 50
    np.testing.assert_array_equal(a, farthest_point_subsample(P, 50))
    chosen = P[a]
    d = np.linalg.norm(chosen[:, None] - chosen[None], axis=-1) + np.eye(50)
    assert d.min() > 0.03  # random 50 of 2000 would typically have pairs < 0.01
    assert len(farthest_point_subsample(P[:10], 50)) == 10


def test_export_files(tmp_path):
    n = 15
    axes = [np.linspace(-1, 1, n)] * 3
    f = (np.linalg.norm(lattice_points(axes), axis=1) - 0.6).reshape(n, n, n)
    ls = marching_tetrahedra(f, axes)
    ply = export_level_set(tmp_path / "s.ply", ls, 3)
    head = ply.read_text().splitlines()
    assert head[0] == "ply" and f"element face {len(ls.elements)}" in head
    stl = export_level_set(tmp_path / "s.stl", ls, 3)
    assert stl.stat().st_size == 84 + 50 * len(ls.elements)
    with pytest.raises(ValueError, match="use .csv, .ply or .obj in 2D"):
        export_level_set(tmp_path / "s.vtk", ls, 3)


@pytest.mark.parametrize("dim", [2, 3])
def test_level_set_keys_name_the_lattice_edge_of_each_vertex(dim):
    n = 17
    axes = [np.linspace(-1, 1, n)] * dim
    P = lattice_points(axes)
    f = (np.linalg.norm(P - 0.05, axis=1) - 0.6).reshape((n,) * dim)
    ls = (marching_squares if dim == 2 else marching_tetrahedra)(f, axes)
    keys = ls.keys
    assert keys.shape == (len(ls.vertices),) and (np.diff(keys) > 0).all()
    lo, hi = keys // P.shape[0], keys % P.shape[0]
    assert (np.sign(f.ravel()[lo]) != np.sign(f.ravel()[hi])).all()
    # each vertex lies on the segment between its two nodes
    a, b = P[lo], P[hi]
    t = np.einsum("ij,ij->i", ls.vertices - a, b - a) / np.einsum("ij,ij->i", b - a, b - a)
    np.testing.assert_allclose(a + t[:, None] * (b - a), ls.vertices, atol=1e-12)
    assert ((t >= 0) & (t <= 1)).all()


def test_farthest_point_subsample_matches_the_plain_definition():
    rng = np.random.default_rng(5)
    for n, d in [(50, 2), (700, 3), (3000, 3)]:
        P = rng.normal(size=(n, d))
        chosen = [int(np.lexsort(P.T[::-1])[0])]
        d2 = ((P - P[chosen[0]]) ** 2).sum(1)
        for _ in range(39):
            chosen.append(int(np.argmax(d2)))
            d2 = np.minimum(d2, ((P - P[chosen[-1]]) ** 2).sum(1))
        np.testing.assert_array_equal(farthest_point_subsample(P, 40), np.sort(chosen))
