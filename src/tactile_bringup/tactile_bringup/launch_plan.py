"""Resolve an experiment for the shell launchers: ``python -m tactile_bringup.launch_plan``.

``plan`` (scripts/explore.sh): check every choice and file against the nodes'
parameter tables (values, names, contradictions; see
:mod:`tactile_bringup.param_checks`), then, and only then, create
``<out>/params/`` with a copy of each file and the overrides, and print the
files every node gets, one per line, in order. ``replay`` (scripts/replay.sh):
check the player's options and any ``--params`` files. Both exit 2 with one
line per problem before anything is started or written.
``resume`` (explore.sh --resume): rebuild an interrupted run and write the next
session's bundle (:mod:`tactile_bringup.resume`); prints ``<session> <mode> <rig>``,
then the files every node gets, one per line.
``wait-joint-states``: exit 0 once /joint_states delivers a message, 1 after
the timeout (the real rig's check).
"""

from __future__ import annotations

import argparse
import shutil
import sys
import time
from pathlib import Path
from typing import Optional, Sequence

from .cli_common import Parser, add_experiment_args, check_outputs, finite_float, run_main
from .experiment import Experiment
from .param_checks import ParamsError, check_cli_values, check_files


def plan(args: argparse.Namespace) -> int:
    check_cli_values({"--real-time-factor": args.real_time_factor})
    check_outputs((Path(args.out), "--out", True))
    exp = Experiment(mode=args.mode, object_name=args.object, strategy=args.strategy, alpha=args.alpha,
                     seed=args.seed, touches=args.touches, user_params_files=args.params, touch=args.touch)
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


def resume(args: argparse.Namespace) -> int:
    from .resume import prepare

    check_cli_values({"--touches": args.touches, "--real-time-factor": args.real_time_factor})
    plan = prepare(Path(args.out), args.touches)
    print(f"{plan.session} {plan.mode} {plan.rig}")
    for path in plan.params_files:
        print(path)
    return 0


def replay(args: argparse.Namespace) -> int:
    """Check replay.sh's options (the player's rules) and its --params files."""
    check_cli_values({"--rate": args.rate, "--wait": args.wait, "--linger": args.linger})
    for path in args.params:
        if not Path(path).is_file():
            raise ValueError(f"{path}: no such parameter file")
    errors = check_files(args.params)
    if errors:
        raise ParamsError(errors)
    return 0


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = Parser(prog="python -m tactile_bringup.launch_plan")
    sub = parser.add_subparsers(dest="cmd", required=True, parser_class=Parser)
    p = sub.add_parser("plan", prog="explore.sh", help="check and write the run's parameter files")
    add_experiment_args(p)
    p.add_argument("--rig", choices=("sim", "hardware"), default="sim")
    p.add_argument("--real-time-factor", type=finite_float, default=None)
    p.add_argument("--out", required=True)
    r = sub.add_parser("replay", prog="replay.sh", help="check replay.sh's options and --params files")
    r.add_argument("--rate", type=finite_float, default=None)
    r.add_argument("--wait", type=finite_float, default=None)
    r.add_argument("--linger", type=finite_float, default=None)
    r.add_argument("--params", action="append", default=[])
    s = sub.add_parser("resume", prog="explore.sh --resume", help="rebuild a run and prepare its next session")
    s.add_argument("--out", required=True)
    s.add_argument("--touches", type=int, default=None)
    s.add_argument("--real-time-factor", type=finite_float, default=None)
    w = sub.add_parser("wait-joint-states", help="wait for /joint_states (real rig check)")
    w.add_argument("--timeout", type=finite_float, default=10.0)
    args = parser.parse_args(argv)
    if args.cmd == "plan":
        return run_main(lambda: plan(args))
    if args.cmd == "replay":
        return run_main(lambda: replay(args))
    if args.cmd == "resume":
        return run_main(lambda: resume(args))
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
