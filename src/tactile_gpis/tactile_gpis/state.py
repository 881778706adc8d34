"""The state of a shape estimate as one JSON file (``estimate.json``), and loading it back.

The file holds what rebuilds the estimate exactly: the estimator's full parameter set
(``params``: kernel, noise, prior, lattice, method; the keys of
:data:`tactile_gpis.estimator.PARAMETERS`) and every accepted observation in the order it
was added (contacts and free-space points, world frame, metres, with the normals as
given). Loading builds a :class:`ShapeEstimator` from ``params`` and adds the observations
again, so the loaded estimate is the original one (the GP update is deterministic; with
``kernel.fit`` the hyperparameter fits happen after the same contacts, on the same rows). For
a reader the file also spells out what the parameters resolved to (``model``: kernel
hyperparameters, the prior sphere, the lattice), and ``check`` holds the posterior mean
and variance at a few points, which loading compares against the rebuilt estimate to catch
a file written by an incompatible estimator. ``run`` is free-form (what the run's
configuration was). Layout: docs/recording.md, "Exports".
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path
from typing import Any, Mapping, Optional

import numpy as np

from .estimator import ShapeEstimator

FORMAT = "tactile_gpis.estimate"
VERSION = 1
_CHECK_POINTS = 16
_REQUIRED = ("format", "version", "params", "observations")
_OBS_KEYS = ("point_m", "normal", "label", "value_var_m2")


class StateError(ValueError):
    """A file that is not a readable, compatible estimate state (the message is one line)."""


def _json_safe(value: Any) -> Any:
    """numpy to Python, non-finite floats to None (strict JSON)."""
    if hasattr(value, "tolist"):
        value = value.tolist()
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {str(k): _json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    return value


def model_description(est: ShapeEstimator) -> dict[str, Any]:
    """What the parameters resolved to (kernel hyperparameters, prior, lattice), metres."""
    sphere = est.prior_sphere
    return {
        "dim": est.dim,
        "kernel": {"type": est.kernel.name, **{k: float(v) for k, v in vars(est.kernel).items()}},
        "prior": {"type": str(est.params["prior.type"]),
                  "centre_m": None if sphere is None else sphere[0], "radius_m": None if sphere is None else sphere[1]},
        "lattice": {"min_m": est.bounds_m[0], "max_m": est.bounds_m[1], "shape": list(est.lattice_shape),
                    "plane_z_m": est.plane_z_m if est.dim == 2 else None},
        "method": est.method,
        "active_method": est.active_method,
        "hyperparameters": dict(est.hyperparameters),  # in use (kernel.fit: the last fit's choice)
    }


def _check_points(est: ShapeEstimator) -> np.ndarray:
    """Deterministic points where the file records the posterior: observations and lattice nodes."""
    pts = est.observations()[0][:, : est.dim]
    pts = pts[np.linspace(0, len(pts) - 1, min(len(pts), _CHECK_POINTS // 2)).astype(int)] if len(pts) else pts
    grid = np.stack(np.meshgrid(*[np.linspace(lo, hi, 4)[1:3] for lo, hi in est.bounds_m.T], indexing="ij"), -1)
    return np.vstack([pts, grid.reshape(-1, est.dim)])


def state_dict(est: ShapeEstimator, run: Optional[Mapping[str, Any]] = None) -> dict[str, Any]:
    """The JSON document of :func:`save_state`."""
    pts, nrm, lab, var = est.observations()
    check = _check_points(est)
    mean, variance = est.predict(check)
    return _json_safe({
        "format": FORMAT,
        "version": VERSION,
        "written_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "units": "metres, world frame; variances m^2",
        "params": dict(est.params),
        "model": model_description(est),
        "n_observations": est.n_observations,
        "n_rejected": est.n_rejected,
        "observations": {"point_m": pts, "normal": [None if np.isnan(n).any() else n for n in nrm],
                         "label": lab, "value_var_m2": var},
        "check": {"point_m": check, "mean": mean, "variance": variance},
        "run": dict(run or {}),
    })


def save_state(est: ShapeEstimator, path: str | Path, run: Optional[Mapping[str, Any]] = None) -> Path:
    """Write ``est``'s state to ``path`` (JSON, written atomically); ``run``: free-form
    JSON-able description of the run that built it."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(state_dict(est, run), allow_nan=False, separators=(",", ":")))
    tmp.replace(path)
    return path


def read_state(path: str | Path) -> dict[str, Any]:
    """The checked document of a state file; :class:`StateError` (one line) otherwise."""
    path = Path(path)
    if not path.is_file():
        raise StateError(f"{path}: no such state file")
    try:
        doc = json.loads(path.read_bytes().decode("utf-8"))
    except UnicodeDecodeError:
        raise StateError(f"{path}: not an estimate state file (binary, not JSON)") from None
    except json.JSONDecodeError as exc:
        raise StateError(f"{path}: not an estimate state file (invalid JSON: {exc.msg}, line {exc.lineno})") \
            from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise StateError(f"{path}: not an estimate state file (no \"format\": \"{FORMAT}\")")
    version = doc.get("version")
    if not isinstance(version, int) or version < 1:
        raise StateError(f"{path}: corrupt state file (version {version!r})")
    if version > VERSION:
        raise StateError(f"{path}: state format version {version} is newer than this estimator reads ({VERSION})")
    missing = [k for k in _REQUIRED if k not in doc]
    if missing:
        raise StateError(f"{path}: corrupt state file (missing {', '.join(missing)})")
    if not isinstance(doc["params"], dict):
        raise StateError(f"{path}: corrupt state file ('params' is not a mapping)")
    doc["_arrays"] = _observation_arrays(path, doc["observations"])
    return doc


def _observation_arrays(path: Path, obs: Any) -> tuple[np.ndarray, ...]:
    if not isinstance(obs, dict) or any(k not in obs for k in _OBS_KEYS):
        raise StateError(f"{path}: corrupt state file (observations need {', '.join(_OBS_KEYS)})")
    try:
        n = len(obs["point_m"])
        pts = np.array(obs["point_m"], dtype=float).reshape(n, 3)
        nrm = np.array([[np.nan] * 3 if v is None else v for v in obs["normal"]], dtype=float).reshape(-1, 3)
        lab = np.array(obs["label"], dtype=float).reshape(-1)
        var = np.array([np.nan if v is None else v for v in obs["value_var_m2"]], dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise StateError(f"{path}: corrupt state file (observations are not N x 3 points and normals, "
                         "N labels and variances)") from None
    if not (len(nrm) == len(lab) == len(var) == n):
        raise StateError(f"{path}: corrupt state file (observation arrays differ in length: {n} points, "
                         f"{len(nrm)} normals, {len(lab)} labels, {len(var)} variances)")
    if not np.isfinite(pts).all() or not np.isin(lab, (0, 1)).all():
        raise StateError(f"{path}: corrupt state file (non-finite points or labels other than 0/1)")
    return pts, nrm, lab.astype(int), var


def build_estimator(doc: Mapping[str, Any], path: str | Path = "state",
                    params: Optional[Mapping[str, Any]] = None) -> tuple[ShapeEstimator, int]:
    """The estimator of a checked document: its parameters (updated by ``params``), its
    observations added in order. Returns (estimator, observations rejected on the way).

    Without ``params`` the rebuilt estimate must equal the saved one: every observation
    accepted and the recorded ``check`` posterior reproduced, else :class:`StateError`.
    """
    try:
        est = ShapeEstimator.from_params({**doc["params"], **dict(params or {})})
    except ValueError as exc:
        raise StateError(f"{path}: incompatible estimator parameters: {exc}") from None
    pts, nrm, lab, var = doc["_arrays"]
    rejected = 0
    for i in range(len(pts)):
        ok, reason = est.add_observation(pts[i], None if np.isnan(nrm[i]).any() else nrm[i], int(lab[i]),
                                         None if np.isnan(var[i]) else float(var[i]))
        if not ok and not params:
            raise StateError(f"{path}: observation {i} no longer fits the estimate ({reason}): "
                             "written by an incompatible estimator")
        rejected += not ok
    if not params:
        _verify(doc, est, path)
        if isinstance(doc.get("n_rejected"), int):
            est.n_rejected = doc["n_rejected"]  # what the original refused, for its counters
    return est, rejected


def _verify(doc: Mapping[str, Any], est: ShapeEstimator, path: str | Path) -> None:
    check = doc.get("check")
    if not isinstance(check, dict):
        return
    try:
        P = np.array(check["point_m"], dtype=float).reshape(-1, est.dim)
        mean = np.array(check["mean"], dtype=float).reshape(len(P))
        var = np.array(check["variance"], dtype=float).reshape(len(P))
    except (KeyError, TypeError, ValueError):
        raise StateError(f"{path}: corrupt state file ('check' is not {est.dim}D points with mean and variance)") \
            from None
    m, v = est.predict(P)
    dm, dv = float(np.abs(m - mean).max(initial=0.0)), float(np.abs(v - var).max(initial=0.0))
    # the same arithmetic gives the same numbers; allow another BLAS's rounding
    if dm > 1e-9 + 1e-7 * float(np.abs(mean).max(initial=0.0)) or dv > 1e-9 * est.kernel.k0:
        raise StateError(f"{path}: the observations do not reproduce the saved estimate (mean differs by "
                         f"{dm:.3g} m, variance by {dv:.3g} m^2): written by an incompatible estimator")


def load_state(path: str | Path, params: Optional[Mapping[str, Any]] = None
               ) -> tuple[ShapeEstimator, dict[str, Any]]:
    """Read a state file and rebuild its estimator (see :func:`build_estimator`);
    returns (estimator, document). Every problem is a one-line :class:`StateError`."""
    doc = read_state(path)
    est, rejected = build_estimator(doc, path, params)
    doc["rejected_on_load"] = rejected
    return est, doc
