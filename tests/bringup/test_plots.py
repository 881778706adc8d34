"""Figures: they run on small synthetic reports and write PNGs; what they plot is checked
against hand and analytic computations (crossings, bands, true-surface rings, paths)."""

import numpy as np
import pytest

from tactile_bringup import figure_data, plots
from tactile_bringup.figures2d import contour_length_m, plot_progress_2d
from tactile_bringup.figures3d import plot_progress_3d, truth_rings
from tactile_bringup.progress import _path_record
from tactile_bringup.report import make_report
from tactile_gpis.estimator import ShapeEstimator
from tactile_sim.objects import make_object

PNG = b"\x89PNG\r\n\x1a\n"


def _touch(i, travel, time_s, iou, contact=None, normal=None, probe=None, path=None, **extra):
    t = {"index": i, "target": [0.5, 0.0, 0.06], "contact": contact, "normal": normal,
         "outcome": "contact" if contact else "free_space", "probe_end": probe, "travel_m": travel,
         "time_s": time_s, "iou": iou, "surface_error_m": 0.001, "decision_ms": 5.0, "path": path}
    t.update(extra)
    return t


def _circle_run(mode="2d", n=8, reachable=False):
    """A synthetic run on the circle of radius 0.04 m at (0.5, 0) (3D: the sphere): contacts on
    the true surface with true normals, one free-space probe; IoU values set by hand."""
    obj = make_object("circle" if mode == "2d" else "sphere", mode=mode)
    params = {"mode": mode, "lattice.points_per_axis_2d": 48, "lattice.points_per_axis_3d": 18}
    est = ShapeEstimator(params)
    ious = [0.5, 0.7, 0.85, 0.91, 0.93, 0.96, 0.97, 0.97][:n]
    touches, start = [], np.array([0.40, 0.0, 0.06])
    surface = obj.surface_samples(0.004)
    if mode == "3d":
        surface = surface[surface[:, 2] > 0.01]
    pick = surface[np.linspace(0, len(surface) - 1, n).astype(int)]
    for i, p in enumerate(pick):
        p3 = np.array([p[0], p[1], 0.06]) if mode == "2d" else p
        n3 = np.zeros(3)
        n3[:obj.dim] = obj.gradient(p[None, :obj.dim])[0]
        path = np.vstack([start, p3 + 0.03 * n3])
        if i == 3:  # a free-space probe (its end well outside)
            probe = p3 + 0.02 * n3
            est.add_observation(probe, None, 0)
            touches.append(_touch(i, 0.2 * (i + 1), 3.0 * (i + 1), ious[i], probe=probe.tolist(),
                                  path=path.tolist(), **({"iou_reachable": min(1, ious[i] + 0.02)} if reachable else {})))
        else:
            est.add_observation(p3, n3, 1)
            touches.append(_touch(i, 0.2 * (i + 1), 3.0 * (i + 1), ious[i], contact=p3.tolist(),
                                  normal=n3.tolist(), path=path.tolist(),
                                  **({"iou_reachable": min(1, ious[i] + 0.02)} if reachable else {})))
        start = p3 + 0.03 * n3
    report = make_report(obj.name, mode, "proposed", 0, {}, touches, 0.3, "touch budget")
    if reachable:
        report["summary"]["prior_iou_reachable"] = 0.32
    return report, est, obj


def _is_png(path, min_bytes=20_000):
    data = path.read_bytes()
    return data[:8] == PNG and len(data) > min_bytes


def test_2d_progress_figure_and_its_crossings(tmp_path):
    report, est, obj = _circle_run("2d", reachable=True)
    out = tmp_path / "p.png"
    drawn = plot_progress_2d(report, out, est, obj)
    assert _is_png(out)
    # Hand: IoU 0.91 first at touch 3 (travel 0.8 m, 12 s), 0.96 first at touch 5 (1.2 m, 18 s);
    # reachable = IoU + 0.02: 0.92 ≥ 0.90 at touch 3, 0.95 at touch 4 (1.0 m, 15 s).
    assert drawn["travel_m"][("iou", 0.90)] == pytest.approx((0.8, 0.91))
    assert drawn["travel_m"][("iou", 0.95)] == pytest.approx((1.2, 0.96))
    assert drawn["time_s"][("iou", 0.95)] == pytest.approx((18.0, 0.96))
    assert drawn["travel_m"][("iou_reachable", 0.95)] == pytest.approx((1.0, 0.95))
    assert drawn["time_s"][("iou_reachable", 0.90)] == pytest.approx((12.0, 0.93))


def test_progress_figure_without_estimator_or_truth(tmp_path):
    """The graph's recorder may have no ground truth: the figure still draws what it has."""
    report, est, _ = _circle_run("2d", n=4)
    for t in report["touches"]:
        t["iou"] = None
        t["path"] = None
    out = plots.plot_progress(report, tmp_path / "p.png", est.surface_points(), None)
    assert _is_png(out)


def test_3d_progress_figure(tmp_path):
    report, est, obj = _circle_run("3d", n=5)
    c = np.array(report["touches"][1]["contact"])
    report["touches"][1]["slide_contacts"] = [(c + [0.0, 0.0, -dz]).tolist() for dz in (0.01, 0.005)]
    out = tmp_path / "p3.png"
    drawn = plot_progress_3d(report, out, est, obj)
    assert _is_png(out)
    assert drawn["travel_m"][("iou", 0.90)] == pytest.approx((0.8, 0.91))
    assert ("iou", 0.95) not in drawn["travel_m"], "0.93 is the best of five touches"


def test_truth_rings_lie_on_the_sphere():
    sphere = make_object("sphere", mode="3d")
    lo, hi = sphere.bounds
    centre, radius = 0.5 * (lo + hi), 0.5 * (hi[0] - lo[0])
    rings = truth_rings(sphere, levels=6, points=120)
    assert len(rings) == 6
    for seg in rings:
        p = seg.reshape(-1, 3)
        expect = np.sqrt(radius ** 2 - (p[0, 2] - centre[2]) ** 2)
        r = np.linalg.norm(p[:, :2] - centre[:2], axis=1)
        assert np.allclose(p[:, 2], p[0, 2])
        assert np.abs(r - expect).max() < 2e-3 * radius / 0.04 + 1e-4  # lattice 120 over the box


def test_contour_length_is_the_circumference():
    circle = make_object("circle", mode="2d")
    lo, hi = circle.bounds
    assert contour_length_m(circle) == pytest.approx(np.pi * (hi[0] - lo[0]), rel=1e-4)


def test_crossing_and_step_sampling_by_hand():
    x = np.array([0.0, 1.0, 2.0, 3.0])
    y = np.array([0.2, 0.89, 0.90, 0.99])
    assert figure_data.crossing(x, y, 0.90) == (2.0, 0.90)
    assert figure_data.crossing(x, y, 0.995) is None
    got = figure_data.sample_step(x, y, np.array([0.0, 0.5, 1.0, 2.9, 3.0, 10.0]))
    assert got.tolist() == [0.2, 0.2, 0.89, 0.90, 0.99, 0.99]


def test_band_median_and_quartiles_by_hand():
    """Five runs; at each probe travel the value of each run is read off its touches by a loop."""
    rng = np.random.default_rng(7)
    runs = []
    for k in range(5):
        travel = np.cumsum(rng.uniform(0.1, 0.5, size=6))
        iou = np.sort(rng.uniform(0.3, 1.0, size=6))
        runs.append({"summary": {"prior_iou": 0.1 * k}, "touches": [
            {"travel_m": float(a), "time_s": 0.0, "iou": float(b)} for a, b in zip(travel, iou)]})
    b = figure_data.band(runs, "travel_m", points=50)
    for j in (0, 7, 20, 49):
        x = b.grid[j]
        vals = []
        for r in runs:
            v = r["summary"]["prior_iou"]
            for t in r["touches"]:
                if t["travel_m"] <= x:
                    v = t["iou"]
            vals.append(v)
        s = sorted(vals)  # 5 values: linear-interpolation quartiles are the 2nd and 4th
        assert b.median[j] == pytest.approx(s[2])
        assert b.q25[j] == pytest.approx(s[1])
        assert b.q75[j] == pytest.approx(s[3])
    assert b.grid[-1] == pytest.approx(max(r["touches"][-1]["travel_m"] for r in runs))


def test_band_without_a_prior_starts_at_the_first_touches():
    """Two runs without a recorded prior of the reachable IoU: no value before either's first
    touch, one run's value between the first touches, the median of both after."""
    runs = [{"summary": {}, "touches": [{"travel_m": 1.0, "time_s": 1.0, "iou_reachable": 0.4},
                                        {"travel_m": 3.0, "time_s": 2.0, "iou_reachable": 0.8}]},
            {"summary": {}, "touches": [{"travel_m": 2.0, "time_s": 1.0, "iou_reachable": 0.6}]}]
    b = figure_data.band(runs, "travel_m", "iou_reachable", points=7)  # grid 0, 0.5, ..., 3
    assert np.isnan(b.median[:2]).all()
    assert b.median[2:4].tolist() == [0.4, 0.4]
    assert b.median[4:6].tolist() == pytest.approx([0.5, 0.5])
    assert b.median[6] == pytest.approx(0.7)


def test_strategy_figures_and_gallery(tmp_path):
    runs = []
    for fam in ("convex", "concave"):
        for strat in ("proposed", "random"):
            for seed in range(3):
                report, _, _ = _circle_run("2d", n=5)
                report.update(strategy=strat, seed=seed, family=fam)
                runs.append(report)
    assert {figure_data.group_key(r) for r in runs} == {"convex", "concave"}
    assert _is_png(plots.plot_strategies(runs, tmp_path / "t.png", "travel_m"))
    assert _is_png(plots.plot_strategies(runs, tmp_path / "s.png", "time_s"))
    reach, _, _ = _circle_run("2d", n=5, reachable=True)
    assert _is_png(plots.plot_strategies([reach] * 3, tmp_path / "r.png", "travel_m", "iou_reachable",
                                         group=lambda r: "one panel"), min_bytes=8_000)
    circle = make_object("circle", mode="2d").surface_samples(0.002)
    assert plots.plot_gallery([("a\nIoU 0.9", circle, circle)] * 3, tmp_path / "g.png").stat().st_size > 5000


def test_slide_geometry_and_figure(tmp_path):
    """A slide: the approach ends at its first contact, its trace ends at the recorded (last) contact."""
    report, est, obj = _circle_run("2d", n=3)
    t = report["touches"][1]
    c = np.array(t["contact"])
    ang = np.arctan2(c[1], c[0] - 0.5)
    arc = [[0.5 + 0.04 * np.cos(a), 0.04 * np.sin(a), 0.06] for a in ang - np.array([0.6, 0.4, 0.2])]
    t.update(slide_contacts=arc, touch="slide")
    g = figure_data.touch_geometry(report)[1]
    assert g.approach_end_xyz.tolist() == arc[0]
    assert g.slide_line_xyz.tolist() == arc + [c.tolist()]
    assert len(figure_data.touch_geometry(report)[0].slide_xyz) == 0, "a poke has no slide"
    assert _is_png(tmp_path / "s.png") if plot_progress_2d(report, tmp_path / "s.png", est, obj) is not None else False


def test_bad_input_is_named(tmp_path):
    with pytest.raises(ValueError, match="mode must be"):
        plots.plot_progress({"mode": "4d", "touches": []}, tmp_path / "x.png")
    with pytest.raises(ValueError, match="x_key"):
        figure_data.step_curve({"touches": [], "summary": {}}, "laps")
    with pytest.raises(ValueError, match="at least one run"):
        plots.plot_strategies([], tmp_path / "x.png")
    with pytest.raises(ValueError, match="y_key must be one of"):
        plots.plot_strategies([{"touches": []}], tmp_path / "x.png", y_key="laps")
    with pytest.raises(ValueError, match="cols must be at least 1"):
        plots.plot_gallery([("a", np.zeros((0, 2)), np.zeros((0, 2)))], tmp_path / "x.png", cols=-1)


def test_path_record_is_the_followed_part():
    P = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.1, 0.2, 0.0]])
    assert _path_record(P, None) == P.tolist()
    assert _path_record(P, 0.05) == [[0.0, 0.0, 0.0], [0.05, 0.0, 0.0]]
    assert _path_record(P, 0.2) == [[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.1, 0.1, 0.0]]
    assert _path_record(P, 1.0) == P.tolist()
    assert _path_record(None, None) is None
