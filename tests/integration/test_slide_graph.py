"""Sliding on the node graph end to end: scripts/explore.sh --touch slide, then replay --offline.

The checks are independent of the code under test where they can be: rosbags reads the recording,
the object's analytic SDF judges the streamed contacts, and the commander's limits are checked on
every recorded trajectory by the TrajectoryMonitor (scipy splines), the servo's short replacing
trajectories from the joint state recorded just before each (the controller starts them there).
"""

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

from tactile_bringup.experiment import Experiment
from tactile_common import topics
from tactile_driver.kinematics import ArmModel
from tactile_driver.trajectory_monitor import TrajectoryMonitor
from tactile_sim.objects import make_object

ROOT = Path(__file__).resolve().parents[2]
pytestmark = [pytest.mark.graph, pytest.mark.slow]
TOUCHES = 3


def _logs(out: Path) -> str:
    return "\n".join(f"--- {p.name}\n{p.read_text()[-3000:]}" for p in sorted((out / "logs").glob("*.log")))


def _monitor(run_dir: Path) -> TrajectoryMonitor:
    """The commander's own limits and box, from the parameter files the run's nodes got."""
    exp = Experiment.from_files("2d", [str(p) for p in sorted((run_dir / "params").glob("*.yaml"))])
    p = {**{k: v[0] for k, v in __import__("tactile_driver.commander_node", fromlist=["PARAMS"]).PARAMS.items()},
         **exp.arm_params}
    model = ArmModel(p["urdf_path"], p["joint_names"], p["flange_frame"], p["tip_offset_m"])
    return TrajectoryMonitor.from_params(model, p["max_joint_velocity_rad_s"], p["max_joint_acceleration_rad_s2"],
                                         p["box_x_m"], p["box_y_m"], p["box_z_m"], p["table_z_m"],
                                         p["table_margin_m"], p["tip_radius_m"], p["tip_speed_mps"])


def test_slide_run_streams_contacts_within_limits_and_replays_offline(domain_env, tmp_path):
    out = tmp_path / "run"
    # Three slides whatever they sense: the confidence stop of a slide run (explore_slide.yaml) off.
    budget = tmp_path / "budget.yaml"
    budget.write_text("explorer:\n  ros__parameters:\n    confidence_max_var_m2: 0.0\n")
    result = subprocess.run(["bash", str(ROOT / "scripts/explore.sh"), "--out", str(out), "--touch", "slide",
                             "--touches", str(TOUCHES), "--real-time-factor", "2", "--params", str(budget)],
                            env=domain_env, capture_output=True, text=True, timeout=900, stdin=subprocess.DEVNULL)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:] + _logs(out)
    check_slide_run(out, domain_env)


def check_slide_run(out: Path, env: dict) -> None:
    """The checks of a finished ``explore.sh --touch slide`` run folder (also usable on a manual run)."""
    report = json.loads((out / "report.json").read_text())
    assert len(report["touches"]) == TOUCHES and all(t["touch"] == "slide" for t in report["touches"])
    slid = [t for t in report["touches"] if t["slide_m"]]
    assert slid, report["touches"]  # at least one touch slid along the surface
    assert sum(t["contacts_gathered"] for t in report["touches"]) > TOUCHES

    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    monitor = _monitor(out)
    names = list(monitor.model.joint_names)
    contacts, states, trajectories = [], [], []
    with AnyReader([out / "run.mcap"], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        for conn, t_ns, raw in reader.messages():
            if conn.topic not in (topics.CONTACTS, topics.JOINT_STATES, topics.JOINT_TRAJECTORY):
                continue
            msg = reader.deserialize(raw, conn.msgtype)
            if conn.topic == topics.CONTACTS:  # decoded here from the PointField layout (sensor_msgs)
                kinds = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}
                dtype = np.dtype({"names": [f.name for f in msg.fields], "offsets": [f.offset for f in msg.fields],
                                  "formats": [kinds[f.datatype] for f in msg.fields], "itemsize": msg.point_step})
                for point in np.frombuffer(bytes(msg.data), dtype=dtype):
                    if int(point["label"]) == 1:
                        contacts.append(np.array([point["x"], point["y"]], dtype=float))
            elif conn.topic == topics.JOINT_STATES:
                index = {n: i for i, n in enumerate(msg.name)}
                qd = np.array([msg.velocity[index[n]] for n in names]) if len(msg.velocity) == len(msg.name) \
                    else np.zeros(len(names))
                states.append((t_ns, np.array([msg.position[index[n]] for n in names]), qd))
            else:
                trajectories.append((t_ns, msg))
    # the contact stream: more contacts than touches, all on the true ellipse (1.5 mm)
    assert len(contacts) > 2 * TOUCHES, len(contacts)
    ellipse = make_object("ellipse", mode="2d")
    assert np.abs(ellipse.sdf(np.array(contacts))).max() < 1.5e-3
    # every trajectory within the commander's limits and box. A servo step (first point later than 0)
    # starts from the arm's state when it arrives, moving (a streamed step continues the motion): the
    # recorder takes the 100 Hz joint states up to a second late on a loaded machine, so the recording
    # cannot say which state the commander planned from; the step must be safe from at least one state
    # (position and velocity) recorded within 1 s of it (the graph tests of tests/faults check the
    # start strictly, from their own subscription).
    steps = 0
    state_t = np.array([t for t, _, _ in states])
    probe = _monitor(out)
    for t_ns, msg in trajectories:
        if not msg.points:
            continue  # stop and hold
        times = [p.time_from_start.sec + 1e-9 * p.time_from_start.nanosec for p in msg.points]
        q = [list(p.positions) for p in msg.points]
        qd = [list(p.velocities) for p in msg.points]
        if times[0] <= 0:
            monitor.check(msg.joint_names, times, q, qd)
            continue
        steps += 1
        gap_ns = np.abs(state_t - t_ns)
        near_idx = np.flatnonzero(gap_ns <= 1e9)
        # nearest first: the state it was planned from is usually among the closest, so the search ends
        # after a few checks instead of trying the states of a second earlier one by one (minutes per run)
        near = [states[k][1:] for k in near_idx[np.argsort(gap_ns[near_idx], kind="stable")]]
        found = None
        for q_now, qd_now in near:
            found = probe.check(msg.joint_names, times, q, qd, q_now=q_now, qd_now=qd_now)
            if not found:
                break
        probe.violations.clear()
        if found is None or found:  # no state near it, or unsafe from every one: a violation
            k = int(np.searchsorted(state_t, t_ns, side="right")) - 1
            monitor.check(msg.joint_names, times, q, qd, q_now=states[max(k, 0)][1], qd_now=states[max(k, 0)][2])
    assert monitor.violations == [], "\n".join(map(str, monitor.violations[:10]))
    assert steps > 10, "the slides were driven by short replacing trajectories"

    # replay --offline rebuilds the same estimate from the recorded stream: the same final IoU
    re = subprocess.run(["bash", str(ROOT / "scripts/replay.sh"), str(out / "run.mcap"), "--offline"],
                        env=env, capture_output=True, text=True, timeout=300)
    assert re.returncode == 0, re.stdout + re.stderr
    again = json.loads((out / "reanalysis" / "report.json").read_text())
    assert again["summary"]["final_iou"] == pytest.approx(report["summary"]["final_iou"], abs=1e-9)
    assert [t["contacts_gathered"] for t in again["touches"]] == [t["contacts_gathered"] for t in report["touches"]]
