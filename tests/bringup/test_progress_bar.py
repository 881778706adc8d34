"""The sweep's progress line and its failure handling (a fake clock: no sleeps)."""

import io
import shlex

import pytest

from tactile_bringup.progress_bar import ProgressBar, format_duration
from tactile_bringup.sweep import failure_line, guarded, is_failure, job_command


class FakeClock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


class Tty(io.StringIO):
    def isatty(self):
        return True


def test_time_left_and_counts_in_a_log():
    clock, out = FakeClock(), io.StringIO()
    bar = ProgressBar(4, stream=out, clock=clock, width=8)
    clock.t += 30.0
    bar.update(True, "run a")
    clock.t += 30.0
    bar.update(False, "run b failed")
    # 2 of 4 finished in 60 s: 60 s left.
    assert bar.left_s() == pytest.approx(60.0)
    lines = out.getvalue().splitlines()
    assert lines == ["[1/4, 0 failed, ~1 min 30 s left] run a", "[2/4, 1 failed, ~1 min 00 s left] run b failed"]
    assert bar.status() == "[####----] 2/4 runs, 1 failed, 1 min 00 s elapsed, ~1 min 00 s left"
    bar.update(True)
    bar.update(True)
    assert bar.status().endswith("done")


def test_terminal_redraws_one_line():
    clock, out = FakeClock(), Tty()
    bar = ProgressBar(2, stream=out, clock=clock, width=4)
    bar.update(True, "a")
    bar.update(True, "b")
    bar.close()
    text = out.getvalue()
    assert text.startswith("a\n[##--] 1/2")
    assert "\r\033[Kb\n[####] 2/2 runs, 0 failed" in text and text.endswith("done\n")


def test_format_duration_and_bad_total():
    assert [format_duration(s) for s in (None, 5, 65, 3725)] == ["?", "5 s", "1 min 05 s", "1 h 02 min"]
    with pytest.raises(ValueError, match="total must be at least 1"):
        ProgressBar(0)


def _boom(job):
    raise RuntimeError("planner exploded\nsecond line")


def test_a_failed_job_is_reported_with_its_command():
    job = dict(mode="3d", object="my cup.stl", strategy="random", seed=3, touches=9, alpha=None,
               params=["/tmp/a b.yaml"])
    result = guarded(_boom, job)
    assert is_failure(result)
    assert result["error"] == "RuntimeError: planner exploded"
    assert "Traceback" in result["traceback"]
    argv = shlex.split(result["command"])
    assert argv[0] == "tactile-explore-offline"
    opts = dict(zip(argv[1::2], argv[2::2]))
    assert opts == {"--mode": "3d", "--object": "my cup.stl", "--strategy": "random", "--seed": "3",
                    "--touches": "9", "--params": "/tmp/a b.yaml"}
    assert "repeat with: tactile-explore-offline" in failure_line(result)
    ok = guarded(lambda j: {"summary": {}}, job)
    assert not is_failure(ok)
    assert "--alpha 2.5" in job_command({**job, "alpha": 2.5})
