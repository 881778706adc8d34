"""Non-blocking serial port with reconnection and exponential back-off (ROS-free).

``poll(now_s)`` returns the bytes available now (b"" if none or while
disconnected). A read error (device unplugged, pty closed) closes the port;
reconnection attempts follow at back-off delays doubling from
``backoff_min_s`` to ``backoff_max_s``, reset by a successful open. Input
already buffered when the port opens is discarded (it is stale).
"""

from __future__ import annotations

import logging
from typing import Callable, Optional

import serial

_log = logging.getLogger(__name__)


class SerialLink:
    """One serial device path, reopened whenever it disappears."""

    def __init__(
        self,
        port: str,
        baud: int,
        backoff_min_s: float = 0.1,
        backoff_max_s: float = 2.0,
        opener: Callable[..., serial.Serial] = serial.Serial,
        read_size: int = 65536,
    ) -> None:
        if not port:
            raise ValueError("serial port path is empty")
        if baud <= 0:
            raise ValueError(f"baud must be > 0, got {baud}")
        if not 0 < backoff_min_s <= backoff_max_s:
            raise ValueError("need 0 < backoff_min_s <= backoff_max_s")
        self.port, self.baud = port, baud
        self.backoff_min_s, self.backoff_max_s = backoff_min_s, backoff_max_s
        self._opener = opener
        self._read_size = read_size
        self._serial: Optional[serial.Serial] = None
        self._next_attempt_s = float("-inf")
        self._backoff_s = backoff_min_s
        self.connects = 0  # successful opens (the first one included)
        self.disconnects = 0  # losses of an open port
        self.failed_attempts = 0
        self.last_error = ""

    @property
    def connected(self) -> bool:
        return self._serial is not None

    @property
    def reconnects(self) -> int:
        return max(0, self.connects - 1)

    def poll(self, now_s: float) -> bytes:
        """Bytes available now; (re)opens the port when due. Never raises for device errors."""
        if self._serial is None:
            if now_s < self._next_attempt_s:
                return b""
            self._open(now_s)
            if self._serial is None:
                return b""
        try:
            return self._serial.read(self._read_size)
        except (serial.SerialException, OSError) as exc:
            self._lost(now_s, str(exc))
            return b""

    def _open(self, now_s: float) -> None:
        try:
            ser = self._opener(self.port, self.baud, timeout=0)
            ser.reset_input_buffer()
        except (serial.SerialException, OSError, ValueError) as exc:
            self.failed_attempts += 1
            self.last_error = str(exc)
            self._next_attempt_s = now_s + self._backoff_s
            self._backoff_s = min(2 * self._backoff_s, self.backoff_max_s)
            return
        self._serial = ser
        self.connects += 1
        self._backoff_s = self.backoff_min_s
        _log.info("opened %s", self.port)

    def _lost(self, now_s: float, reason: str) -> None:
        self.close()
        self.disconnects += 1
        self.last_error = reason
        self._next_attempt_s = now_s + self._backoff_s

    def close(self) -> None:
        if self._serial is not None:
            try:
                self._serial.close()
            except (serial.SerialException, OSError):
                pass
            self._serial = None
