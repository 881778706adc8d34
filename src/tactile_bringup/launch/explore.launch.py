"""``ros2 launch tactile_bringup explore.launch.py`` — for machines with a full ROS 2 install.

Starts the same nodes with the same parameter files as ``scripts/explore.sh``
(the primary entry point; the PyPI wheels have no ``launch``):

    ros2 launch tactile_bringup explore.launch.py mode:=2d object:=star strategy:=proposed \\
        touches:=20 seed:=0 out:=runs/star rig:=sim real_time_factor:=4.0
"""

import time
from pathlib import Path

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, EmitEvent, OpaqueFunction, RegisterEventHandler
from launch.event_handlers import OnProcessExit
from launch.events import Shutdown
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from tactile_planner.strategies import STRATEGY_NAMES

ARGS = {
    "mode": ("2d", "2d or 3d"),
    "object": ("", "object name or file (sim); empty = the mode's default"),
    "strategy": ("", " | ".join(STRATEGY_NAMES)),
    "alpha": ("", "trade-off of the proposed strategy"),
    "touches": ("", "touch budget"),
    "seed": ("0", "seed of every random choice"),
    "out": ("", "run folder (default runs/<timestamp>)"),
    "rig": ("sim", "sim or hardware"),
    "sensor_port": ("/dev/ttyUSB0", "hardware: the sensor's serial device"),
    "real_time_factor": ("4.0", "sim: simulated seconds per wall second"),
    "params": ("", "extra parameter file"),
}


def _nodes(context):
    from tactile_bringup.experiment import Experiment
    from tactile_common import topics

    a = {k: LaunchConfiguration(k).perform(context) for k in ARGS}
    out = Path(a["out"] or f"runs/{time.strftime('%Y%m%d-%H%M%S')}").resolve()
    (out / "params").mkdir(parents=True, exist_ok=True)
    exp = Experiment(mode=a["mode"], object_name=a["object"] or None, strategy=a["strategy"] or None,
                     alpha=float(a["alpha"]) if a["alpha"] else None, seed=int(a["seed"]),
                     touches=int(a["touches"]) if a["touches"] else None,
                     user_params_files=[a["params"]] if a["params"] else [])
    files = [str(p) for p in exp.params_files] + [str(exp.write_overrides(out / "params" / "overrides.yaml"))]
    sim = a["rig"] == "sim"
    common = {"use_sim_time": sim}
    port = str(out / "sensor.pty") if sim else a["sensor_port"]

    def node(executable, package, extra=None):
        return Node(package=package, executable=executable, name=executable, output="screen",
                    parameters=files + [common, extra or {}])

    nodes = [node("recorder", "tactile_bringup",
                  {"output": str(out / "run.mcap"), "exclude": [topics.ROSOUT, topics.PARAMETER_EVENTS]})]
    if sim:
        nodes.append(node("sim_rig", "tactile_sim",
                          {"real_time_factor": float(a["real_time_factor"]), "sensor_link_path": port}))
    explorer = node("explorer", "tactile_bringup",
                    {"params_files": files, "out_dir": str(out), "mode": a["mode"], "evaluate": sim})
    nodes += [node("tactile_sensor", "tactile_driver", {"port": port}),
              node("gpis_estimator", "tactile_gpis"), node("soc_planner", "tactile_planner"),
              node("arm_commander", "tactile_driver"), node("viz", "tactile_bringup"), explorer,
              RegisterEventHandler(OnProcessExit(target_action=explorer,
                                                 on_exit=[EmitEvent(event=Shutdown(reason="exploration done"))]))]
    return nodes


def generate_launch_description():
    return LaunchDescription(
        [DeclareLaunchArgument(k, default_value=v, description=d) for k, (v, d) in ARGS.items()]
        + [OpaqueFunction(function=_nodes)])
