"""Parameter tables: types, rules, names, descriptors; every node's defaults obey their own rules."""

from __future__ import annotations

import math

import pytest

from tactile_common.param_spec import ROS_BUILTIN, Rule, check_sections, check_value, nearest, spec, specs


def _reason(default, value, rule=None):
    s = spec("p", (default, "d") if rule is None else (default, "d", rule))
    return check_value(s, value)


@pytest.mark.parametrize("default, good, bad, why", [
    (1.0, 2.5, 2, "must be a double: write 2.0"),  # ROS reads 2 as an integer
    (1.0, -0.5, True, "must be a double, not a bool"),
    (3, 4, 4.0, "must be an integer, not a double"),
    (3, -7, False, "must be an integer, not a bool"),
    (True, False, 1, "must be a bool, not an integer"),
    ("x", "y", 1.0, "must be a string, not a double"),
    ([0.0, 1.0], [2.0], [1, 2], "every element must be a double"),
    (["a"], [], "a", "must be a list (string[])"),
])
def test_type_follows_the_default(default, good, bad, why):
    assert _reason(default, good) is None
    assert why in _reason(default, bad)


@pytest.mark.parametrize("rule, inside, outside, text", [
    (Rule(gt=0.0), [1e-12, 5.0], [0.0, -1.0, math.nan], "> 0"),
    (Rule(ge=0.0), [0.0, 3.0], [-1e-12, math.nan], "≥ 0"),
    (Rule(gt=0.0, le=1.0), [0.5, 1.0], [0.0, 1.0 + 1e-9], "> 0 and ≤ 1"),
    (Rule(ge=-1.0, lt=1.0), [-1.0, 0.99], [1.0, -1.5], "≥ -1 and < 1"),
])
def test_bounds_are_strict_or_inclusive_as_written(rule, inside, outside, text):
    s = spec("x", (0.5, "d", rule))
    assert s.rule.text() == text
    for v in inside:
        assert check_value(s, v) is None, v
    for v in outside:
        assert check_value(s, v) == f"x = {v}: must be {text}"


def test_choices_length_and_order():
    assert _reason("2d", "3d", Rule(choices=("2d", "3d"))) is None
    assert _reason("2d", "4d", Rule(choices=("2d", "3d"))) == "p = '4d': must be one of '2d', '3d'"
    box = Rule(length=2, increasing=True)
    assert _reason([0.0, 1.0], [0.2, 0.3], box) is None
    assert _reason([0.0, 1.0], [0.3, 0.3], box) == "p = [0.3, 0.3]: must be increasing ([min, max] with min < max)"
    assert _reason([0.0, 1.0], [0.1, 0.2, 0.3], box) == "p = [0.1, 0.2, 0.3]: must have 2 values, got 3"
    assert _reason([1.0], [1.0, -2.0], Rule(gt=0.0)) == "p = [1.0, -2.0]: every element must be > 0"


def test_a_rule_may_be_written_as_a_dict():
    assert spec("a", (1.0, "d", {"gt": 0.0, "dynamic": True})).rule == Rule(gt=0.0, dynamic=True)
    with pytest.raises(TypeError):
        spec("a", (1.0, "d", {"greater": 0.0}))  # a typo in a rule fails at import, not silently


def test_nearest_name():
    names = ["alpha", "kernel.length_scale_m", "kernel.R_m", "lattice.points_per_axis_2d"]
    assert nearest("alhpa", names) == "alpha"
    assert nearest("kernel.lenght_scale_m", names) == "kernel.length_scale_m"
    assert nearest("lattice.points_per_axis2d", names) == "lattice.points_per_axis_2d"
    assert nearest("completely_else", names) is None


def test_sections_check_node_names_parameter_names_and_the_wildcard():
    tables = {"planner": {"alpha": (1.0, "a", Rule(ge=0.0)), "mode": ("2d", "m")},
              "gpis": {"mode": ("2d", "m", Rule(choices=("2d", "3d")))}}
    errors = check_sections({
        "planer": {"alpha": 1.0},
        "planner": {"alhpa": 1.0, "alpha": -1.0, "use_sim_time": True},
        "/**": {"mode": "4d", "nothing_like_it": 1},
    }, tables, where="f.yaml: ")
    assert errors == [
        "f.yaml: unknown node 'planer' (did you mean 'planner'?)",
        "f.yaml: planner: unknown parameter 'alhpa' (did you mean 'alpha'?)",
        "f.yaml: planner.alpha = -1.0: must be ≥ 0",
        "f.yaml: /**: mode = '4d': must be one of '2d', '3d'",  # one node's rule refuses it
        f"f.yaml: /**: unknown parameter 'nothing_like_it' (known: {', '.join(sorted({'alpha', 'mode', *ROS_BUILTIN}))})",
    ]


def test_every_node_table_is_valid_and_its_defaults_obey_its_rules():
    from tactile_bringup.param_checks import NODE_TABLES, node_table

    for node in NODE_TABLES:
        for s in specs(node_table(node)).values():
            if s.type_name.endswith("[]") and s.default == [""]:
                continue  # an unset list ("no topics")
            assert check_value(s, s.default) is None, (node, s.name, s.default, s.rule.text())


def test_descriptors_carry_ranges_and_read_only():
    from rclpy.parameter import Parameter

    from tactile_common.params import descriptor

    d = descriptor(spec("n", (3, "count", Rule(gt=0))), Parameter.Type.INTEGER.value)
    assert (d.integer_range[0].from_value, d.read_only) == (1, True)  # > 0 for an integer is ≥ 1
    assert "read-only" in d.additional_constraints and "> 0" in d.additional_constraints
    d = descriptor(spec("x", (0.5, "x", Rule(ge=0.0, le=1.0, dynamic=True))), Parameter.Type.DOUBLE.value)
    r = d.floating_point_range[0]
    assert (r.from_value, r.to_value, d.read_only) == (0.0, 1.0, False)
    d = descriptor(spec("s", ("a", "s", Rule(choices=("a", "b")))), Parameter.Type.STRING.value)
    assert not d.floating_point_range and not d.integer_range and "one of 'a', 'b'" in d.additional_constraints


def test_every_package_params_file_names_only_declared_parameters():
    """A key a node does not declare is silently ignored by rclpy: none may sit in our config files."""
    from pathlib import Path

    from tactile_bringup.param_checks import check_files

    root = Path(__file__).resolve().parents[2]
    files = [f for f in sorted(root.glob("src/*/config/*.yaml")) if "ros__parameters" in f.read_text()]
    assert len(files) >= 8
    assert check_files(files) == []


@pytest.mark.parametrize("yaml_text, expected", [
    ("gpis_estimator:\n  ros__parameters:\n    workspace:\n      max_m: [0.65, 0.15, 0.0]\n",
     "an empty box (max must exceed min on every axis; not on z)"),
    ("gpis_estimator:\n  ros__parameters:\n    kernel:\n      R_m: 0.1\n",
     "gpis_estimator.kernel.R_m = 0.1: must be 0 (auto) or at least the workspace diagonal"),
    ("gpis_estimator:\n  ros__parameters:\n    method: local\n    kernel:\n      fit: true\n",
     "gpis_estimator.kernel.fit = true with method 'local': the fit rebuilds one exact GP"),
    ("gpis_estimator:\n  ros__parameters:\n    plane_z_m: 0.5\n",
     "gpis_estimator.plane_z_m = 0.5: must lie in the workspace's z range [0, 0.22]"),
    ("/**:\n  ros__parameters:\n    start_tip_xyz_m: [0.33, 0.0, 0.005]\n",
     "z must be at least table_z_m + table_margin_m + tip_radius_m = 0.015 m"),
    ("tactile_sensor:\n  ros__parameters:\n    reconnect_min_s: 5.0\n",
     "tactile_sensor.reconnect_min_s = 5.0: must not exceed reconnect_max_s = 2.0"),
    ("soc_planner:\n  ros__parameters:\n    margin_m: 0.05\n",
     "soc_planner.margin_m = 0.05: must be below standoff_m + tip_radius_m = 0.02 m"),
])
def test_contradictions_are_named(tmp_path, yaml_text, expected):
    from tactile_bringup.experiment import Experiment
    from tactile_bringup.param_checks import ParamsError

    f = tmp_path / "user.yaml"
    f.write_text(yaml_text)
    with pytest.raises(ParamsError) as info:
        Experiment(mode="2d", user_params_files=[f])
    assert len(info.value.errors) == 1 and expected in info.value.errors[0], info.value.errors


def test_a_finger_rod_shorter_than_the_finger_is_named_in_3d(tmp_path):
    from tactile_bringup.experiment import Experiment
    from tactile_bringup.param_checks import ParamsError

    f = tmp_path / "user.yaml"
    f.write_text("soc_planner:\n  ros__parameters:\n    shaft_length_m: 0.1\n")
    with pytest.raises(ParamsError) as info:
        Experiment(mode="3d", user_params_files=[f])
    assert len(info.value.errors) == 1 and "shorter than the finger, arm_commander.tip_offset_m = 0.16" \
        in info.value.errors[0], info.value.errors
    Experiment(mode="2d", user_params_files=[f])  # 2D keeps no rod clear: nothing to contradict
    f.write_text("soc_planner:\n  ros__parameters:\n    shaft_length_m: 0.1\n    shaft_clear: false\n")
    Experiment(mode="3d", user_params_files=[f])
