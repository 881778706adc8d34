"""--touch slide: the run's choices reach the nodes, and contradictions fail before any node starts."""

import pytest
import yaml

from tactile_bringup.experiment import SLIDE_TOUCH_TIMEOUT_S, Experiment
from tactile_bringup.param_checks import ParamsError


def _params(tmp_path, doc):
    path = tmp_path / "user.yaml"
    path.write_text(yaml.safe_dump(doc))
    return [path]


def test_touch_slide_reaches_the_planner_and_the_explorer():
    exp = Experiment(touch="slide", touches=2)
    assert exp.node_params("soc_planner")["touch"] == "slide"
    assert exp.node_params("explorer")["touch_timeout_s"] == SLIDE_TOUCH_TIMEOUT_S
    assert "touch_timeout_s" not in Experiment(touches=2).node_params("explorer")  # a poke run: unchanged


def test_the_planner_and_the_servo_must_agree_on_the_slide_speed(tmp_path):
    files = _params(tmp_path, {"soc_planner": {"ros__parameters": {"slide_speed_mps": 0.08}}})
    with pytest.raises(ParamsError, match="slide_speed_mps"):
        Experiment(touch="slide", user_params_files=files)
    Experiment(touch="poke", user_params_files=files)  # only a slide run uses the servo


def test_a_bad_force_band_is_one_line_before_start(tmp_path):
    files = _params(tmp_path, {"arm_commander": {"ros__parameters": {"slide.min_force_n": 0.5}}})
    with pytest.raises(ParamsError, match="force band"):
        Experiment(touch="slide", user_params_files=files)


def test_a_slide_run_stops_once_the_surface_is_known_unless_the_user_says_otherwise(tmp_path):
    """explore_slide.yaml: the confidence stop is on for slides (a lap senses the whole contour),
    off for pokes, and a --params file still decides."""
    assert Experiment(touch="slide").confidence_max_var_m2 == pytest.approx(1e-6)
    assert Experiment(touch="poke").confidence_max_var_m2 == 0.0
    assert Experiment().confidence_max_var_m2 == 0.0
    files = _params(tmp_path, {"explorer": {"ros__parameters": {"confidence_max_var_m2": 0.0}}})
    assert Experiment(touch="slide", user_params_files=files).confidence_max_var_m2 == 0.0


def test_a_3d_slide_run_does_not_probe_under_a_floating_estimate_unless_the_user_says_so(tmp_path):
    """explore_slide.yaml: slides down a wall reach the table, so a 3D slide run has no support probes;
    3D pokes keep them (explore_3d.yaml), and a --params file still decides."""
    assert Experiment(mode="3d", touch="slide").node_params("soc_planner")["support_gap_m"] == 0.0
    assert Experiment(mode="3d", touch="poke").node_params("soc_planner")["support_gap_m"] == pytest.approx(0.03)
    files = _params(tmp_path, {"soc_planner": {"ros__parameters": {"support_gap_m": 0.02}}})
    assert Experiment(mode="3d", touch="slide", user_params_files=files).node_params("soc_planner")[
        "support_gap_m"] == pytest.approx(0.02)
