"""Check a run's parameters before any node starts: values, names, contradictions.

Every node's table (``tactile_common.param_spec``) is imported from the
module that declares it; no node is started and rclpy is never initialised.
Three kinds of problem, each reported as one line naming the value and what
is allowed:

- a command-line value outside its parameter's rule (``--touches -3``);
- a parameter file naming an unknown node or parameter (with the nearest
  valid name), or holding a value of the wrong type or outside its rule;
- settings that contradict each other once merged: an empty or inverted
  box, a start position outside the arm's safety box or below the table
  clearance, a contact hysteresis upside down, the planner's margin that
  leaves no free pre-touch point, a thin-plate R below the workspace diagonal,
  ``kernel.fit`` with the local GP path.
"""

from __future__ import annotations

import functools
import importlib
from pathlib import Path
from typing import TYPE_CHECKING, Any, Iterable, Mapping, Optional, Sequence

import numpy as np

from tactile_common.param_spec import ParamSpec, check_sections, check_value, spec
from tactile_common.params_file import read_params_file

if TYPE_CHECKING:  # pragma: no cover
    from .experiment import Experiment

#: node name -> the (module, attribute) tables its parameters come from.
NODE_TABLES: dict[str, tuple[tuple[str, str], ...]] = {
    "gpis_estimator": (("tactile_gpis.estimator", "PARAMETERS"), ("tactile_gpis.node", "NODE_PARAMETERS")),
    "soc_planner": (("tactile_planner.planner", "PARAMETERS"), ("tactile_planner.planner", "NODE_PARAMETERS")),
    "tactile_sensor": (("tactile_driver.sensor_node", "PARAMS"),),
    "arm_commander": (("tactile_driver.commander_node", "PARAMS"),),
    "sim_rig": (("tactile_sim.rig_node", "PARAMS"),),
    "sim_sensor_device": (("tactile_sim.sensor_device_node", "PARAMS"),),
    "explorer": (("tactile_bringup.experiment", "RUN_PARAMETERS"), ("tactile_bringup.explorer_node", "PARAMS")),
    "recorder": (("tactile_bringup.recorder_node", "PARAMS"), ("tactile_bringup.param_checks", "RECORDER_LISTS")),
    "player": (("tactile_bringup.player_node", "PARAMS"), ("tactile_bringup.param_checks", "PLAYER_LISTS")),
}

#: The string-list parameters the recorder and player declare unset (bag_ros.string_list_parameter).
RECORDER_LISTS = {"topics": ([""], "topics to record; empty = every topic seen"),
                  "exclude": ([""], "topics never recorded")}
PLAYER_LISTS = {"topics": ([""], "topics to play; empty = all recorded")}

#: command-line option -> (node, parameter) whose rule it must satisfy.
CLI_OPTIONS = {
    "--touches": ("explorer", "touches"),
    "--alpha": ("soc_planner", "alpha"),
    "--strategy": ("soc_planner", "strategy"),
    "--touch": ("soc_planner", "touch"),
    "--seed": ("soc_planner", "seed"),
    "--real-time-factor": ("sim_rig", "real_time_factor"),
    "--rate": ("player", "rate"),
    "--wait": ("player", "wait_for_subscribers_s"),
    "--linger": ("player", "linger_s"),
}


class ParamsError(ValueError):
    """Parameters that cannot start a run; ``errors`` holds one line per problem."""

    def __init__(self, errors: Sequence[str]) -> None:
        self.errors = list(errors)
        super().__init__("\n".join(self.errors))


@functools.lru_cache(maxsize=None)
def node_table(node: str) -> dict[str, tuple]:
    """The merged table of ``node`` (imports its modules; starts nothing)."""
    table: dict[str, tuple] = {}
    for module, attr in NODE_TABLES[node]:
        table.update(getattr(importlib.import_module(module), attr))
    return table


def all_tables() -> dict[str, dict[str, tuple]]:
    return {node: node_table(node) for node in NODE_TABLES}


def param_spec(node: str, name: str) -> ParamSpec:
    """One parameter's entry; imports the node's modules only up to the table that has it
    (``--touches`` needs the experiment's table, not the explorer node's imports)."""
    for module, attr in NODE_TABLES[node]:
        table = getattr(importlib.import_module(module), attr)
        if name in table:
            return spec(name, table[name])
    raise KeyError(f"{node} has no parameter '{name}'")


def check_cli(option: str, value: Any) -> Optional[str]:
    """``--touches -3: must be ≥ 1 (explorer.touches)``, or None."""
    if value is None:
        return None
    node, name = CLI_OPTIONS[option]
    s = param_spec(node, name)
    msg = check_value(s, value)
    if msg is None:
        return None
    reason = msg.split(": ", 1)[1]
    if s.rule.choices is not None and value not in s.rule.choices:
        reason = f"unknown {name}; {reason}"
    return f"{option} {value}: {reason} ({node}.{name})"


def check_cli_values(values: Mapping[str, Any]) -> None:
    """Raise :class:`ParamsError` for every ``{option: value}`` outside its rule."""
    errors = [e for e in (check_cli(o, v) for o, v in values.items()) if e]
    if errors:
        raise ParamsError(errors)


def check_files(paths: Iterable[Path]) -> list[str]:
    """Unknown nodes / names and bad values in parameter files, one line each."""
    tables = all_tables()
    errors: list[str] = []
    for path in paths:
        errors += check_sections(read_params_file(Path(path)), tables, where=f"{path}: ")
    return errors


def _resolved(exp: "Experiment", node: str) -> dict[str, Any]:
    return {**{k: v[0] for k, v in node_table(node).items()}, **exp.node_params(node)}


def _fmt(v: Any) -> str:
    return str(np.round(np.asarray(v, dtype=float), 4).tolist())


def check_contradictions(exp: "Experiment") -> list[str]:
    """Settings that are valid one by one but cannot hold together."""
    errors: list[str] = []
    g = _resolved(exp, "gpis_estimator")
    lo, hi = np.asarray(g["workspace.min_m"], float), np.asarray(g["workspace.max_m"], float)
    dim = 2 if exp.mode == "2d" else 3
    if lo.shape == hi.shape == (3,):
        bad = [a for a, l, h in zip("xyz", lo, hi) if not h > l]
        if bad:
            errors.append(f"gpis_estimator.workspace.min_m {_fmt(lo)} .. workspace.max_m {_fmt(hi)}: an empty box "
                          f"(max must exceed min on every axis; not on {', '.join(bad)})")
        elif str(g["kernel.type"]) == "thin_plate" and float(g["kernel.R_m"]) > 0:
            diag = float(np.linalg.norm(hi[:dim] - lo[:dim]))
            if float(g["kernel.R_m"]) < diag:
                errors.append(f"gpis_estimator.kernel.R_m = {g['kernel.R_m']}: must be 0 (auto) or at least the "
                              f"workspace diagonal {diag:.4f} m")
        if bool(g["kernel.fit"]) and str(g["method"]) != "exact":
            errors.append(f"gpis_estimator.kernel.fit = true with method '{g['method']}': the fit rebuilds one exact "
                          f"GP; set method: exact, or kernel.fit: false")
        if dim == 2 and not errors and not lo[2] <= float(g["plane_z_m"]) <= hi[2]:
            errors.append(f"gpis_estimator.plane_z_m = {g['plane_z_m']}: must lie in the workspace's z range "
                          f"[{lo[2]:g}, {hi[2]:g}]")

    a = _resolved(exp, "arm_commander")
    boxes = [np.asarray(a[k], float) for k in ("box_x_m", "box_y_m", "box_z_m")]
    start = np.asarray(_resolved(exp, "explorer")["start_tip_xyz_m"], float)
    if all(b.shape == (2,) and b[1] > b[0] for b in boxes) and start.shape == (3,):
        outside = [f"{axis} {v:g} not in [{b[0]:g}, {b[1]:g}]" for axis, v, b in zip("xyz", start, boxes)
                   if not b[0] <= v <= b[1]]
        if outside:
            errors.append(f"explorer.start_tip_xyz_m {_fmt(start)}: outside the arm's safety box "
                          f"(arm_commander.box_*_m): {'; '.join(outside)}")
        floor = float(a["table_z_m"]) + float(a["table_margin_m"]) + float(a["tip_radius_m"])
        if start[2] < floor - 1e-9:
            errors.append(f"explorer.start_tip_xyz_m {_fmt(start)}: z must be at least table_z_m + table_margin_m "
                          f"+ tip_radius_m = {floor:g} m")
    cmd_start = np.asarray(a["start_tip_xyz_m"], float)
    if a.get("move_to_start", True) and cmd_start.shape == start.shape and not np.allclose(cmd_start, start):
        errors.append(f"arm_commander.start_tip_xyz_m {_fmt(cmd_start)} and explorer.start_tip_xyz_m {_fmt(start)}: "
                      "must be equal (the explorer waits for the tip where the commander puts it; set it under /**)")

    s = _resolved(exp, "tactile_sensor")
    if float(s["contact.off_threshold_n"]) > float(s["contact.on_threshold_n"]):
        errors.append(f"tactile_sensor.contact.off_threshold_n = {s['contact.off_threshold_n']}: must not exceed "
                      f"contact.on_threshold_n = {s['contact.on_threshold_n']} (hysteresis)")
    if float(s["reconnect_min_s"]) > float(s["reconnect_max_s"]):
        errors.append(f"tactile_sensor.reconnect_min_s = {s['reconnect_min_s']}: must not exceed "
                      f"reconnect_max_s = {s['reconnect_max_s']}")

    p = _resolved(exp, "soc_planner")
    if float(p["margin_m"]) >= float(p["standoff_m"]) + float(p["tip_radius_m"]):
        errors.append(f"soc_planner.margin_m = {p['margin_m']}: must be below standoff_m + tip_radius_m = "
                      f"{float(p['standoff_m']) + float(p['tip_radius_m']):g} m, or no pre-touch point is free")
    if dim == 3 and bool(p["shaft_clear"]) and float(p["shaft_length_m"]) < float(a["tip_offset_m"]) - 1e-9:
        errors.append(f"soc_planner.shaft_length_m = {p['shaft_length_m']}: shorter than the finger, "
                      f"arm_commander.tip_offset_m = {a['tip_offset_m']} (the rod from the tip centre to the flange): "
                      "the planner would not keep the rest of it clear of the object; set both")
    if p.get("touch") == "slide":  # the servo is the commander's; the offline loop reads the same keys
        from tactile_driver.slide_servo import SlideServoConfig

        if abs(float(p["slide_speed_mps"]) - float(a["slide.slide_speed_mps"])) > 1e-12:
            errors.append(f"soc_planner.slide_speed_mps = {p['slide_speed_mps']} and arm_commander."
                          f"slide.slide_speed_mps = {a['slide.slide_speed_mps']}: must be equal (the planner's "
                          "motion model and the commander's servo; set both)")
        try:
            SlideServoConfig.from_params(a, "slide.")
        except ValueError as exc:
            errors.append(f"arm_commander.{exc}")
    return errors


def check_experiment(exp: "Experiment") -> None:
    """Raise :class:`ParamsError` with every problem of ``exp``'s files and choices."""
    errors = check_files(exp.params_files)
    if not errors:  # contradictions are only meaningful between valid values
        errors = check_contradictions(exp)
    if errors:
        raise ParamsError(errors)

