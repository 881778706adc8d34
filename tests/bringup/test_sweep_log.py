"""The sweep log (runs.jsonl): what a resumed sweep keeps, repeats and leaves out."""

from __future__ import annotations

import json

import pytest

from tactile_bringup.sweep import failure_record, job_command
from tactile_bringup.sweep_backends import ClusterError, cluster_address
from tactile_bringup.sweep_log import SweepLog, job_key


def _job(seed: int = 0, **kw) -> dict:
    job = dict(mode="2d", object="circle", strategy="proposed", seed=seed, alpha=None, touches=3,
               params=[], touch=None)
    job.update(kw)
    return job


def test_reports_survive_a_reload_and_a_failed_job_stays_pending(tmp_path):
    log = SweepLog(tmp_path / "runs.jsonl")
    jobs = [_job(s) for s in range(3)]
    log.add(job_key(jobs[0]), report={"seed": 0})
    log.add(job_key(jobs[1]), failure={"error": "boom"})
    again = SweepLog(tmp_path / "runs.jsonl")
    assert [j["seed"] for j in again.pending(jobs)] == [1, 2]
    assert again.reports_of(jobs) == [{"seed": 0}]
    # A later report of the failed job replaces its failure, also after a reload.
    again.add(job_key(jobs[1]), report={"seed": 1})
    assert [j["seed"] for j in SweepLog(tmp_path / "runs.jsonl").pending(jobs)] == [2]


def test_a_line_cut_by_a_crash_is_ignored_and_the_next_record_starts_its_own_line(tmp_path):
    path = tmp_path / "runs.jsonl"
    log = SweepLog(path)
    log.add(job_key(_job(0)), report={"seed": 0})
    with path.open("a") as f:
        f.write('{"key": "x", "report": {"se')  # the process died while writing
    log = SweepLog(path)
    assert log.cut_lines == 1 and len(log.reports) == 1
    log.add(job_key(_job(1)), report={"seed": 1})
    lines = path.read_text().splitlines()
    assert json.loads(lines[-1])["report"] == {"seed": 1}
    assert SweepLog(path).cut_lines == 1 and len(SweepLog(path).reports) == 2


def test_the_key_follows_the_content_of_a_parameter_file(tmp_path):
    f = tmp_path / "p.yaml"
    f.write_text("soc_planner:\n  ros__parameters:\n    alpha: 1.0\n")
    before = job_key(_job(params=[str(f)]))
    f.write_text("soc_planner:\n  ros__parameters:\n    alpha: 2.0\n")
    assert job_key(_job(params=[str(f)])) != before
    # Carried text counts as the file would.
    assert job_key(_job(params=[str(f)], params_text=[f.read_text()])) == job_key(_job(params=[str(f)]))
    assert job_key(_job(object_file=b"a")) != job_key(_job(object_file=b"b"))
    assert job_key(_job(seed=1)) != job_key(_job(seed=0))


def test_runs_of_other_settings_are_counted_and_left_out(tmp_path):
    log = SweepLog(tmp_path / "runs.jsonl")
    log.add(job_key(_job(0, touches=9)), report={"touches": 9})
    log.add(job_key(_job(0)), report={"touches": 3})
    assert log.others([_job(0)]) == 1
    assert log.reports_of([_job(0)]) == [{"touches": 3}]


def test_add_takes_exactly_one_of_report_and_failure(tmp_path):
    log = SweepLog(tmp_path / "runs.jsonl")
    with pytest.raises(ValueError, match="a report or a failure"):
        log.add("k")
    with pytest.raises(ValueError, match="a report or a failure"):
        log.add("k", report={}, failure={})


def test_a_failure_record_repeats_the_job_without_its_carried_files():
    job = _job(2, touch="slide", params=["/x/p.yaml"], params_text=["a: 1\n"], object_file=b"\0")
    rec = failure_record(job, RuntimeError("lost\nsecond line"))
    assert rec["error"] == "RuntimeError: lost"
    assert "params_text" not in rec["job"] and "object_file" not in rec["job"]
    assert "--touch slide" in rec["command"] and "--params /x/p.yaml" in rec["command"]
    assert json.dumps(rec)  # JSON-safe as it goes into the log
    assert job_command(job) == rec["command"]


@pytest.mark.parametrize("text, address", [
    ("127.0.0.1:8786", "tcp://127.0.0.1:8786"),
    ("tcp://localhost:8786", "tcp://localhost:8786"),
    ("tls://sched.lab:9000", "tls://sched.lab:9000"),
    ("[::1]:8786", "tcp://[::1]:8786"),
])
def test_cluster_addresses(text, address):
    assert cluster_address(text) == address


@pytest.mark.parametrize("text", ["8786", "localhost", "tcp://host:", "udp://host:1", "host:70000", "host:80/x"])
def test_bad_cluster_addresses_say_what_is_expected(text):
    with pytest.raises(ClusterError, match=r"not a scheduler address \(HOST:PORT or tcp://HOST:PORT"):
        cluster_address(text)
