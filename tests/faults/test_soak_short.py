"""The long-run check, short (CI): a 12-touch 2D graph run with the soak monitor on.

``scripts/bench.sh soak`` runs the long version (200 touches 2D, 100 touches 3D;
docs/reliability.md, "Long runs"). Here the same pipeline (tactile_bringup.soak)
samples a short run and the test checks that it found every node process and
the recording, that the report gave a decision time per touch, that explore.sh
left no node running, and that no node's resident memory grew by more than
RSS_RISE_MB between touch 4 and the last touch before the run's end (the last
interval holds the report and progress.png, not a touch).
"""

from pathlib import Path

import numpy as np
import pytest

from tactile_bringup.soak import NODES, analyse, print_result, run_soak

pytestmark = [pytest.mark.graph, pytest.mark.slow]

TOUCHES = 12
#: Largest rise of a node's RSS from touch 4 to touch 11. The 200-touch run rose at most
#: 12 MB (the estimator, touches 20-40, then flat): a leak of 2 MB per touch fails here.
RSS_RISE_MB = 15.0


def test_a_short_soak_samples_every_node_and_memory_stays_bounded(domain_env, tmp_path):
    out = tmp_path / "2d"
    res = run_soak("2d", TOUCHES, out, seed=1, interval_s=0.5, max_minutes=4.0, env=domain_env)
    console = Path(f"{out}.log").read_text(errors="replace")[-3000:]
    assert res["status"] == 0 and res["stopped_because"] == "touch budget", console
    assert res["left_running"] == [], "explore.sh left nodes of the run running"
    seen = set().union(*(s["rss_mb"].keys() for s in res["samples"]))
    assert seen == set(NODES), f"node processes never found: {set(NODES) - seen}"

    a = analyse(res, warmup=4)
    print_result(dict(res, analysis=a))  # the curves, in the test's output
    assert a["touches"] == TOUCHES and a["last_judged"] == TOUCHES - 1
    c = {k: np.array([np.nan if v is None else v for v in vals], dtype=float) for k, vals in a["curves"].items()}
    assert np.isfinite(c["decision_ms"]).all() and (c["decision_ms"] > 0).all()
    mcap = c["mcap_mb"]
    assert np.isfinite(mcap).all() and (np.diff(mcap) >= 0).all() and mcap[-1] > mcap[0] > 0
    assert mcap[-1] <= (out / "run.mcap").stat().st_size / 1e6 + 1e-3  # sampled while written (curves: 1 kB steps)
    assert a["growth"]["mcap_mb"]["slope"] > 0
    for node in NODES:
        rss = c[f"{node}_mb"]
        assert np.isfinite(rss[3:]).all(), f"{node}: no RSS sample after touch 4"
        rise = np.max(rss[3:TOUCHES - 1]) - rss[3]
        assert rise <= RSS_RISE_MB, f"{node}: RSS rose {rise:.1f} MB from touch 4 to {TOUCHES - 1} ({rss.round(1)})"
