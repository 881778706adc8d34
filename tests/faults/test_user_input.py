"""A new user's mistakes: each is refused before any node starts, with one line and exit code 2.

Categories: a bad command-line value, a bad value in a ``--params`` file, an
unknown node or parameter name (with the nearest valid one), settings that
contradict each other, console scripts called straight from ``.venv/bin``,
and ``set_parameters`` on a running node (graph test).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
BIN = Path(sys.prefix) / "bin"


def _run(cmd, env=None, timeout_s=120.0) -> subprocess.CompletedProcess:
    return subprocess.run([str(c) for c in cmd], capture_output=True, text=True, timeout=timeout_s, env=env,
                          stdin=subprocess.DEVNULL)


def _bare_env() -> dict:
    """What a user's shell has without sourcing .venv/tactile.env (no AMENT_PREFIX_PATH)."""
    env = {k: v for k, v in os.environ.items() if not k.startswith(("AMENT", "VIRTUAL_ENV", "ROS_DOMAIN"))}
    env["PATH"] = "/usr/bin:/bin"
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    return env


def _params(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "user.yaml"
    path.write_text(text)
    return path


def _refused(result: subprocess.CompletedProcess, *expected: str) -> list[str]:
    """Exit code 2; stderr's lines hold each expected text; no traceback."""
    assert result.returncode == 2, (result.returncode, result.stdout, result.stderr)
    assert "Traceback" not in result.stderr, result.stderr
    lines = result.stderr.strip().splitlines()
    for text in expected:
        assert any(text in line for line in lines), (text, lines)
    return lines


def _explore(tmp_path: Path, *args) -> subprocess.CompletedProcess:
    out = tmp_path / "run"
    result = _run([ROOT / "scripts" / "explore.sh", "--out", out, *args])
    # Refused before any node started: no node log, no recording, not even the folder.
    assert not (out / "run.mcap").exists()
    assert not list(out.glob("logs/*.log"))
    assert not out.exists()
    return result


# -- command-line values --------------------------------------------------------
@pytest.mark.parametrize("args, expected", [
    (["--touches", "-3"], "--touches -3: must be ≥ 1 (explorer.touches)"),
    (["--touches", "two"], "argument --touches: 'two' is not an integer"),
    (["--alpha", "-1"], "--alpha -1.0: must be ≥ 0 (soc_planner.alpha)"),
    (["--real-time-factor", "0"], "--real-time-factor 0.0: must be > 0 (sim_rig.real_time_factor)"),
    (["--real-time-factor", "nan"], "--real-time-factor: 'nan' is not a finite number"),
    (["--strategy", "greedy"], "--strategy greedy: unknown strategy; must be one of 'proposed'"),
    (["--seed", "-1"], "--seed -1: must be ≥ 0"),
    (["--mode", "4d"], "argument --mode: invalid choice: '4d'"),
    (["--touches"], "--touches needs a value"),
    (["--tuoches", "3"], "unknown option '--tuoches'"),
])
def test_explore_refuses_a_bad_command_line_value(tmp_path, args, expected):
    lines = _refused(_explore(tmp_path, *args), expected)
    assert len(lines) == 1


def test_explore_refuses_a_run_folder_that_is_a_file(tmp_path):
    out = tmp_path / "a_file"
    out.write_text("")
    _refused(_run([ROOT / "scripts" / "explore.sh", "--out", out]), f"--out {out}: is a file")
    assert out.read_text() == ""


# -- values and names in --params files -------------------------------------------
def test_explore_refuses_a_bad_value_in_a_params_file(tmp_path):
    f = _params(tmp_path, "soc_planner:\n  ros__parameters:\n    alpha: -2.0\n")
    lines = _refused(_explore(tmp_path, "--params", f), f"{f}: soc_planner.alpha = -2.0: must be ≥ 0")
    assert len(lines) == 1


def test_explore_refuses_a_lattice_size_below_three(tmp_path):
    f = _params(tmp_path, "gpis_estimator:\n  ros__parameters:\n    lattice:\n      points_per_axis_2d: -5\n")
    _refused(_explore(tmp_path, "--params", f), "gpis_estimator.lattice.points_per_axis_2d = -5: must be ≥ 3")


def test_explore_refuses_an_integer_where_a_double_is_declared(tmp_path):
    # A ROS node would refuse '2' for a double parameter at start-up: say so now, and how to write it.
    f = _params(tmp_path, "soc_planner:\n  ros__parameters:\n    alpha: 2\n")
    _refused(_explore(tmp_path, "--params", f), "soc_planner.alpha = 2: must be a double: write 2.0")


def test_explore_names_the_nearest_valid_parameter_and_node(tmp_path):
    f = _params(tmp_path, "soc_planner:\n  ros__parameters:\n    alhpa: 1.0\n"
                          "gpis_estimater:\n  ros__parameters:\n    mode: '2d'\n"
                          "/**:\n  ros__parameters:\n    tip_radius: 0.01\n")
    lines = _refused(_explore(tmp_path, "--params", f),
                     "soc_planner: unknown parameter 'alhpa' (did you mean 'alpha'?)",
                     "unknown node 'gpis_estimater' (did you mean 'gpis_estimator'?)",
                     "/**: unknown parameter 'tip_radius' (did you mean 'tip_radius_m'?)")
    assert len(lines) == 3


# -- contradictions ------------------------------------------------------------------
@pytest.mark.parametrize("yaml_text, expected", [
    ("gpis_estimator:\n  ros__parameters:\n    workspace:\n      min_m: [0.65, -0.15, 0.0]\n"
     "      max_m: [0.35, 0.15, 0.22]\n", "an empty box (max must exceed min on every axis; not on x)"),
    ("arm_commander:\n  ros__parameters:\n    box_z_m: [0.6, 0.0]\n",
     "arm_commander.box_z_m = [0.6, 0.0]: must be increasing"),
    ("/**:\n  ros__parameters:\n    start_tip_xyz_m: [0.9, 0.0, 0.06]\n",
     "explorer.start_tip_xyz_m [0.9, 0.0, 0.06]: outside the arm's safety box (arm_commander.box_*_m): "
     "x 0.9 not in [0.25, 0.75]"),
    ("explorer:\n  ros__parameters:\n    start_tip_xyz_m: [0.4, 0.0, 0.06]\n",
     "arm_commander.start_tip_xyz_m [0.33, 0.0, 0.06] and explorer.start_tip_xyz_m [0.4, 0.0, 0.06]: must be equal"),
    ("tactile_sensor:\n  ros__parameters:\n    contact:\n      off_threshold_n: 0.5\n",
     "tactile_sensor.contact.off_threshold_n = 0.5: must not exceed contact.on_threshold_n = 0.05"),
])
def test_explore_refuses_contradictory_settings(tmp_path, yaml_text, expected):
    _refused(_explore(tmp_path, "--params", _params(tmp_path, yaml_text)), expected)


# -- replay.sh ---------------------------------------------------------------------------
@pytest.mark.parametrize("args, expected", [
    (["--rate", "0"], "--rate 0.0: must be > 0 (player.rate)"),
    (["--wait", "-1"], "--wait -1.0: must be ≥ 0 (player.wait_for_subscribers_s)"),
    (["--linger", "-2.5"], "--linger -2.5: must be ≥ 0 (player.linger_s)"),
    (["--rate", "fast"], "argument --rate: 'fast' is not a number"),
])
def test_replay_refuses_a_bad_option(tmp_path, args, expected):
    bag = tmp_path / "run.mcap"
    bag.write_bytes(b"")  # never opened: the options are refused first
    _refused(_run([ROOT / "scripts" / "replay.sh", bag, *args]), expected)


def test_replay_offline_refuses_an_unknown_parameter(tmp_path):
    bag = tmp_path / "run.mcap"
    bag.write_bytes(b"")
    f = _params(tmp_path, "gpis_estimator:\n  ros__parameters:\n    kernel:\n      lenght_scale_m: 0.1\n")
    _refused(_run([ROOT / "scripts" / "replay.sh", bag, "--offline", "--params", f]),
             "gpis_estimator: unknown parameter 'kernel.lenght_scale_m' (did you mean 'kernel.length_scale_m'?)")



def test_replay_offline_refuses_an_output_folder_that_is_a_file(tmp_path):
    bag = tmp_path / "run.mcap"
    bag.write_bytes(b"")  # never opened: the output is refused first
    out = tmp_path / "a_file"
    out.write_text("")
    _refused(_run([ROOT / "scripts" / "replay.sh", bag, "--offline", "--out", out]), f"--out {out}: is a file")

# -- console scripts, called directly without tactile.env -------------------------------
def test_explore_offline_runs_from_venv_bin_without_tactile_env(tmp_path):
    report = tmp_path / "report.json"
    result = _run([BIN / "tactile-explore-offline", "--touches", "1", "--quiet", "--report", report],
                  env=_bare_env(), timeout_s=300)
    assert result.returncode == 0, result.stderr
    assert report.exists()


@pytest.mark.parametrize("args, expected", [
    (["--touches", "-3"], "--touches -3: must be ≥ 1"),
    (["--alpha", "-1"], "--alpha -1.0: must be ≥ 0"),
    (["--touch", "drag"], "--touch drag: unknown touch; must be one of 'poke', 'slide' (soc_planner.touch)"),
])
def test_explore_offline_refuses_bad_values(tmp_path, args, expected):
    result = _run([BIN / "tactile-explore-offline", *args, "--report", tmp_path / "r.json"], env=_bare_env())
    _refused(result, expected)
    assert not (tmp_path / "r.json").exists()


def test_explore_offline_refuses_a_bad_params_file(tmp_path):
    f = _params(tmp_path, "soc_planner:\n  ros__parameters:\n    alpha: -2.0\n")
    _refused(_run([BIN / "tactile-explore-offline", "--params", f, "--report", tmp_path / "r.json"],
                  env=_bare_env()), "soc_planner.alpha = -2.0: must be ≥ 0")


@pytest.mark.parametrize("args, expected", [
    (["--seeds", "0"], "--seeds 0: must be ≥ 1"),
    (["--strategies", "proposed,greedy"], "--strategies: unknown strategy 'greedy'"),
    (["--objects", "circle,no_such_shape"], "--objects: unknown object 'no_such_shape'"),
    (["--touches", "0"], "--touches 0: must be ≥ 1"),
])
def test_benchmark_refuses_bad_values_before_any_run(tmp_path, args, expected):
    out = tmp_path / "bench"
    _refused(_run([BIN / "tactile-benchmark", *args, "--out", out], env=_bare_env()), expected)
    assert not out.exists()


def test_benchmark_refuses_outputs_and_inputs_it_cannot_use(tmp_path):
    a_file = tmp_path / "a_file"
    a_file.write_text("not json\n")
    bench = BIN / "tactile-benchmark"
    _refused(_run([bench, "--objects", "circle", "--seeds", "1", "--out", a_file], env=_bare_env()),
             f"--out {a_file}: is a file")
    _refused(_run([bench, "--objects", "circle", "--seeds", "1", "--out", a_file / "sub"], env=_bare_env()),
             f"--out {a_file / 'sub'}: {a_file} is not a folder")
    _refused(_run([bench, "--from-runs", tmp_path / "none.json", "--out", tmp_path / "o"], env=_bare_env()),
             f"--from-runs {tmp_path / 'none.json'}: no such file")
    _refused(_run([bench, "--from-runs", a_file, "--out", tmp_path / "o"], env=_bare_env()),
             f"--from-runs {a_file}: not a runs.json of tactile-benchmark")


def test_explore_offline_refuses_outputs_it_cannot_write_before_the_run(tmp_path):
    a_file = tmp_path / "a_file"
    a_file.write_text("")
    offline = BIN / "tactile-explore-offline"
    for args, expected in (((["--out", a_file]), f"--out {a_file}: is a file"),
                           ((["--plot", tmp_path]), f"--plot {tmp_path}: is a folder"),
                           ((["--report", a_file / "r.json"]), f"--report {a_file / 'r.json'}: {a_file} is not a folder"),
                           ((["--report", "/proc/r.json"]), "--report /proc/r.json: cannot write in /proc")):
        lines = _refused(_run([offline, "--touches", "1", *args], env=_bare_env()), expected)
        assert not any(line.startswith("touch") for line in lines)  # refused before the first touch


# -- nodes ------------------------------------------------------------------------------------
@pytest.mark.graph
def test_a_node_started_directly_refuses_a_bad_value(ros_graph):
    """From .venv/bin without tactile.env: the node finds its package files and ends with its FATAL line."""
    env = {k: v for k, v in ros_graph.env().items() if not k.startswith("AMENT")}
    result = _run([BIN / "tactile_sensor", "--ros-args", "-p", "contact.min_active_taxels:=0"], env=env)
    assert result.returncode == 2, result.stdout + result.stderr
    assert "contact.min_active_taxels = 0: must be ≥ 1" in result.stdout + result.stderr
    assert "Traceback" not in result.stdout + result.stderr


def _bag_with_one_topic(path: Path) -> None:
    from rosbags.typesys import Stores, get_typestore

    from tactile_bringup.mcap_recorder import McapBagWriter, qos_profile_dict

    store = get_typestore(Stores.ROS2_JAZZY)
    w = McapBagWriter(path)
    w.add_topic("/note", "std_msgs/msg/String", [qos_profile_dict("keep_last", 10, "reliable", "volatile")],
                store.hash_rihs01("std_msgs/msg/String"))
    msg = store.types["std_msgs/msg/String"](data="hello")
    w.write("/note", bytes(store.serialize_cdr(msg, "std_msgs/msg/String")), 1_000, 1_000)
    w.close()


@pytest.mark.graph
def test_set_parameters_on_a_running_node_is_checked(ros_graph, tmp_path):
    """The player waits for subscribers; an out-of-range or read-only change is refused with the
    reason, a valid change of a dynamic parameter takes effect (it stops waiting and ends)."""
    from rcl_interfaces.srv import SetParameters
    from rclpy.parameter import Parameter

    bag = tmp_path / "one.mcap"
    _bag_with_one_topic(bag)
    player = ros_graph.start("player", ["player", "--ros-args", "-p", f"bag:={bag}",
                                        "-p", "wait_for_subscribers_s:=300.0"])

    def set_one(name, value):
        request = SetParameters.Request(parameters=[Parameter(name, value=value).to_parameter_msg()])
        return ros_graph.call(SetParameters, "/player/set_parameters", request, timeout_s=30,
                              what=f"the answer to setting {name}").results[0]

    r = set_one("linger_s", -1.0)
    assert not r.successful and "linger_s" in r.reason and "-1.0" in r.reason  # out of range, with the value
    r = set_one("wait_for_subscribers_s", float("nan"))
    assert not r.successful and "wait_for_subscribers_s" in r.reason and "nan" in r.reason
    r = set_one("rate", 2.0)
    assert not r.successful and r.reason == "Trying to set a read-only parameter: rate."
    r = set_one("loop", "yes")
    assert not r.successful and "type" in r.reason.lower()
    assert player.alive()  # nothing was applied: still waiting for a subscriber of /note
    r = set_one("wait_for_subscribers_s", 0.0)
    assert r.successful, r.reason
    ros_graph.wait_for(lambda: not player.alive(), timeout_s=30, what="the player to play and end")
    assert player.popen.returncode == 0, player.log()
