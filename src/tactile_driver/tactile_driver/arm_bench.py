"""Arm commander benchmark: FK/Jacobian, IK and touch planning time, as ratios measured in one run.

    python -m tactile_driver.arm_bench [--touches 20] [--seed 0] [--json FILE]

Prints the time to plan one touch (path + approach + retract: box check,
IK per waypoint, time parameterisation) against the robot time that touch
takes to execute: the ratio says how much planning adds to a touch.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from tactile_driver.ik import IKSettings, solve_ik
from tactile_driver.kinematics import ArmModel
from tactile_driver.trajectory import MotionLimits, plan_tip_path

HOME = np.array([0.0, -0.1897, 0.0, -2.079, 0.0, 1.8893, 0.7854])


def _per_call_s(fn, n: int) -> float:
    t = time.perf_counter()
    for _ in range(n):
        fn()
    return (time.perf_counter() - t) / n


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--touches", type=int, default=20)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", default="")
    a = ap.parse_args(argv)
    rng = np.random.default_rng(a.seed)
    arm = ArmModel()
    fkj_s = _per_call_s(lambda: arm.fk_jacobian(HOME), 2000)
    targets = rng.uniform([0.35, -0.15, 0.03], [0.65, 0.15, 0.25], size=(100, 3))
    t = time.perf_counter()
    iters = [solve_ik(arm, x, HOME, IKSettings()).iterations for x in targets]
    ik_s = (time.perf_counter() - t) / len(targets)
    fast = MotionLimits.for_model(arm, 1.0, 2.0, 0.10)
    slow = MotionLimits.for_model(arm, 1.0, 2.0, 0.02)
    plan_s, exec_s, q = [], [], HOME
    for _ in range(a.touches):
        angle = rng.uniform(0, 2 * np.pi)
        n = np.array([np.cos(angle), np.sin(angle), 0.0])
        pre = np.array([0.5, 0.0, 0.06]) + 0.07 * n
        here = arm.fk(q)[0]
        path = np.array([here, [here[0], here[1], 0.15], [pre[0], pre[1], 0.15], pre])
        t = time.perf_counter()
        to_goal = plan_tip_path(arm, path, q, fast)
        approach = plan_tip_path(arm, [pre - 0.04 * n], to_goal.positions_rad[-1], slow, max_step_m=0.005)
        retract = plan_tip_path(arm, [pre], approach.positions_rad[-1], slow, max_step_m=0.005)
        plan_s.append(time.perf_counter() - t)
        exec_s.append(to_goal.duration_s + approach.duration_s + retract.duration_s)
        q = retract.positions_rad[-1]
    figures = {
        "fk_jacobian_us": fkj_s * 1e6,
        "ik_ms": ik_s * 1e3,
        "ik_iterations_mean": float(np.mean(iters)),
        "plan_touch_ms_mean": float(np.mean(plan_s)) * 1e3,
        "execute_touch_s_mean": float(np.mean(exec_s)),
        "plan_over_execute_ratio": float(np.sum(plan_s) / np.sum(exec_s)),
    }
    print(f"FK + frame Jacobian: {figures['fk_jacobian_us']:.1f} us")
    print(f"IK (DLS, finger vertical): {figures['ik_ms']:.2f} ms, {figures['ik_iterations_mean']:.1f} iterations")
    print(f"plan one touch: {figures['plan_touch_ms_mean']:.1f} ms; execute it: {figures['execute_touch_s_mean']:.2f} s "
          f"(robot time); planning / execution = {figures['plan_over_execute_ratio']:.4f}")
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(figures, fh, indent=2)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
