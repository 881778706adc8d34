"""Progress of a sweep of many runs on stderr: runs done, failed, elapsed and time left.

On a terminal one status line (a bar) is redrawn in place (``\\r``) under
the per-run lines; into a file or pipe each run is one plain line that
starts with the counts (a log stays readable). Time left = elapsed /
finished × remaining (finished counts failed runs too). The clock is
injected so that tests need no sleeps.
"""

from __future__ import annotations

import sys
import time
from typing import Callable, Optional, TextIO


def format_duration(seconds: Optional[float]) -> str:
    """'42 s', '3 min 05 s', '1 h 02 min'; '?' when unknown."""
    if seconds is None or seconds != seconds or seconds < 0:
        return "?"
    s = int(round(seconds))
    if s < 60:
        return f"{s} s"
    if s < 3600:
        return f"{s // 60} min {s % 60:02d} s"
    return f"{s // 3600} h {(s % 3600) // 60:02d} min"


class ProgressBar:
    """Counts finished runs of a sweep of ``total`` and shows where it stands.

    Args:
        total: number of runs in the sweep (>= 1).
        stream: where to write (default stderr).
        clock: seconds, monotonic (default ``time.monotonic``).
        width: characters of the bar.
    """

    def __init__(self, total: int, stream: Optional[TextIO] = None,
                 clock: Callable[[], float] = time.monotonic, width: int = 24) -> None:
        if int(total) < 1:
            raise ValueError(f"total must be at least 1, got {total}")
        self.total = int(total)
        self.stream = stream if stream is not None else sys.stderr
        self.clock = clock
        self.width = int(width)
        self.t0 = clock()
        self.done = 0
        self.failed = 0
        isatty = getattr(self.stream, "isatty", None)
        self.live = bool(isatty()) if callable(isatty) else False
        self._drawn = False

    @property
    def finished(self) -> int:
        return self.done + self.failed

    def elapsed_s(self) -> float:
        return self.clock() - self.t0

    def left_s(self) -> Optional[float]:
        """Estimated seconds left (None before the first run finished)."""
        if self.finished == 0:
            return None
        return self.elapsed_s() / self.finished * (self.total - self.finished)

    def status(self) -> str:
        """e.g. ``[#####-----] 12/40 runs, 1 failed, 2 min 10 s elapsed, ~5 min 03 s left``."""
        filled = int(round(self.width * self.finished / self.total))
        bar = "#" * filled + "-" * (self.width - filled)
        left = "done" if self.finished == self.total else f"~{format_duration(self.left_s())} left"
        return (f"[{bar}] {self.finished}/{self.total} runs, {self.failed} failed, "
                f"{format_duration(self.elapsed_s())} elapsed, {left}")

    def short_status(self) -> str:
        """e.g. ``[12/40, 1 failed, ~5 min 03 s left]`` (the prefix of a log line)."""
        left = "done" if self.finished == self.total else f"~{format_duration(self.left_s())} left"
        return f"[{self.finished}/{self.total}, {self.failed} failed, {left}]"

    def update(self, ok: bool, message: str = "") -> None:
        """One run finished (``ok`` False: it failed); ``message`` is printed above the status."""
        if ok:
            self.done += 1
        else:
            self.failed += 1
        if self.live:
            clear = "\r\033[K" if self._drawn else ""
            text = f"{clear}{message}\n" if message else clear
            self.stream.write(f"{text}{self.status()}")
            self._drawn = True
        else:  # a log: one line per run, the counts first
            self.stream.write(f"{self.short_status()} {message}".rstrip() + "\n")
        self.stream.flush()

    def close(self) -> None:
        """End the redrawn line (a terminal); nothing to do in a log."""
        if self.live and self._drawn:
            self.stream.write("\n")
            self.stream.flush()
            self._drawn = False
