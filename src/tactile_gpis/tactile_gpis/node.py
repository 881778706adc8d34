"""gpis_estimator: contacts in, GPIS variance map / surface / occupancy out.

Subscribes  /tactile/contacts (PointCloud2, CONTACT_DTYPE, EVENTS)
Publishes   /gpis/variance_map (PointCloud2, VARIANCE_MAP_DTYPE, MAP latched)
            /gpis/surface (Marker, MAP), /gpis/occupancy (OccupancyGrid, MAP; 2D only)
Service     ~/reset (std_srvs/Trigger)
Parameters  tactile_gpis.estimator.PARAMETERS (config/gpis_estimator.yaml)

Contacts arrive on a durable topic (qos.OBSERVATIONS): a restarted estimator
is handed every observation so far by the driver and the commander, and
rebuilds the estimate from them; an observation seen twice (same stamp,
label and point) is added once.

One map per contacts message (accepted or rejected), stamped with the newest
header.stamp received so far (map stamps never go back: a contact that arrives
after a newer observation, from a slower publisher, still yields a map at least
as new as everything it holds); the prior map at start has stamp 0.
"""

from __future__ import annotations

import numpy as np
from builtin_interfaces.msg import Time
from nav_msgs.msg import OccupancyGrid
from rclpy.node import Node
from sensor_msgs.msg import PointCloud2
from std_srvs.srv import Trigger
from visualization_msgs.msg import Marker

from tactile_common import qos, topics
from tactile_common.fields import CONTACT_DTYPE, normals, xyz
from tactile_common.node_main import run_node
from tactile_common.observations_file import read_observations
from tactile_common.params import declare_parameters
from tactile_common.pointcloud import PointCloudError, from_pointcloud2, to_pointcloud2
from tactile_common.stamps import stamp_ns

from .estimator import PARAMETERS, ShapeEstimator
from .ros_convert import occupancy_grid, surface_marker

#: Most points accepted in one contacts message (the contract is one point per touch).
MAX_CLOUD_POINTS = 16

#: The node's own parameters (the estimate's are ``PARAMETERS``).
NODE_PARAMETERS = {
    "initial_observations_file": ("", "observations to start from (a resumed run, tactile_common."
                                  "observations_file CSV); '' = the prior"),
}


class GpisEstimatorNode(Node):
    def __init__(self) -> None:
        super().__init__("gpis_estimator")
        values = vars(declare_parameters(self, PARAMETERS))
        self.estimator = ShapeEstimator.from_params({k: values[k.replace(".", "_")] for k in PARAMETERS})
        initial = str(declare_parameters(self, NODE_PARAMETERS).initial_observations_file)
        self.frame_id = str(values["frame_id"])
        self.n_received = 0
        self.n_rejected = 0
        self.n_duplicates = 0
        self._seen: set[tuple] = set()  # (stamp ns, label, x, y, z) of every observation added
        self.stamp = Time()
        self.map_pub = self.create_publisher(PointCloud2, topics.VARIANCE_MAP, qos.MAP)
        self.surface_pub = self.create_publisher(Marker, topics.SURFACE, qos.MAP)
        self.occupancy_pub = (
            self.create_publisher(OccupancyGrid, topics.OCCUPANCY, qos.MAP) if self.estimator.dim == 2 else None
        )
        if initial:
            self.add_initial(initial)
        self.create_subscription(PointCloud2, topics.CONTACTS, self.on_contacts, qos.OBSERVATIONS)
        self.create_service(Trigger, "~/reset", self.on_reset)
        self.publish_estimate()
        self.get_logger().info(
            f"{self.estimator.dim}D GPIS, lattice {self.estimator.lattice_shape}, "
            f"kernel {self.estimator.kernel.name}: prior map published"
        )

    def add_initial(self, path: str) -> None:
        """Start from a run's observations (a resumed run); a bad file ends the node with one line."""
        obs = read_observations(path)
        before = dict(self.estimator.hyperparameters)
        rejected = [reason for p, n, label in zip(xyz(obs), normals(obs), obs["label"])
                    for ok, reason in [self.estimator.add_observation(p, n, int(label))] if not ok]
        self.get_logger().info(f"started from {len(obs) - len(rejected)} observations of {path}"
                               + (f" ({len(rejected)} rejected: {rejected[0]})" if rejected else ""))
        self.log_hyperparameters(before)

    def on_contacts(self, msg: PointCloud2) -> None:
        self.n_received += 1
        if stamp_ns(msg.header.stamp) > stamp_ns(self.stamp):
            self.stamp = msg.header.stamp
        before = dict(self.estimator.hyperparameters)
        for ok, reason in self.add_cloud(msg):
            if not ok:
                self.n_rejected += 1
                self.get_logger().warn(f"observation rejected ({self.n_rejected} so far): {reason}")
        self.log_hyperparameters(before)
        self.publish_estimate()

    def log_hyperparameters(self, before: dict[str, float]) -> None:
        """One INFO line when kernel.fit changed the hyperparameters."""
        after = self.estimator.hyperparameters
        changed = [f"{k} {before[k]:.4g} -> {v:.4g}" for k, v in after.items() if v != before.get(k)]
        if changed:
            fit = self.estimator.last_fit
            self.get_logger().info(f"hyperparameters by marginal likelihood ({self.estimator.n_observations} "
                                   f"observations, log p(y) {fit.log_marginal_likelihood:.4g}): "
                                   + ", ".join(changed))

    def add_cloud(self, msg: PointCloud2) -> list[tuple[bool, str]]:
        if msg.header.frame_id != self.frame_id:
            return [(False, f"frame_id '{msg.header.frame_id}', expected '{self.frame_id}'")]
        try:
            pts = from_pointcloud2(msg, list(CONTACT_DTYPE.names))
        except PointCloudError as exc:
            return [(False, f"bad cloud: {exc}")]
        if len(pts) == 0:
            return [(False, "empty cloud")]
        if len(pts) > MAX_CLOUD_POINTS:  # each point is a GP update: a flood would stall the node for minutes
            return [(False, f"{len(pts)} points in one message; at most {MAX_CLOUD_POINTS} (one per touch)")]
        labels = np.asarray(pts["label"], dtype=float)
        if not (np.isfinite(labels).all() and (labels == np.round(labels)).all()):
            return [(False, f"labels must be integers (1 contact, 0 free space), got {labels[:5].tolist()}")]
        results = []
        for p, n, label in zip(xyz(pts), normals(pts), pts["label"]):
            key = (stamp_ns(msg.header.stamp), int(label), *map(float, p))
            if key in self._seen:
                self.n_duplicates += 1
                continue
            ok, reason = self.estimator.add_observation(p, n, int(label))
            if ok:
                self._seen.add(key)
            results.append((ok, reason))
        return results

    def on_reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        n = self.estimator.n_observations
        self.estimator.reset()
        self._seen.clear()
        self.publish_estimate()
        response.success = True
        response.message = f"estimate reset ({n} observations dropped)"
        self.get_logger().info(response.message)
        return response

    def publish_estimate(self) -> None:
        self.map_pub.publish(to_pointcloud2(self.estimator.map_array(), self.frame_id, self.stamp))
        self.surface_pub.publish(surface_marker(self.estimator, self.frame_id, self.stamp))
        if self.occupancy_pub is not None:
            self.occupancy_pub.publish(occupancy_grid(self.estimator, self.frame_id, self.stamp))


def main(args=None) -> int:
    return run_node(GpisEstimatorNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
