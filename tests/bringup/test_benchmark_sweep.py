"""tactile-benchmark as a sweep: resumed after an interruption, and run on a Dask cluster.

The cluster is a ``distributed.LocalCluster`` this test starts on 127.0.0.1 (two worker
processes); its runs must equal the local process pool's, touch for touch.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

BIN = Path(sys.prefix) / "bin"
SWEEP = ["--objects", "circle", "--strategies", "proposed,random", "--touches", "2"]


def _bench(*args, timeout_s: float = 300.0) -> subprocess.CompletedProcess:
    return subprocess.run([str(BIN / "tactile-benchmark"), *map(str, args)], capture_output=True, text=True,
                          timeout=timeout_s, stdin=subprocess.DEVNULL)


def _touches(out: Path) -> dict:
    """(object, strategy, seed) → every touch's target, contact, travel and IoU (no timings)."""
    runs = json.loads((out / "runs.json").read_text())
    return {(r["object"], r["strategy"], r["seed"]):
            [(t["target"], t["contact"], t["travel_m"], t["iou"]) for t in r["touches"]] for r in runs}


@pytest.fixture(scope="module")
def local_sweep(tmp_path_factory) -> Path:
    """Two seeds of the small sweep on the local pool."""
    out = tmp_path_factory.mktemp("local")
    r = _bench(*SWEEP, "--seeds", "2", "--out", out)
    assert r.returncode == 0, r.stderr
    return out


@pytest.mark.slow
def test_a_sweep_started_again_runs_only_what_it_lacks(local_sweep, tmp_path):
    out = tmp_path / "sweep"
    r = _bench(*SWEEP, "--seeds", "1", "--out", out)
    assert r.returncode == 0, r.stderr
    first = (out / "runs.jsonl").read_text()
    r = _bench(*SWEEP, "--seeds", "2", "--out", out)
    assert r.returncode == 0, r.stderr
    assert "resuming: 2 of 4 runs already in" in r.stderr
    assert "4 runs (1 objects × 2 strategies × 2 seeds, 2 touches), 2 to run on" in r.stderr
    # The kept runs are not touched; the summary covers all four, as one sweep would.
    assert (out / "runs.jsonl").read_text().startswith(first)
    assert len((out / "runs.jsonl").read_text().splitlines()) == 4
    assert _touches(out) == _touches(local_sweep)
    # Other settings into the same folder: the earlier runs are said and left out of the summary.
    r = _bench(*SWEEP, "--seeds", "1", "--touches", "3", "--out", out, "--jobs", "1")
    assert r.returncode == 0, r.stderr
    assert "4 run(s) of other settings left out of this summary" in r.stderr
    assert len(json.loads((out / "runs.json").read_text())) == 2


@pytest.mark.slow
def test_ctrl_c_keeps_the_finished_runs_and_the_same_command_goes_on(tmp_path):
    out = tmp_path / "sweep"
    # runs long enough (10 of ~2 s) that a loaded machine cannot finish them all before the Ctrl-C
    # this test sends once the first is kept
    args = [str(BIN / "tactile-benchmark"), "--objects", "circle", "--strategies", "proposed",
            "--touches", "6", "--seeds", "10", "--jobs", "1", "--out", str(out)]
    # SIGINT as at a terminal: a test runner started in the background (`cmd &` in a script) has it
    # ignored, and an ignored signal stays ignored through exec, so the sweep would never see Ctrl-C
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            stdin=subprocess.DEVNULL, start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    log = out / "runs.jsonl"
    deadline = time.monotonic() + 240.0
    while not (log.exists() and log.read_text().count("\n") >= 1):
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, "no run finished within 240 s"
        time.sleep(0.2)
    os.killpg(proc.pid, signal.SIGINT)  # Ctrl-C reaches the whole process group
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    kept = len(log.read_text().splitlines())
    assert 1 <= kept < 10
    assert f"interrupted: {kept} of 10 runs kept in {log}" in err
    assert "Traceback" not in err
    assert not (out / "runs.json").exists()
    r = _bench(*args[1:])
    assert r.returncode == 0, r.stderr
    assert f"resuming: {kept} of 10 runs already in" in r.stderr
    assert len(json.loads((out / "runs.json").read_text())) == 10


@pytest.fixture(scope="module")
def cluster():
    """A Dask scheduler and two single-threaded worker processes on 127.0.0.1."""
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None, env={"OPENBLAS_NUM_THREADS": "1"}) as c:
        yield c


@pytest.mark.slow
def test_a_cluster_makes_the_runs_of_the_local_pool(local_sweep, cluster, tmp_path):
    out = tmp_path / "cluster"
    r = _bench(*SWEEP, "--seeds", "2", "--out", out, "--cluster", cluster.scheduler_address)
    assert r.returncode == 0, r.stderr
    assert f"on the Dask cluster at {cluster.scheduler_address}: 2 workers, 2 threads" in r.stderr
    assert "[4/4, 0 failed, done]" in r.stderr
    assert _touches(out) == _touches(local_sweep)


def test_a_cluster_with_other_code_is_refused(cluster, monkeypatch):
    from tactile_bringup import sweep_backends

    monkeypatch.setattr(sweep_backends, "code_fingerprint", lambda: "not-this-tree")
    with pytest.raises(sweep_backends.ClusterError, match=r"run other code than this tree .* install this tree"):
        list(sweep_backends.dask_cluster([{"seed": 0}], dict, cluster.scheduler_address))


def test_an_unreachable_scheduler_is_one_line(tmp_path):
    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    t0 = time.monotonic()
    r = _bench(*SWEEP, "--seeds", "1", "--out", tmp_path / "x", "--cluster", f"127.0.0.1:{port}")
    assert r.returncode == 2, r.stderr
    assert f"error: --cluster tcp://127.0.0.1:{port}: cannot reach the Dask scheduler within 10 s" in r.stderr
    assert "Traceback" not in r.stderr
    assert time.monotonic() - t0 < 60


@pytest.mark.parametrize("args, expected", [
    (["--cluster", "localhost"], "--cluster localhost: not a scheduler address"),
    (["--cluster", "127.0.0.1:8786", "--jobs", "2"], "--jobs with --cluster"),
])
def test_bad_cluster_options_are_refused_before_any_run(tmp_path, args, expected):
    r = _bench(*SWEEP, "--out", tmp_path / "x", *args)
    assert r.returncode == 2 and expected in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert not (tmp_path / "x").exists()


@pytest.mark.slow
def test_files_travel_with_the_jobs_and_an_edited_file_is_another_run(tmp_path):
    """The report names the user's files (not the run's private copies); a parameter file edited
    after a sweep makes its runs new ones, the old ones are left out."""
    obj = tmp_path / "square.csv"
    obj.write_text("x,y\n0.46,-0.04\n0.54,-0.04\n0.54,0.04\n0.46,0.04\n")
    params = tmp_path / "mine.yaml"
    params.write_text("soc_planner:\n  ros__parameters:\n    alpha: 1.0\n")
    out = tmp_path / "sweep"
    args = ["--objects", obj, "--strategies", "proposed", "--seeds", "1", "--touches", "2", "--params", params,
            "--out", out, "--jobs", "1"]
    r = _bench(*args)
    assert r.returncode == 0, r.stderr
    report = json.loads((out / "runs.json").read_text())[0]
    assert report["object"] == str(obj) and report["config"]["params_files"][-1] == str(params)
    assert "tactile-run-" not in json.dumps(report)
    params.write_text("soc_planner:\n  ros__parameters:\n    alpha: 2.0\n")
    r = _bench(*args)
    assert r.returncode == 0, r.stderr
    assert "resuming" not in r.stderr and "1 run(s) of other settings left out" in r.stderr
    assert json.loads((out / "runs.json").read_text())[0]["config"]["soc_planner"]["alpha"] == 2.0


def test_a_worker_that_dies_with_a_run_is_replaced_and_the_run_made_again(cluster, tmp_path):
    """The first attempt kills its worker process; the nanny restarts it and Dask runs the job again.
    A job that kills every worker it lands on ends as a failed run (KilledWorker), not as a stopped sweep.
    (One job at a time: a worker's death also counts against the jobs queued on it.)"""
    from tactile_bringup.sweep import is_failure
    from tactile_bringup.sweep_backends import dask_cluster

    def worker(job: dict) -> dict:  # sent by value (cloudpickle): the workers do not import this module
        import os
        from pathlib import Path

        if job["kind"] == "always" or not Path(job["marker"]).exists():
            Path(job["marker"]).touch()
            os._exit(1)  # the worker process dies with the run
        return {"seed": job["seed"]}

    def job(kind: str) -> dict:
        return dict(kind=kind, marker=str(tmp_path / kind), seed=0, object="circle", strategy="proposed",
                    mode="2d", touches=1)

    [(_, once)] = list(dask_cluster([job("once")], worker, cluster.scheduler_address))
    assert once == {"seed": 0}
    [(_, always)] = list(dask_cluster([job("always")], worker, cluster.scheduler_address))
    assert is_failure(always) and always["error"].startswith("KilledWorker"), always
