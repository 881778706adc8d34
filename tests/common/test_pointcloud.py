"""PointCloud2 codec against an independent per-point ``struct`` decoding."""

import struct

import numpy as np
import pytest
from sensor_msgs.msg import PointCloud2, PointField

from tactile_common import fields
from tactile_common.pointcloud import PointCloudError, from_pointcloud2, to_pointcloud2

_STRUCT = {PointField.INT8: "b", PointField.UINT8: "B", PointField.INT16: "h",
           PointField.UINT16: "H", PointField.INT32: "i", PointField.UINT32: "I",
           PointField.FLOAT32: "f", PointField.FLOAT64: "d"}


def decode_with_struct(msg: PointCloud2) -> list[dict]:
    """Reference decoder: one point at a time with ``struct``."""
    order = ">" if msg.is_bigendian else "<"
    data = bytes(msg.data)
    out = []
    for row in range(msg.height):
        for col in range(msg.width):
            base = row * msg.row_step + col * msg.point_step
            out.append({f.name: struct.unpack_from(order + _STRUCT[f.datatype], data, base + f.offset)[0]
                        for f in msg.fields})
    return out


def make_cloud(rng, n):
    dtype = np.dtype([("x", "f4"), ("y", "f8"), ("label", "u1"), ("count", "i4"), ("z", "f4")])
    cloud = np.zeros(n, dtype=dtype)
    cloud["x"] = rng.normal(size=n)
    cloud["y"] = rng.normal(size=n)
    cloud["label"] = rng.integers(0, 255, size=n)
    cloud["count"] = rng.integers(-1000, 1000, size=n)
    cloud["z"] = rng.normal(size=n)
    return cloud


def test_encode_matches_struct_reference():
    cloud = make_cloud(np.random.default_rng(0), 7)
    msg = to_pointcloud2(cloud, "world")
    ref = decode_with_struct(msg)
    for name in cloud.dtype.names:
        np.testing.assert_array_equal(cloud[name], [p[name] for p in ref])
    assert msg.point_step == 4 + 8 + 1 + 4 + 4
    assert msg.row_step == 7 * msg.point_step and msg.is_dense


def test_decode_padded_bigendian_organised_cloud():
    """A cloud laid out by someone else: padding in points and rows, big-endian, 2 rows."""
    rng = np.random.default_rng(1)
    height, width, point_step, row_step = 2, 3, 24, 3 * 24 + 8
    fields_ = [PointField(name="x", offset=0, datatype=PointField.FLOAT32, count=1),
               PointField(name="i", offset=8, datatype=PointField.INT32, count=1),
               PointField(name="v", offset=12, datatype=PointField.FLOAT64, count=1)]
    data = bytearray(row_step * height)
    values = []
    for r in range(height):
        for c in range(width):
            x, i, v = float(np.float32(rng.normal())), int(rng.integers(-99, 99)), float(rng.normal())
            struct.pack_into(">f", data, r * row_step + c * point_step, x)
            struct.pack_into(">i", data, r * row_step + c * point_step + 8, i)
            struct.pack_into(">d", data, r * row_step + c * point_step + 12, v)
            values.append((x, i, v))
    msg = PointCloud2(height=height, width=width, fields=fields_, is_bigendian=True,
                      point_step=point_step, row_step=row_step, data=bytes(data), is_dense=True)
    got = from_pointcloud2(msg)
    ref = decode_with_struct(msg)
    assert got.dtype.names == ("x", "i", "v")
    np.testing.assert_array_equal(got["x"], [p["x"] for p in ref])
    np.testing.assert_array_equal(got["i"], [v[1] for v in values])
    np.testing.assert_array_equal(got["v"], [v[2] for v in values])
    sub = from_pointcloud2(msg, fields=["v", "x"])
    assert sub.dtype.names == ("v", "x")


def test_large_round_trip_and_nan_marks_not_dense():
    rng = np.random.default_rng(2)
    cloud = np.zeros(200_000, dtype=fields.VARIANCE_MAP_DTYPE)
    for name in cloud.dtype.names:
        cloud[name] = rng.normal(size=cloud.size) if name != "kind" else rng.integers(0, 2, cloud.size)
    back = from_pointcloud2(to_pointcloud2(cloud, "world"))
    np.testing.assert_array_equal(back, cloud)
    cloud["mean"][5] = np.nan
    assert not to_pointcloud2(cloud, "world").is_dense


def test_empty_cloud_round_trip():
    cloud = np.zeros(0, dtype=fields.CONTACT_DTYPE)
    back = from_pointcloud2(to_pointcloud2(cloud, "world"))
    assert back.size == 0 and back.dtype.names == fields.CONTACT_DTYPE.names


@pytest.mark.parametrize("mutate, match", [
    (lambda m: setattr(m, "data", bytes(m.data)[:-1]), "expected row_step"),
    (lambda m: setattr(m, "row_step", m.row_step - 1), "row_step"),
    (lambda m: setattr(m, "point_step", 4), "overruns point_step"),
    (lambda m: m.fields.__setitem__(0, PointField(name="x", offset=0, datatype=99, count=1)), "unsupported"),
    (lambda m: m.fields.__setitem__(0, PointField(name="x", offset=0, datatype=7, count=3)), "count 3"),
])
def test_malformed_clouds_raise_clear_errors(mutate, match):
    msg = to_pointcloud2(make_cloud(np.random.default_rng(3), 5), "world")
    mutate(msg)
    with pytest.raises(PointCloudError, match=match):
        from_pointcloud2(msg)


def test_missing_field_and_bad_array():
    msg = to_pointcloud2(make_cloud(np.random.default_rng(4), 3), "world")
    with pytest.raises(PointCloudError, match="no field"):
        from_pointcloud2(msg, fields=["normal_x"])
    with pytest.raises(PointCloudError, match="structured"):
        to_pointcloud2(np.zeros((3, 3)), "world")
