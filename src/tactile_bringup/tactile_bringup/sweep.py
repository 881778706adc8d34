"""Run many jobs of a sweep so that one failure does not stop the others.

A job is the dict the benchmark hands to its worker; :func:`guarded` runs the
worker and turns an exception into a failure record that names the job and
the command line that repeats it alone (``tactile-explore-offline ...``).
"""

from __future__ import annotations

import shlex
import traceback
from typing import Any, Callable

#: key of a failure record (a successful run's report never carries it)
FAILED = "_failed"


def job_command(job: dict) -> str:
    """The ``tactile-explore-offline`` command line that runs this one job."""
    args = ["tactile-explore-offline", "--mode", str(job["mode"]), "--object", str(job["object"]),
            "--strategy", str(job["strategy"]), "--seed", str(job["seed"]), "--touches", str(job["touches"])]
    if job.get("alpha") is not None:
        args += ["--alpha", str(job["alpha"])]
    if job.get("touch") is not None:
        args += ["--touch", str(job["touch"])]
    for p in job.get("params") or []:
        args += ["--params", str(p)]
    return shlex.join(args)


def failure_record(job: dict, exc: BaseException) -> dict[str, Any]:
    """``{FAILED: True, "job", "command", "error" (first line), "traceback"}`` of a job that raised."""
    job = {k: v for k, v in job.items() if k not in ("params_text", "object_file")}  # the names say enough
    return {FAILED: True, "job": job, "command": job_command(job),
            "error": f"{type(exc).__name__}: {exc}".splitlines()[0],
            "traceback": "".join(traceback.format_exception(exc))}


def guarded(worker: Callable[[dict], dict], job: dict) -> dict[str, Any]:
    """``worker(job)``, or on any exception its :func:`failure_record`."""
    try:
        return worker(job)
    except Exception as exc:  # noqa: BLE001 - a sweep reports every failure and goes on
        return failure_record(job, exc)


def is_failure(result: dict) -> bool:
    return bool(result.get(FAILED))


def failure_line(result: dict) -> str:
    """One line for the log: what failed, why, and how to repeat it."""
    j = result["job"]
    return (f"FAILED {j['object']} {j['strategy']} seed {j['seed']}: {result['error']}\n"
            f"    repeat with: {result['command']}")
