"""Message plumbing shared by every node: PointCloud2 codec, QoS, topic names, node main().

Modules:
    topics: default topic names and frame ids.
    qos: the graph's QoS profiles.
    fields: structured dtypes of the graph's PointCloud2 layouts.
    pointcloud: vectorised PointCloud2 <-> numpy codec.
    node_main: the shared ``main()`` (SIGINT/SIGTERM, clean shutdown).
    param_spec: parameter tables (type, range, read-only) and their checks, ROS-free.
    params: declare ROS parameters from a table, with descriptors and an on-set check.
    ros_env: AMENT_PREFIX_PATH and the discovery range when the caller set none.
    testing: pytest harness for graph tests (processes, domains, waits).
"""

from .ros_env import ensure_ros_environment as _ensure_ros_environment

_ensure_ros_environment()
