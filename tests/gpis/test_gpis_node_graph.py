"""gpis_estimator in a real process: prior map at start, one map per contacts message,
low variance at the contacts, invalid input rejected without crashing, reset service."""

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from rclpy.qos import QoSProfile
from sensor_msgs.msg import PointCloud2
from std_srvs.srv import Trigger

from tactile_common import qos, topics
from tactile_common.fields import CONTACT_DTYPE, KIND_CANDIDATE, KIND_LATTICE
from tactile_common.pointcloud import from_pointcloud2, to_pointcloud2

pytestmark = pytest.mark.graph

# the map QoS with a deep reader queue, so the test keeps every map it is sent
MAP_READER = QoSProfile(depth=50, reliability=qos.MAP.reliability, durability=qos.MAP.durability)

CENTRE = np.array([0.5, 0.0])
RADIUS = 0.05


def contact(angle_rad: float, z: float = 0.06, label: int = 1) -> np.ndarray:
    p = np.zeros(1, dtype=CONTACT_DTYPE)
    n = np.array([np.cos(angle_rad), np.sin(angle_rad)])
    p["x"], p["y"] = CENTRE + RADIUS * n
    p["z"] = z
    p["normal_x"], p["normal_y"] = n
    p["force"] = 1.0
    p["label"] = label
    return p


def stamp_of(sec: int) -> Time:
    return Time(sec=sec, nanosec=0)


def test_node_maps_contacts(ros_graph):
    ros_graph.start("gpis", ["gpis_estimator", "--ros-args", "-p", "lattice.points_per_axis_2d:=64"])
    maps = ros_graph.collect(topics.VARIANCE_MAP, PointCloud2, MAP_READER)
    ros_graph.wait_for(lambda: maps, 30, "the prior map")
    prior = maps[0]
    assert prior.header.stamp.sec == 0 and prior.header.stamp.nanosec == 0
    prior_arr = from_pointcloud2(prior)
    assert (prior_arr["kind"] == KIND_LATTICE).sum() == 64 * 64

    pub = ros_graph.node.create_publisher(PointCloud2, topics.CONTACTS, qos.EVENTS)
    ros_graph.wait_for(lambda: pub.get_subscription_count() > 0, 20, "the estimator's subscription")
    angles = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    for i, a in enumerate(angles, start=1):
        pub.publish(to_pointcloud2(contact(a), "world", stamp_of(i)))
    # invalid: wrong frame, NaN, outside the workspace, duplicate -> still one map each
    pub.publish(to_pointcloud2(contact(0.3), "base_link", stamp_of(9)))
    bad = contact(0.3)
    bad["x"] = np.nan
    pub.publish(to_pointcloud2(bad, "world", stamp_of(10)))
    far = contact(0.3)
    far["x"] = 2.0
    pub.publish(to_pointcloud2(far, "world", stamp_of(11)))
    pub.publish(to_pointcloud2(contact(angles[0]), "world", stamp_of(12)))

    ros_graph.wait_for(lambda: any(m.header.stamp.sec == 12 for m in maps), 30, "the map of the last message")
    # One map per message, in order; a latched depth-1 topic may overwrite a map the
    # subscriber has not taken yet (the planner only needs the newest), so under
    # load some may be skipped, never reordered.
    stamps = [m.header.stamp.sec for m in maps]
    assert stamps[0] == 0 and stamps[-1] == 12 and stamps == sorted(set(stamps)), stamps
    arr = from_pointcloud2(maps[-1])
    cand = arr[arr["kind"] == KIND_CANDIDATE]
    assert len(cand) > 0
    lattice = arr[arr["kind"] == KIND_LATTICE]
    # variance at the contacts (nearest lattice nodes / direct check against the prior)
    pts = np.stack([lattice["x"], lattice["y"]], axis=1)
    contacts = CENTRE + RADIUS * np.stack([np.cos(angles), np.sin(angles)], axis=1)
    nearest = np.argmin(((pts[:, None] - contacts[None]) ** 2).sum(-1), axis=0)
    assert (lattice["variance"][nearest] < 0.02 * prior_arr["variance"][nearest]).all()
    # contacts' nearest candidates have low variance too
    cpts = np.stack([cand["x"], cand["y"]], axis=1)
    near_c = np.argmin(((cpts[:, None] - contacts[None]) ** 2).sum(-1), axis=0)
    assert (cand["variance"][near_c] < 0.1 * prior_arr["variance"].max()).all()
    assert ros_graph.procs["gpis"].alive()
    # An observation older than the newest one (a slower publisher: the driver's contact arriving
    # after the commander's free-space point) still gives a map stamped with the newest stamp.
    n_before = len(maps)
    pub.publish(to_pointcloud2(contact(0.7), "world", stamp_of(11)))
    ros_graph.wait_for(lambda: len(maps) > n_before, 20, "the map of the late observation")
    assert maps[-1].header.stamp.sec == 12

    n_before = len(maps)
    assert ros_graph.call(Trigger, "/gpis_estimator/reset", Trigger.Request(), 20, "the reset reply").success
    ros_graph.wait_for(lambda: len(maps) > n_before, 20, "the map after reset")
    after = from_pointcloud2(maps[-1])
    np.testing.assert_allclose(after["variance"][: 64 * 64], prior_arr["variance"][: 64 * 64])
    assert ros_graph.stop_all() == {"gpis": 0}


def test_node_3d_map_and_mesh(ros_graph):
    ros_graph.start("gpis3d", ["gpis_estimator", "--ros-args", "-p", "mode:=3d",
                               "-p", "lattice.points_per_axis_3d:=16"])
    maps = ros_graph.collect(topics.VARIANCE_MAP, PointCloud2, MAP_READER)
    from visualization_msgs.msg import Marker

    markers = ros_graph.collect(topics.SURFACE, Marker, MAP_READER)
    ros_graph.wait_for(lambda: maps and markers, 30, "the prior map and mesh")
    pub = ros_graph.node.create_publisher(PointCloud2, topics.CONTACTS, qos.EVENTS)
    ros_graph.wait_for(lambda: pub.get_subscription_count() > 0, 20, "the estimator's subscription")
    top = contact(0.0, z=0.12)
    top["x"], top["y"] = 0.5, 0.0
    top["normal_x"], top["normal_y"], top["normal_z"] = 0.0, 0.0, 1.0
    pub.publish(to_pointcloud2(top, "world", stamp_of(5)))
    ros_graph.wait_for(lambda: any(m.header.stamp.sec == 5 for m in maps), 30, "the map of the contact")
    arr = from_pointcloud2(maps[-1])
    assert (arr["kind"] == KIND_LATTICE).sum() == 16**3
    cand = arr[arr["kind"] == KIND_CANDIDATE]
    assert len(cand) > 0 and (cand["z"] > 0.005).all()
    lat = arr[arr["kind"] == KIND_LATTICE]
    near = np.argmin((lat["x"] - 0.5) ** 2 + lat["y"] ** 2 + (lat["z"] - 0.12) ** 2)
    prior = from_pointcloud2(maps[0])
    assert lat["variance"][near] < 0.2 * prior["variance"][near]
    ros_graph.wait_for(lambda: any(m.header.stamp.sec == 5 for m in markers), 20, "the mesh of the contact")
    mesh = [m for m in markers if m.header.stamp.sec == 5][-1]
    assert mesh.type == Marker.TRIANGLE_LIST and len(mesh.points) % 3 == 0 and len(mesh.points) > 0
    assert ros_graph.stop_all() == {"gpis3d": 0}
