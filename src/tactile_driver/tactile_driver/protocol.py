"""Framed binary protocol of the tactile sensor's serial stream (ROS-free).

One frame (all integers little-endian; byte layout in docs/sensor_protocol.md)::

    offset  size  field
    0       2     sync            0xAA 0x55
    2       2     seq             uint16, +1 per frame, wraps 65535 -> 0
    4       8     timestamp_us    uint64, device clock, microseconds
    12      2     n_taxels        uint16, N (1..MAX_TAXELS)
    14      2N    values          N x uint16 raw taxel counts
    14+2N   2     crc             uint16, CRC-16/CCITT-FALSE over bytes 2 .. 13+2N

CRC-16/CCITT-FALSE: polynomial 0x1021, init 0xFFFF, no reflection, no final
xor (check value 0x29B1 for b"123456789"); ``binascii.crc_hqx(data, 0xFFFF)``.

:class:`FrameDecoder` parses an arbitrary byte stream in chunks: it skips
garbage until a sync word, waits for a complete frame, drops frames whose CRC
fails (and resumes the search one byte after their sync word, so a valid
frame hidden behind a false sync is not lost), and counts sequence gaps.
"""

from __future__ import annotations

import binascii
import struct
from dataclasses import dataclass, field

import numpy as np

SYNC = b"\xaa\x55"
HEADER = struct.Struct("<2sHQH")  # sync, seq, timestamp_us, n_taxels
HEADER_SIZE = HEADER.size  # 14
CRC_SIZE = 2
#: Largest taxel count a frame may declare; a larger count is a false sync.
MAX_TAXELS = 1024
_SEQ_MOD = 1 << 16


def crc16_ccitt(data: bytes) -> int:
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF) of ``data``."""
    return binascii.crc_hqx(data, 0xFFFF)


@dataclass(frozen=True)
class Frame:
    """One decoded frame: sequence number, device time (µs), raw taxel counts."""

    seq: int
    timestamp_us: int
    values: np.ndarray  # (N,) uint16

    @property
    def timestamp_s(self) -> float:
        return self.timestamp_us * 1e-6


def frame_size(n_taxels: int) -> int:
    """Bytes of a frame with ``n_taxels`` values."""
    return HEADER_SIZE + 2 * n_taxels + CRC_SIZE


def encode_frame(seq: int, timestamp_us: int, values: np.ndarray) -> bytes:
    """The bytes of one frame.

    Args:
        seq: sequence number (taken modulo 65536).
        timestamp_us: device time in microseconds, 0 <= t < 2**64.
        values: taxel counts, 1..MAX_TAXELS values in [0, 65535].

    Raises:
        ValueError: a value or count out of range.
    """
    v = np.asarray(values)
    if v.ndim != 1 or not 1 <= v.size <= MAX_TAXELS:
        raise ValueError(f"values must be 1-D with 1..{MAX_TAXELS} entries, got shape {v.shape}")
    if v.size and (np.min(v) < 0 or np.max(v) > 0xFFFF):
        raise ValueError("taxel values must be in [0, 65535]")
    if not 0 <= int(timestamp_us) < 1 << 64:
        raise ValueError(f"timestamp_us {timestamp_us} out of uint64 range")
    body = HEADER.pack(SYNC, int(seq) % _SEQ_MOD, int(timestamp_us), v.size) + v.astype("<u2").tobytes()
    return body + struct.pack("<H", crc16_ccitt(body[2:]))


@dataclass
class DecoderStats:
    """Fault and traffic counters of a :class:`FrameDecoder` (monotonic)."""

    frames: int = 0  # valid frames returned
    bytes_in: int = 0  # bytes fed
    crc_errors: int = 0  # complete frames whose CRC failed (dropped)
    bad_lengths: int = 0  # sync words followed by an impossible taxel count
    resyncs: int = 0  # runs of skipped bytes before a sync word
    garbage_bytes: int = 0  # bytes skipped while searching for a sync word
    gaps: int = 0  # sequence discontinuities between consecutive valid frames
    lost_frames: int = 0  # frames missing according to the sequence numbers
    startup_bytes: int = 0  # bytes skipped before the first valid frame (stream joined mid-frame)

    def as_dict(self) -> dict:
        return dict(self.__dict__)


@dataclass
class FrameDecoder:
    """Streaming decoder: ``feed(chunk)`` returns the complete valid frames in it.

    Keeps at most one partial frame between calls. ``max_taxels`` bounds the
    declared count so that a false sync in garbage cannot stall the stream
    for long.
    """

    max_taxels: int = MAX_TAXELS
    stats: DecoderStats = field(default_factory=DecoderStats)

    def __post_init__(self) -> None:
        self._buf = bytearray()
        self._last_seq: int | None = None

    def reset(self) -> None:
        """Forget buffered bytes and the sequence (e.g. after a reconnect); keep the counters.

        Until the next valid frame, skipped bytes and failed frames count as
        ``startup_bytes``: a stream opened mid-frame is not a fault.
        """
        self._buf.clear()
        self._last_seq = None

    @property
    def _joined(self) -> bool:
        return self._last_seq is not None

    def feed(self, data: bytes) -> list[Frame]:
        """Append ``data`` to the stream; return the valid frames completed by it."""
        self.stats.bytes_in += len(data)
        buf = self._buf
        buf.extend(data)
        frames: list[Frame] = []
        pos = 0
        while True:
            start = buf.find(SYNC, pos)
            if start < 0:
                # Keep a trailing 0xAA: it may be the first half of a sync word.
                keep = 1 if buf[-1:] == SYNC[:1] else 0
                self._skip(len(buf) - keep - pos)
                pos = len(buf) - keep
                break
            self._skip(start - pos)
            pos = start
            if len(buf) - pos < HEADER_SIZE:
                break
            _, seq, ts_us, n = HEADER.unpack_from(buf, pos)
            if not 1 <= n <= self.max_taxels:
                self._fault("bad_lengths")
                pos += 1
                continue
            size = frame_size(n)
            if len(buf) - pos < size:
                break
            (crc,) = struct.unpack_from("<H", buf, pos + size - CRC_SIZE)
            if crc != crc16_ccitt(bytes(buf[pos + 2 : pos + size - CRC_SIZE])):
                self._fault("crc_errors")
                pos += 1
                continue
            values = np.frombuffer(bytes(buf[pos + HEADER_SIZE : pos + size - CRC_SIZE]), dtype="<u2").astype(np.uint16)
            self._count_sequence(seq)
            frames.append(Frame(seq=seq, timestamp_us=ts_us, values=values))
            self.stats.frames += 1
            pos += size
        del buf[:pos]
        return frames

    def _skip(self, n_bytes: int) -> None:
        if n_bytes <= 0:
            return
        if not self._joined:
            self.stats.startup_bytes += n_bytes
            return
        self.stats.resyncs += 1
        self.stats.garbage_bytes += n_bytes

    def _fault(self, counter: str) -> None:
        """A false sync or a corrupted frame: one byte skipped."""
        if not self._joined:
            self.stats.startup_bytes += 1
            return
        setattr(self.stats, counter, getattr(self.stats, counter) + 1)
        self.stats.garbage_bytes += 1

    def _count_sequence(self, seq: int) -> None:
        if self._last_seq is not None:
            missing = (seq - self._last_seq - 1) % _SEQ_MOD
            if missing:
                self.stats.gaps += 1
                if missing < _SEQ_MOD // 2:  # else a repeat or reordering: nothing lost
                    self.stats.lost_frames += missing
        self._last_seq = seq
