"""The estimated solid leaves out what floats untouched (tactile_gpis.solid, ShapeEstimator in 3D).

Oracles: the analytic insides of spheres on a lattice, and the prior sphere a short-range kernel keeps
far from the data."""

import numpy as np
import pytest

from tactile_gpis.estimator import ShapeEstimator, _without_nodes
from tactile_gpis.levelset import lattice_points, zero_level_set
from tactile_gpis.solid import floating_untouched

AXES = [np.linspace(0.35, 0.65, 40), np.linspace(-0.15, 0.15, 40), np.linspace(0.0, 0.22, 30)]
GRID = lattice_points(AXES)
SHAPE = tuple(len(a) for a in AXES)
ON_TABLE = (np.array([0.44, -0.06, 0.04]), 0.04)  # centre, radius: rests on the table
FLOATING = (np.array([0.56, 0.07, 0.15]), 0.03)  # lowest point 12 cm above the table


def _ball_field(*balls):
    """μ = the signed distance to the union of the balls (lattice shape)."""
    return np.min([np.linalg.norm(GRID - c, axis=1) - r for c, r in balls], axis=0).reshape(SHAPE)


def _inside(ball):
    c, r = ball
    return (np.linalg.norm(GRID - c, axis=1) < r).reshape(SHAPE)


def _on_surface(ball, direction):
    c, r = ball
    d = np.asarray(direction, float)
    return c + r * d / np.linalg.norm(d)


def test_a_floating_component_no_contact_touches_is_left_out():
    mean = _ball_field(ON_TABLE, FLOATING)
    got = floating_untouched(mean, AXES, _on_surface(ON_TABLE, [1, 0, 0])[None], floating_gap_m=0.02)
    np.testing.assert_array_equal(got, _inside(FLOATING))


def test_a_touched_or_grounded_component_stays():
    mean = _ball_field(ON_TABLE, FLOATING)
    contacts = np.array([_on_surface(ON_TABLE, [1, 0, 0]), _on_surface(FLOATING, [0, -1, 1])])
    assert not floating_untouched(mean, AXES, contacts, 0.02).any()  # touched
    assert not floating_untouched(_ball_field(ON_TABLE), AXES, np.zeros((0, 3)), 0.02).any()  # on the table
    # floating by less than the gap: its lowest node is 12 cm up
    assert not floating_untouched(mean, AXES, np.zeros((0, 3)), 0.13).any()
    # joined to the grounded ball by a third that overlaps both: one component, touched
    bridge = ((ON_TABLE[0] + FLOATING[0]) / 2, 0.75 * np.linalg.norm(FLOATING[0] - ON_TABLE[0]) / 2 + 0.02)
    joined = _ball_field(ON_TABLE, FLOATING, bridge)
    assert not floating_untouched(joined, AXES, _on_surface(ON_TABLE, [-1, 0, 0])[None], 0.02).any()


def test_many_contacts_give_the_brute_force_answer():
    """Hundreds of contacts (several lookup chunks), the one that touches a floating ball last: the
    answer is the definition's, each component's nodes against each contact by distance."""
    other = (np.array([0.40, 0.08, 0.16]), 0.025)  # a second floating ball
    mean = _ball_field(ON_TABLE, FLOATING, other)
    rng = np.random.default_rng(3)
    on_table = np.array([_on_surface(ON_TABLE, d) for d in rng.normal(size=(100, 3))])
    # within a cell diagonal (1.3 cm) of the second ball's bounding box (nodes up to 1.9 cm from its
    # centre per axis), more than that from its surface (2.3 cm): looked up, touching nothing
    corners = other[0] + 0.028 * rng.choice([-1.0, 1.0], size=(200, 3)) + rng.uniform(-1e-3, 1e-3, (200, 3))
    reach = float(np.linalg.norm([a[1] - a[0] for a in AXES]))
    near_miss = np.vstack([on_table, corners])
    for contacts in (near_miss, np.vstack([near_miss, _on_surface(other, [1, 1, -1])])):
        got = floating_untouched(mean, AXES, contacts, 0.02)
        want = np.zeros(SHAPE, bool)
        for ball in (FLOATING, other):
            nodes = GRID[_inside(ball).ravel()]
            near = np.linalg.norm(nodes[:, None, :] - contacts[None], axis=2).min() <= reach
            want |= _inside(ball) & (not near)
        np.testing.assert_array_equal(got, want)
    assert got.sum() == _inside(FLOATING).sum()  # the last contact kept the second ball


def test_the_level_set_without_a_component_is_the_rest_s_own():
    both = zero_level_set(_ball_field(ON_TABLE, FLOATING), AXES)
    alone = zero_level_set(_ball_field(ON_TABLE), AXES)
    got = _without_nodes(both, _inside(FLOATING))
    np.testing.assert_array_equal(got.keys, alone.keys)
    np.testing.assert_allclose(got.vertices, alone.vertices, atol=1e-12)
    # the same triangles, by their vertices' lattice edges (the numbering may differ)
    as_keys = lambda ls: sorted(map(tuple, np.sort(ls.keys[ls.elements], axis=1)))  # noqa: E731
    assert as_keys(got) == as_keys(alone) and len(got.elements) > 100


def test_nothing_inside_nothing_left_out():
    assert not floating_untouched(np.ones(SHAPE), AXES, np.zeros((0, 3)), 0.02).any()


def _estimator(drop: bool, centre, radius) -> ShapeEstimator:
    """A squared-exponential GP (2 cm) with a prior sphere: far from the data its mean is the prior's."""
    return ShapeEstimator({"mode": "3d", "lattice.points_per_axis_3d": 32, "kernel.type": "squared_exponential",
                           "kernel.length_scale_m": 0.02, "prior.type": "given", "prior.centre_m": list(centre),
                           "prior.radius_m": radius, "solid.drop_floating": drop})


@pytest.mark.parametrize("drop", [False, True])
def test_the_estimator_leaves_a_floating_untouched_prior_out_of_its_solid(drop):
    c, r = FLOATING
    est = _estimator(drop, c, r)
    contact = _on_surface(ON_TABLE, [1, 0, 0])
    assert est.add_observation(contact, [1.0, 0.0, 0.0], 1)[0]
    assert est.predict(c[None])[0][0] < -0.02  # the GP's mean: the prior sphere, 15 cm from the contact
    ls = est.level_set()
    on_prior = np.abs(np.linalg.norm(ls.vertices - c, axis=1) - r) < 0.01
    cand = est.map_array()[len(est._lattice):]
    cand_xyz = np.column_stack([cand["x"], cand["y"], cand["z"]])
    if drop:
        assert not est.refined_inside(c[None])[0] and not est.lattice_inside(c[None])[0]
        assert not on_prior.any()
        assert np.all(np.linalg.norm(cand_xyz - c, axis=1) > r + 0.01)
    else:  # the option off: the solid is {μ < 0}, as before
        assert est.refined_inside(c[None])[0] and on_prior.sum() > 50
        assert np.any(np.linalg.norm(cand_xyz - c, axis=1) < r + 0.01)


def test_a_contact_on_the_floating_part_keeps_it():
    c, r = FLOATING
    est = _estimator(True, c, r)
    est.add_observation(_on_surface(ON_TABLE, [1, 0, 0]), [1.0, 0.0, 0.0], 1)
    est.add_observation(_on_surface(FLOATING, [0, 0, 1]), [0.0, 0.0, 1.0], 1)
    assert est.refined_inside(c[None])[0]


def test_a_prior_resting_on_the_table_stays_without_contacts():
    est = _estimator(True, [0.5, 0.0, 0.05], 0.05)
    assert est.refined_inside(np.array([[0.5, 0.0, 0.05]]))[0]
    assert len(est.level_set().vertices)


def test_2d_is_unchanged():
    est = ShapeEstimator({"mode": "2d", "solid.drop_floating": True})
    assert not est.drop_floating
