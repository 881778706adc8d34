"""The explorer's RunRecorder: the touch target it records from a goal pose message."""

import numpy as np
from geometry_msgs.msg import PoseStamped
from scipy.spatial.transform import Rotation

from tactile_bringup.experiment import Experiment
from tactile_bringup.progress import RunRecorder
from tactile_common.fields import CONTACT_DTYPE, LABEL_CONTACT
from tactile_planner.pose import approach_rotation


def test_target_is_the_candidate_behind_the_pre_touch_point(tmp_path):
    exp = Experiment(mode="2d", object_name="circle", touches=3, seed=0)
    run = RunRecorder(exp, tmp_path, evaluate=False)
    offset_m = float(exp.planner_params["standoff_m"]) + float(exp.planner_params["tip_radius_m"])
    candidate = np.array([0.55, 0.0, 0.06])
    normal = np.array([0.6, 0.8, 0.0])  # outward at the candidate
    pre_touch = candidate + offset_m * normal
    goal = PoseStamped()
    goal.pose.position.x, goal.pose.position.y, goal.pose.position.z = pre_touch
    x, y, z, w = Rotation.from_matrix(approach_rotation(normal)).as_quat()  # x-axis = −normal
    goal.pose.orientation.x, goal.pose.orientation.y, goal.pose.orientation.z, goal.pose.orientation.w = x, y, z, w
    obs = np.zeros(1, CONTACT_DTYPE)[0]
    obs["x"], obs["y"], obs["z"] = candidate
    obs["normal_x"], obs["normal_y"] = normal[:2]
    obs["force"], obs["label"] = 1.0, LABEL_CONTACT
    record = run.add_touch(goal, obs, travel_m=0.1, time_s=1.0, decision_ms=5.0)
    np.testing.assert_allclose(record["target"], candidate, atol=1e-7)
    assert record["outcome"] == "contact" and record["travel_m"] == 0.1


def test_motion_after_the_last_touch_is_in_the_summary(tmp_path):
    """A run that ends on aborted touches moved after its last record: the summary counts it."""
    exp = Experiment(mode="2d", object_name="circle", touches=3, seed=0)
    run = RunRecorder(exp, tmp_path, evaluate=False)
    obs = np.zeros(1, CONTACT_DTYPE)[0]
    obs["x"], obs["y"], obs["z"] = 0.54, 0.0, 0.06
    obs["normal_x"], obs["label"] = 1.0, LABEL_CONTACT
    run.add_touch(None, obs, travel_m=0.1, time_s=1.0, decision_ms=5.0)
    run.add_travel(0.25, 3.0)  # an aborted touch, then the run gave up
    summary = run.report("touch aborted: ...")["summary"]
    assert summary["touches"] == 1
    assert summary["travel_m"] == 0.35 and summary["time_s"] == 4.0
