"""Map device timestamps to host (ROS) time (ROS-free).

host_time(frame) = device_time + offset, offset = min over the last
``window_s`` of (arrival host time - device time). Transport only adds delay,
so the smallest difference is the best estimate of the clock offset; the
window lets it follow a slow drift. A device clock that jumps backwards
(reboot, reconnect) or an offset that jumps by more than ``max_jump_s``
restarts the estimate.
"""

from __future__ import annotations

from collections import deque


class DeviceClock:
    """Sliding-window minimum of host - device time differences."""

    def __init__(self, window_s: float = 2.0, max_jump_s: float = 1.0) -> None:
        self.window_s = window_s
        self.max_jump_s = max_jump_s
        self._samples: deque[tuple[float, float]] = deque()  # (host arrival, offset), offsets increasing
        self._last_device_s: float | None = None
        self.resets = 0

    def reset(self) -> None:
        self._samples.clear()
        self._last_device_s = None

    def to_host(self, device_s: float, arrival_host_s: float) -> float:
        """Host time of a frame stamped ``device_s`` that arrived at ``arrival_host_s``."""
        offset = arrival_host_s - device_s
        if self._last_device_s is not None and (
            device_s < self._last_device_s or (self._samples and abs(offset - self._samples[0][1]) > self.max_jump_s)
        ):
            self.reset()
            self.resets += 1
        self._last_device_s = device_s
        while self._samples and self._samples[-1][1] >= offset:  # monotonic deque of minima
            self._samples.pop()
        self._samples.append((arrival_host_s, offset))
        while self._samples[0][0] < arrival_host_s - self.window_s:
            self._samples.popleft()
        return device_s + self._samples[0][1]
