"""Two node processes exchange a PointCloud2 through the codec (harness smoke test)."""

import numpy as np
import pytest
from sensor_msgs.msg import PointCloud2

from tactile_common import qos
from tactile_common.pointcloud import from_pointcloud2
from tactile_common.smoke import seeded_cloud

pytestmark = pytest.mark.graph


def test_cloud_goes_through_two_processes(ros_graph):
    ros_graph.start("talker", ["cloud_talker", "--ros-args", "-p", "seed:=7", "-p", "n_points:=5000"])
    ros_graph.start("echo", ["cloud_echo"])
    msg = ros_graph.wait_for_message("cloud_echo", PointCloud2, qos.EVENTS, timeout_s=30)
    got = from_pointcloud2(msg)
    want = seeded_cloud(7, 5000)
    for name in ("normal_x", "normal_y", "normal_z"):
        want[name] = -want[name]
    np.testing.assert_array_equal(got, want)
    codes = ros_graph.stop_all()
    assert codes == {"echo": 0, "talker": 0}, "nodes must exit cleanly on SIGINT"
