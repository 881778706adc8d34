"""Resuming a run (tactile_bringup.resume) from a synthetic run folder: sessions, the observations
file, the rebuilt state, and the errors a user gets. The whole-graph resume is tested in
tests/integration/test_explore_graph.py."""

from pathlib import Path

import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped
from rclpy.serialization import serialize_message

from tactile_bringup import launch_plan
from tactile_bringup.mcap_recorder import McapBagWriter
from tactile_bringup.progress import RunRecorder, observe
from tactile_bringup.reanalyse import run_sessions
from tactile_bringup.resume import load_bundle, prepare, run_files
from tactile_common import topics
from tactile_common.cycle import TouchOutcome, TouchReport
from tactile_common.cycle_msgs import report_msg
from tactile_common.fields import CONTACT_DTYPE
from tactile_common.observations_file import read_observations, write_observations
from tactile_common.pointcloud import to_pointcloud2
from tactile_common.stamps import time_from_ns


def _obs(x, y, label=1, normal=(1.0, 0.0, 0.0)) -> np.ndarray:
    o = np.zeros(1, dtype=CONTACT_DTYPE)
    o["x"], o["y"], o["z"], o["label"] = x, y, 0.04, label
    o["normal_x"], o["normal_y"], o["normal_z"] = normal
    o["force"] = 0.3
    return o


def test_observations_file_reads_back_bit_for_bit(tmp_path):
    rng = np.random.default_rng(0)
    obs = np.zeros(7, dtype=CONTACT_DTYPE)
    for name in CONTACT_DTYPE.names[:-1]:
        obs[name] = rng.normal(size=7) / 3.0
    obs["label"] = [1, 0, 1, 1, 0, 1, 1]
    back = read_observations(write_observations(tmp_path / "o.csv", obs))
    assert back.dtype == CONTACT_DTYPE and back.tobytes() == obs.tobytes()
    assert len(read_observations(write_observations(tmp_path / "e.csv", obs[:0]))) == 0


@pytest.mark.parametrize("text, expected", [
    ("x,y\n1,2\n", "not an observations file"),
    (None, "cannot read observations"),
    ("x,y,z,normal_x,normal_y,normal_z,force,label\n1,2,3,0,0,1,0,7\n", "labels must be"),
    ("x,y,z,normal_x,normal_y,normal_z,force,label\n1,nan,3,0,0,1,0,1\n", "not finite"),
    ("x,y,z,normal_x,normal_y,normal_z,force,label\n1,a,3,0,0,1,0,1\n", "unreadable row"),
])
def test_observations_file_errors_name_the_file(tmp_path, text, expected):
    path = tmp_path / "o.csv"
    if text is not None:
        path.write_text(text)
    with pytest.raises(ValueError, match=expected) as err:
        read_observations(path)
    assert str(path) in str(err.value)


def test_sessions_in_order(tmp_path):
    for name in ("run.mcap", "run.2.mcap", "run.10.mcap", "run.1.mcap", "run.resume1.mcap",
                 "run.resume1.1.mcap", "run.resume2.mcap", "run.resume4.mcap"):
        (tmp_path / name).write_bytes(b"")
    names = [[f.name for f in s] for s in run_sessions(tmp_path / "run.mcap")]
    assert names == [["run.mcap", "run.1.mcap", "run.2.mcap", "run.10.mcap"],
                     ["run.resume1.mcap", "run.resume1.1.mcap"], ["run.resume2.mcap"]]  # resume4: no resume3
    assert run_sessions(tmp_path / "other.mcap") == [[tmp_path / "other.mcap"]]


def _write_session(path: Path, touches: list, orphan=None) -> None:
    """A recording with what re-analysis reads: per touch a goal, its observation and touch_done."""
    w = McapBagWriter(path)
    for topic, type_name in ((topics.CONTACTS, "sensor_msgs/msg/PointCloud2"),
                             (topics.GOAL, "geometry_msgs/msg/PoseStamped"),
                             (topics.TOUCH_DONE, "diagnostic_msgs/msg/DiagnosticStatus")):
        w.add_topic(topic, type_name)
    t = 1_000_000_000
    for i, obs in enumerate(touches):
        goal_ns, obs_ns = t + 10 * i, t + 10 * i + 5
        goal = PoseStamped()
        goal.header.frame_id, goal.header.stamp = "world", time_from_ns(goal_ns)
        goal.pose.position.x, goal.pose.position.y, goal.pose.orientation.w = float(obs["x"][0]), 0.0, 1.0
        w.write(topics.GOAL, serialize_message(goal), goal_ns)
        w.write(topics.CONTACTS, serialize_message(to_pointcloud2(obs, "world", time_from_ns(obs_ns))), obs_ns)
        outcome = TouchOutcome.CONTACT if int(obs["label"][0]) == 1 else TouchOutcome.FREE_SPACE
        done = report_msg(TouchReport(goal_ns, outcome, "", obs_ns, 0.1 * (i + 1), 2.0))
        w.write(topics.TOUCH_DONE, serialize_message(done), obs_ns + 1)
        w.write(topics.TOUCH_DONE, serialize_message(done), obs_ns + 2)  # re-sent (durable): one touch
    if orphan is not None:  # the touch in flight at the interruption: observed, never ended
        w.write(topics.CONTACTS, serialize_message(to_pointcloud2(orphan, "world", time_from_ns(t + 999))), t + 999)
    w.close()


@pytest.fixture
def run_dir(tmp_path):
    """A 2D run folder as explore.sh leaves it after an interruption: 3 touches, one more observed."""
    out = tmp_path / "run"
    assert launch_plan.main(["plan", "--out", str(out), "--touches", "6", "--seed", "4"]) == 0
    (out / "params" / "99_launch.yaml").write_text(
        'explorer:\n  ros__parameters:\n    mode: "2d"\n    evaluate: true\n')
    touches = [_obs(0.43, 0.0), _obs(0.35, 0.05, normal=(0.0, 1.0, 0.0)), _obs(0.2, 0.2, label=0)]
    _write_session(out / "run.mcap", touches, orphan=_obs(0.27, 0.0, normal=(-1.0, 0.0, 0.0)))
    return out, touches


def test_prepare_rebuilds_the_run_and_writes_the_bundle(run_dir, capsys):
    out, touches = run_dir
    plan = prepare(out)
    assert (plan.session, plan.recording_stem, plan.mode, plan.rig) == (1, "run.resume1", "2d", "sim")
    assert (plan.touches_before, plan.touches) == (3, 6)
    assert [Path(f).name for f in plan.params_files] == [f.name for f in run_files(out / "params")]
    report, obs_file = load_bundle(plan.bundle_dir)
    obs = read_observations(obs_file)
    # every observation the interrupted estimator took, the orphan last
    assert [float(v) for v in obs["x"]] == [0.43, 0.35, 0.2, 0.27]
    assert [t["index"] for t in report["touches"]] == [0, 1, 2]
    assert report["resume"]["travel_m"] == pytest.approx(0.6) and report["resume"]["time_s"] == pytest.approx(6.0)

    # The explorer's replica restored from the bundle equals an estimate fed the same points directly.
    from tactile_bringup.experiment import Experiment

    exp = Experiment.from_files("2d", plan.params_files)
    restored = RunRecorder(exp, out, evaluate=False)
    restored.restore(report, obs)
    direct = RunRecorder(exp, out, evaluate=False).estimator
    for o in np.concatenate(touches + [_obs(0.27, 0.0, normal=(-1.0, 0.0, 0.0))]):
        observe(direct, np.array([o["x"], o["y"], o["z"]]), np.array([o["normal_x"], o["normal_y"], o["normal_z"]]),
                int(o["label"]) == 1)
    q = np.random.default_rng(1).uniform([0.2, -0.15, 0.04], [0.5, 0.15, 0.04], size=(20, 3))
    m1, v1 = restored.estimator.predict(q)
    m2, v2 = direct.predict(q)
    assert np.allclose(m1, m2, atol=1e-12) and np.allclose(v1, v2, atol=1e-12)
    assert len(restored.touches) == 3 and restored.travel_m == pytest.approx(0.6)

    # launch_plan resume: the session line, then the files (what explore.sh reads)
    assert launch_plan.main(["resume", "--out", str(out), "--touches", "8"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == "1 2d sim" and lines[-1].endswith("resume1_overrides.yaml")


def test_prepare_refuses_what_cannot_be_resumed(run_dir, tmp_path):
    out, _ = run_dir
    with pytest.raises(ValueError, match="no such run folder"):
        prepare(tmp_path / "nope")
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match="not a run folder"):
        prepare(tmp_path / "empty")
    with pytest.raises(ValueError, match="already made 3 touches of its budget 2"):
        prepare(out, touches=2)
    (out / "run.mcap").write_bytes(b"not mcap at all")
    with pytest.raises(ValueError, match="not a recording"):
        prepare(out)
    assert (out / "run.mcap").read_bytes() == b"not mcap at all"  # nothing of the user's is overwritten


def test_prepare_recovers_a_cut_recording_and_keeps_the_cut_file(run_dir):
    out, _ = run_dir
    whole = (out / "run.mcap").read_bytes()
    (out / "run.mcap").write_bytes(whole[: len(whole) * 2 // 3])  # killed while writing: no summary
    lines = []
    plan = prepare(out, log=lines.append)
    assert (out / "run.mcap.cut").read_bytes() == whole[: len(whole) * 2 // 3]
    assert any("was cut" in line for line in lines) and plan.touches_before >= 1
