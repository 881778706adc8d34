"""The simulated tactile sensor as a virtual serial device on a pseudo-terminal (ROS-free).

``open()`` creates a pty in raw mode and a symlink ``link_path`` to its slave
side, so the driver opens ``link_path`` exactly like the physical sensor's
serial port. The caller drives time: ``step(now_s)`` writes every frame due
up to the simulated time ``now_s`` (frame k at t0 + k / frame_rate_hz), with
the taxel counts of the pose last given to ``set_pose`` and the device
timestamp t_k in microseconds. Bytes the pty cannot take yet (reader
stalled) wait in a small transmit buffer; when that is full, whole frames are
lost, as on a real serial line.

Faults (:class:`FaultConfig`, all seeded): garbage bytes between frames, a
corrupted byte (bad CRC), dropped frames (sequence gaps), a stuck taxel, and a
disconnect (the pty and link disappear for a while, then a new pty appears
at the same link).
"""

from __future__ import annotations

import logging
import os
import tty
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional

import numpy as np

from tactile_driver.protocol import encode_frame
from tactile_driver.taxels import TaxelLayout
from tactile_sim.sensor_model import SensorModel, SensorModelConfig

_log = logging.getLogger(__name__)


@dataclass(frozen=True)
class FaultConfig:
    """Injected faults. Probabilities are per frame; times are simulated seconds since the first step."""

    garbage_prob: float = 0.0  # a burst of random bytes before a frame
    garbage_max_bytes: int = 32
    crc_error_prob: float = 0.0  # one payload byte flipped after the CRC is computed
    drop_prob: float = 0.0  # the frame is not sent (its sequence number is used)
    stuck_taxel: int = -1  # index of a taxel stuck at ``stuck_value`` (-1: none)
    stuck_value: int = 4000
    stuck_after_s: float = 0.0
    disconnect_at_s: float = -1.0  # negative: never
    disconnect_for_s: float = 1.0

    def validate(self, n_taxels: int) -> "FaultConfig":
        for name in ("garbage_prob", "crc_error_prob", "drop_prob"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"fault {name} must be a probability in [0, 1]")
        if self.stuck_taxel >= n_taxels:
            raise ValueError(f"stuck_taxel {self.stuck_taxel} >= number of taxels {n_taxels}")
        if not 0 <= self.stuck_value <= 0xFFFF:
            raise ValueError("stuck_value must be in [0, 65535]")
        return self


@dataclass
class DeviceStats:
    """What the device did (to compare with the driver's diagnostics)."""

    frames_sent: int = 0
    frames_dropped: int = 0  # by the drop fault
    frames_lost: int = 0  # transmit buffer full (reader stalled), backlog skipped, or disconnected
    garbage_bursts: int = 0
    garbage_bytes: int = 0
    crc_corrupted: int = 0
    disconnects: int = 0
    reconnects: int = 0


def motion_key(positions_rad: np.ndarray) -> int:
    """The noise key of a commanded motion (K, n) joint positions: a checksum of where it starts and
    ends, rounded to a µrad, so the same motion gets the same key on every run even when its joints
    differ in the last bits (a contact placed 1e-15 m apart moves the next plan by as much)."""
    q = np.asarray(positions_rad, dtype=float)
    ends = np.round(np.vstack([q[0], q[-1]]) * 1e6).astype(np.int64)
    return zlib.crc32(ends.tobytes())


class SimulatedSensorDevice:
    """A pty speaking the sensor protocol, fed by :class:`SensorModel`."""

    #: Frames older than this behind ``now_s`` are skipped, not written in a burst.
    MAX_BACKLOG_S = 0.5
    #: Unloaded frames repeat this many noise vectors (the driver's calibration_frames, 40 by
    #: default, must be a multiple of it for a timing-independent baseline).
    IDLE_NOISE_PERIOD = 8
    #: Transmit buffer of the device: bytes the pty did not take yet are sent later.
    TX_BUFFER_BYTES = 8192

    def __init__(
        self,
        obj: Any,
        layout: TaxelLayout,
        link_path: str | os.PathLike,
        frame_rate_hz: float = 200.0,
        seed: int = 0,
        faults: FaultConfig = FaultConfig(),
        model_config: SensorModelConfig = SensorModelConfig(),
    ) -> None:
        if frame_rate_hz <= 0:
            raise ValueError("frame_rate_hz must be > 0")
        self.obj = obj
        self.layout = layout
        self.link_path = Path(link_path)
        self.frame_rate_hz = float(frame_rate_hz)
        self.faults = faults.validate(layout.n_taxels)
        self.model = SensorModel(layout, model_config, seed=seed)
        self.stats = DeviceStats()
        self._rng = np.random.default_rng(seed + 1)  # faults only
        self.seed = int(seed)
        self._motions: list[tuple[int, float]] = []  # (key, start time): the motion under way, then any queued
        self._out = bytearray()  # transmit buffer
        self._master: Optional[int] = None
        self._slave: Optional[int] = None
        self._position = np.array([0.0, 0.0, 1.0e3])  # far from everything until set_pose
        self._rotation = np.eye(3)
        self._t0: Optional[float] = None
        self._k = 0  # index of the next frame
        self._down_until: Optional[float] = None
        self._disconnected_once = False

    # -- lifecycle -----------------------------------------------------------
    def open(self) -> None:
        """Create the pty (raw mode, non-blocking master) and the symlink to its slave."""
        if self._master is not None:
            return
        master, slave = os.openpty()
        tty.setraw(slave)
        os.set_blocking(master, False)
        self._master, self._slave = master, slave
        target = os.ttyname(slave)
        self.link_path.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.link_path.with_name(self.link_path.name + ".tmp")
        if tmp.is_symlink() or tmp.exists():
            tmp.unlink()
        os.symlink(target, tmp)
        os.replace(tmp, self.link_path)  # atomically replaces a stale link
        _log.info("simulated sensor on %s -> %s", self.link_path, target)

    def close(self) -> None:
        """Close the pty and remove the link (if it still points to our pty)."""
        if self._master is None:
            return
        target = os.ttyname(self._slave)
        for fd in (self._master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass
        self._master = self._slave = None
        self._out.clear()
        try:
            if self.link_path.is_symlink() and os.readlink(self.link_path) == target:
                self.link_path.unlink()
        except OSError:
            pass

    @property
    def is_open(self) -> bool:
        return self._master is not None

    # -- simulation ----------------------------------------------------------
    def set_pose(self, position_xyz: np.ndarray, rotation_3x3: np.ndarray) -> None:
        """Fingertip pose in the world frame (fingertip -> world), used by the next frames."""
        p = np.asarray(position_xyz, dtype=float).reshape(3)
        R = np.asarray(rotation_3x3, dtype=float).reshape(3, 3)
        if not (np.all(np.isfinite(p)) and np.all(np.isfinite(R))):
            raise ValueError("fingertip pose must be finite")
        self._position, self._rotation = p, R

    @property
    def backlog_bytes(self) -> int:
        """Bytes the pty did not take yet (after trying to write them now): the reader (driver)
        is behind by at least a kernel buffer."""
        if self.is_open and self._out:
            self._flush()
        return len(self._out) if self.is_open else 0

    def begin_motion(self, key: int, start_s: float) -> None:
        """A commanded motion starts at simulated time ``start_s`` (the rig calls this).

        The noise of every frame that carries a contact load is drawn from a
        counter-based stream keyed on (seed, ``key``, frame index within the
        motion), so a touch senses the same frames whatever the wall-clock
        timing between motions was. ``key`` identifies the motion (the rig
        uses a checksum of the trajectory: the same command gives the same key).
        """
        # A motion that starts later (a timed start) takes over at its start: until then the frames of
        # the motion under way keep their keys (a repeated key would repeat frames: "stuck" taxels).
        self._motions = [m for m in self._motions if m[1] < start_s][-1:] + [(int(key), float(start_s))]

    def noise_rng(self, k: int, t_s: float, loaded: bool) -> np.random.Generator:
        """The noise stream of frame ``k`` at ``t_s`` (see :meth:`begin_motion`).

        Frames without a contact load repeat a pattern of ``IDLE_NOISE_PERIOD``
        noise vectors: every run of the driver's calibration frames (a multiple
        of the period) then has the same mean and spread, wherever the driver
        started reading, and unloaded frames never trip a contact. Loaded
        frames use the motion's keyed stream.
        """
        started = [m for m in self._motions if m[1] <= t_s + 1e-9]
        if loaded and started:
            key, start_s = started[-1]
            j = int(round((t_s - start_s) * self.frame_rate_hz))
            return np.random.default_rng([self.seed, 1, key, j])
        return np.random.default_rng([self.seed, 2, k % self.IDLE_NOISE_PERIOD])

    def frame_values(self, k: int, t_s: float, clean: np.ndarray) -> np.ndarray:
        """(N,) uint16 counts of frame ``k`` at ``t_s`` with noise-free counts ``clean`` (no faults):
        noise from :meth:`noise_rng`, loaded when ``clean`` is not the baseline."""
        loaded = not np.array_equal(clean, self.model.baseline_counts)
        return self.model.add_noise(clean, self.noise_rng(k, t_s, loaded))

    def step(self, now_s: float) -> int:
        """Write every frame due up to simulated time ``now_s``; the number written."""
        if self._t0 is None:
            self._t0 = float(now_s)
        period = 1.0 / self.frame_rate_hz
        due = int(np.floor((now_s - self._t0) * self.frame_rate_hz + 1e-9))
        if due < self._k:
            return 0
        skip_to = due - int(self.MAX_BACKLOG_S * self.frame_rate_hz)
        if skip_to > self._k:
            self.stats.frames_lost += skip_to - self._k
            self._k = skip_to
        self._handle_disconnect(now_s - self._t0)
        if self.is_open and self._out:
            self._flush()
        clean = None
        written = 0
        while self._k <= due:
            t_s = self._t0 + self._k * period
            k = self._k
            self._k += 1
            if not self.is_open:
                self.stats.frames_lost += 1
                continue
            if clean is None:
                clean = self.model.clean_counts(self.obj, self._position, self._rotation)
            written += self._send(k, t_s, clean)
        return written

    def _send(self, k: int, t_s: float, clean: np.ndarray) -> int:
        f = self.faults
        if len(self._out) > self.TX_BUFFER_BYTES:  # the reader stalls: the device drops whole frames
            self.stats.frames_lost += 1
            return 0
        values = self.frame_values(k, t_s, clean)
        if f.stuck_taxel >= 0 and t_s - self._t0 >= f.stuck_after_s:
            values[f.stuck_taxel] = f.stuck_value
        if f.drop_prob and self._rng.random() < f.drop_prob:
            self.stats.frames_dropped += 1
            return 0
        data = bytearray()
        if f.garbage_prob and self._rng.random() < f.garbage_prob:
            n = int(self._rng.integers(1, f.garbage_max_bytes + 1))
            data += self._rng.integers(0, 256, n, dtype=np.uint8).tobytes()
            self.stats.garbage_bursts += 1
            self.stats.garbage_bytes += n
        frame = bytearray(encode_frame(k, int(round(t_s * 1e6)), values))
        if f.crc_error_prob and self._rng.random() < f.crc_error_prob:
            i = int(self._rng.integers(2, len(frame) - 2))
            frame[i] ^= 1 << int(self._rng.integers(0, 8))
            self.stats.crc_corrupted += 1
        data += frame
        self._out += data
        self._flush()
        self.stats.frames_sent += 1
        return 1

    def _flush(self) -> None:
        """Write as much of the transmit buffer as the pty takes now."""
        try:
            n = os.write(self._master, bytes(self._out))
        except (BlockingIOError, InterruptedError):
            return
        except OSError as exc:
            _log.warning("simulated sensor write failed: %s", exc)
            return
        del self._out[:n]

    def _handle_disconnect(self, t_rel_s: float) -> None:
        f = self.faults
        if f.disconnect_at_s < 0:
            return
        if not self._disconnected_once and t_rel_s >= f.disconnect_at_s and self.is_open:
            self.close()
            self._disconnected_once = True
            self._down_until = f.disconnect_at_s + f.disconnect_for_s
            self.stats.disconnects += 1
            _log.info("simulated sensor disconnected at t=%.3f s", t_rel_s)
        elif self._down_until is not None and t_rel_s >= self._down_until:
            self._down_until = None
            self.open()
            self.stats.reconnects += 1
