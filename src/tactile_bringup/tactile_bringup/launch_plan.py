"""Resolve an experiment for the shell launcher: ``python -m tactile_bringup.launch_plan``.

``plan``: validate the choices (object, strategy, files), write
``<out>/params/overrides.yaml`` and print the parameter files every node gets,
one per line, in order. ``wait-joint-states``: exit 0 once /joint_states
delivers a message, 1 after the timeout (the real rig's check).
"""

from __future__ import annotations

import argparse
import shutil
import sys
import time
from pathlib import Path
from typing import Optional, Sequence

from .cli_common import add_experiment_args, run_main
from .experiment import Experiment

STRATEGIES = ("proposed", "uncertainty", "random", "sequential", "info_gain")


def plan(args: argparse.Namespace) -> int:
    exp = Experiment(mode=args.mode, object_name=args.object, strategy=args.strategy, alpha=args.alpha,
                     seed=args.seed, touches=args.touches, user_params_files=args.params)
    if exp.strategy not in STRATEGIES:
        raise ValueError(f"unknown strategy '{exp.strategy}'; choose one of {', '.join(STRATEGIES)}")
    if args.rig == "sim":
        from tactile_sim.objects import make_object

        make_object(exp.object_name, mode=exp.mode, **exp.object_pose_kwargs())  # fails clearly if unknown
    # Copy every file into the run folder: the run stays reproducible when the
    # package defaults change later (replay.sh --offline reads them back).
    params_dir = Path(args.out) / "params"
    params_dir.mkdir(parents=True, exist_ok=True)
    copies = []
    for i, path in enumerate(exp.params_files):
        copy = params_dir / f"{i:02d}_{Path(path).name}"
        shutil.copyfile(path, copy)
        copies.append(copy)
    copies.append(exp.write_overrides(params_dir / f"{len(copies):02d}_overrides.yaml"))
    for path in copies:
        print(path.resolve())
    print(f"{exp.object_name} {exp.mode} {exp.strategy} seed {exp.seed}, {exp.touches} touches", file=sys.stderr)
    return 0


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m tactile_bringup.launch_plan")
    sub = parser.add_subparsers(dest="cmd", required=True)
    p = sub.add_parser("plan", help="validate and write the run's parameter files")
    add_experiment_args(p)
    p.add_argument("--rig", choices=("sim", "hardware"), default="sim")
    p.add_argument("--out", required=True)
    w = sub.add_parser("wait-joint-states", help="wait for /joint_states (real rig check)")
    w.add_argument("--timeout", type=float, default=10.0)
    args = parser.parse_args(argv)
    if args.cmd == "plan":
        return run_main(lambda: plan(args))
    return wait_joint_states(args.timeout)


def wait_joint_states(timeout_s: float) -> int:
    """0 once a sensor_msgs/JointState arrives on /joint_states, 1 after ``timeout_s``."""
    import rclpy
    from sensor_msgs.msg import JointState

    from tactile_common import qos, topics

    rclpy.init()
    node = rclpy.create_node("explore_rig_check")
    got: list = []
    node.create_subscription(JointState, topics.JOINT_STATES, got.append, qos.SENSOR)
    deadline = time.monotonic() + timeout_s
    try:
        while not got and time.monotonic() < deadline:
            rclpy.spin_once(node, timeout_sec=0.1)
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    if not got:
        print(f"error: no message on {topics.JOINT_STATES} within {timeout_s:.0f} s: is ros2_control's "
              "joint_state_broadcaster running on this ROS_DOMAIN_ID?", file=sys.stderr)
        return 1
    print(f"joint states: {', '.join(got[0].name)}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
