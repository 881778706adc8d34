"""Parameter files read for ROS-free code the way --params-file reads them."""

import pytest

from tactile_common.params_file import ParamsFileError, load_yaml, node_params, read_params_file


def test_numbers_follow_ros_rules_not_yaml_1_1():
    doc = load_yaml("a: 2.0e7\nb: 1e-12\nc: 3\nd: .5\ne: -1.5E+3\nf: x1e5\ng: true\nh: '1e3'")
    assert doc == {"a": 2.0e7, "b": 1e-12, "c": 3, "d": 0.5, "e": -1500.0, "f": "x1e5", "g": True, "h": "1e3"}
    assert isinstance(doc["c"], int) and isinstance(doc["b"], float)


def test_sections_wildcard_and_later_files_win(tmp_path):
    a = tmp_path / "a.yaml"
    a.write_text("/**:\n  ros__parameters:\n    mode: 2d\n    shared: 1\n"
                 "node:\n  ros__parameters:\n    kernel:\n      type: tp\n      R_m: 1.0e-1\n    shared: 2\n")
    b = tmp_path / "b.yaml"
    b.write_text("/node:\n  ros__parameters:\n    kernel:\n      type: se\n/**:\n  ros__parameters:\n    mode: 3d\n")
    assert read_params_file(a)["node"] == {"kernel.type": "tp", "kernel.R_m": 0.1, "shared": 2}
    assert node_params([a, b], "node") == {"mode": "3d", "shared": 2, "kernel.type": "se", "kernel.R_m": 0.1}
    assert node_params([a], "other") == {"mode": "2d", "shared": 1}


@pytest.mark.parametrize("text, match", [
    ("node: {x: 1}", "no 'ros__parameters'"),
    ("[1, 2]", "sections"),
    ("a: [", "not valid YAML"),
])
def test_bad_files_name_the_problem(tmp_path, text, match):
    f = tmp_path / "bad.yaml"
    f.write_text(text)
    with pytest.raises(ParamsFileError, match=match):
        read_params_file(f)
    with pytest.raises(ParamsFileError, match="no such parameter file"):
        read_params_file(tmp_path / "missing.yaml")
