"""The main job end to end: scripts/explore.sh on the simulated rig, then replay --offline.

Every node runs as its own process on a private ROS_DOMAIN_ID with
localhost-only discovery. The checks are independent of the code under test
where they can be: rosbags reads the recording, the object's analytic SDF
judges the contacts, the offline planner must re-make the graph's
decisions from the graph's own observations, and the offline loop must make
the graph's touches (the main run is made with both cores kept busy).
"""

import json
import os
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

from tactile_bringup.experiment import Experiment
from tactile_bringup.loop import ExplorationLoop
from tactile_bringup.report import check_report
from tactile_common import topics
from tactile_planner.planner import PARAMETERS as PLANNER_PARAMETERS
from tactile_sim.objects import make_object

ROOT = Path(__file__).resolve().parents[2]
pytestmark = [pytest.mark.graph, pytest.mark.slow]


def _explore(env, out: Path, *args: str, timeout_s: float = 420) -> subprocess.CompletedProcess:
    return subprocess.run(["bash", str(ROOT / "scripts/explore.sh"), "--out", str(out), *args],
                          env=env, capture_output=True, text=True, timeout=timeout_s, stdin=subprocess.DEVNULL)


def _logs(out: Path) -> str:
    return "\n".join(f"--- {p.name}\n{p.read_text()[-3000:]}" for p in sorted((out / "logs").glob("*.log")))


KIDNEY = ("--object", "kidney", "--touches", "10", "--seed", "2")


def _observation(touch: dict) -> list:
    """Where a touch observed: the contact, or the probe end of a free-space approach."""
    return touch["contact"] if touch["contact"] is not None else touch["probe_end"]


@pytest.fixture(scope="module")
def kidney_run(tmp_path_factory):
    """One uninterrupted default-strategy run (kidney, seed 2, 10 touches): its folder and result."""
    from tactile_common.testing import BusyCores, DomainLease

    lease = DomainLease()
    env = dict(os.environ, ROS_DOMAIN_ID=str(lease.domain_id))
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    out = tmp_path_factory.mktemp("kidney") / "run"
    try:
        with BusyCores(2):  # both cores kept busy: what the rig senses must not depend on timing
            result = _explore(env, out, *KIDNEY, "--real-time-factor", "2")
        yield out, result
    finally:
        lease.release()


def test_graph_run_records_reports_and_replays_offline(domain_env, kidney_run):
    out, result = kidney_run
    touches = 10
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:] + _logs(out)
    assert "touch  10/10" in result.stdout + result.stderr, "progress is printed per touch"
    for name in ("run.mcap", "report.json", "progress.png", "shape.csv"):
        assert (out / name).stat().st_size > 0, name

    report = json.loads((out / "report.json").read_text())
    check_report(report)
    assert len(report["touches"]) == touches and report["strategy"] == PLANNER_PARAMETERS["strategy"][0]  # the default
    kidney = make_object("kidney", mode="2d")
    contacts = [t for t in report["touches"] if t["outcome"] == "contact"]
    assert len(contacts) >= touches // 2
    for t in contacts:  # on the true surface (2 mm) with the true normal (10 degrees)
        p = np.array([t["contact"][:2]])
        assert abs(kidney.sdf(p)[0]) < 2e-3
        assert np.dot(kidney.gradient(p)[0], t["normal"][:2]) > np.cos(np.radians(10))

    # The recording opens with an independent reader and every message deserialises.
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    counts, observed_goals = {}, set()
    with AnyReader([out / "run.mcap"], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        for conn, _, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            counts[conn.topic] = counts.get(conn.topic, 0) + 1
            if conn.topic == topics.TOUCH_DONE and msg.message in ("contact", "free_space"):
                observed_goals.add({kv.key: kv.value for kv in msg.values}["goal_stamp_ns"])
    for topic in (topics.CONTACTS, topics.GOAL, topics.PATH, topics.VARIANCE_MAP,
                  topics.TOUCH_DONE, topics.JOINT_STATES, topics.CLOCK):
        assert counts.get(topic, 0) > 0, f"{topic} not recorded: {sorted(counts)}"
    # every touch that observed something is recorded once (an unreachable goal, or a report the
    # commander sent again for a goal it saw twice, adds a message, never a touch)
    assert len(observed_goals) == touches, (counts[topics.TOUCH_DONE], sorted(observed_goals))

    # Offline re-analysis: same final IoU, and the planner re-makes every decision
    # of the graph from the graph's own observations (same code, parameters, seed).
    re = subprocess.run(["bash", str(ROOT / "scripts/replay.sh"), str(out / "run.mcap"), "--offline"],
                        env=domain_env, capture_output=True, text=True, timeout=300)
    assert re.returncode == 0, re.stdout + re.stderr
    again = json.loads((out / "reanalysis" / "report.json").read_text())
    assert again["summary"]["final_iou"] == pytest.approx(report["summary"]["final_iou"], abs=1e-12)
    assert [d["same"] for d in again["decisions"]] == [True] * touches, again["decisions"]

    # The offline loop (the rig, driver and commander plans in one process) makes the same touches,
    # although the graph ran with both cores kept busy: same outcomes, every observation within 0.5 mm.
    offline = ExplorationLoop(Experiment(mode="2d", object_name="kidney", touches=touches, seed=2)).run()
    assert [t["outcome"] for t in offline["touches"]] == [t["outcome"] for t in report["touches"]]
    gaps_mm = [1e3 * float(np.linalg.norm(np.subtract(_observation(a), _observation(b))))
               for a, b in zip(offline["touches"], report["touches"])]
    assert max(gaps_mm) <= 0.5, gaps_mm


def test_ctrl_c_keeps_the_report_and_resume_completes_the_run(domain_env, tmp_path, kidney_run):
    """Ctrl-C after touch 5 of 10 stops every node and keeps the report; ``--resume`` continues
    the run from its recorded observations into the same folder, and the whole run compares with
    an uninterrupted run of the same seed."""
    out = tmp_path / "run"
    proc = subprocess.Popen(["bash", str(ROOT / "scripts/explore.sh"), "--out", str(out), *KIDNEY],
                            env=domain_env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            stdin=subprocess.DEVNULL, start_new_session=True)
    try:
        deadline = time.monotonic() + 300
        log = out / "logs" / "explorer.log"
        while time.monotonic() < deadline:  # wait for the fifth finished touch
            if log.exists() and "touch   5/10" in log.read_text():
                break
            assert proc.poll() is None, proc.stdout.read()
            time.sleep(0.2)
        else:
            pytest.fail("5 touches did not finish within 300 s\n" + _logs(out))
        os.killpg(proc.pid, signal.SIGINT)  # what Ctrl-C in the terminal sends
        output, _ = proc.communicate(timeout=90)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 130, output[-3000:]
    cut = json.loads((out / "report.json").read_text())
    assert cut["summary"]["stopped_because"] == "interrupted" and 5 <= len(cut["touches"]) < 10
    from mcap.reader import make_reader

    with open(out / "run.mcap", "rb") as fh:  # finalised: the summary section is there
        assert make_reader(fh).get_summary().statistics.message_count > 0
    left = subprocess.run(["pgrep", "-f", str(out)], capture_output=True, text=True).stdout.split()
    assert left == [], f"processes left behind: {left}"

    # A resume may not change what the run is.
    refused = subprocess.run(["bash", str(ROOT / "scripts/explore.sh"), "--resume", str(out), "--seed", "3"],
                             env=domain_env, capture_output=True, text=True, timeout=60)
    assert refused.returncode == 2 and "--resume continues a run with its own" in refused.stderr

    resumed = subprocess.run(["bash", str(ROOT / "scripts/explore.sh"), "--resume", str(out)], env=domain_env,
                             capture_output=True, text=True, timeout=420, stdin=subprocess.DEVNULL)
    assert resumed.returncode == 0, resumed.stdout[-3000:] + resumed.stderr[-3000:] + _logs(out / "logs" / "resume1")
    assert (out / "run.resume1.mcap").stat().st_size > 0 and "run.resume1.mcap" in resumed.stdout
    whole = json.loads((out / "report.json").read_text())
    check_report(whole)
    assert whole["summary"]["stopped_because"] == "touch budget" and len(whole["touches"]) == 10
    # The touches before the cut are the ones the interrupted run reported (rebuilt from its recording).
    for before, after in zip(cut["touches"], whole["touches"]):
        for key in ("index", "target", "contact", "normal", "outcome"):
            assert before[key] == after[key], (key, before, after)
        for key in ("travel_m", "time_s", "iou"):
            assert after[key] == pytest.approx(before[key], abs=1e-9), (key, before, after)
    # Travel and time go on from where they were; the resumed session starts at the start position.
    n = len(cut["touches"])
    assert whole["touches"][n]["travel_m"] > cut["touches"][-1]["travel_m"]
    # The same seed uninterrupted: the same first touch (graph runs of one seed sense it identically),
    # the same budget, and an estimate at the end no worse than 0.05 below it (after the resume the
    # runs part: the resumed session starts at the start position, so its travel costs differ).
    k_out, k_result = kidney_run
    assert k_result.returncode == 0, k_result.stderr[-2000:]
    straight = json.loads((k_out / "report.json").read_text())
    assert len(straight["touches"]) == len(whole["touches"])
    assert np.allclose(whole["touches"][0]["target"], straight["touches"][0]["target"], atol=5e-4)
    assert whole["summary"]["final_iou"] >= straight["summary"]["final_iou"] - 0.05, \
        (whole["summary"]["final_iou"], straight["summary"]["final_iou"])
    # The recordings of both sessions re-analyse to the resumed run's final estimate.
    re = subprocess.run(["bash", str(ROOT / "scripts/replay.sh"), str(out / "run.mcap"), "--offline"],
                        env=domain_env, capture_output=True, text=True, timeout=300)
    assert re.returncode == 0 and "2 sessions" in re.stdout, re.stdout + re.stderr
    again = json.loads((out / "reanalysis" / "report.json").read_text())
    assert again["summary"]["final_iou"] == pytest.approx(whole["summary"]["final_iou"], abs=1e-12)


def test_bad_choices_fail_before_any_node_starts(domain_env, tmp_path):
    for args, message in ((["--object", "no_such_shape"], "unknown object"),
                          (["--strategy", "fastest"], "unknown strategy"),
                          (["--mode", "4d"], "invalid choice"),
                          (["--real-time-factor", "fast"], "real-time-factor")):
        result = _explore(domain_env, tmp_path / args[0].strip("-"), *args, timeout_s=120)
        assert result.returncode == 2, (args, result.stdout, result.stderr)
        assert message in result.stderr and "Traceback" not in result.stderr, result.stderr
        assert not (tmp_path / args[0].strip("-") / "logs" / "explorer.log").exists()


def test_hardware_rig_refuses_without_joint_states(domain_env, tmp_path):
    """--rig hardware starts no simulator and refuses to move without ros2_control's joint states."""
    port = tmp_path / "fake_tty"
    port.touch()
    result = _explore(domain_env, tmp_path / "run", "--rig", "hardware", "--sensor-port", str(port), "--yes",
                      timeout_s=120)
    assert result.returncode == 1, result.stdout + result.stderr
    assert "no message on /joint_states" in result.stderr
    assert not (tmp_path / "run" / "logs" / "sim_rig.log").exists()
    assert not (tmp_path / "run" / "logs" / "arm_commander.log").exists(), "nothing that moves was started"
