"""The results of a sweep, one line per finished run, kept on disk as they come.

``runs.jsonl`` in the sweep's output folder holds one JSON object per line:
``{"key": K, "report": {...}}`` for a run that finished, or ``{"key": K,
"failure": {...}}`` for one that raised. ``K`` (:func:`job_key`) names the
job by everything that decides its result: mode, object, strategy, seed,
touch budget, alpha, touch kind, and the *content* of each parameter file
(an edited file makes a new job). Each line is flushed and synced before the
next run is counted, so a sweep stopped by Ctrl-C, a crash or a lost cluster
keeps every run it had finished; started again with the same ``--out`` it runs
only the jobs without a report (failed ones are tried again). A last line cut
by a crash is ignored with a warning; lines of other settings are kept in the
file and left out of this sweep's summary.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import Iterable, Optional

#: file name of the log in the sweep's output folder
LOG_NAME = "runs.jsonl"

_KEY_FIELDS = ("mode", "object", "strategy", "seed", "touches", "alpha", "touch")


def _digest(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()[:16]


def _file_bytes(path: str) -> bytes:
    """A file's bytes (an unreadable file counts as empty: the run itself will say why)."""
    try:
        return Path(path).read_bytes()
    except OSError:
        return b""


def job_key(job: dict) -> str:
    """A stable text naming the job by what decides its result (see the module docstring):
    the parameter files by name and content (``params_text`` when the job carries it, else
    read from disk), an object file (``object_file``) by its content too."""
    fields = {k: job.get(k) for k in _KEY_FIELDS}
    paths = [str(p) for p in job.get("params") or []]
    texts = job.get("params_text")
    data = [t.encode() for t in texts] if texts is not None else [_file_bytes(p) for p in paths]
    fields["params"] = [f"{Path(p).name}:{_digest(d)}" for p, d in zip(paths, data)]
    if job.get("object_file") is not None:
        fields["object_sha256"] = _digest(job["object_file"])
    return json.dumps(fields, sort_keys=True, separators=(",", ":"))


def _key(job: dict) -> str:
    """The job's key: the one it carries (``make_jobs`` sets it), else :func:`job_key`."""
    return job.get("key") or job_key(job)


class SweepLog:
    """Append-only JSON-lines record of a sweep's finished runs (see the module docstring).

    Args:
        path: the ``runs.jsonl`` file (created with its folder on the first record).
    """

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self.reports: dict[str, dict] = {}
        self.failures: dict[str, dict] = {}
        self.cut_lines = 0
        if self.path.exists():
            self._load()

    def _load(self) -> None:
        lines = self.path.read_bytes().split(b"\n")
        for number, raw in enumerate(lines, start=1):
            if not raw.strip():
                continue
            try:
                rec = json.loads(raw)
                key = rec["key"]
            except (ValueError, KeyError, TypeError):
                self.cut_lines += 1  # a line cut by a crash (or edited by hand): that run is repeated
                continue
            if "report" in rec:
                self.reports[key] = rec["report"]
                self.failures.pop(key, None)
            elif "failure" in rec and key not in self.reports:
                self.failures[key] = rec["failure"]

    def done(self, key: str) -> bool:
        """Whether the job of ``key`` has a report (a failed job is not done)."""
        return key in self.reports

    def pending(self, jobs: Iterable[dict]) -> list[dict]:
        """The jobs without a report, in their order."""
        return [j for j in jobs if not self.done(_key(j))]

    def add(self, key: str, report: Optional[dict] = None, failure: Optional[dict] = None) -> None:
        """Record one finished run (``report``) or failed one (``failure``), synced to disk."""
        if (report is None) == (failure is None):
            raise ValueError("SweepLog.add takes a report or a failure")
        rec = {"key": key, "report": report} if report is not None else {"key": key, "failure": failure}
        line = json.dumps(rec, allow_nan=False) + "\n"
        self.path.parent.mkdir(parents=True, exist_ok=True)
        if self.path.exists() and self.path.stat().st_size:
            with self.path.open("rb") as f:  # a line cut by a crash gets its own line ended first
                f.seek(-1, os.SEEK_END)
                if f.read(1) != b"\n":
                    line = "\n" + line
        with self.path.open("a", encoding="utf-8") as f:
            f.write(line)
            f.flush()
            os.fsync(f.fileno())
        if report is not None:
            self.reports[key] = report
            self.failures.pop(key, None)
        else:
            self.failures[key] = failure

    def reports_of(self, jobs: Iterable[dict]) -> list[dict]:
        """The reports of these jobs that have one (records of other settings left out)."""
        return [self.reports[k] for k in map(_key, jobs) if k in self.reports]

    def others(self, jobs: Iterable[dict]) -> int:
        """How many reports in the log belong to no job of this sweep."""
        keys = {_key(j) for j in jobs}
        return sum(k not in keys for k in self.reports)
