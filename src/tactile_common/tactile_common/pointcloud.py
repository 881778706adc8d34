"""Vectorised sensor_msgs/PointCloud2 <-> numpy structured array codec.

The PyPI ROS 2 wheels ship no ``sensor_msgs_py``; this replaces its
``read_points``/``create_cloud`` for what the graph needs, without a Python
loop over points.

Supported field datatypes: INT8, UINT8, INT16, UINT16, INT32, UINT32,
FLOAT32, FLOAT64, with ``count == 1``. ``point_step`` may exceed the packed
size (padding), ``row_step`` may exceed ``width * point_step`` (row padding),
and ``is_bigendian`` is honoured.
"""

from __future__ import annotations

from typing import Optional

import numpy as np
from builtin_interfaces.msg import Time
from sensor_msgs.msg import PointCloud2, PointField
from std_msgs.msg import Header

_DATATYPE_TO_NUMPY = {
    PointField.INT8: np.dtype("i1"),
    PointField.UINT8: np.dtype("u1"),
    PointField.INT16: np.dtype("i2"),
    PointField.UINT16: np.dtype("u2"),
    PointField.INT32: np.dtype("i4"),
    PointField.UINT32: np.dtype("u4"),
    PointField.FLOAT32: np.dtype("f4"),
    PointField.FLOAT64: np.dtype("f8"),
}
_NUMPY_TO_DATATYPE = {v.str[1:]: k for k, v in _DATATYPE_TO_NUMPY.items()}


class PointCloudError(ValueError):
    """A PointCloud2 message or array that cannot be converted, with the reason."""


def _field_dtype(datatype: int, bigendian: bool) -> np.dtype:
    try:
        dt = _DATATYPE_TO_NUMPY[datatype]
    except KeyError:
        raise PointCloudError(f"unsupported PointField datatype {datatype}") from None
    return dt.newbyteorder(">" if bigendian else "<")


def dtype_of(msg: PointCloud2) -> np.dtype:
    """Structured dtype (with offsets and itemsize = point_step) of a cloud's points."""
    names, formats, offsets = [], [], []
    for f in msg.fields:
        if f.count != 1:
            raise PointCloudError(f"field '{f.name}' has count {f.count}; only 1 is supported")
        dt = _field_dtype(f.datatype, msg.is_bigendian)
        if f.offset + dt.itemsize > msg.point_step:
            raise PointCloudError(
                f"field '{f.name}' (offset {f.offset}, {dt.itemsize} bytes) "
                f"overruns point_step {msg.point_step}"
            )
        names.append(f.name)
        formats.append(dt)
        offsets.append(f.offset)
    if len(set(names)) != len(names):
        raise PointCloudError(f"duplicate field names in {names}")
    return np.dtype(
        {"names": names, "formats": formats, "offsets": offsets, "itemsize": msg.point_step}
    )


def from_pointcloud2(msg: PointCloud2, fields: Optional[list[str]] = None) -> np.ndarray:
    """Decode a cloud into a packed, native-endian structured array of shape (height*width,).

    Args:
        msg: the cloud.
        fields: names to keep (default: all), in this order.

    Raises:
        PointCloudError: the layout is inconsistent (sizes, offsets, unknown
            datatypes, missing fields).
    """
    n = int(msg.width) * int(msg.height)
    point_step, row_step = int(msg.point_step), int(msg.row_step)
    if n == 0:
        point_step = max(point_step, 1)
    dt = dtype_of(msg) if msg.fields else np.dtype({"names": [], "formats": [], "itemsize": point_step})
    if n and point_step <= 0:
        raise PointCloudError("point_step must be positive")
    if n and row_step < msg.width * point_step:
        raise PointCloudError(
            f"row_step {row_step} < width {msg.width} * point_step {point_step}"
        )
    data = msg.data
    buf = data.tobytes() if hasattr(data, "tobytes") else bytes(data)
    expected = row_step * msg.height
    if len(buf) < expected:
        raise PointCloudError(
            f"data has {len(buf)} bytes, expected row_step * height = {expected}"
        )
    if n == 0:
        out = np.zeros(0, dtype=dt)
    elif row_step == msg.width * point_step:
        out = np.frombuffer(buf, dtype=dt, count=n)
    else:
        rows = np.frombuffer(buf, dtype=np.uint8, count=expected).reshape(msg.height, row_step)
        packed = np.ascontiguousarray(rows[:, : msg.width * point_step])
        out = np.frombuffer(packed.tobytes(), dtype=dt, count=n)
    names = list(dt.names) if fields is None else list(fields)
    missing = [f for f in names if f not in (dt.names or ())]
    if missing:
        raise PointCloudError(f"cloud has no field(s) {missing}; it has {list(dt.names or ())}")
    result = np.empty(n, dtype=[(f, dt.fields[f][0].newbyteorder("=")) for f in names])
    for f in names:
        result[f] = out[f]
    return result


def to_pointcloud2(
    points: np.ndarray,
    frame_id: str,
    stamp: Optional[Time] = None,
    is_dense: Optional[bool] = None,
) -> PointCloud2:
    """Encode a structured array (one record per point) as an unorganised cloud.

    Args:
        points: 1-D structured array; every field a supported scalar type.
        frame_id: frame of the points.
        stamp: header stamp (default zero).
        is_dense: default: True iff no floating field holds a NaN/inf.

    Raises:
        PointCloudError: not a 1-D structured array, or an unsupported field type.
    """
    points = np.asarray(points)
    if points.dtype.names is None or points.ndim != 1:
        raise PointCloudError("points must be a 1-D numpy structured array")
    packed_dtype = np.dtype([(f, points.dtype.fields[f][0].newbyteorder("<")) for f in points.dtype.names])
    fields = []
    for name in packed_dtype.names:
        dt, offset = packed_dtype.fields[name][:2]
        if dt.shape:
            raise PointCloudError(f"field '{name}' is an array; only scalar fields are supported")
        try:
            datatype = _NUMPY_TO_DATATYPE[dt.str[1:]]
        except KeyError:
            raise PointCloudError(f"field '{name}' has unsupported type {dt}") from None
        fields.append(PointField(name=name, offset=offset, datatype=datatype, count=1))
    packed = points.astype(packed_dtype, copy=False)
    if is_dense is None:
        is_dense = all(
            bool(np.isfinite(packed[f]).all())
            for f in packed_dtype.names
            if packed_dtype.fields[f][0].kind == "f"
        )
    msg = PointCloud2()
    msg.header = Header(frame_id=frame_id, stamp=stamp if stamp is not None else Time())
    msg.height = 1
    msg.width = int(points.shape[0])
    msg.fields = fields
    msg.is_bigendian = False
    msg.point_step = packed_dtype.itemsize
    msg.row_step = packed_dtype.itemsize * msg.width
    msg.is_dense = bool(is_dense)
    msg.data = packed.tobytes()
    return msg
