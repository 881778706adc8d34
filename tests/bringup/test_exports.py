"""A run's exports: the files write_outputs leaves (graph runs, offline runs, re-analysis), and
the state file loaded back by tactile-explore-offline --load-state and replay.sh --offline."""

import json

import numpy as np
import pytest

from tactile_bringup import explore_offline, state_replay
from tactile_bringup.experiment import Experiment
from tactile_bringup.progress import RunRecorder, observe
from tactile_gpis.state import load_state


def _files(folder):
    return sorted(p.name for p in folder.iterdir())


@pytest.mark.parametrize("mode, shapes", [("2d", ["shape.csv", "shape.obj", "shape.ply"]),
                                          ("3d", ["shape.obj", "shape.ply", "shape.stl"])])
def test_run_outputs_hold_the_shape_files_contacts_and_a_state_that_reloads(tmp_path, mode, shapes):
    exp = Experiment(mode=mode, object_name="circle" if mode == "2d" else "sphere", touches=3, seed=0)
    run = RunRecorder(exp, tmp_path, evaluate=False)
    centre = np.array([0.5, 0.0, 0.06])
    for a in np.linspace(0, 2 * np.pi, 5, endpoint=False):
        n = np.array([np.cos(a), np.sin(a), 0.3 if mode == "3d" else 0.0])
        n /= np.linalg.norm(n)
        observe(run.estimator, centre + 0.04 * n, n, True)
    observe(run.estimator, centre + [0.0, 0.09, 0.0], None, False)
    written = run.write("test")
    assert _files(tmp_path) == sorted(["contacts.ply", "estimate.json", "progress.png", "report.json", *shapes])
    assert sorted(written) == sorted(str(p) for p in tmp_path.iterdir())
    loaded, doc = load_state(tmp_path / "estimate.json")
    assert doc["run"]["object"] == exp.object_name and doc["run"]["mode"] == mode
    Q = np.random.default_rng(0).uniform(loaded.bounds_m[0], loaded.bounds_m[1], (50, loaded.dim))
    np.testing.assert_allclose(loaded.predict(Q)[1], run.estimator.predict(Q)[1], rtol=0, atol=1e-12)
    contacts = (tmp_path / "contacts.ply").read_text().splitlines()
    body = np.array([r.split() for r in contacts[contacts.index("end_header") + 1:]], float)
    np.testing.assert_array_equal(body[:, 6], [1, 1, 1, 1, 1, 0])


@pytest.fixture(scope="module")
def offline_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("run")
    assert explore_offline.main(["--object", "circle", "--touches", "3", "--out", str(out), "--quiet"]) == 0
    return out


def test_offline_run_folder_and_evaluating_its_state(offline_run, tmp_path):
    assert {"report.json", "progress.png", "shape.csv", "shape.ply", "shape.obj", "contacts.ply",
            "estimate.json"} <= set(_files(offline_run))
    saved = json.loads((offline_run / "report.json").read_text())
    # --mode and --object come from the state
    assert explore_offline.main(["--load-state", str(offline_run / "estimate.json"), "--evaluate-only",
                                 "--report", str(tmp_path / "eval.json")]) == 0
    evaluated = json.loads((tmp_path / "eval.json").read_text())
    assert evaluated["object"] == "circle" and evaluated["touches"] == []
    assert evaluated["summary"]["final_iou"] == saved["summary"]["final_iou"]
    assert evaluated["loaded_state"]["observations"] == 3


def test_offline_run_continues_from_a_state(offline_run, tmp_path):
    out = tmp_path / "more"
    assert explore_offline.main(["--load-state", str(offline_run / "estimate.json"), "--touches", "2",
                                 "--out", str(out), "--quiet"]) == 0
    report = json.loads((out / "report.json").read_text())
    assert len(report["touches"]) == 2
    loaded, _ = load_state(out / "estimate.json")
    first, _ = load_state(offline_run / "estimate.json")
    assert loaded.n_observations == 5
    np.testing.assert_array_equal(loaded.observations()[0][:3], first.observations()[0])


def test_replay_offline_of_a_state_rebuilds_and_measures_it(offline_run, tmp_path, capsys):
    saved = json.loads((offline_run / "report.json").read_text())
    assert state_replay.main([str(offline_run / "estimate.json"), "--out", str(tmp_path / "same")]) == 0
    same = json.loads((tmp_path / "same" / "report.json").read_text())
    assert same["summary"]["final_iou"] == saved["summary"]["final_iou"]
    assert same["loaded_state"]["params_changed"] == []
    params = tmp_path / "p.yaml"
    params.write_text("gpis_estimator:\n  ros__parameters:\n    noise.contact_var_m2: 1.0e-04\n")
    assert state_replay.main([str(offline_run / "estimate.json"), "--params", str(params),
                              "--out", str(tmp_path / "other")]) == 0
    other = json.loads((tmp_path / "other" / "report.json").read_text())
    assert other["loaded_state"]["params_changed"] == ["noise.contact_var_m2"]
    assert json.loads((tmp_path / "other" / "estimate.json").read_text())["params"]["noise.contact_var_m2"] == 1e-4
    assert "parameters changed: noise.contact_var_m2" in capsys.readouterr().out


@pytest.mark.parametrize("make", ["report", "truncated", "missing"])
def test_a_wrong_state_file_is_one_line_and_status_2(offline_run, tmp_path, capsys, make):
    path = {"report": offline_run / "report.json", "missing": tmp_path / "none.json"}.get(make, tmp_path / "cut.json")
    if make == "truncated":
        path.write_text((offline_run / "estimate.json").read_text()[:200])
    for run in (lambda: explore_offline.main(["--load-state", str(path), "--evaluate-only"]),
                lambda: state_replay.main([str(path)])):
        rc = run()
        err = capsys.readouterr().err.strip().splitlines()
        assert rc == 2 and len(err) == 1 and err[0].startswith(f"error: {path}: ") and "Traceback" not in err[0]
