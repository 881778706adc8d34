"""Tilted-finger entries (3D): reach a candidate the vertical finger cannot, by inserting a tilted finger.

World frame, metres, radians. The finger axis ``a`` is the unit vector from the tip centre towards the
flange (vertical: +z). A candidate whose approach would put the vertical rod into the estimate (under
an overhang, a bridge's deck) or whose surface faces down may still be touched with the finger tilted:

1. travel on the free-space graph (vertical finger) to an *entry point* E = p + s·a, where p is the
   candidate's pre-touch point and s ∈ (0, ``insert_max_m``] the insertion length;
2. turn the finger about the tip centre at E from +z to ``a``;
3. insert: move the tip from E to p along −a, the rod trailing on its own line;
4. approach along −n, touch, retract to p; then back out to E and turn back to vertical (the commander
   does that at the end of every tilted touch, so between touches the finger is vertical).

The insertion sweeps the rod along one line only: the rod is clear during it when the line from p along
``a`` is clear up to s + the rod's length. Checks, against the estimate's clearance field of the free
graph (:class:`~tactile_planner.graph.FreeSpaceGraph`):

- approach: the rod along ``a`` above the tip centres from p to the expected contact keeps ``touch_need_m``
  (the rod's radius + its gap at the touch) — as the vertical check; and the contact falls on the skin's
  sensing side, n · a ≥ ``min_normal_axis`` (for a = +z the planner's "facing down" rule);
- insertion: the tip line p → E keeps the graph's margin (from the estimated surface); the rod line from p along ``a`` keeps
  ``path_need_m`` (the rod's radius + the tip's skin clearance, as on graph paths) up to s + length;
- entry: the vertical rod above E keeps ``path_need_m``; the turn: the rod keeps it on axes between +z
  and ``a`` (great circle, every ``turn_step_rad``);
- the wrist: the rod's far end (the flange) at the pre-touch point is at least ``min_flange_z_m`` above
  the table, and (``wrist``) the links behind the flange, cylinders about the finger axis
  (:mod:`tactile_planner.wrist`), clear of the table and the estimate at the contact, along the insertion
  and on the turn. Nothing else of the arm is modelled: the commander refuses what its IK cannot reach.

Axes tried, smallest tilt first (``tilts_rad``), at each tilt the azimuth of the candidate's outward
normal first, then the others by their angle from it (the rod leaves the surface it faces); for each
axis the shortest insertion that passes, in steps of ``insert_step_m``. The first axis that passes wins.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from tactile_common.finger_axis import EZ, slerp_axes

from .wrist import WristCheck

@dataclass(frozen=True)
class TiltedEntries:
    """Per candidate (M rows): the finger axis, the entry point and the insertion length (NaN: none)."""

    axis_xyz: np.ndarray  # (M, 3) unit, world
    entry_xyz: np.ndarray  # (M, 3) world, m
    insert_m: np.ndarray  # (M,) m

    @property
    def ok(self) -> np.ndarray:
        return np.isfinite(self.insert_m)


@dataclass(frozen=True)
class TiltSettings:
    """Which tilted entries are tried and what they must keep (m, rad)."""

    tilts_rad: tuple = (np.pi / 4, np.pi / 3, 5 * np.pi / 12, np.pi / 2)
    n_azimuths: int = 8
    insert_max_m: float = 0.06
    insert_step_m: float = 0.01
    rod_step_m: float = 0.006
    turn_step_rad: float = np.pi / 8
    min_flange_z_m: float = 0.10


def finger_axes(normal_xyz: np.ndarray, tilt_rad: float, n_azimuths: int) -> np.ndarray:
    """(M, n_azimuths + 1, 3) unit axes at ``tilt_rad`` from +z: first towards the horizontal part of each
    normal (any azimuth when it has none), then the ``n_azimuths`` evenly spaced ones ordered by their
    angle from it."""
    n = np.asarray(normal_xyz, float).reshape(-1, 3)
    az0 = np.arctan2(n[:, 1], n[:, 0])
    az0 = np.where(np.hypot(n[:, 0], n[:, 1]) > 1e-6, az0, 0.0)
    grid = 2.0 * np.pi * np.arange(n_azimuths) / n_azimuths
    off = np.angle(np.exp(1j * (grid[None, :] - az0[:, None])))  # (M, A) in (−π, π]
    order = np.argsort(np.abs(off), axis=1, kind="stable")
    az = np.concatenate([az0[:, None], np.take_along_axis(grid[None, :].repeat(len(n), 0), order, axis=1)], axis=1)
    s, c = np.sin(tilt_rad), np.cos(tilt_rad)
    return np.stack([s * np.cos(az), s * np.sin(az), np.full(az.shape, c)], axis=2)


def turn_axes(axis_xyz: np.ndarray, step_rad: float) -> np.ndarray:
    """(M, T, 3) axes strictly between +z and each (M, 3) axis on the great circle, at most ``step_rad``
    apart (T ≥ 1; the ends are checked elsewhere)."""
    a = np.asarray(axis_xyz, float).reshape(-1, 3)
    ang = np.arccos(np.clip(a[:, 2], -1.0, 1.0))
    t_count = max(int(np.ceil(float(ang.max(initial=0.0)) / step_rad)) - 1, 1)
    f = np.arange(1, t_count + 1) / (t_count + 1)  # (T,)
    turns = slerp_axes(np.tile(EZ, (len(a) * t_count, 1)), np.repeat(a, t_count, axis=0), np.tile(f, len(a)))
    return turns.reshape(len(a), t_count, 3)


def tilted_entries(graph, pretouch_xyz: np.ndarray, contact_tip_xyz: np.ndarray, normal_xyz: np.ndarray,
                   tip_radius_m: float, touch_need_m: float, path_need_m: float, max_tilt_rad: float,
                   settings: TiltSettings = TiltSettings(), min_normal_axis: float = -1.0,
                   wrist: Optional[WristCheck] = None) -> TiltedEntries:
    """The first tilted entry that passes the checks (module docstring) for each candidate.

    Args:
        graph: the free-space graph with the rod's clearance field (``shaft_field_m`` not None).
        pretouch_xyz, contact_tip_xyz, normal_xyz: (M, 3) pre-touch points, tip centres at the expected
            contact, unit outward normals.
        tip_radius_m: the rod starts this far past the tip centre.
        touch_need_m, path_need_m: clearance the rod keeps at the touch / on the way in.
        max_tilt_rad: tilts above it are not tried.
        min_normal_axis: the sensed side: n · a ≥ this (the planner's ``min_normal_z`` for the vertical
            finger, a = +z): the contact, at −n from the tip centre, must fall on the skin's taxels,
            which cover the tip's far side from the flange and a band above its equator.
        wrist: the links behind the flange, kept off the table and the estimate (tactile_planner.wrist) at the
            contact, at every whole insertion step from the pre-touch point to the entry, and on the turn
            (None: not checked).
    """
    s = settings
    p = np.asarray(pretouch_xyz, float).reshape(-1, 3)
    c = np.asarray(contact_tip_xyz, float).reshape(-1, 3)
    m = len(p)
    axis_out = np.full((m, 3), np.nan)
    entry_out = np.full((m, 3), np.nan)
    insert_out = np.full(m, np.nan)
    if m == 0 or graph.shaft_field_m is None:
        return TiltedEntries(axis_out, entry_out, insert_out)
    L = float(graph.shaft_length_m)
    steps = np.arange(1, int(np.floor(s.insert_max_m / s.insert_step_m + 1e-9)) + 1) * s.insert_step_m  # (K,)
    seg_t = np.linspace(0.0, 1.0, 5)
    for tilt in sorted(t for t in s.tilts_rad if t <= max_tilt_rad + 1e-12):
        todo = np.flatnonzero(~np.isfinite(insert_out))
        if len(todo) == 0:
            break
        axes = finger_axes(normal_xyz[todo], tilt, s.n_azimuths)  # (R, A, 3)
        R, A = axes.shape[:2]
        pa = np.repeat(p[todo], A, axis=0)  # (R·A, 3) rows follow (candidate, axis)
        ax = axes.reshape(-1, 3)
        # the approach: rod along a above the tip from p to the expected contact
        seg = p[todo][:, None, :] + seg_t[None, :, None] * (c[todo] - p[todo])[:, None, :]  # (R, S, 3)
        seg_ra = np.repeat(seg, A, axis=0).reshape(-1, 3)
        ok_app = (graph.rod_clearance_m(seg_ra, tip_radius_m, s.rod_step_m, np.repeat(ax, len(seg_t), axis=0))
                  .reshape(R * A, len(seg_t)).min(axis=1) >= touch_need_m)
        ok_app &= (np.repeat(np.asarray(normal_xyz, float)[todo], A, axis=0) * ax).sum(axis=1) >= min_normal_axis
        # the insertion: the rod's line from p, its clearance up to each insertion + L (cumulative minimum)
        t_line = tip_radius_m + np.arange(0.0, steps[-1] + L - tip_radius_m + 1e-12, s.rod_step_m)
        line = pa[:, None, :] + t_line[None, :, None] * ax[:, None, :]
        c_line = np.minimum.accumulate(graph.shaft_field_at(line.reshape(-1, 3))
                                       .reshape(R * A, -1), axis=1)
        upto = np.searchsorted(t_line, steps + L, side="right") - 1  # (K,)
        ok_rod = c_line[:, upto] >= path_need_m  # (R·A, K)
        # the tip's line p → E keeps the margin (sampled at half steps, cumulative)
        h = np.arange(1, 2 * len(steps) + 1) * (s.insert_step_m / 2.0)
        tip_line = pa[:, None, :] + h[None, :, None] * ax[:, None, :]
        # (the rod-free field: the graph's own clearance also holds the vertical rod's term)
        c_tip = np.minimum.accumulate(graph.shaft_field_at(tip_line.reshape(-1, 3)).reshape(R * A, -1), axis=1)
        ok_tip = c_tip[:, 1::2] >= graph.margin_m - 1e-9  # at each whole step
        ok = ok_app[:, None] & ok_rod & np.logical_and.accumulate(ok_tip, axis=1)  # (R·A, K)
        ok &= (pa[:, 2] + L * ax[:, 2] >= s.min_flange_z_m)[:, None]  # the wrist above the table
        # the entry: the vertical rod, and the rod while turning (only where the rest passed: the costly part)
        E = pa[:, None, :] + steps[None, :, None] * ax[:, None, :]  # (R·A, K, 3)
        if ok.any():
            ok[ok] = graph.rod_clearance_m(E[ok], tip_radius_m, s.rod_step_m) >= path_need_m
        if ok.any():
            rows, ks = np.nonzero(ok)
            turns = turn_axes(ax[rows], s.turn_step_rad)  # (P, T, 3)
            T = turns.shape[1]
            clear = graph.rod_clearance_m(np.repeat(E[rows, ks], T, axis=0), tip_radius_m, s.rod_step_m,
                                          turns.reshape(-1, 3)).reshape(-1, T).min(axis=1)
            ok[rows, ks] = clear >= path_need_m
        if wrist is not None and ok.any():
            ok = _wrist_ok(wrist, ok, pa, c[todo], ax, A, steps, E, s.turn_step_rad)
        first = np.where(ok.any(axis=1), ok.argmax(axis=1), -1).reshape(R, A)  # shortest insertion per axis
        has = (first >= 0).any(axis=1)
        r = np.flatnonzero(has)
        a = (first[r] >= 0).argmax(axis=1)  # the first axis (in the order tried) that passes
        k = first[r, a]
        axis_out[todo[r]] = axes[r, a]
        insert_out[todo[r]] = steps[k]
        entry_out[todo[r]] = E[r * A + a, k]
    return TiltedEntries(axis_out, entry_out, insert_out)


def _wrist_ok(wrist: WristCheck, ok: np.ndarray, pa: np.ndarray, contact: np.ndarray, ax: np.ndarray, n_axes: int,
              steps: np.ndarray, E: np.ndarray, turn_step_rad: float) -> np.ndarray:
    """``ok`` (rows = (candidate, axis), K insertions) where the wrist is clear too: at the contact, at the
    pre-touch point and every whole insertion step up to the entry (the wrist moves along the axis line),
    and at the entry on the turn from +z (both ends included)."""
    ok = ok.copy()
    rows = np.flatnonzero(ok.any(axis=1))
    at_contact = wrist.clear(np.repeat(contact, n_axes, axis=0)[rows], ax[rows])
    pos = pa[rows][:, None, :] + np.r_[0.0, steps][None, :, None] * ax[rows][:, None, :]  # (P, K + 1, 3)
    at_pos = wrist.clear(pos.reshape(-1, 3), np.repeat(ax[rows], len(steps) + 1, axis=0)).reshape(len(rows), -1)
    upto = np.logical_and.accumulate(at_pos, axis=1)[:, 1:]  # positions 0..k+1 for insertion k
    ok[rows] &= at_contact[:, None] & upto
    if ok.any():
        r, k = np.nonzero(ok)
        turns = np.concatenate([np.tile(EZ, (len(r), 1, 1)), turn_axes(ax[r], turn_step_rad)], axis=1)  # (P, T, 3)
        T = turns.shape[1]
        ok[r, k] = wrist.clear(np.repeat(E[r, k], T, axis=0), turns.reshape(-1, 3)).reshape(-1, T).all(axis=1)
    return ok
