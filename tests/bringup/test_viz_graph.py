"""The viz node through the project's recorder: every topic of the shipped Foxglove layout is in
the MCAP with the type of the README topic table and the fixed frame ``world``, read back by
``rosbags`` (an independent rosbag2 implementation)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Path as PathMsg
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore
from sensor_msgs.msg import JointState, PointCloud2

from tactile_common import fields, qos, topics
from tactile_common.pointcloud import to_pointcloud2

pytestmark = pytest.mark.graph

LAYOUT = Path(__file__).resolve().parents[2] / "src/tactile_bringup/config/foxglove_layout.json"
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
#: the README topic table and docs/recording.md (not the node's code)
EXPECTED_TYPES = {
    "/tactile/contact_markers": "visualization_msgs/msg/MarkerArray",
    "/viz/surface_sigma": "visualization_msgs/msg/Marker",
    "/viz/arm": "visualization_msgs/msg/MarkerArray",
    "/robot_description": "std_msgs/msg/String",
    "/gpis/surface": "visualization_msgs/msg/Marker",
    "/gpis/occupancy": "nav_msgs/msg/OccupancyGrid",
    "/planner/path": "nav_msgs/msg/Path",
    "/planner/goal": "geometry_msgs/msg/PoseStamped",
    "/arm/fingertip_pose": "geometry_msgs/msg/PoseStamped",
}
CONTACTS = [((0.54, 0.0, 0.06), (1.0, 0.0, 0.0), 1), ((0.5, 0.04, 0.06), (0.0, 1.0, 0.0), 1),
            ((0.46, 0.0, 0.06), (-1.0, 0.0, 0.0), 1), ((0.5, -0.08, 0.06), (0.0, 0.0, 0.0), 0)]


def layout_topics(layout: dict) -> set:
    """Every topic a panel of the layout reads (3D topics and layers, plot paths, raw messages)."""
    out = set()
    for panel in layout["configById"].values():
        out |= set(panel.get("topics", {}))
        out |= {layer["topic"] for layer in panel.get("layers", {}).values() if "topic" in layer}
        out |= {p["value"].split(".")[0] for p in panel.get("paths", [])}
        if panel.get("topicPath"):
            out.add(panel["topicPath"].split(".")[0])
    return out


def frames_of(msg) -> list:
    """The frame ids a message carries (every marker's; none for a String)."""
    if hasattr(msg, "markers"):
        return [m.header.frame_id for m in msg.markers]
    if hasattr(msg, "header"):
        return [msg.header.frame_id]
    return []


def _inputs():
    """What the estimator, planner and rig would publish, built with their own converters."""
    from tactile_gpis.estimator import ShapeEstimator
    from tactile_gpis.ros_convert import occupancy_grid, surface_marker

    est = ShapeEstimator({"mode": "2d", "lattice.points_per_axis_2d": 40})
    cloud = np.zeros(len(CONTACTS), dtype=fields.CONTACT_DTYPE)
    for i, (p, n, label) in enumerate(CONTACTS):
        cloud[i]["x"], cloud[i]["y"], cloud[i]["z"] = p
        cloud[i]["normal_x"], cloud[i]["normal_y"], cloud[i]["normal_z"] = n
        cloud[i]["label"] = label
        est.add_observation(np.array(p), np.array(n) if label else None, label)
    stamp = PoseStamped().header.stamp
    return (to_pointcloud2(cloud, topics.WORLD_FRAME), to_pointcloud2(est.map_array(), topics.WORLD_FRAME),
            surface_marker(est, topics.WORLD_FRAME, stamp), occupancy_grid(est, topics.WORLD_FRAME, stamp))


def test_layout_topics_are_recorded_with_type_and_frame(ros_graph, tmp_path):
    from visualization_msgs.msg import Marker, MarkerArray
    from nav_msgs.msg import OccupancyGrid

    layout = json.loads(LAYOUT.read_text())
    wanted = layout_topics(layout)
    assert wanted == set(EXPECTED_TYPES), "the layout and this test's table name the same topics"
    out = tmp_path / "viz.mcap"
    ros_graph.start("recorder", ["recorder", "--ros-args", "-p", f"output:={out}", "-p", "discovery_period_s:=0.2",
                                 "-p", f"topics:={json.dumps(sorted(wanted))}"])
    ros_graph.start("viz", ["viz", "--ros-args", "-p", "arm_period_s:=0.0"])
    node = ros_graph.node
    contacts, vmap, surface, grid = _inputs()
    contacts_pub = node.create_publisher(PointCloud2, topics.CONTACTS, qos.SENSOR)
    pubs = {
        topics.VARIANCE_MAP: node.create_publisher(PointCloud2, topics.VARIANCE_MAP, qos.MAP),
        topics.SURFACE: node.create_publisher(Marker, topics.SURFACE, qos.MAP),
        topics.OCCUPANCY: node.create_publisher(OccupancyGrid, topics.OCCUPANCY, qos.MAP),
    }
    pubs[topics.VARIANCE_MAP].publish(vmap)
    pubs[topics.SURFACE].publish(surface)
    pubs[topics.OCCUPANCY].publish(grid)
    joints_pub = node.create_publisher(JointState, topics.JOINT_STATES, qos.SENSOR)
    path_pub = node.create_publisher(PathMsg, topics.PATH, qos.SENSOR)
    goal_pub = node.create_publisher(PoseStamped, topics.GOAL, qos.SENSOR)
    tip_pub = node.create_publisher(PoseStamped, topics.FINGERTIP_POSE, qos.SENSOR)
    markers = ros_graph.collect("/tactile/contact_markers", MarkerArray, qos.LATCHED)
    coloured = ros_graph.collect("/viz/surface_sigma", Marker, qos.LATCHED)
    arm = ros_graph.collect("/viz/arm", MarkerArray, qos.SENSOR)
    log = ros_graph.procs["recorder"].log
    ros_graph.wait_for(lambda: contacts_pub.get_subscription_count() >= 1 and
                       all(f"recording {t} " in log() for t in ("/robot_description", "/viz/arm",
                                                                "/tactile/contact_markers")),
                       timeout_s=60, what="viz to subscribe and the recorder to record its topics")
    contacts_pub.publish(contacts)
    tick = [0]

    def stream():  # the rig, commander and planner streams, stamped in order
        tick[0] += 1
        pose = PoseStamped()
        pose.header.frame_id = topics.WORLD_FRAME
        pose.header.stamp.sec = tick[0]
        pose.pose.position.x, pose.pose.orientation.w = 0.4, 1.0
        js = JointState(name=[f"panda_joint{i}" for i in range(1, 8)],
                        position=[0.0, -0.19, 0.0, -2.08, 0.0, 1.89, 0.785])
        js.header.stamp.sec = tick[0]
        joints_pub.publish(js)
        goal_pub.publish(pose)
        tip_pub.publish(pose)
        path = PathMsg(poses=[pose, pose])
        path.header = pose.header
        path_pub.publish(path)

    timer = node.create_timer(0.05, stream)

    def viz_done():
        if not (markers and coloured and arm):
            return False
        lists = {m.ns: m for m in markers[-1].markers}
        return len(lists.get("contacts", Marker()).points) == 3 and len(lists.get("free_space", Marker()).points) == 1
    ros_graph.wait_for(viz_done, timeout_s=60, what="viz to publish the contact, surface and arm markers")
    ros_graph.wait_for(lambda: all(f"recording {t} " in log() for t in wanted), timeout_s=60,
                       what="the recorder to record every layout topic")
    seen = tick[0]
    ros_graph.wait_for(lambda: tick[0] >= seen + 10, timeout_s=30, what="ten more stream ticks")
    node.destroy_timer(timer)
    assert ros_graph.procs["recorder"].stop() == 0, ros_graph.logs()

    # What viz sent, as the viewer gets it: 3 contact spheres, 1 probe, 3 normal arrows.
    last = markers[-1].markers
    assert sum(m.ns == "normals" and m.type == m.ARROW for m in last) == 3
    for m in (x for x in last if x.ns == "normals"):
        a, b = m.points
        assert np.hypot(b.x - a.x, b.y - a.y) == pytest.approx(0.02)  # normal_length_m default
    assert len(coloured[-1].colors) == len(coloured[-1].points) == len(surface.points) > 0

    with Reader(out) as reader:
        conns = {c.topic: c for c in reader.connections}
        missing = wanted - set(conns)
        assert not missing, f"layout topics not in the recording: {sorted(missing)}"
        for t in wanted:
            assert conns[t].msgtype == EXPECTED_TYPES[t], t
        counts = {t: 0 for t in wanted}
        description = None
        for conn, _, data in reader.messages():
            msg = TYPESTORE.deserialize_cdr(data, conn.msgtype)
            counts[conn.topic] += 1
            assert set(frames_of(msg)) <= {"world"}, f"{conn.topic}: frames {set(frames_of(msg))}"
            if conn.topic == "/robot_description":
                description = msg.data
    assert all(counts[t] >= 1 for t in wanted), counts
    assert description is not None and "<robot" in description and "panda_joint1" in description
    assert "package://example-robot-data" not in description, "mesh URIs resolved to files"
