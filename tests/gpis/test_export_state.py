"""Exports (PLY with variance, STL, OBJ, contacts PLY) against an analytic sphere/circle,
read back by readers written here; the estimate state file's round trip and its errors."""

import json

import numpy as np
import pytest

from tactile_gpis.estimator import ShapeEstimator
from tactile_gpis.state import StateError, load_state, save_state

from reference import dense_posterior
from shapes import fibonacci_sphere

CENTRE = np.array([0.5, 0.0, 0.08])
RADIUS = 0.05


def read_ply(path):
    """Tiny ASCII PLY reader: {element: (property names, rows as float arrays)}."""
    lines = path.read_text().splitlines()
    assert lines[0] == "ply" and lines[1] == "format ascii 1.0"
    elements, i = [], 2
    while lines[i] != "end_header":
        words = lines[i].split()
        if words[0] == "element":
            elements.append((words[1], int(words[2]), []))
        elif words[0] == "property":
            elements[-1][2].append(words[-1])
        i += 1
    out, i = {}, i + 1
    for name, count, props in elements:
        rows = [np.array(line.split(), dtype=float) for line in lines[i: i + count]]
        out[name] = (props, np.array(rows).reshape(count, -1))
        i += count
    assert i == len(lines)
    return out


def read_stl(path):
    """Binary STL by numpy: (T, 3) normals, (T, 3, 3) vertices."""
    raw = path.read_bytes()
    n = int(np.frombuffer(raw[80:84], "<u4")[0])
    rec = np.frombuffer(raw[84:], dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")], count=n)
    assert len(raw) == 84 + 50 * n
    return rec["n"].astype(float), rec["v"].astype(float)


def read_obj(path):
    v = [ln.split()[1:] for ln in path.read_text().splitlines() if ln.startswith("v ")]
    e = [ln.split() for ln in path.read_text().splitlines() if ln[:2] in ("f ", "l ")]
    return np.array(v, float), [x[0] for x in e], np.array([x[1:] for x in e], int) - 1


def sphere_estimate(dim, n_axis, **kw):
    """Prior = the true circle/sphere and contacts on it with its normals: the posterior
    mean is the signed distance exactly (zero residuals), the variance is not the prior's."""
    # the free-space point as an equality observation (noise 1e-4, as the dense reference below)
    params = {"mode": f"{dim}d", f"lattice.points_per_axis_{dim}d": n_axis, "prior.type": "given",
              "prior.centre_m": CENTRE.tolist(), "prior.radius_m": RADIUS, "free_space.model": "equality", **kw}
    est = ShapeEstimator.from_params(params)
    if dim == 3:
        normals = fibonacci_sphere(8)
    else:
        a = np.linspace(0, 2 * np.pi, 6, endpoint=False)
        normals = np.column_stack([np.cos(a), np.sin(a), np.zeros_like(a)])
    centre = CENTRE if dim == 3 else np.r_[CENTRE[:2], 0.06]
    for n in normals:
        assert est.add_observation(centre + RADIUS * n, n, 1)[0]
    free = centre + np.array([0.09, 0.0, 0.0])
    assert est.add_observation(free, None, 0)[0]
    return est, normals, centre


def reference_variance(est, normals, centre, Q):
    """Posterior variance at Q by the independent dense reference (thin plate, R = diag)."""
    d = est.dim
    R = float(np.linalg.norm(est.bounds_m[1] - est.bounds_m[0]))
    X, t, noise = [], [], []
    for n in normals:
        X += [(centre + RADIUS * n)[:d]] * (1 + d)
        t += [-1] + list(range(d))
        noise += [1e-6 + 1e-10] + [1e-2 + 1e-10] * d
    X.append((centre + [0.09, 0, 0])[:d]), t.append(-1), noise.append(1e-4 + 1e-10)
    X, t = np.array(X), np.array(t)
    _, var = dense_posterior("thin_plate", X, t, np.zeros(len(t)), np.array(noise), Q, np.full(len(Q), -1), R=R)
    return var


def test_3d_ply_stl_obj_lie_on_the_sphere_with_the_posterior_variance(tmp_path):
    est, normals, centre = sphere_estimate(3, 24)
    h = float((est.bounds_m[1] - est.bounds_m[0]).max()) / 23
    tol = 0.35 * h  # linear interpolation of the distance along a lattice edge or diagonal (up to sqrt(3) h)

    ply = read_ply(est.export_shape(tmp_path / "shape.ply"))
    props, V = ply["vertex"]
    assert props == ["x", "y", "z", "variance"]
    r = np.linalg.norm(V[:, :3] - CENTRE, axis=1)
    assert len(V) > 300 and np.abs(r - RADIUS).max() < tol and np.sqrt(np.mean((r - RADIUS) ** 2)) < 0.1 * h
    faces = ply["face"][1]
    assert (faces[:, 0] == 3).all() and faces[:, 1:].max() < len(V)
    tri = V[faces[:, 1:].astype(int), :3]
    outward = np.einsum("ij,ij->i", np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), tri.mean(1) - CENTRE)
    assert (outward > 0).all()
    pick = np.linspace(0, len(V) - 1, 25).astype(int)
    ref = reference_variance(est, normals, centre, V[pick, :3])
    np.testing.assert_allclose(V[pick, 3], ref, rtol=1e-5, atol=1e-12)  # float32 in the file
    assert V[:, 3].min() < 0.5 * V[:, 3].max()  # lower near the contacts: not the prior's constant

    n, T = read_stl(est.export_shape(tmp_path / "shape.stl"))
    assert len(T) == len(faces)
    assert np.abs(np.linalg.norm(T - CENTRE, axis=2) - RADIUS).max() < tol + 1e-6  # float32
    assert (np.einsum("ij,ij->i", n, T.mean(1) - CENTRE) > 0).all()
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-5)

    v, kinds, f = read_obj(est.export_shape(tmp_path / "shape.obj"))
    assert set(kinds) == {"f"} and f.shape == (len(faces), 3)
    np.testing.assert_allclose(v, V[:, :3], atol=1e-9)
    np.testing.assert_array_equal(f, faces[:, 1:])


def test_2d_csv_ply_obj_lie_on_the_circle_and_stl_is_refused(tmp_path):
    est, normals, centre = sphere_estimate(2, 64)
    h = float((est.bounds_m[1] - est.bounds_m[0]).max()) / 63
    tol = 0.2 * h
    ply = read_ply(est.export_shape(tmp_path / "shape.ply"))
    props, V = ply["vertex"]
    assert props == ["x", "y", "z", "variance"] and ply["edge"][0] == ["vertex1", "vertex2"]
    assert np.abs(np.linalg.norm(V[:, :2] - CENTRE[:2], axis=1) - RADIUS).max() < tol
    np.testing.assert_array_equal(V[:, 2], est.plane_z_m)
    E = ply["edge"][1].astype(int)
    assert len(E) == len(V)  # one closed loop: as many segments as vertices
    pick = np.linspace(0, len(V) - 1, 20).astype(int)
    np.testing.assert_allclose(V[pick, 3], reference_variance(est, normals, centre, V[pick, :2]),
                               rtol=1e-5, atol=1e-12)
    v, kinds, lines = read_obj(est.export_shape(tmp_path / "shape.obj"))
    assert set(kinds) == {"l"}
    np.testing.assert_allclose(v, V[:, :3], atol=1e-9)
    np.testing.assert_array_equal(lines, E)
    rows = np.loadtxt(est.export_shape(tmp_path / "shape.csv"), delimiter=",", skiprows=1)
    assert np.abs(np.linalg.norm(rows[:, :2] - CENTRE[:2], axis=1) - RADIUS).max() < tol
    with pytest.raises(ValueError, match="an STL holds triangles"):
        est.export_shape(tmp_path / "shape.stl")


def test_contacts_ply_lists_every_observation_with_its_normal_and_label(tmp_path):
    est, normals, centre = sphere_estimate(3, 12)
    assert not est.add_observation(centre + RADIUS * normals[0], normals[0], 1)[0]  # duplicate: not listed
    props, V = read_ply(est.export_observations(tmp_path / "contacts.ply"))["vertex"]
    assert props == ["x", "y", "z", "nx", "ny", "nz", "label"]
    assert len(V) == len(normals) + 1
    np.testing.assert_allclose(V[:-1, :3], centre + RADIUS * normals, atol=1e-9)
    np.testing.assert_allclose(V[:-1, 3:6], normals, atol=1e-6)
    np.testing.assert_array_equal(V[:, 6], [1] * len(normals) + [0])
    np.testing.assert_array_equal(V[-1, 3:6], 0.0)
    np.testing.assert_allclose(V[-1, :3], centre + [0.09, 0, 0], atol=1e-9)


@pytest.mark.parametrize("params", [
    {"mode": "2d", "lattice.points_per_axis_2d": 40},
    {"mode": "3d", "lattice.points_per_axis_3d": 14, "kernel.type": "matern52", "kernel.length_scale_m": 0.04},
    {"mode": "2d", "lattice.points_per_axis_2d": 40, "method": "auto", "local.auto_min_contacts": 6},
], ids=["2d-exact", "3d-matern", "2d-auto-local"])
def test_state_round_trip_reproduces_mean_and_variance(tmp_path, params):
    rng = np.random.default_rng(3)
    est = ShapeEstimator.from_params(params)
    for k in range(12):
        n = rng.normal(size=3)
        n[2] = n[2] if est.dim == 3 else 0.0
        n /= np.linalg.norm(n)
        label = int(k % 4 != 3)
        point = CENTRE + (RADIUS if label else 0.08) * n + rng.normal(0, 0.002, 3) * (est.dim == 3)
        var = 2e-6 if k == 5 else None
        est.add_observation(point, n if label else None, label, var)
    assert est.add_observation([9.0, 0, 0], None, 0)[0] is False  # outside: counted as rejected
    path = save_state(est, tmp_path / "estimate.json", run={"object": "test"})
    loaded, doc = load_state(path)
    assert doc["run"] == {"object": "test"} and doc["model"]["dim"] == est.dim
    assert loaded.n_observations == est.n_observations and loaded.active_method == est.active_method
    assert loaded.n_rejected == est.n_rejected == 1
    Q = rng.uniform(est.bounds_m[0], est.bounds_m[1], (200, est.dim))  # not the file's check points
    m0, v0 = est.predict(Q)
    m1, v1 = loaded.predict(Q)
    np.testing.assert_allclose(m1, m0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(v1, v0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(loaded.lattice_mean(), est.lattice_mean(), rtol=0, atol=1e-12)
    for a, b in zip(loaded.observations(), est.observations()):
        np.testing.assert_array_equal(a, b)
    # other hyperparameters: the same observations, another estimate (no reproduction check)
    other, doc = load_state(path, params={"noise.contact_var_m2": 1e-4})
    assert other.n_observations == est.n_observations
    assert np.abs(other.predict(Q)[0] - m0).max() > 1e-6


@pytest.mark.parametrize("mode", ["2d", "3d"])
def test_an_estimate_without_observations_round_trips(tmp_path, mode):
    est = ShapeEstimator.from_params({"mode": mode, "lattice.points_per_axis_2d": 16, "lattice.points_per_axis_3d": 8})
    loaded, doc = load_state(save_state(est, tmp_path / "estimate.json"))
    assert loaded.n_observations == 0 and doc["observations"]["point_m"] == []
    np.testing.assert_array_equal(loaded.lattice_mean(), est.lattice_mean())


def _state(tmp_path):
    est = ShapeEstimator.from_params({"lattice.points_per_axis_2d": 24})
    est.add_observation([0.55, 0.0, 0.06], [1, 0, 0], 1)
    est.add_observation([0.45, 0.0, 0.06], [-1, 0, 0], 1)
    return json.loads(save_state(est, tmp_path / "ok.json").read_text())


def _set(path: str, value):
    """An edit of the saved document: ``path`` is keys joined by '/' (parameter names hold dots)."""
    def edit(doc):
        *parents, last = path.split("/")
        node = doc
        for k in parents:
            node = node[k]
        node[last] = value
    return edit


@pytest.mark.parametrize("content, match", [
    (b"\x89MCAP0\r\n\x00\x01", "binary, not JSON"),
    (b'{"format": "tactile_gpis.estimate", "vers', "invalid JSON"),
    (b'{"object": "ellipse", "touches": []}', "not an estimate state file"),
    (_set("version", 2), "newer than this estimator reads"),
    (_set("version", 0), "corrupt state file"),
    (_set("params", None), "'params' is not a mapping"),
    (_set("observations", None), "observations need"),
    (_set("observations/point_m", [[1, 2]]), "not N x 3"),
    (_set("observations/label", [1]), "differ in length"),
    (_set("observations/label", [1, 7]), "labels other than 0/1"),
    (_set("params/kernel.type", "rbf"), "incompatible estimator parameters: unknown kernel type"),
    (_set("params/new.thing", 1), "incompatible estimator parameters: unknown GPIS parameter"),
    (_set("observations/point_m", [[0.55, 0.0, 0.06], [0.45, 0.001, 0.06]]), "do not reproduce the saved estimate"),
    (_set("observations/point_m", [[0.55, 0.0, 0.06], [0.5502, 0.0, 0.06]]), "no longer fits the estimate"),
], ids=lambda v: v if isinstance(v, str) else None)
def test_bad_state_files_are_one_line_errors(tmp_path, content, match):
    path = tmp_path / "bad.json"
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        doc = _state(tmp_path)
        content(doc)
        path.write_text(json.dumps(doc))
    with pytest.raises(StateError, match=match) as err:
        load_state(path)
    assert "\n" not in str(err.value) and str(path) in str(err.value)


def test_a_missing_state_file_is_a_one_line_error(tmp_path):
    with pytest.raises(StateError, match="no such state file"):
        load_state(tmp_path / "nope.json")
