"""The arm commander's start-up move, ROS-free: up to a clearance height, across, down to the start.

The explorer waits for the tip at ``start_xyz_m`` before its first request.
A move that ends because the joint states stalled (a loaded machine, a
controller restart) is planned again from where the arm stopped, up to
``attempts`` times; any other failure (unreachable, a contact, e-stop) is
final and logged. :meth:`update` is called every control tick; ``done``
turns true once the move succeeded or was given up (queued touches may go).
"""

from __future__ import annotations

import enum
import logging
from typing import Any

import numpy as np

from .commander_api import TaskResult


class StartState(enum.Enum):
    PENDING = "pending"  # waiting for joint states / e-stop release, then plan
    MOVING = "moving"
    DONE = "done"


class StartupMove:
    def __init__(self, arm: Any, start_xyz_m: np.ndarray, clearance_z_m: float, attempts: int = 3,
                 log: Any = None) -> None:
        start = np.asarray(start_xyz_m, dtype=float)
        if start.shape != (3,) or not np.all(np.isfinite(start)):
            raise ValueError(f"start_tip_xyz_m needs 3 finite values, got {list(np.ravel(start_xyz_m))}")
        self.arm, self.start_xyz_m, self.clearance_z_m = arm, start, float(clearance_z_m)
        self.attempts = int(attempts)
        self.log = log if log is not None else logging.getLogger("startup_move")
        self.state = StartState.PENDING
        self.tries = 0
        self.succeeded = False

    @property
    def done(self) -> bool:
        return self.state is StartState.DONE

    def update(self) -> None:
        arm = self.arm
        if self.state is StartState.PENDING:
            if (arm.tip_xyz is None and not arm.cfg.dry_run) or arm.estop.engaged or arm.watchdog_stale():
                return  # wait for joint states / e-stop release
            here = arm.tip_xyz if arm.tip_xyz is not None else arm.model.fk(arm.home)[0]
            z = max(here[2], self.clearance_z_m, self.start_xyz_m[2])
            path = np.array([[here[0], here[1], z], [self.start_xyz_m[0], self.start_xyz_m[1], z], self.start_xyz_m])
            self.tries += 1
            if arm.follow_path(path):
                self.state = StartState.MOVING
            else:
                self._failed("cannot move to the start position")
        elif self.state is StartState.MOVING and arm.is_task_complete():
            if arm.get_result() is TaskResult.SUCCEEDED:
                self.log.info(f"tip at the start position {self.start_xyz_m.tolist()}")
                self.state, self.succeeded = StartState.DONE, True
            else:
                self._failed("move to the start position ended")

    def _failed(self, what: str) -> None:
        task = self.arm.last_task
        if task is not None and task.joint_states_lost and self.tries < self.attempts:
            self.log.warning(f"{what}: {task.reason}; trying again when joint states flow "
                             f"(attempt {self.tries + 1}/{self.attempts})")
            self.state = StartState.PENDING
        else:
            self.log.error(f"{what}: {task.reason if task is not None else 'no task'}")
            self.state = StartState.DONE
