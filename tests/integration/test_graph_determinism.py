"""Two graph runs of one seed make the same touches, run side by side (each loads the other's cores).

The simulated rig senses in step with the commanded motion (timed starts on
its tick, lock-step with the driver, noise keyed on the motion and the frame),
so wall-clock timing must not change what is sensed, and a touch ends on joints
that do not depend on how late the arm stopped (a path contact backs off to a
waypoint of the plan). Judged from the two run folders only: outcomes equal,
every observation within 0.5 mm.
"""

import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

from tactile_common.testing import DomainLease

ROOT = Path(__file__).resolve().parents[2]
pytestmark = [pytest.mark.graph, pytest.mark.slow]


def _observation(touch: dict) -> np.ndarray:
    return np.asarray(touch["contact"] if touch["contact"] is not None else touch["probe_end"], dtype=float)


def test_two_graph_runs_of_one_seed_touch_the_same_points(tmp_path):
    leases = [DomainLease(), DomainLease()]
    try:
        procs = []
        for i, lease in enumerate(leases):
            env = dict(os.environ, ROS_DOMAIN_ID=str(lease.domain_id))
            env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
            procs.append(subprocess.Popen(
                ["bash", str(ROOT / "scripts/explore.sh"), "--out", str(tmp_path / f"run{i}"), "--object", "kidney",
                 "--touches", "10", "--seed", "5"], env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                text=True, stdin=subprocess.DEVNULL))
        outs = [p.communicate(timeout=600)[0] for p in procs]
    finally:
        for lease in leases:
            lease.release()
    for p, out in zip(procs, outs):
        assert p.returncode == 0, out[-3000:]
    a, b = (json.loads((tmp_path / f"run{i}" / "report.json").read_text())["touches"] for i in range(2))
    assert len(a) == len(b) == 10
    assert [t["outcome"] for t in a] == [t["outcome"] for t in b]
    gaps_mm = [1e3 * float(np.linalg.norm(_observation(s) - _observation(t))) for s, t in zip(a, b)]
    assert max(gaps_mm) <= 0.5, gaps_mm
