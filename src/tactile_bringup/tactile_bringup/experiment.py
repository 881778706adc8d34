"""One experiment's configuration, shared by the offline loop and the node graph.

The parameters come from the same ROS parameter files the nodes get, in this
order (later wins): each node's package defaults (``share/<pkg>/config``),
``tactile_bringup/config/explore_<mode>.yaml`` (what differs between 2D and
3D), the user's ``--params`` files, then the command-line choices (object,
strategy, alpha, seed, touches) as an overrides file. ``write_overrides``
writes that last file so the graph's nodes get exactly what the offline loop
uses.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional, Sequence

import numpy as np
import yaml

from tactile_common.param_spec import Rule
from tactile_common.params_file import node_params, package_config

#: node name -> (package, defaults file)
NODE_DEFAULTS = {
    "gpis_estimator": ("tactile_gpis", "gpis_estimator.yaml"),
    "soc_planner": ("tactile_planner", "soc_planner.yaml"),
    "tactile_sensor": ("tactile_driver", "tactile_sensor.yaml"),
    "arm_commander": ("tactile_driver", "arm_commander.yaml"),
    "sim_rig": ("tactile_sim", "sim_rig.yaml"),
    "explorer": ("tactile_bringup", "explorer.yaml"),
}
MODES = ("2d", "3d")
#: The explorer's touch_timeout_s with --touch slide (wall clock; the poke default is 60 s).
SLIDE_TOUCH_TIMEOUT_S = 600.0

#: The explorer's parameters that define the run (read from the files by the
#: offline loop and the explorer node alike; the explorer also declares them).
RUN_PARAMETERS = {
    "touches": (20, "touch budget", Rule(ge=1)),
    "max_travel_m": (0.0, "travel budget (0 = none)", Rule(ge=0.0)),
    "confidence_max_var_m2": (0.0, "stop when the max variance on the estimated surface is below (0 = off)",
                              Rule(ge=0.0)),
    "evaluation_resolution_m": (0.002, "IoU lattice spacing (simulation only)", Rule(gt=0.0)),
    "evaluation_partial_volume": (True, "IoU: a cell a surface passes through counts by the fraction of it "
                                  "inside, not by its centre (tactile_sim.metrics.partial_volume_iou)", Rule()),
    "start_tip_xyz_m": ([0.35, 0.0, 0.06], "tip centre where exploration starts (world)", Rule(length=3)),
}


#: Defaults of a sliding run (--touch slide), between the mode's file and the user's.
SLIDE_PARAMS_FILE = "explore_slide.yaml"


def default_params_files(mode: str) -> list[Path]:
    """Every node's defaults, then the mode's file."""
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, not '{mode}'")
    files = []
    for package, filename in NODE_DEFAULTS.values():
        try:
            files.append(package_config(package, filename))
        except ValueError:
            continue  # a package without defaults file: its node's declared defaults apply
    files.append(package_config("tactile_bringup", f"explore_{mode}.yaml"))
    return files


@dataclass
class Experiment:
    """The choices of one run; every node's parameters derive from it."""

    mode: str = "2d"
    object_name: Optional[str] = None
    strategy: Optional[str] = None
    alpha: Optional[float] = None
    seed: int = 0
    touches: Optional[int] = None
    user_params_files: Sequence[Path] = field(default_factory=list)
    touch: Optional[str] = None  # 'poke' | 'slide' (soc_planner.touch; None: the files')

    #: the explorer's run parameters (see :data:`RUN_PARAMETERS`)
    RUN_PARAMETERS = RUN_PARAMETERS

    def __post_init__(self) -> None:
        """Resolve and check everything: a bad value, an unknown name or a contradiction
        raises :class:`~tactile_bringup.param_checks.ParamsError` (one line per problem)."""
        from .param_checks import check_cli_values, check_experiment

        check_cli_values({"--alpha": self.alpha, "--touches": self.touches, "--strategy": self.strategy,
                          "--seed": self.seed, "--touch": self.touch})
        slide = [package_config("tactile_bringup", SLIDE_PARAMS_FILE)] if self.touch == "slide" else []
        self.params_files = default_params_files(self.mode) + slide + [Path(p) for p in self.user_params_files]
        for path in self.params_files:
            if not Path(path).is_file():
                raise ValueError(f"{path}: no such parameter file")
        self.overrides = self._overrides()
        check_experiment(self)
        self._resolve()

    @classmethod
    def from_files(cls, mode: str, params_files: Sequence[str]) -> "Experiment":
        """The experiment a graph node was started with: exactly these files
        (they already include the overrides that ``write_overrides`` wrote)."""
        exp = cls.__new__(cls)
        exp.mode, exp.seed, exp.user_params_files = mode, 0, []
        exp.object_name = exp.strategy = exp.alpha = exp.touches = None
        exp.params_files = [Path(p) for p in params_files]
        exp.overrides = {}
        exp._resolve()
        exp.seed = int(exp.node_params("soc_planner").get("seed", 0))
        return exp

    def _resolve(self) -> None:
        """Read the choices back from the parameters (one source of truth)."""
        for path in self.params_files:
            if not Path(path).exists():
                raise ValueError(f"{path}: no such parameter file")
        explorer = {**{k: v[0] for k, v in RUN_PARAMETERS.items()}, **self.node_params("explorer")}
        self.object_name = self.object_name or str(self.node_params("sim_rig").get("object", "ellipse"))
        if self.overrides:
            self.overrides["sim_rig"]["object"] = self.object_name
        self.strategy = self.node_params("soc_planner").get("strategy", "proposed")
        self.alpha = self.node_params("soc_planner").get("alpha")
        self.touches = int(explorer["touches"])
        self.max_travel_m = float(explorer["max_travel_m"])
        self.confidence_max_var_m2 = float(explorer["confidence_max_var_m2"])
        self.evaluation_resolution_m = float(explorer["evaluation_resolution_m"])
        self.evaluation_partial_volume = bool(explorer["evaluation_partial_volume"])
        self.start_tip_xyz = np.asarray(explorer["start_tip_xyz_m"], dtype=float)

    # -- parameters ------------------------------------------------------------
    def _overrides(self) -> dict[str, dict[str, Any]]:
        """The command-line choices as per-node parameters."""
        o: dict[str, dict[str, Any]] = {"/**": {"mode": self.mode}}
        o["soc_planner"] = {"seed": int(self.seed)}
        o["sim_rig"] = {"sensor_seed": int(self.seed)}
        if self.strategy is not None:
            o["soc_planner"]["strategy"] = self.strategy
        if self.alpha is not None:
            o["soc_planner"]["alpha"] = float(self.alpha)
        o["explorer"] = {}
        if getattr(self, "touch", None) is not None:
            o["soc_planner"]["touch"] = str(self.touch)
            if self.touch == "slide":
                # A slide is one long touch (up to slide_max_length_m at the servo's pace, which a
                # loaded machine slows further): the explorer waits that long before re-issuing it.
                o["explorer"]["touch_timeout_s"] = SLIDE_TOUCH_TIMEOUT_S
        if self.touches is not None:
            o["explorer"]["touches"] = int(self.touches)
        return o

    def node_params(self, node: str) -> dict[str, Any]:
        """Parameters of ``node`` as the graph's node gets them."""
        params = node_params(self.params_files, node)
        params.update(self.overrides.get("/**", {}))
        params.update(self.overrides.get(node, {}))
        return params

    @property
    def gpis_params(self) -> dict[str, Any]:
        """The estimator's parameters, its declared defaults filling what no file sets."""
        from tactile_gpis.estimator import PARAMETERS

        return {**{k: v[0] for k, v in PARAMETERS.items()}, **self.node_params("gpis_estimator")}

    @property
    def planner_params(self) -> dict[str, Any]:
        """The planner's parameters, its declared defaults filling what no file sets."""
        from tactile_planner.planner import PARAMETERS

        return {**{k: v[0] for k, v in PARAMETERS.items()}, **self.node_params("soc_planner")}

    @property
    def sensor_params(self) -> dict[str, Any]:
        return self.node_params("tactile_sensor")

    @property
    def sim_params(self) -> dict[str, Any]:
        return self.node_params("sim_rig")

    @property
    def arm_params(self) -> dict[str, Any]:
        return self.node_params("arm_commander")

    def object_pose_kwargs(self) -> dict[str, Any]:
        sim = self.sim_params
        kwargs: dict[str, Any] = {}
        if "object_xy_m" in sim:
            kwargs["center_xy_m"] = tuple(float(v) for v in sim["object_xy_m"])
        if "object_yaw_rad" in sim:
            kwargs["yaw_rad"] = float(sim["object_yaw_rad"])
        if "object_scale" in sim:
            kwargs["scale"] = float(sim["object_scale"])
        return kwargs

    def evaluation_bounds(self) -> np.ndarray:
        """(2, dim) box where IoU is measured: the estimator's workspace (z ≥ 0 in 3D)."""
        g = self.gpis_params
        lo = np.asarray(g["workspace.min_m"], dtype=float)
        hi = np.asarray(g["workspace.max_m"], dtype=float)
        dim = 2 if self.mode == "2d" else 3
        lo, hi = lo[:dim].copy(), hi[:dim].copy()
        if dim == 3:
            lo[2] = max(lo[2], 0.0)
        return np.stack([lo, hi])

    def config_summary(self) -> dict[str, Any]:
        """What the report records of the configuration."""
        return {
            "params_files": [str(p) for p in self.params_files],
            "overrides": self.overrides,
            "gpis_estimator": self.gpis_params,
            "soc_planner": self.planner_params,
            "motion": {k: self.planner_params.get(k) for k in ("tip_speed_mps", "approach_speed_mps", "dwell_s")},
            "evaluation": {"resolution_m": self.evaluation_resolution_m,
                           "partial_volume": self.evaluation_partial_volume},
        }

    def write_overrides(self, path: Path) -> Path:
        """The overrides as a ROS parameter file, for the graph's nodes."""
        doc = {node: {"ros__parameters": values} for node, values in self.overrides.items()}
        Path(path).write_text(yaml.safe_dump(doc, sort_keys=False))
        return Path(path)
