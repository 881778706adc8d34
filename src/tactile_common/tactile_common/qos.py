"""QoS profiles of the graph, chosen once so that publishers and subscribers match.

- ``LATCHED``: last value reaches late subscribers (robot description, e-stop,
  the last variance map): RELIABLE, TRANSIENT_LOCAL, depth 1.
- ``MAP``: large clouds (variance map). Large PointCloud2 over BEST_EFFORT is
  mostly dropped, so RELIABLE; latched so a planner started late still plans.
- ``EVENTS``: observations that must never be lost (contacts, touch done, goals,
  paths): RELIABLE, VOLATILE, deep queue.
- ``SENSOR``: high-rate streams where the newest sample matters most (raw
  taxels, fingertip pose, joint states): RELIABLE, VOLATILE, shallow queue.
- ``CLOCK``: as rclpy's time source subscribes to ``/clock``.
"""

from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
)

LATCHED = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)

MAP = LATCHED

EVENTS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=100,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)

SENSOR = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)

CLOCK = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.BEST_EFFORT,
    durability=DurabilityPolicy.VOLATILE,
)
