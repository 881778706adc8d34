"""QoS profiles of the graph, chosen once so that publishers and subscribers match.

- ``LATCHED``: last value reaches late subscribers (robot description, e-stop,
  the last variance map): RELIABLE, TRANSIENT_LOCAL, depth 1.
- ``MAP``: large clouds (variance map). Large PointCloud2 over BEST_EFFORT is
  mostly dropped, so RELIABLE; latched so a planner started late still plans.
- ``EVENTS``: the one-off events of the touch cycle (requests, goals, paths,
  planner status, touch done): RELIABLE, **TRANSIENT_LOCAL**, depth 100. On a
  loaded machine discovery takes seconds, and a VOLATILE sample published
  before *this* writer has matched *that* reader is never delivered to it (a
  run ended that way about one time in seven). A durable writer hands its
  recent history to every reader it matches later, so an event published
  "too early", and the events before a reader's restart, still arrive.
  Readers therefore see events again after a restart: every event carries an
  identifier (request id, goal stamp) and readers drop duplicates and
  superseded ones (docs/architecture.md, "Delivery").
- ``OBSERVATIONS``: contacts and free-space probe ends. Durable like EVENTS,
  with a history deep enough for a whole run (10 000 points, a few MB), so a
  restarted estimator rebuilds its estimate from every observation so far.
- ``COMMANDS``: trajectories to the controller: RELIABLE, VOLATILE. A command
  must never reach a controller that joins late (that would replay motion).
- ``STATE``: joint states and the fingertip pose: RELIABLE, VOLATILE, a
  deep queue (1000, 10 s at 100 Hz). The driver places each contact with the
  fingertip pose interpolated at the frame's time: a pose dropped under load
  would move the contact by up to a frame's travel and make runs differ.
- ``SENSOR``: high-rate streams where the newest sample matters most (raw
  taxels; readers of the pose that only want the latest): RELIABLE, VOLATILE,
  shallow queue.
- ``CLOCK``: as rclpy's time source subscribes to ``/clock``.

A TRANSIENT_LOCAL reader matches only TRANSIENT_LOCAL writers: whoever
publishes on an EVENTS or OBSERVATIONS topic (a test, a script) uses the same
profile.
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
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)

OBSERVATIONS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10000,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)

COMMANDS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)

STATE = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1000,
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
