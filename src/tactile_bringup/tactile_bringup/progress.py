"""Touch records and run outputs, shared by the offline loop and the explorer node.

A touch record is one entry of the report's ``touches`` list
(:mod:`tactile_bringup.report`); the outputs of a run are ``report.json``,
``progress.png`` and the exports (:mod:`tactile_bringup.exports`: the estimated
shape, ``contacts.ply``, ``estimate.json``).
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Optional, Sequence

import numpy as np

from tactile_common.fields import LABEL_CONTACT, LABEL_FREE_SPACE
from tactile_common.rotations import quaternion_x_axis, xyzw
from tactile_common.touch_geometry import back_off_target

from . import plots
from .cores import make_estimator
from .evaluation import Evaluator
from .exports import run_description, write_exports
from .report import check_report, make_report, write_report

_LOG = logging.getLogger("tactile_bringup.progress")


def _round(v: Sequence[float]) -> list:
    return [round(float(x), 7) for x in np.asarray(v).ravel()]


def observe(estimator, point_xyz: np.ndarray, normal_xyz: Optional[np.ndarray], contact: bool) -> None:
    """Feed one touch's observation to an estimator: a contact with its normal, or a free-space
    point with its sweep vector in ``normal_xyz`` (from the point back to where the approach began;
    zero or None: the point alone; ``tactile_gpis.estimator``)."""
    normal = None if normal_xyz is None else np.asarray(normal_xyz, dtype=float).ravel()
    if not contact and normal is not None and not (np.isfinite(normal).all() and np.any(normal != 0)):
        normal = None
    estimator.add_observation(np.asarray(point_xyz, dtype=float), normal,
                              LABEL_CONTACT if contact else LABEL_FREE_SPACE)


def observe_record(estimator, obs: np.ndarray) -> None:
    """:func:`observe` of one CONTACT_DTYPE record (a recorded or restored observation)."""
    observe(estimator, np.array([obs["x"], obs["y"], obs["z"]], dtype=float),
            np.array([obs["normal_x"], obs["normal_y"], obs["normal_z"]], dtype=float),
            int(obs["label"]) == LABEL_CONTACT)


def _path_record(path_xyz, followed_m: Optional[float]) -> Optional[list]:
    """The free-space path the finger followed, (K, 3) rounded to 0.1 mm: all of it, or
    its first ``followed_m`` metres (a path that met the object stopped there)."""
    if path_xyz is None:
        return None
    P = np.asarray(path_xyz, dtype=float).reshape(-1, 3)
    if followed_m is not None and len(P) > 1:
        cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(P, axis=0), axis=1))])
        k = int(np.searchsorted(cum, followed_m, side="right"))
        if k < len(P):  # cut inside segment k-1 → k
            t = (followed_m - cum[k - 1]) / max(cum[k] - cum[k - 1], 1e-12)
            P = np.vstack([P[:k], P[k - 1] + t * (P[k] - P[k - 1])])
    return np.round(P, 4).tolist()


def _tip_track(path: Optional[list], contact: bool, point_xyz, normal_xyz, slide, tip_radius_m: float,
               path_axes: Optional[list] = None) -> tuple[np.ndarray, Optional[np.ndarray]]:
    """Where the tip centre went in one touch, (K, 3) world frame: the free-space path, the approach's
    end (the contact's tip centre: point + r·n, or without a normal r back towards the path's end, where
    the approach began; a miss: the probe's end) and a slide's contacts' tip centres; and the finger axis
    at each of those points ((K, 3); None: vertical throughout), from ``path_axes`` (one per path point;
    the approach keeps the path's last axis; a tilted finger does not slide)."""
    track = _tip_points(path, contact, point_xyz, normal_xyz, slide, tip_radius_m)
    if path_axes is None:
        return track, None
    A = np.asarray(path_axes, dtype=float).reshape(-1, 3)
    return track, np.vstack([A, np.repeat(A[-1:], len(track) - len(A), axis=0)])


def _tip_points(path: Optional[list], contact: bool, point_xyz, normal_xyz, slide, tip_radius_m: float) -> np.ndarray:
    """The tip centres of :func:`_tip_track`."""
    rows = [np.asarray(path, dtype=float).reshape(-1, 3)] if path else []
    point = np.asarray(point_xyz, dtype=float).reshape(3)
    end = None
    if contact:
        n = np.asarray([np.nan] * 3 if normal_xyz is None else normal_xyz, dtype=float).reshape(3)
        towards = point + n if np.isfinite(n).all() and np.linalg.norm(n) > 0 else \
            (rows[0][-1] if rows and len(rows[0]) else point)
        end = back_off_target(point, towards, tip_radius_m)
    rows.append((point if end is None else end)[None])
    if slide is not None and slide.n_contacts:
        n = slide.normals_xyz
        norm = np.linalg.norm(n, axis=1, keepdims=True)
        ok = np.isfinite(norm[:, 0]) & (norm[:, 0] > 0)
        rows.append(slide.points_xyz[ok] + tip_radius_m * n[ok] / norm[ok])
    return np.vstack(rows) if rows else np.zeros((0, 3))


def touch_record(index: int, target_xyz, contact: bool, point_xyz, normal_xyz, travel_m: float,
                 time_s: float, decision_ms: float, estimator, evaluator: Optional[Evaluator],
                 path_xyz=None, path_followed_m: Optional[float] = None, slide=None,
                 stream: Optional[list] = None, contacts_used: Optional[int] = None,
                 path_axes_xyz=None) -> dict:
    """The report entry of one touch, with metrics of the estimate after it.

    ``path_xyz`` (K, 3): the free-space path from the tip to the pre-touch point
    (world frame), recorded as ``path`` (see :func:`_path_record`) for the figures.
    ``slide`` (a :class:`tactile_sim.slide.SlideResult`, or None for a poke): its
    slid length ``slide_m``, why it stopped ``slide_stop`` and its contacts
    ``slide_contacts`` (K, 3, 0.1 mm); ``contacts_gathered`` counts the touch's
    contacts (a poke: 1 or 0). ``stream``: checkpoints of the estimate while the
    slide's contacts streamed in (``{travel_m, time_s, iou, iou_reachable,
    contacts}``, cumulative over the run; :func:`tactile_bringup.slide_touch.observe_stream`);
    ``contacts_used``: how many of the slide's contacts the estimator took (the rest were thinned
    as already known). ``path_axes_xyz`` (K, 3): the finger axis at each path point of a tilted touch
    (tactile_planner.tilt; None: vertical), recorded as ``path_axes`` for the points of ``path``.
    """
    cand = estimator.map_array()
    cand = cand[cand["kind"] == 1]
    path = _path_record(path_xyz, path_followed_m)
    axes = None
    if path is not None and path_axes_xyz is not None and len(path_axes_xyz):
        axes = np.round(np.asarray(path_axes_xyz, dtype=float).reshape(-1, 3)[: len(path)], 4).tolist()
    track, track_axes = _tip_track(path, contact, point_xyz, normal_xyz, slide,
                                   evaluator.tip_radius_m if evaluator else 0.0, axes)
    return {
        "index": index,
        "target": _round(target_xyz),
        "contact": _round(point_xyz) if contact else None,
        "normal": _round(normal_xyz) if contact else None,
        "outcome": "contact" if contact else "free_space",
        "probe_end": None if contact else _round(point_xyz),  # free space: finger centre at max depth
        "travel_m": float(travel_m),
        "time_s": float(time_s),
        "iou": evaluator.iou(estimator) if evaluator else None,
        "iou_reachable": evaluator.iou_reachable(estimator) if evaluator else None,
        "surface_error_m": evaluator.surface_error_m(estimator) if evaluator else None,
        "decision_ms": float(decision_ms),
        "max_surface_var_m2": float(cand["variance"].max()) if len(cand) else None,
        "path": path,
        "path_axes": axes,
        "shaft_clearance_m": evaluator.shaft_clearance_m(track, axes_xyz=track_axes) if evaluator else None,
        "wrist_clearance_m": evaluator.wrist_clearance_m(track, track_axes) if evaluator else None,
        "touch": "poke" if slide is None else "slide",
        "slide_m": None if slide is None else float(slide.slid_m),
        "slide_stop": None if slide is None else slide.stop.value,
        "slide_contacts": None if slide is None else np.round(slide.points_xyz, 4).tolist(),
        "contacts_gathered": int(contact) + (0 if slide is None else slide.n_contacts),
        "stream": stream,
        "slide_contacts_used": contacts_used,
    }


def misses_before_contact(touches: Sequence[dict]) -> int:
    """How many touch records met nothing while none has met the object yet (0 after the first
    contact): the plan request's ``misses_before_contact``, the same offline and on the graph."""
    return 0 if any(record.get("contact") is not None for record in touches) else len(touches)


def stop_reason(experiment, touches: list) -> Optional[str]:
    """Why the run stops after these touches (None: go on)."""
    if len(touches) >= experiment.touches:
        return "touch budget"
    last = touches[-1] if touches else None
    if last and experiment.max_travel_m and last["travel_m"] >= experiment.max_travel_m:
        return "travel budget"
    if last and experiment.confidence_max_var_m2 and last["max_surface_var_m2"] is not None \
            and last["max_surface_var_m2"] < experiment.confidence_max_var_m2:
        return "confidence"
    return None


def write_outputs(report: dict, estimator, evaluator: Optional[Evaluator], out_dir: Path,
                  mode: str) -> list[str]:
    """report.json, progress.png and the exports (:mod:`tactile_bringup.exports`: shape files,
    contacts.ply, estimate.json) into ``out_dir``; the paths written."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    check_report(report)
    written = []
    write_report(report, out_dir / "report.json")
    written.append(str(out_dir / "report.json"))
    surface = estimator.surface_points()
    written += write_exports(estimator, out_dir, mode, run_description(report))
    try:  # a figure that fails must not cost the run its report and shape (written above)
        plots.plot_progress(report, out_dir / "progress.png", surface,
                            evaluator.true_surface if evaluator else None, estimator=estimator,
                            obj=evaluator.obj if evaluator else None)
    except Exception as exc:  # noqa: BLE001 - any plotting failure; the data is safe
        _LOG.error("progress.png not written: %s: %s (report.json and the shape are)", type(exc).__name__, exc)
        return written
    written.append(str(out_dir / "progress.png"))
    return written


class RunRecorder:
    """The explorer node's bookkeeping: a replica estimate, touch records, outputs."""

    def __init__(self, experiment, out_dir: Path, evaluate: bool = True) -> None:
        self.exp = experiment
        self.out_dir = Path(out_dir)
        self.estimator = make_estimator(experiment)
        self.evaluator = Evaluator(experiment) if evaluate else None
        self.prior_iou = self.evaluator.iou(self.estimator) if self.evaluator else None
        self.touches: list[dict] = []
        self.travel_m = 0.0
        self.time_s = 0.0
        self.standoff_m = float(experiment.planner_params.get("standoff_m", 0.01)) + \
            float(experiment.planner_params.get("tip_radius_m", 0.01))

    def restore(self, report: dict, observations: np.ndarray) -> None:
        """Continue a run (``explore.sh --resume``): its touch records and totals so far
        (``report`` with its ``resume`` entry, :mod:`tactile_bringup.resume`) and every
        observation its estimate took (CONTACT_DTYPE, in order)."""
        for obs in observations:
            observe_record(self.estimator, obs)
        self.touches = list(report["touches"])
        self.travel_m = float(report["resume"]["travel_m"])
        self.time_s = float(report["resume"]["time_s"])

    def add_travel(self, travel_m: float, time_s: float) -> None:
        """Motion that produced no observation (an aborted or unreachable goal)."""
        self.travel_m += travel_m
        self.time_s += time_s

    def add_touch(self, goal, observation, travel_m: float, time_s: float, decision_ms: float,
                  path_xyz=None, slide=None, path_axes_xyz=None) -> dict:
        """Record a finished touch: its goal pose message and its observation point
        (``path_xyz`` (K, 3), optional: the planned free-space path, for the figure; ``path_axes_xyz``
        (K, 3): its finger axes, a tilted touch's).
        ``slide`` (a :class:`tactile_bringup.slide_stream.GraphSlide`): the estimate takes its
        whole stream in order, ``observation`` (its last contact) last."""
        from .slide_stream import free_path

        self.add_travel(travel_m, time_s)
        path_xyz = free_path(path_xyz, goal)  # without a slide goal's marker
        for obs in (slide.observations[:-1] if slide is not None else []):
            observe(self.estimator, np.array([obs["x"], obs["y"], obs["z"]], dtype=float),
                    np.array([obs["normal_x"], obs["normal_y"], obs["normal_z"]], dtype=float), True)
        contact = int(observation["label"]) == LABEL_CONTACT
        point = np.array([observation["x"], observation["y"], observation["z"]], dtype=float)
        normal = np.array([observation["normal_x"], observation["normal_y"], observation["normal_z"]])
        target = np.full(3, np.nan)
        if goal is not None:  # target = pre-touch point + standoff along the approach (x-axis)
            p = goal.pose.position
            target = np.array([p.x, p.y, p.z]) + self.standoff_m * quaternion_x_axis(xyzw(goal.pose.orientation))
        observe(self.estimator, point, normal, contact)
        record = touch_record(len(self.touches), target, contact, point, normal, self.travel_m, self.time_s,
                              decision_ms, self.estimator, self.evaluator, path_xyz=path_xyz, slide=slide,
                              path_axes_xyz=path_axes_xyz)
        self.touches.append(record)
        return record

    def stop_reason(self) -> Optional[str]:
        return stop_reason(self.exp, self.touches)

    def report(self, stopped_because: str) -> dict:
        return make_report(self.exp.object_name, self.exp.mode, self.exp.strategy, self.exp.seed,
                           self.exp.config_summary(), self.touches, self.prior_iou, stopped_because,
                           self.travel_m, self.time_s)

    def write(self, stopped_because: str) -> list[str]:
        return write_outputs(self.report(stopped_because), self.estimator, self.evaluator, self.out_dir,
                             self.exp.mode)

    def progress_line(self, record: dict) -> str:
        from .cli_common import progress_line

        return progress_line(record, self.exp.touches)

    def summary_line(self) -> str:
        s = self.report("").get("summary")
        iou = "n/a" if s["final_iou"] is None else f"{s['final_iou']:.3f}"
        return f"{s['touches']} touches, travel {s['travel_m']:.2f} m, time {s['time_s']:.0f} s, final IoU {iou}"
