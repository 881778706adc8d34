"""``viz``: viewer markers for Foxglove / RViz, all in the fixed frame ``world``.

Subscribes                         Publishes (latched unless noted)
``/tactile/contacts``          ->  ``/tactile/contact_markers`` MarkerArray: contacts and
                                   free-space probe ends (SPHERE_LIST), one ARROW per
                                   contact normal
``/gpis/surface`` +            ->  ``/viz/surface_sigma`` Marker: the estimated contour /
``/gpis/variance_map``             mesh with per-vertex colours of log10 σ (viridis)
``/joint_states``              ->  ``/viz/arm`` MarkerArray (volatile, at most every
                                   ``arm_period_s`` of stamp time): the arm as a line
                                   through its link origins and the fingertip sphere
(at start)                     ->  ``/robot_description`` std_msgs/String: the arm
                                   commander's URDF (same parameters and default: the
                                   Panda of example-robot-data), mesh URIs as file://

The arrays come from :mod:`tactile_bringup.viz_markers`; this node only makes messages.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from geometry_msgs.msg import Point
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState, PointCloud2
from std_msgs.msg import ColorRGBA, Header, String
from visualization_msgs.msg import Marker, MarkerArray

from tactile_common import fields, qos, topics
from tactile_common.node_main import run_node
from tactile_common.params import declare_parameters
from tactile_common.pointcloud import from_pointcloud2
from tactile_common.stamps import stamp_ns

from .viz_markers import SigmaField, arm_link_frames, arm_polyline, joint_vector, ramp_rgba, resolve_package_uris

CONTACT_MARKERS = "/tactile/contact_markers"
SURFACE_SIGMA = "/viz/surface_sigma"
ARM = "/viz/arm"
ROBOT_DESCRIPTION = "/robot_description"

PARAMS = {
    "urdf_path": ("", "URDF of the arm (the arm commander's); '' = Franka Panda from example-robot-data"),
    "joint_names": ([f"panda_joint{i}" for i in range(1, 8)], "actuated joints (the arm commander's)"),
    "flange_frame": ("panda_link8", "URDF frame the finger is mounted on (the arm commander's)"),
    "tip_offset_m": (0.16, "tip centre along the flange z-axis (the arm commander's)", {"ge": 0.0}),
    "tip_radius_m": (0.01, "fingertip sphere radius drawn", {"gt": 0.0}),
    "contact_diameter_m": (0.006, "diameter of a contact sphere", {"gt": 0.0}),
    "normal_length_m": (0.02, "length of a normal arrow", {"gt": 0.0}),
    "arm_period_s": (0.1, "publish the arm at most this often (joint-state stamp time)", {"ge": 0.0}),
    "frame_id": (topics.WORLD_FRAME, "fixed frame of every marker"),
}

CONTACTS_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.VOLATILE)
CONTACT_RGBA = (0.9, 0.15, 0.1, 1.0)
PROBE_RGBA = (0.55, 0.55, 0.55, 0.8)
NORMAL_RGBA = (0.1, 0.1, 0.1, 1.0)
ARM_RGBA = (0.95, 0.6, 0.1, 1.0)


def _colour(rgba) -> ColorRGBA:
    r, g, b, a = (float(v) for v in rgba)
    return ColorRGBA(r=r, g=g, b=b, a=a)


def _points(xyz: np.ndarray) -> list:
    return [Point(x=x, y=y, z=z) for x, y, z in np.asarray(xyz, dtype=float).reshape(-1, 3).tolist()]


class VizNode(Node):
    def __init__(self) -> None:
        super().__init__("viz")
        self.p = declare_parameters(self, PARAMS)
        from tactile_driver.kinematics import ArmModel

        self.arm = ArmModel(self.p.urdf_path, tuple(self.p.joint_names), self.p.flange_frame, self.p.tip_offset_m)
        self.link_frames = arm_link_frames(self.arm)
        urdf = Path(self.arm.urdf_path)
        self.description_pub = self.create_publisher(String, ROBOT_DESCRIPTION, qos.LATCHED)
        self.description_pub.publish(String(data=resolve_package_uris(urdf.read_text(), str(urdf))))
        self.contacts_pub = self.create_publisher(MarkerArray, CONTACT_MARKERS, qos.LATCHED)
        self.surface_pub = self.create_publisher(Marker, SURFACE_SIGMA, qos.LATCHED)
        self.arm_pub = self.create_publisher(MarkerArray, ARM, qos.SENSOR)
        # VOLATILE matches a volatile or a durable writer; a durable writer's re-sent
        # history (after a restart) is dropped as exact duplicates in on_contacts.
        self.create_subscription(PointCloud2, topics.CONTACTS, self.on_contacts, CONTACTS_QOS)
        self.create_subscription(PointCloud2, topics.VARIANCE_MAP, self.on_map, qos.MAP)
        self.create_subscription(Marker, topics.SURFACE, self.on_surface, qos.MAP)
        self.create_subscription(JointState, topics.JOINT_STATES, self.on_joints, qos.SENSOR)
        self.contacts = np.zeros(0, dtype=fields.CONTACT_DTYPE)
        self.sigma = None
        self.surface = None
        self.last_arm_ns = None
        self.get_logger().info(f"viz: markers in '{self.p.frame_id}', robot description from {urdf}")

    # -- contacts ------------------------------------------------------------
    def on_contacts(self, msg: PointCloud2) -> None:
        try:
            if msg.header.frame_id != self.p.frame_id:  # drawn in the fixed frame, it would be misplaced
                raise ValueError(f"frame_id '{msg.header.frame_id}', expected '{self.p.frame_id}'")
            pts = from_pointcloud2(msg, list(fields.CONTACT_DTYPE.names))
        except ValueError as exc:
            self.get_logger().warning(f"contacts cloud ignored: {exc}")
            return
        ok = np.isfinite(fields.xyz(pts)).all(axis=1) & np.isin(np.asarray(pts["label"], dtype=float),
                                                                (fields.LABEL_FREE_SPACE, fields.LABEL_CONTACT))
        if not ok.all():
            self.get_logger().warning(f"{int((~ok).sum())} contact point(s) ignored: not finite or unknown label")
        pts = pts[ok].astype(fields.CONTACT_DTYPE)
        if len(self.contacts):
            pts = pts[~np.isin(pts, self.contacts)]  # exact duplicates: a durable writer's re-sent history
        if len(pts) == 0:
            return
        self.contacts = np.concatenate([self.contacts, pts])
        self.contacts_pub.publish(self.contact_markers(msg.header.stamp))

    def contact_markers(self, stamp) -> MarkerArray:
        c = self.contacts
        header = Header(frame_id=self.p.frame_id, stamp=stamp)
        is_contact = c["label"] == fields.LABEL_CONTACT
        out = MarkerArray()
        for mid, (ns, sel, rgba) in enumerate((("contacts", is_contact, CONTACT_RGBA),
                                               ("free_space", ~is_contact, PROBE_RGBA))):
            m = Marker(header=header, ns=ns, id=mid, type=Marker.SPHERE_LIST, action=Marker.ADD)
            m.pose.orientation.w = 1.0
            m.scale.x = m.scale.y = m.scale.z = self.p.contact_diameter_m
            m.color = _colour(rgba)
            m.points = _points(fields.xyz(c[sel]))
            out.markers.append(m)
        P, N = fields.xyz(c[is_contact]), fields.normals(c[is_contact])
        norm = np.linalg.norm(N, axis=1)
        for i in np.nonzero(norm > 0.5)[0]:
            m = Marker(header=header, ns="normals", id=int(i), type=Marker.ARROW, action=Marker.ADD)
            m.pose.orientation.w = 1.0
            m.scale.x, m.scale.y, m.scale.z = 0.0015, 0.003, 0.004  # shaft and head diameters, head length
            m.color = _colour(NORMAL_RGBA)
            m.points = _points(np.stack([P[i], P[i] + self.p.normal_length_m * N[i] / norm[i]]))
            out.markers.append(m)
        return out

    # -- surface coloured by sigma --------------------------------------------
    def on_map(self, msg: PointCloud2) -> None:
        try:
            self.sigma = SigmaField(from_pointcloud2(msg, ["x", "y", "z", "variance", "kind"]))
        except ValueError as exc:
            self.get_logger().warning(f"variance map ignored: {exc}")
            return
        self.publish_surface()

    def on_surface(self, msg: Marker) -> None:
        self.surface = msg
        self.publish_surface()

    def publish_surface(self) -> None:
        if self.surface is None or self.sigma is None:
            return
        m = self.surface
        out = Marker(header=Header(frame_id=self.p.frame_id, stamp=m.header.stamp), ns="surface_sigma", id=0,
                     type=m.type, action=Marker.ADD, pose=m.pose, scale=m.scale, points=m.points)
        if m.points:
            xyz = np.array([[p.x, p.y, p.z] for p in m.points])
            lo, hi = self.sigma.range()
            out.colors = [_colour(c) for c in ramp_rgba(self.sigma(xyz), lo, hi, alpha=1.0).tolist()]
        out.color = _colour((1.0, 1.0, 1.0, 1.0))
        self.surface_pub.publish(out)

    # -- arm -------------------------------------------------------------------
    def on_joints(self, msg: JointState) -> None:
        now = stamp_ns(msg.header.stamp)
        if self.last_arm_ns is not None and 0 <= now - self.last_arm_ns < self.p.arm_period_s * 1e9:
            return
        q = joint_vector(list(msg.name), list(msg.position), self.arm.joint_names)
        if q is None or not np.isfinite(q).all():
            return
        self.last_arm_ns = now
        pts = arm_polyline(self.arm, q, self.link_frames)
        header = Header(frame_id=self.p.frame_id, stamp=msg.header.stamp)
        line = Marker(header=header, ns="arm", id=0, type=Marker.LINE_STRIP, action=Marker.ADD)
        line.pose.orientation.w = 1.0
        line.scale.x = 0.02
        line.color = _colour(ARM_RGBA)
        line.points = _points(pts)
        tip = Marker(header=header, ns="arm", id=1, type=Marker.SPHERE, action=Marker.ADD)
        tip.pose.position = _points(pts[-1])[0]
        tip.pose.orientation.w = 1.0
        tip.scale.x = tip.scale.y = tip.scale.z = 2.0 * self.p.tip_radius_m
        tip.color = _colour((0.2, 0.4, 0.9, 1.0))
        self.arm_pub.publish(MarkerArray(markers=[line, tip]))


def main(args=None) -> int:
    return run_node(VizNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
