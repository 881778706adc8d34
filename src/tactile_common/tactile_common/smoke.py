"""Two tiny nodes that check the plumbing end to end (used by the smoke test).

``cloud_talker`` publishes a seeded random contact cloud on ``cloud`` every
period; ``cloud_echo`` decodes each cloud from ``cloud``, negates the
normals and republishes it on ``cloud_echo``. A test that receives the echo
and compares it with its own seeded copy checks encode, transport, decode,
re-encode across two processes.
"""

from __future__ import annotations

import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import PointCloud2

from tactile_common import fields, qos, topics
from tactile_common.node_main import run_node
from tactile_common.params import declare_parameters
from tactile_common.pointcloud import from_pointcloud2, to_pointcloud2


def seeded_cloud(seed: int, n_points: int) -> np.ndarray:
    """The cloud ``cloud_talker`` publishes for a seed (label alternates 1, 0)."""
    rng = np.random.default_rng(seed)
    cloud = np.zeros(n_points, dtype=fields.CONTACT_DTYPE)
    for name in ("x", "y", "z", "normal_x", "normal_y", "normal_z", "force"):
        cloud[name] = rng.normal(size=n_points)
    cloud["label"] = (np.arange(n_points) + 1) % 2
    return cloud


class CloudTalker(Node):
    def __init__(self) -> None:
        super().__init__("cloud_talker")
        p = declare_parameters(self, {
            "seed": (0, "seed of the random cloud"),
            "n_points": (1000, "points per cloud"),
            "period_s": (0.1, "publish period"),
        })
        self._msg = to_pointcloud2(seeded_cloud(p.seed, p.n_points), topics.WORLD_FRAME)
        self._pub = self.create_publisher(PointCloud2, "cloud", qos.EVENTS)
        self.create_timer(p.period_s, lambda: self._pub.publish(self._msg))


class CloudEcho(Node):
    def __init__(self) -> None:
        super().__init__("cloud_echo")
        self._pub = self.create_publisher(PointCloud2, "cloud_echo", qos.EVENTS)
        self.create_subscription(PointCloud2, "cloud", self._on_cloud, qos.EVENTS)

    def _on_cloud(self, msg: PointCloud2) -> None:
        cloud = from_pointcloud2(msg)
        for name in ("normal_x", "normal_y", "normal_z"):
            cloud[name] = -cloud[name]
        self._pub.publish(to_pointcloud2(cloud, msg.header.frame_id, msg.header.stamp))


def talker_main(args=None) -> int:
    return run_node(CloudTalker, args)


def echo_main(args=None) -> int:
    return run_node(CloudEcho, args)
