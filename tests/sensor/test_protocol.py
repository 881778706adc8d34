"""Sensor frame protocol: round trip, CRC against a bitwise reference, fuzzing, gaps."""

import struct

import numpy as np
import pytest

from tactile_driver.protocol import (
    HEADER_SIZE, MAX_TAXELS, FrameDecoder, crc16_ccitt, encode_frame, frame_size,
)


def crc_bitwise(data: bytes) -> int:
    """CRC-16/CCITT-FALSE, bit by bit (independent reference)."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) if crc & 0x8000 else (crc << 1)
            crc &= 0xFFFF
    return crc


def test_crc_matches_reference_and_check_value():
    assert crc16_ccitt(b"123456789") == 0x29B1
    rng = np.random.default_rng(0)
    for n in (0, 1, 7, 100):
        data = rng.integers(0, 256, n, dtype=np.uint8).tobytes()
        assert crc16_ccitt(data) == crc_bitwise(data)


def test_frame_layout_byte_by_byte():
    frame = encode_frame(0x1234, 0x0102030405060708, np.array([1, 0xBEEF], dtype=np.uint16))
    assert len(frame) == frame_size(2) == HEADER_SIZE + 4 + 2
    assert frame[:2] == b"\xaa\x55"
    assert frame[2:4] == b"\x34\x12"
    assert frame[4:12] == bytes([8, 7, 6, 5, 4, 3, 2, 1])
    assert frame[12:14] == b"\x02\x00"
    assert frame[14:18] == b"\x01\x00\xef\xbe"
    assert struct.unpack("<H", frame[18:20])[0] == crc_bitwise(frame[2:18])


def test_round_trip_in_random_chunks():
    rng = np.random.default_rng(1)
    sent = [(k, 5000 * k + 17, rng.integers(0, 65536, 96).astype(np.uint16)) for k in range(50)]
    stream = b"".join(encode_frame(*f) for f in sent)
    dec = FrameDecoder()
    got = []
    pos = 0
    while pos < len(stream):
        n = int(rng.integers(1, 300))
        got += dec.feed(stream[pos : pos + n])
        pos += n
    assert [(f.seq, f.timestamp_us) for f in got] == [(k, t) for k, t, _ in sent]
    for f, (_, _, v) in zip(got, sent):
        np.testing.assert_array_equal(f.values, v)
    assert dec.stats.frames == 50 and dec.stats.gaps == 0 and dec.stats.crc_errors == 0


def test_encoder_rejects_bad_input():
    with pytest.raises(ValueError, match="in \\[0, 65535\\]"):
        encode_frame(0, 0, np.array([70000]))
    with pytest.raises(ValueError, match="entries"):
        encode_frame(0, 0, np.zeros(MAX_TAXELS + 1))


def test_pure_garbage_never_crashes_nor_yields_frames():
    rng = np.random.default_rng(2)
    dec = FrameDecoder()
    # Dense sync words make false starts with random lengths and CRCs likely.
    for _ in range(200):
        chunk = rng.integers(0, 256, int(rng.integers(1, 2000)), dtype=np.uint8)
        chunk[rng.random(chunk.size) < 0.05] = 0xAA
        frames = dec.feed(chunk.tobytes())
        for f in frames:  # a frame out of garbage must at least carry a valid CRC
            raw = encode_frame(f.seq, f.timestamp_us, f.values)
            assert crc16_ccitt(raw[2:-2]) == struct.unpack("<H", raw[-2:])[0]
    assert dec.stats.frames <= 1  # 2**-16 per false start with a matching CRC


def test_garbage_and_corruption_between_valid_frames():
    rng = np.random.default_rng(3)
    dec = FrameDecoder()
    stream = bytearray()
    expected, n_corrupt = [], 0
    for k in range(300):
        if rng.random() < 0.3:
            stream += rng.integers(0, 256, int(rng.integers(1, 40)), dtype=np.uint8).tobytes()
        if rng.random() < 0.2:
            stream += b"\xaa\x55" + rng.integers(0, 256, 10, dtype=np.uint8).tobytes()  # false sync
        values = rng.integers(0, 65536, 40).astype(np.uint16)
        frame = bytearray(encode_frame(k, k, values))
        if rng.random() < 0.1:
            frame[int(rng.integers(2, len(frame)))] ^= 0x10
            n_corrupt += 1
        else:
            expected.append(k)
        stream += frame
    got = []
    for i in range(0, len(stream), 97):
        got += dec.feed(bytes(stream[i : i + 97]))
    assert [f.seq for f in got] == expected, "every intact frame, no corrupted one"
    assert dec.stats.crc_errors + dec.stats.bad_lengths >= n_corrupt
    assert dec.stats.garbage_bytes > 0 and dec.stats.resyncs > 0


def test_sequence_gaps_are_counted_with_wrap_around():
    dec = FrameDecoder()
    seqs = [65530, 65531, 65534, 65535, 0, 1, 5, 6]  # gaps: 65531->65534 (2 lost), 1->5 (3 lost)
    stream = b"".join(encode_frame(s, 0, np.ones(4, np.uint16)) for s in seqs)
    assert len(dec.feed(stream)) == len(seqs)
    assert dec.stats.gaps == 2
    assert dec.stats.lost_frames == 5


def test_joining_mid_frame_is_not_a_fault_but_later_garbage_is():
    frames = [encode_frame(k, k, np.full(8, k, np.uint16)) for k in range(4)]
    dec = FrameDecoder()
    got = dec.feed(frames[0][7:] + frames[1] + b"\x01\x02\xaa" + frames[2])
    assert [f.seq for f in got] == [1, 2]
    assert dec.stats.startup_bytes == len(frames[0]) - 7
    assert dec.stats.resyncs == 1 and dec.stats.garbage_bytes == 3
    dec.reset()  # a reconnect: joining again
    assert [f.seq for f in dec.feed(frames[3][3:] + frames[3])] == [3]
    assert dec.stats.startup_bytes == len(frames[0]) - 7 + len(frames[3]) - 3 and dec.stats.resyncs == 1
