"""When the simulated rig's clock may tick: lock-step with the sensing loop (ROS-free).

The rig's clock is the graph's time. On a loaded machine the processes that
sense and react run late; if the clock ran on regardless, an approach would
press on into the object while its contact is still on its way, further than
the offline loop (which stops at the contact's tick) or a rig on a quiet host.
The clock therefore waits, per tick:

1. **for the driver to read** the frames the device has written (a backlog on
   the serial link), at most ``max_hold_s`` wall in a row; then it runs on and
   the device drops frames (a driver that is gone must not stop the rig);
2. **for the sensing loop to keep up**, once it reports progress: while the
   frames the driver has judged (``/tactile/decided_through``), or the frames
   whose contacts the commander has acted on (``/arm/acted_through``, a stop
   included), are more than ``max_lag_s`` (simulated) behind the clock, at most
   ``max_lag_hold_s`` wall at a time; then one tick goes through (joint states
   keep coming, so the commander's watchdog stays fed).

A stop after a contact then lands within ``max_lag_s`` plus a tick of the
contact's frame, however late the processes run. Times: ``t_s`` simulated,
``now_s`` wall (monotonic), seconds.
"""

from __future__ import annotations

from typing import Optional


class ClockGate:
    """Holds the rig's clock while the driver or the commander is behind (module docstring)."""

    def __init__(self, max_hold_s: float, max_lag_s: float, max_lag_hold_s: float) -> None:
        self.max_hold_s = float(max_hold_s)
        self.max_lag_s = float(max_lag_s)  # 0: no lock-step with the sensing loop
        self.max_lag_hold_s = float(max_lag_hold_s)
        self.decided_s: Optional[float] = None  # the driver has judged its frames up to here (simulated)
        self.acted_s: Optional[float] = None  # the commander has acted on their contacts up to here
        self.held_ticks = 0  # ticks held, for any reason
        self.lag_held_ticks = 0  # ticks held for the sensing loop
        self._held_since: Optional[float] = None
        self._lag_held_since: Optional[float] = None

    def on_decided(self, t_s: float) -> None:
        self.decided_s = t_s if self.decided_s is None else max(self.decided_s, t_s)

    def on_acted(self, t_s: float) -> None:
        self.acted_s = t_s if self.acted_s is None else max(self.acted_s, t_s)

    def through_s(self) -> Optional[float]:
        """How far the sensing loop has come: the driver's progress, and the commander's once it reports."""
        if self.decided_s is None:
            return None
        return self.decided_s if self.acted_s is None else min(self.decided_s, self.acted_s)

    def lagging(self, t_s: float) -> bool:
        through = self.through_s()
        return self.max_lag_s > 0 and through is not None and t_s - through > self.max_lag_s

    def hold(self, t_s: float, backlog_bytes: int, now_s: float) -> bool:
        """True: do not tick now (the clock is at ``t_s``; the device has ``backlog_bytes`` unread)."""
        if backlog_bytes == 0 and self.lagging(t_s):
            if self._lag_held_since is None:
                self._lag_held_since = now_s
            if now_s - self._lag_held_since <= self.max_lag_hold_s:
                self.held_ticks += 1
                self.lag_held_ticks += 1
                return True
            self._lag_held_since = None  # waited long enough: one tick goes through
            return False
        self._lag_held_since = None
        if backlog_bytes == 0:
            self._held_since = None
            return False
        if self._held_since is None:
            self._held_since = now_s
        if now_s - self._held_since > self.max_hold_s:
            return False
        self.held_ticks += 1
        return True
