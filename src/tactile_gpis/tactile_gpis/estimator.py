"""ShapeEstimator: the GPIS facade shared by the estimator node and the offline loop.

World frame, metres. In 2D the field lives in the x-y plane at ``plane_z_m`` (points
are (x, y); z is ignored on input and set to ``plane_z_m`` on output). In 3D the
table top z = 0 bounds the object: the estimated solid is clipped to z >= 0
(``inside`` is False below the table) and candidates lie above
``candidates.table_margin_m``.

Observations (label 1 contact, 0 free space, ``tactile_common.fields``):
  contact:    f(x) = 0 (noise ``noise.contact_var_m2``) and, if ``use_normals`` and a
              unit normal n is given, grad f(x) = n (noise ``noise.normal_var``);
  free space: f(x) ≥ ``free_space.value_m`` (``free_space.model`` 'inequality', the default:
              one assumed-density step, :meth:`ShapeEstimator._free_space_row`; 'equality':
              f(x) = value_m with noise ``noise.free_space_var_m2``) at the
              point and, if a sweep vector v is given in the normal's place (from the
              point back to where the finger's guarded approach began: it swept that
              segment without contact), at every ``free_space.sweep_step_m`` along
              x + t v, t in (0, 1] (0 = the point only).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping, Optional

import numpy as np
from scipy.special import log_ndtr, ndtr

from tactile_common.fields import (
    KIND_CANDIDATE,
    KIND_LATTICE,
    LABEL_CONTACT,
    LABEL_FREE_SPACE,
    VARIANCE_MAP_DTYPE,
)

from .export import export_level_set, write_observations_ply
from .gp import GPIS, VALUE, FactorError, gradient_rows
from .hyperfit import (LENGTH, NOISE, RADIUS, SCALE, FitResult, FitRows, R as THIN_PLATE_R, fit_hyperparameters,
                       kernel_of, mean_of, search_grid)
from .kernels import KERNEL_TYPES, make_kernel
from .local import LocalGPIS
from .levelset import LevelSet, farthest_point_subsample, lattice_points, zero_level_set
from .prior import sphere_mean, zero_mean
from .solid import floating_untouched

METHODS = ("exact", "local", "auto")

#: name -> (default, description). The node declares exactly these ROS parameters;
#: ``ShapeEstimator.from_params`` takes a dict with these keys (missing keys: default).
PARAMETERS: dict[str, tuple[Any, str]] = {
    "mode": ("2d", "'2d' (contour at plane_z_m) or '3d' (full surface)", {"choices": ("2d", "3d")}),
    "frame_id": ("world", "frame of contacts and maps"),
    "workspace.min_m": ([0.35, -0.15, 0.0], "workspace box lower corner x, y, z (m)", {"length": 3}),
    "workspace.max_m": ([0.65, 0.15, 0.22], "workspace box upper corner x, y, z (m)", {"length": 3}),
    "plane_z_m": (0.06, "2D: height of the estimated contour (m)"),
    "lattice.points_per_axis_2d": (128, "2D lattice nodes per axis", {"ge": 3}),
    "lattice.points_per_axis_3d": (48, "3D lattice nodes per axis", {"ge": 3}),
    "kernel.type": ("thin_plate", f"one of {KERNEL_TYPES}", {"choices": KERNEL_TYPES}),
    "kernel.length_scale_m": (0.05, "stationary kernels: length scale (m)", {"gt": 0.0}),
    "kernel.signal_variance": (1.0, "stationary: signal variance (m^2); thin_plate: scale of k", {"gt": 0.0}),
    "kernel.R_m": (0.0, "thin_plate R (m); 0 = workspace diagonal (above every data distance)", {"ge": 0.0}),
    "kernel.fit": (False, "choose the hyperparameters (kernel scale, thin_plate R or length scale, "
                   "noise.contact_var_m2, the prior sphere's radius) by maximising the log marginal likelihood "
                   "log p(y | θ) of the observations so far, on a grid around the configured values (exact path "
                   "only; off until the generated-suite benchmark says it helps: docs/gpis.md)"),
    "kernel.fit_every": (4, "kernel.fit: refit after every this many contacts added to the GP (free-space points "
                         "do not count)", {"ge": 1}),
    "kernel.fit_min_contacts": (3, "kernel.fit: the first fit at this many contacts added to the GP", {"ge": 1}),
    "kernel.fit_factors": ([0.25, 0.5, 1.0, 2.0, 4.0], "kernel.fit: each hyperparameter's grid, these factors "
                           "times its configured value (1 is always in; thin_plate R only factors >= 1)",
                           {"gt": 0.0}),
    "noise.contact_var_m2": (1e-6, "variance of a contact's value f(x) = 0 (m^2)", {"ge": 0.0}),
    "noise.normal_var": (1e-2, "variance of each component of a normal (gradient) observation", {"ge": 0.0}),
    "noise.free_space_var_m2": (1e-4, "variance of a free-space observation (m^2)", {"ge": 0.0}),
    "free_space.value_m": (0.01, "value of f observed at a free-space point (> 0, m)", {"gt": 0.0}),
    "free_space.model": ("inequality", "'inequality': a free-space point observes f ≥ value_m (one assumed-density "
                         "step: the posterior at the point takes the moments of the truncated prediction, so it "
                         "lifts the estimate where it says inside or too close and never pulls it down); 'equality': "
                         "f = value_m with noise noise.free_space_var_m2", {"choices": ("inequality", "equality")}),
    "free_space.posterior": ("mean", "'inequality': the value the posterior at a free-space point takes: 'mean' "
                             "(the truncated prediction's mean μ + sλ) or 'mode' (its mode max(μ, value_m): lifts "
                             "the estimate to the bound and no farther, whatever the prior's kernel scale)",
                             {"choices": ("mean", "mode")}),
    "free_space.sweep_step_m": (0.0, "a free-space point with a sweep vector (the approach it ended) also observes "
                                "f there every this many metres back along it (0 = the point only; off by default: "
                                "the generated suite did not gain, docs/benchmarks.md)", {"ge": 0.0}),
    "use_normals": (True, "use contact normals as gradient observations"),
    "prior.type": ("auto", "'auto' (circle/sphere of 1/4 the smallest workspace extent at the workspace centre; 3D: resting on the table), 'given' (centre_m, radius_m), 'none'", {"choices": ("auto", "given", "none")}),
    "prior.centre_m": ([0.5, 0.0, 0.06], "'given' prior: centre x, y, z (m); 2D uses x, y", {"length": 3}),
    "prior.radius_m": (0.05, "'given' prior: radius (m)", {"gt": 0.0}),
    "candidates.max_count": (200, "maximum number of touch candidates (farthest-point subsample)", {"ge": 1}),
    "candidates.table_margin_m": (0.005, "3D: candidates only above this height (m)", {"ge": 0.0}),
    "candidates.snap_m": (1e-5, "local path: a level-set vertex (a candidate) that moved less than this along its "
                          "lattice edge since the last map keeps its last position, so the experts' candidate "
                          "columns are reused (0 = off) (m)", {"ge": 0.0}),
    "duplicate_distance_m": (0.001, "reject an observation this close to an earlier one (m)", {"ge": 0.0}),
    "thinning.var_ratio": (0.0, "thin a contact whose predicted variance of f at its point is below this "
                           "fraction of its value noise, whose |mean| there is within 2 noise sd and whose normal "
                           "(if given) is within thinning.normal_angle_deg of the predicted one (0 = off)",
                           {"ge": 0.0}),
    "thinning.distance_m": (0.0, "thin a contact within this distance of an earlier contact whose normal is within "
                            "thinning.normal_angle_deg of its own (both without normal: the distance alone; "
                            "0 = off) (m)", {"ge": 0.0}),
    "thinning.normal_angle_deg": (20.0, "thinning: normals this close (deg) count as consistent",
                                  {"ge": 0.0, "le": 180.0}),
    "solid.drop_floating": (True, "3D: the estimated solid (the level set, the candidates, the inside tests the "
                            "metrics read) leaves out each component of {mean < 0} that no contact touches and whose "
                            "lowest node floats more than solid.floating_gap_m above the table: no observation holds "
                            "it up (tactile_gpis.solid; 2D: no effect)"),
    "solid.floating_gap_m": (0.02, "3D: a component of the estimate whose lowest node is more than this above the "
                             "table floats (m)", {"ge": 0.0}),
    "jitter": (1e-10, "added to the covariance diagonal of every new observation", {"ge": 0.0}),
    "method": ("exact", "'exact' (one GP, the whole lattice updated per contact), 'local' (local GP experts on "
               "an octree over an anchor GP, evaluated on a narrow band: docs/gpis.md), 'auto' (exact until "
               "local.auto_min_contacts observations, then local)", {"choices": METHODS}),
    "local.auto_min_contacts": (300, "'auto': observations from which the local path takes over", {"ge": 1}),
    "local.leaf_capacity_2d": (200, "local, 2D: observations in a quadtree cell before it splits", {"ge": 1}),
    "local.leaf_capacity_3d": (32, "local, 3D: observations in an octree cell before it splits", {"ge": 1}),
    "local.max_rows_2d": (1600, "local, 2D: a quadtree cell wider than its context whose data box holds more rows "
                          "than this splits too (dense contacts: fewer rows per hit expert; 0 = no limit)", {"ge": 0}),
    "local.context_m_2d": (0.02, "local, 2D: an expert sees the data at least this far beyond its cell (m)",
                           {"gt": 0.0}),
    "local.context_m_3d": (0.012, "local, 3D: an expert sees the data at least this far beyond its cell (m)",
                           {"gt": 0.0}),
    "local.context_spacings": (1.6, "local: ... and this many spacings of its own observations (sparse data), "
                               "up to 2.5 context_m", {"ge": 0.0}),
    "local.blend": (0.25, "local: half-width of the experts' blending ramp, a fraction of min(cell size, "
                    "local.context_m)", {"gt": 0.0, "lt": 1.0}),
    "local.anchor_spacing_m": (0.015, "local: an observation this far from every anchor becomes one (m)",
                               {"gt": 0.0}),
    "local.max_anchors": (256, "local: anchors of the global GP (far field, inside/outside sign)", {"ge": 1}),
    "local.band_m": (0.008, "local: lattice band around the zero level set and the contacts, exactly blended (m)",
                     {"gt": 0.0}),
    "local.coarse_stride": (3, "local: the anchor GP's lattice takes every n-th node per axis", {"ge": 1}),
}


#: ROS parameters a params file may carry that are not the estimator's own.
NODE_ONLY_PARAMETERS = ("use_sim_time",)


def load_params(path: str | Path, node_name: str = "gpis_estimator") -> dict[str, Any]:
    """The parameters of ``node_name`` in a ROS params YAML (its section and ``/**``),
    flattened to dotted names (``kernel: {type: x}`` -> ``kernel.type``), numbers read
    as ROS reads them."""
    from tactile_common.params_file import node_params

    params = node_params([Path(path)], node_name)
    if not params:
        raise ValueError(f"{path}: no '{node_name}: ros__parameters:' section")
    return params


class ShapeEstimator:
    """GPIS shape estimate over a workspace lattice with touch candidates."""

    def __init__(self, params: Optional[Mapping[str, Any]] = None) -> None:
        p = {k: v[0] for k, v in PARAMETERS.items()}
        params = {k: v for k, v in (params or {}).items() if k not in NODE_ONLY_PARAMETERS}
        unknown = set(params) - set(p)
        if unknown:
            raise ValueError(f"unknown GPIS parameter(s) {sorted(unknown)}")
        p.update(params)
        self.params = p
        mode = str(p["mode"]).lower()
        if mode not in ("2d", "3d"):
            raise ValueError(f"mode must be '2d' or '3d', got '{p['mode']}'")
        self.dim = 2 if mode == "2d" else 3
        lo = np.asarray(p["workspace.min_m"], float)
        hi = np.asarray(p["workspace.max_m"], float)
        if lo.shape != (3,) or hi.shape != (3,) or not (np.isfinite(lo).all() and np.isfinite(hi).all()):
            raise ValueError("workspace.min_m and workspace.max_m must be 3 finite numbers each")
        if not (hi > lo).all():
            raise ValueError(f"workspace.max_m {hi.tolist()} must exceed workspace.min_m {lo.tolist()}")
        self.bounds_m = np.stack([lo, hi])[:, : self.dim]
        self.plane_z_m = float(p["plane_z_m"])
        n_axis = int(p["lattice.points_per_axis_2d" if self.dim == 2 else "lattice.points_per_axis_3d"])
        if n_axis < 3:
            raise ValueError(f"lattice needs at least 3 points per axis, got {n_axis}")
        self.lattice_axes = [np.linspace(self.bounds_m[0, i], self.bounds_m[1, i], n_axis) for i in range(self.dim)]
        self.lattice_shape = tuple(len(a) for a in self.lattice_axes)
        self._lattice = lattice_points(self.lattice_axes)
        self._lattice_map: Optional[np.ndarray] = None  # the map's lattice rows (positions, kind), built once
        diag = float(np.linalg.norm(self.bounds_m[1] - self.bounds_m[0]))
        R = float(p["kernel.R_m"]) or diag
        if str(p["kernel.type"]) == "thin_plate" and R < diag:
            raise ValueError(f"kernel.R_m {R} must be at least the workspace diagonal {diag:.4f} m")
        self.kernel = make_kernel(str(p["kernel.type"]), R_m=R, length_scale_m=float(p["kernel.length_scale_m"]),
                                  signal_variance=float(p["kernel.signal_variance"]))
        self.contact_var = _nonneg(p, "noise.contact_var_m2")
        self.normal_var = _nonneg(p, "noise.normal_var")
        self.free_var = _nonneg(p, "noise.free_space_var_m2")
        self.free_value = float(p["free_space.value_m"])
        self.free_model = str(p["free_space.model"])
        if self.free_model not in ("inequality", "equality"):
            raise ValueError(f"free_space.model must be 'inequality' or 'equality', got '{self.free_model}'")
        self.free_posterior = str(p["free_space.posterior"])
        if self.free_posterior not in ("mean", "mode"):
            raise ValueError(f"free_space.posterior must be 'mean' or 'mode', got '{self.free_posterior}'")
        self.n_free_space_implied = 0  # free-space points the estimate already implied (not added)
        if not self.free_value > 0:
            raise ValueError(f"free_space.value_m must be > 0, got {self.free_value}")
        self.sweep_step_m = _nonneg(p, "free_space.sweep_step_m")
        self.use_normals = bool(p["use_normals"])
        self.max_candidates = int(p["candidates.max_count"])
        self.table_margin_m = float(p["candidates.table_margin_m"])
        self.snap_m = _nonneg(p, "candidates.snap_m")
        self.duplicate_distance_m = _nonneg(p, "duplicate_distance_m")
        self.drop_floating = _flag(p, "solid.drop_floating") and self.dim == 3
        self.floating_gap_m = _nonneg(p, "solid.floating_gap_m")
        self.thin_var_ratio = _nonneg(p, "thinning.var_ratio")
        self.thin_distance_m = _nonneg(p, "thinning.distance_m")
        angle = float(p["thinning.normal_angle_deg"])
        if not 0.0 <= angle <= 180.0:
            raise ValueError(f"thinning.normal_angle_deg must be in [0, 180], got {angle}")
        self.thin_cos = float(np.cos(np.radians(angle)))
        self.method = str(p["method"])
        if self.method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, got '{p['method']}'")
        self.auto_min_contacts = int(p["local.auto_min_contacts"])
        self._local_args = dict(
            leaf_capacity=int(p[f"local.leaf_capacity_{self.dim}d"]),
            max_rows=int(p["local.max_rows_2d"]) if self.dim == 2 else 0,
            context_m=float(p[f"local.context_m_{self.dim}d"]),
            context_spacings=float(p["local.context_spacings"]),
            blend=float(p["local.blend"]), anchor_spacing_m=float(p["local.anchor_spacing_m"]),
            max_anchors=int(p["local.max_anchors"]), band_m=float(p["local.band_m"]),
            coarse_stride=int(p["local.coarse_stride"]))
        if not 0 < self._local_args["blend"] < 1:
            raise ValueError(f"local.blend must be in (0, 1), got {p['local.blend']}")
        if not self._local_args["context_m"] > 0:
            raise ValueError(f"local.context_m_{self.dim}d must be > 0, got {self._local_args['context_m']}")
        self.gp = GPIS(self.kernel, self.dim, self._prior(p), jitter=_nonneg(p, "jitter"))
        self.local: Optional[LocalGPIS] = None
        self.fit_enabled = _flag(p, "kernel.fit")
        self.fit_every = _count(p, "kernel.fit_every")
        self.fit_min_contacts = _count(p, "kernel.fit_min_contacts")
        fit_factors = _factors(p, "kernel.fit_factors")
        if self.fit_enabled and self.method != "exact":
            raise ValueError(f"kernel.fit: true needs method 'exact' (the local path has no single GP to refit), "
                             f"got method '{self.method}'")
        self._theta_cfg = self._configured_hyperparameters()
        #: the hyperparameters in use, by parameter name (the configured ones until a fit changes them)
        self.hyperparameters: dict[str, float] = dict(self._theta_cfg)
        self._fit_grid = search_grid(self._theta_cfg, fit_factors)
        self.reset()

    @classmethod
    def from_params(cls, params: Mapping[str, Any]) -> "ShapeEstimator":
        """Build from a dict keyed by the node's ROS parameter names (e.g. the
        ``gpis_estimator: ros__parameters:`` section of config/gpis_estimator.yaml)."""
        return cls(params)

    def _prior(self, p: Mapping[str, Any]):
        """The prior mean function; sets ``prior_sphere`` ((centre (dim,), radius) in metres, or None)."""
        kind = str(p["prior.type"])
        self.prior_sphere: Optional[tuple[np.ndarray, float]] = None
        if kind == "none":
            return zero_mean
        if kind == "auto":
            lo, hi = self.bounds_m
            centre, radius = 0.5 * (lo + hi), 0.25 * float((hi - lo).min())
            if self.dim == 3:  # the object stands on the table: the prior sphere rests on z = min z
                centre[2] = lo[2] + radius
            self.prior_sphere = (centre, radius)
            return sphere_mean(centre, radius)
        if kind == "given":
            c = np.asarray(p["prior.centre_m"], float)
            if c.shape != (3,):
                raise ValueError("prior.centre_m must be 3 numbers (x, y, z)")
            self.prior_sphere = (c[: self.dim], float(p["prior.radius_m"]))
            return sphere_mean(*self.prior_sphere)
        raise ValueError(f"prior.type must be 'auto', 'given' or 'none', got '{kind}'")

    def _configured_hyperparameters(self) -> dict[str, float]:
        """The hyperparameters ``kernel.fit`` searches, at their configured values, in search order."""
        theta = {SCALE: float(self.params["kernel.signal_variance"])}
        if self.kernel.name == "thin_plate":
            theta[THIN_PLATE_R] = self.kernel.R_m
        else:
            theta[LENGTH] = self.kernel.length_scale_m
        theta[NOISE] = self.contact_var
        if self.prior_sphere is not None:
            theta[RADIUS] = self.prior_sphere[1]
        return theta

    # -- state ---------------------------------------------------------------
    def reset(self) -> None:
        """Forget every observation (back to the prior and the configured hyperparameters)."""
        if self.hyperparameters != self._theta_cfg:
            kernel = kernel_of(self.kernel.name, self._theta_cfg)
            self.gp.rebuild(kernel, mean_of(self._prior_centre(), self._theta_cfg), np.zeros((0, self.dim)),
                            np.zeros(0, int), np.zeros(0), np.zeros(0))
            self._adopt(self._theta_cfg, kernel)
        self.gp.reset()
        if self.method == "local":
            self.gp.clear_eval_points()
            self.local = self._new_local()
        else:
            if self.gp.eval_points is None:
                self.gp.set_eval_points(self._lattice)
            self.local = None
        self._obs: list[tuple] = []  # accepted GP observations (x, value, var, normal, normal var)
        self._obs_tuned: list[bool] = []  # per _obs: its value noise is noise.contact_var_m2 (kernel.fit tunes it)
        self._obs_anchor: list[bool] = []  # per _obs: a probe's free-space end (the local path anchors it at once)
        self._n_gp_contacts = 0  # contacts added to the GP (kernel.fit's schedule)
        #: the last kernel.fit search (None: none yet)
        self.last_fit: Optional[FitResult] = None
        self._inputs: list[tuple] = []  # the accepted add_observation arguments (point, normal, label, var)
        self._version = 0
        self._points = np.zeros((0, self.dim))
        self.n_observations = 0
        self.n_rejected = 0
        self.n_thinned = 0
        self._contact_points = np.zeros((0, self.dim))  # added contacts (thinning by distance)
        self._contact_normals = np.zeros((0, self.dim))  # their unit normals (NaN: none)
        self._cache: Optional[tuple[int, np.ndarray, LevelSet]] = None
        self._floating: Optional[tuple[int, Optional[np.ndarray]]] = None  # (version, _floating_nodes())
        self._refined: Optional[tuple[int, int, LevelSet]] = None  # (version, steps, refined_level_set())
        self._snap_prev: Optional[tuple[np.ndarray, np.ndarray]] = None  # last map's (vertex keys, positions)

    def add_observation(
        self,
        point_xyz: np.ndarray,
        normal_xyz: Optional[np.ndarray],
        label: int,
        value_var_m2: Optional[float] = None,
    ) -> tuple[bool, str]:
        """Add one contact (label 1) or free-space point (label 0), world frame.

        Args:
            value_var_m2: noise variance of this observation's value (default: the
                ``noise.contact_var_m2`` / ``noise.free_space_var_m2`` parameter), so
                that an uncertain contact can be down-weighted.

        Returns:
            (accepted, reason): reason says why it was rejected; '' if accepted, 'thinned: ...'
            if it was accepted as consistent with the estimate but not added (``thinning.*``,
            counted in ``n_thinned``).
        """
        ok, reason = self._add(point_xyz, normal_xyz, label, value_var_m2)
        if not ok:
            self.n_rejected += 1
        return ok, reason

    def _add(self, point_xyz, normal_xyz, label, value_var_m2) -> tuple[bool, str]:
        pt = np.asarray(point_xyz, float).ravel()
        if pt.shape != (3,):
            return False, f"point must have 3 coordinates, got {pt.shape[0]}"
        x = pt[: self.dim]
        if not np.isfinite(x).all():
            return False, "non-finite point"
        if (x < self.bounds_m[0]).any() or (x > self.bounds_m[1]).any():
            return False, f"point {np.round(x, 4).tolist()} outside the workspace"
        if label not in (LABEL_CONTACT, LABEL_FREE_SPACE):
            return False, f"unknown label {label} (1 contact, 0 free space)"
        if value_var_m2 is not None and not (np.isfinite(value_var_m2) and value_var_m2 >= 0):
            return False, f"noise variance {value_var_m2} is not a finite number >= 0"
        if len(self._points):
            d = float(np.sqrt(((self._points - x) ** 2).sum(1).min()))
            if d < self.duplicate_distance_m:
                return False, f"duplicate: {d * 1000:.2f} mm from an earlier observation"
        if label == LABEL_FREE_SPACE:
            row = self._free_space_row(x, self.free_var if value_var_m2 is None else float(value_var_m2))
            if row is None:
                self.n_free_space_implied += 1
                return True, "free space already implied by the estimate"
            obs = (x, row[0], row[1], None, 0.0)
        else:
            obs = (x, 0.0, self.contact_var if value_var_m2 is None else float(value_var_m2),
                   self._unit_normal(normal_xyz), self.normal_var)
            why = self._thinned(x, obs[3], obs[2])
            if why:
                self.n_thinned += 1
                return True, f"thinned: {why}"
        try:
            self._add_to_model(obs, anchor=label == LABEL_FREE_SPACE)
        except FactorError as exc:
            return False, f"rejected by the GP: {exc}"
        self._obs.append(obs)
        self._obs_tuned.append(label == LABEL_CONTACT and value_var_m2 is None)
        self._obs_anchor.append(label == LABEL_FREE_SPACE)
        if label == LABEL_FREE_SPACE:
            self._add_sweep(x, normal_xyz, obs[2])
        normal = np.full(3, np.nan) if normal_xyz is None else np.asarray(normal_xyz, float).ravel()
        self._inputs.append((pt, normal if normal.shape == (3,) else np.full(3, np.nan), int(label),
                             np.nan if value_var_m2 is None else float(value_var_m2)))
        self._points = np.vstack([self._points, x])
        if label == LABEL_CONTACT:
            self._contact_points = np.vstack([self._contact_points, x])
            self._contact_normals = np.vstack([self._contact_normals,
                                               obs[3] if obs[3] is not None else np.full(self.dim, np.nan)])
        self.n_observations += 1
        self._version += 1
        if label == LABEL_CONTACT:
            self._n_gp_contacts += 1
            if self._fit_due():
                self._fit_hyperparameters()
        if self.method == "auto" and self.local is None and self.n_observations >= self.auto_min_contacts:
            self._switch_to_local()
        return True, ""

    def _add_sweep(self, end: np.ndarray, sweep_xyz: Optional[np.ndarray], var_m2: float) -> None:
        """The free-space rows along a probe's sweep (module docstring), each at least
        ``duplicate_distance_m`` from every earlier observation and inside the workspace."""
        v = None if sweep_xyz is None else np.asarray(sweep_xyz, float).ravel()[: self.dim]
        if self.sweep_step_m <= 0 or v is None or v.shape != (self.dim,) or not np.isfinite(v).all():
            return
        length = float(np.linalg.norm(v))
        n = int(np.floor(length / self.sweep_step_m + 1e-9))
        near = np.vstack([self._points, end[None]])
        for t in np.arange(1, n + 1) * (self.sweep_step_m / max(length, 1e-300)):
            x = end + t * v
            if (x < self.bounds_m[0]).any() or (x > self.bounds_m[1]).any():
                break
            if np.sqrt(((near - x) ** 2).sum(1).min()) < self.duplicate_distance_m:
                continue
            site = self._free_space_row(x, var_m2)
            if site is None:
                continue
            row = (x, site[0], site[1], None, 0.0)
            try:
                self._model().add_observation(*row)
            except FactorError:
                continue  # a row the factor cannot take: the probe end itself is in
            self._obs.append(row)
            self._obs_tuned.append(False)
            self._obs_anchor.append(False)
            near = np.vstack([near, x])
            self._points = np.vstack([self._points, x])

    def _free_space_row(self, x: np.ndarray, var_m2: float) -> Optional[tuple[float, float]]:
        """The (value, noise variance) a free-space point at ``x`` observes, None: nothing to add.

        The finger's centre is at least a = ``free_space.value_m`` off the surface: f(x) ≥ a, an
        inequality. 'equality' observes f = a with ``var_m2``; where the estimate already says farther
        that pulls the mean down (with the thin-plate kernel, far over the workspace). 'inequality'
        (assumed-density filtering, one step): with the prediction N(μ, s²) at x, the constrained
        posterior has the truncated moments m = μ + s λ, v = s² (1 − λ (λ − α)), α = (a − μ)/s,
        λ = φ(α)/(1 − Φ(α)); the Gaussian site giving them is 1/r = 1/v − 1/s², y = r (m/v − μ/s²).
        With ``free_space.posterior: mode`` the posterior takes the truncated prediction's mode
        m = max(μ, a) instead (same v): the mean overshoots a by about 0.8 s, and before the first
        contact the thin-plate s is a kernel scale (0.28 m on the default 2D workspace), not a
        belief in metres, so one miss would lift the whole estimate off the object.
        Far inside the constraint (λ → 0) the site is uninformative and nothing is added; a
        confident estimate that is wrong there (α ≫ 0) gets a strong observation near a."""
        if self.free_model == "equality":
            return self.free_value, var_m2
        mu, s2 = (float(np.ravel(v)[0]) for v in self._model().predict(x[None]))
        if not s2 > 1e-14:
            return None
        s = np.sqrt(s2)
        alpha = (self.free_value - mu) / s
        lam = float(np.exp(-0.5 * alpha ** 2 - 0.5 * np.log(2 * np.pi) - log_ndtr(-alpha)))
        v = s2 * (1.0 - lam * (lam - alpha))
        if not v > 1e-12 * s2:  # far on the wrong side (α ≫ 1, v lost to cancellation): f is pinned at a
            return self.free_value, self.contact_var
        if v >= s2 * (1.0 - 1e-3):
            return None  # the constraint already holds with near certainty: no information
        m = mu + s * lam if self.free_posterior == "mean" else max(mu, self.free_value)
        r = 1.0 / (1.0 / v - 1.0 / s2)
        r = max(r, self.contact_var)  # no stronger than a contact
        y = r * (m / v - mu / s2)
        return y, r

    def _thinned(self, x: np.ndarray, normal: Optional[np.ndarray], value_var: float) -> str:
        """Why the contact (x, unit normal or None, value noise) adds nothing new ('' = add it).

        By distance: within ``thinning.distance_m`` of an earlier contact with a consistent
        normal (angle <= ``thinning.normal_angle_deg``; both without normal: consistent).
        By variance: the predicted variance of f at x is below ``thinning.var_ratio`` times
        the value noise, the predicted |mean| is within 2 noise sd (the contact agrees with
        the estimate) and, with a normal, the predicted normal is consistent with it.
        """
        if self.thin_distance_m > 0 and len(self._contact_points):
            d2 = ((self._contact_points - x) ** 2).sum(1)
            near = np.flatnonzero(d2 < self.thin_distance_m ** 2)
            if len(near):
                nn = self._contact_normals[near]
                ok = np.isnan(nn[:, 0]) if normal is None else np.nan_to_num(nn @ normal, nan=-2.0) >= self.thin_cos
                if ok.any():
                    return f"{1e3 * np.sqrt(d2[near[ok]].min()):.2f} mm from a consistent earlier contact"
        if self.thin_var_ratio > 0 and self.n_observations:
            P = x[None]
            if self.local is not None:
                mu, var, g = self.local.predict(P, return_var=True, return_grad=normal is not None) \
                    if normal is not None else (*self.local.predict(P), None)
            else:
                mu, var = self.gp.predict(P)
                g = self.gp.predict_gradient(P) if normal is not None else None
            consistent = True
            if g is not None:
                gn = float(np.linalg.norm(g[0]))
                consistent = gn > 0 and float(g[0] @ normal) / gn >= self.thin_cos
            if consistent and var[0] < self.thin_var_ratio * value_var and abs(mu[0]) <= 2.0 * np.sqrt(value_var):
                return f"predicted variance {var[0]:.2e} m^2 below {self.thin_var_ratio:g} x its noise"
        return ""

    # -- hyperparameters (kernel.fit) --------------------------------------------
    def _fit_due(self) -> bool:
        """A fit after contact c = fit_min_contacts, then after every fit_every-th more."""
        c = self._n_gp_contacts
        return self.fit_enabled and c >= self.fit_min_contacts and (c - self.fit_min_contacts) % self.fit_every == 0

    def _prior_centre(self) -> Optional[np.ndarray]:
        return None if self.prior_sphere is None else self.prior_sphere[0]

    def fit_rows(self) -> FitRows:
        """The rows the GP holds, in its order (a point's value row, then its gradient rows),
        with the rows whose noise is ``noise.contact_var_m2`` marked."""
        X, t, y, noise, tuned = [], [], [], [], []
        for (x, value, var, normal, normal_var), tun in zip(self._obs, self._obs_tuned):
            X.append(x[None])
            t.append([VALUE])
            y.append([value])
            noise.append([var])
            tuned.append([tun])
            if normal is not None:
                Xg, tg = gradient_rows(x[None])
                X.append(Xg)
                t.append(tg)
                y.append(normal)
                noise.append(np.full(self.dim, normal_var))
                tuned.append(np.zeros(self.dim, bool))
        if not X:
            return FitRows(np.zeros((0, self.dim)), np.zeros(0, int), np.zeros(0), np.zeros(0), np.zeros(0, bool))
        return FitRows(np.vstack(X), np.concatenate(t).astype(int), np.concatenate(y).astype(float),
                       np.concatenate(noise).astype(float), np.concatenate(tuned).astype(bool))

    def _fit_hyperparameters(self) -> None:
        """Search θ (:mod:`tactile_gpis.hyperfit`) and, if it moved, rebuild the GP from the stored
        rows with it (one batch factorisation and the lattice's V). A rebuild the factor
        refuses keeps the current θ."""
        rows = self.fit_rows()
        centre = self._prior_centre()
        result = fit_hyperparameters(rows, self.kernel.name, self.hyperparameters, self._fit_grid, self.gp.jitter,
                                     centre)
        self.last_fit = result
        if result.theta == self.hyperparameters:
            return
        mean = mean_of(centre, result.theta)
        if all(result.theta[k] == v for k, v in self.hyperparameters.items() if k != RADIUS):
            self.gp.set_mean(mean, rows.y)  # the prior radius alone: the factor and V stay
            self._adopt(result.theta, self.kernel)
            return
        kernel = kernel_of(self.kernel.name, result.theta)
        try:
            self.gp.rebuild(kernel, mean, rows.X, rows.t, rows.y, rows.noise_with(result.theta[NOISE]))
        except FactorError:
            return
        self._adopt(result.theta, kernel)

    def _adopt(self, theta: Mapping[str, float], kernel) -> None:
        """Take θ as the estimator's hyperparameters (the GP already has them)."""
        self.kernel = kernel
        self.contact_var = float(theta[NOISE])
        if self.prior_sphere is not None:
            self.prior_sphere = (self.prior_sphere[0], float(theta[RADIUS]))
        self.hyperparameters = dict(theta)
        self._obs = [(x, v, self.contact_var if tun else var, n, nv)
                     for (x, v, var, n, nv), tun in zip(self._obs, self._obs_tuned)]

    # -- paths -----------------------------------------------------------------
    def _new_local(self) -> LocalGPIS:
        return LocalGPIS(self.kernel, self.dim, self.gp.mean_fn, self.gp.jitter, self.bounds_m, self.lattice_axes,
                         **self._local_args)

    def _model(self):
        """The GP taking observations and answering queries: the exact GPIS or the local one."""
        return self.local if self.local is not None else self.gp

    def _add_to_model(self, obs: tuple, anchor: bool) -> None:
        """One observation into the GP; on the local path a probe's free-space end joins the anchor GP
        at once (``anchor``: a miss removes estimated solid anywhere, beyond the experts that hold it)."""
        if self.local is not None:
            self.local.add_observation(*obs, anchor=anchor)
        else:
            self.gp.add_observation(*obs)

    def _switch_to_local(self) -> None:
        """'auto': rebuild the observations so far as a LocalGPIS and drop the exact lattice state."""
        local = self._new_local()
        for obs, anchor in zip(self._obs, self._obs_anchor):
            local.add_observation(*obs, anchor=anchor)
        self.local = local
        self.gp.reset()
        self.gp.clear_eval_points()

    @property
    def version(self) -> int:
        """Bumped by every accepted observation: two reads with the same version see the same estimate."""
        return self._version

    @property
    def active_method(self) -> str:
        """'exact' or 'local': the path answering now."""
        return "local" if self.local is not None else "exact"

    def _unit_normal(self, normal_xyz) -> Optional[np.ndarray]:
        if not self.use_normals or normal_xyz is None:
            return None
        n = np.asarray(normal_xyz, float).ravel()[: self.dim]
        norm = np.linalg.norm(n)
        if n.shape != (self.dim,) or not np.isfinite(n).all() or norm < 0.5:
            return None  # no usable normal (e.g. a 3D normal nearly vertical in 2D)
        return n / norm

    # -- queries -------------------------------------------------------------
    def _xy(self, points: np.ndarray) -> np.ndarray:
        P = np.atleast_2d(np.asarray(points, float))
        if P.shape[1] < self.dim:
            raise ValueError(f"points must have at least {self.dim} columns, got {P.shape[1]}")
        return P[:, : self.dim]

    def predict(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Posterior mean and variance of f at (N, dim) points."""
        return self._model().predict(self._xy(points))

    def inside(self, points: np.ndarray) -> np.ndarray:
        """(N,) bool: mean < 0 (in 3D also z >= 0: nothing below the table)."""
        P = self._xy(points)
        return self._above_table(P, self._model().predict(P, return_var=False) < 0)

    def lattice_inside(self, points: np.ndarray) -> np.ndarray:
        """(N,) bool: the lattice mean, linearly interpolated, is < 0 (outside the
        lattice: False; in 3D also False below the table).

        Costs O(N) from the incrementally maintained lattice mean, where
        :meth:`inside` costs a GP prediction per point (O(N n)); near the surface it
        misplaces thin parts (:meth:`refined_inside`, what the metrics evaluate).
        """
        P = self._xy(points)
        return self._above_table(P, self._interpolated_mean(P) < 0)

    def _interpolated_mean(self, P: np.ndarray) -> np.ndarray:
        """The lattice mean linearly interpolated at (N, dim) points (outside the lattice: +inf), with the
        nodes of floating untouched components (:meth:`_floating_nodes`) read as outside (|μ|)."""
        from scipy.interpolate import RegularGridInterpolator

        mean, floating = self.lattice_mean(), self._floating_nodes()
        if floating is not None:
            mean = np.where(floating, np.abs(mean), mean)
        return RegularGridInterpolator(self.lattice_axes, mean, bounds_error=False, fill_value=np.inf)(P)

    def _floating_nodes(self) -> Optional[np.ndarray]:
        """Bool (lattice shape) over the nodes of the components of {μ < 0} the estimated solid leaves
        out (``solid.drop_floating``, :func:`~tactile_gpis.solid.floating_untouched`); None when none.
        Before the first contact nothing is left out: the estimate is then the prior, shaped by misses
        (the planner searches with it), and no component holds the object's data yet."""
        if not self.drop_floating or not len(self._contact_points):
            return None
        if self._floating is None or self._floating[0] != self._version:
            mask = floating_untouched(self.lattice_mean(), self.lattice_axes, self._contact_points,
                                      self.floating_gap_m)
            self._floating = (self._version, mask if mask.any() else None)
        return self._floating[1]

    def _above_table(self, P: np.ndarray, inside: np.ndarray) -> np.ndarray:
        """``inside`` and, in 3D, z >= 0 (nothing below the table)."""
        return inside & (P[:, 2] >= 0) if self.dim == 3 else inside

    def refined_inside(self, points: np.ndarray, band_cells: float = 1.0) -> np.ndarray:
        """(N,) bool: the posterior mean is < 0 where it matters, at the cost of few predictions.

        The lattice mean, linearly interpolated (:meth:`lattice_inside`), misplaces the zero level
        set where the surface curves within a few lattice cells: linear interpolation of a
        distance-like field overestimates it between the nodes, so thin parts shrink (a pole of
        7 mm radius on the 6.4 mm 3D lattice loses a quarter of its section). Points whose
        interpolated |μ| is below ``band_cells`` × the largest lattice spacing take the sign of the
        GP mean itself (:meth:`inside`); the rest keep the interpolated sign (outside the lattice:
        False; in 3D also False below the table). Within a cell the interpolation errs by less than
        half its diagonal times |∇μ| ≈ 1, so one cell is enough. This is what the metrics evaluate.
        """
        return self.refined_mean(points, band_cells) < 0

    def refined_mean(self, points: np.ndarray, band_cells: float = 1.0) -> np.ndarray:
        """(N,) the field :meth:`refined_inside` reads (inside where < 0): the GP mean within
        ``band_cells`` lattice cells of the surface, the interpolated lattice mean elsewhere, +inf
        outside the lattice and, in 3D, below the table."""
        P = self._xy(points)
        mu = self._interpolated_mean(P)
        band = band_cells * max(float(a[1] - a[0]) for a in self.lattice_axes)
        near = np.abs(mu) < band
        floating = self._floating_nodes()
        if floating is not None:  # not in a cell of a left-out component: the GP mean there is < 0
            from scipy.interpolate import RegularGridInterpolator

            near &= RegularGridInterpolator(self.lattice_axes, floating.astype(float), bounds_error=False,
                                            fill_value=0.0)(P) <= 0
        near = np.flatnonzero(near)
        mu[near] = self._predict_in_chunks(P[near])
        if self.dim == 3:
            mu[P[:, 2] < 0] = np.inf
        return mu

    def _predict_in_chunks(self, P: np.ndarray, return_var: bool = False):
        """The posterior mean (and variance) at (N, dim) points, 2048 at a time: bounded memory, as a
        prediction holds W = L⁻¹K(rows, chunk)."""
        parts = [self._model().predict(P[i: i + 2048], return_var=return_var) for i in range(0, len(P), 2048)]
        if not return_var:
            return np.concatenate([np.zeros(0)] + parts)
        return tuple(np.concatenate([np.zeros(0)] + [q[k] for q in parts]) for k in (0, 1))

    def lattice_mean(self) -> np.ndarray:
        """Posterior mean on the lattice, shaped ``lattice_shape``."""
        m = self.local.lattice_mean() if self.local is not None else self.gp.eval_mean()
        return m.reshape(self.lattice_shape)

    def lattice_variance(self) -> np.ndarray:
        """Posterior variance on the lattice, shaped ``lattice_shape``."""
        v = self.local.lattice_variance() if self.local is not None else self.gp.eval_variance()
        return v.reshape(self.lattice_shape)

    def occupancy(self) -> np.ndarray:
        """P(inside) = Phi(-mu / sigma) on the lattice, shaped ``lattice_shape``."""
        sd = np.sqrt(np.maximum(self.lattice_variance(), 1e-300))
        return ndtr(-self.lattice_mean() / sd)

    def level_set(self) -> LevelSet:
        """Zero level set of the lattice mean (2D segments / 3D triangles)."""
        return self._map_and_level_set()[2]

    def refined_level_set(self, steps: int = 4) -> LevelSet:
        """The zero level set with each vertex moved along its lattice edge (a, b) to the GP mean's own
        zero crossing: regula falsi (Illinois) on the bracket [a, b] (the lattice mean changes sign
        there), ``steps`` predictions of the vertices. The lattice's vertices interpolate μ linearly
        along the edge, which shrinks thin parts (:meth:`refined_inside`); the elements are the lattice's."""
        if self._refined is not None and self._refined[:2] == (self._version, steps):
            return self._refined[2]  # the exports of one estimate (.ply, .stl, .obj) share it
        ls = self.level_set()
        if ls.keys is None or not len(ls.vertices):
            return ls
        m = len(self._lattice)
        lo, hi = ls.keys // m, ls.keys % m
        a, d = self._lattice[lo], self._lattice[hi] - self._lattice[lo]
        mean = self.lattice_mean().ravel()
        fa, fb = mean[lo].copy(), mean[hi].copy()
        ta, tb = np.zeros(len(lo)), np.ones(len(lo))
        kept_a, kept_b = np.zeros(len(lo), bool), np.zeros(len(lo), bool)
        t = np.einsum("ij,ij->i", ls.vertices - a, d) / np.einsum("ij,ij->i", d, d)
        for _ in range(steps):
            v = a + t[:, None] * d
            fv = self._predict_in_chunks(v)
            left = (fv < 0) == (fa < 0)  # the crossing lies between t and b
            # Illinois: the end kept a second time counts half, so neither end sticks
            fb = np.where(left & kept_b, 0.5 * fb, fb)
            fa = np.where(~left & kept_a, 0.5 * fa, fa)
            kept_a, kept_b = ~left, left
            ta, fa = np.where(left, t, ta), np.where(left, fv, fa)
            tb, fb = np.where(left, tb, t), np.where(left, fb, fv)
            t = ta + (tb - ta) * fa / np.where(fa != fb, fa - fb, 1.0)
        self._refined = (self._version, steps, LevelSet(a + t[:, None] * d, ls.elements, ls.keys))
        return self._refined[2]

    def surface_points(self) -> np.ndarray:
        """(K, 3) vertices of the estimated zero level set (2D: z = plane_z_m)."""
        return self._to_xyz(self.level_set().vertices)

    def map_array(self) -> np.ndarray:
        """The variance map: lattice nodes (kind 0, C order) then candidates (kind 1).

        Read-only: the estimator's own map until the next observation builds a new one (no copy of
        the 48³ lattice per decision); ``.copy()`` it to edit."""
        return self._map_and_level_set()[1]

    def observations(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The accepted observations in the order added, as given to :meth:`add_observation`
        (world frame, metres): points (N, 3), normals (N, 3; NaN where none was given),
        labels (N,) int, value noise variances (N,) m^2 (NaN: the parameter's default).
        Adding them in this order to an estimator of the same parameters rebuilds this one."""
        if not self._inputs:
            return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, dtype=int), np.zeros(0)
        pts, nrm, lab, var = zip(*self._inputs)
        return np.array(pts), np.array(nrm), np.array(lab, dtype=int), np.array(var, dtype=float)

    def export_shape(self, path: str | Path) -> Path:
        """Write the estimated shape by extension (world frame, metres): .csv contour (2D),
        .ply (2D polyline / 3D mesh, with the GP posterior variance of f at each vertex),
        .obj (2D polyline / 3D mesh), .stl (3D mesh); the vertices on the GP mean's own zero
        crossing (:meth:`refined_level_set`)."""
        ls = self.refined_level_set()
        variance = None
        if Path(path).suffix.lower() == ".ply":
            variance = self._predict_in_chunks(ls.vertices, return_var=True)[1]
        return export_level_set(path, ls, self.dim, variance=variance, plane_z_m=self.plane_z_m)

    def export_observations(self, path: str | Path) -> Path:
        """Write the accepted observations as a PLY point cloud (x y z nx ny nz label,
        world frame, metres; label 1 contact, 0 free space; normal 0 where none)."""
        pts, nrm, lab, _ = self.observations()
        write_observations_ply(Path(path), pts, nrm, lab)
        return Path(path)

    # -- map -----------------------------------------------------------------
    def _to_xyz(self, P: np.ndarray) -> np.ndarray:
        if self.dim == 3:
            return P.copy()
        return np.column_stack([P, np.full(len(P), self.plane_z_m)])

    def _map_and_level_set(self) -> tuple[int, np.ndarray, LevelSet]:
        if self._cache is not None and self._cache[0] == self._version:
            return self._cache
        mean = self.lattice_mean()
        var = self.lattice_variance().ravel()
        ls = _without_nodes(zero_level_set(mean, self.lattice_axes), self._floating_nodes())
        cand, keys = ls.vertices, ls.keys
        if self.dim == 3:
            above = cand[:, 2] > self.table_margin_m
            cand, keys = cand[above], keys[above]
        if self.local is not None and self.snap_m > 0:
            cand = self._snap(cand, keys)
        cand = cand[farthest_point_subsample(cand, self.max_candidates)]
        if not len(cand):
            c_mean, c_var, c_grad = np.zeros(0), np.zeros(0), np.zeros((0, self.dim))
        elif self.local is not None:
            c_mean, c_var, c_grad = self.local.predict_candidates(cand)
        else:
            c_mean, c_var = self.gp.predict(cand)
            c_grad = self.gp.predict_gradient(cand)
        n_lat = len(self._lattice)
        out = np.empty(n_lat + len(cand), dtype=VARIANCE_MAP_DTYPE)
        # positions and kind of the lattice nodes (fixed); their normals stay 0: no consumer reads a
        # normal off the lattice (the planner's are the candidates'), and ∇μ there cost ~4 ms in 3D
        out[:n_lat] = self._lattice_rows()
        tail = np.zeros(len(cand), dtype=VARIANCE_MAP_DTYPE)
        cxyz = self._to_xyz(cand)
        for i, name in enumerate(("x", "y", "z")):
            tail[name] = cxyz[:, i]
        tail["kind"] = KIND_CANDIDATE
        out[n_lat:] = tail
        out["mean"][:n_lat], out["mean"][n_lat:] = mean.ravel(), c_mean
        out["variance"][:n_lat], out["variance"][n_lat:] = var, c_var
        g = _unit(c_grad)
        for i, name in enumerate(("normal_x", "normal_y", "normal_z")[: self.dim]):
            out[name][n_lat:] = g[:, i]
        out.flags.writeable = False  # handed out by map_array without a copy
        self._cache = (self._version, out, ls)
        return self._cache

    def _lattice_rows(self) -> np.ndarray:
        """The map's lattice rows with x, y, z and kind set (the rest zero), built once."""
        if self._lattice_map is None:
            rows = np.zeros(len(self._lattice), dtype=VARIANCE_MAP_DTYPE)
            xyz = self._to_xyz(self._lattice)
            for i, name in enumerate(("x", "y", "z")):
                rows[name] = xyz[:, i]
            rows["kind"] = KIND_LATTICE
            self._lattice_map = rows
        return self._lattice_map

    def _snap(self, verts: np.ndarray, keys: np.ndarray) -> np.ndarray:
        """Vertices (V, d) with those that moved at most ``candidates.snap_m`` along their
        lattice edge (same key) since the last map put back where they were then."""
        out = verts.copy()
        if self._snap_prev is not None and len(self._snap_prev[0]) and len(keys):
            pk, pv = self._snap_prev
            j = np.minimum(np.searchsorted(pk, keys), len(pk) - 1)
            near = (pk[j] == keys) & (((verts - pv[j]) ** 2).sum(1) <= self.snap_m ** 2)
            out[near] = pv[j[near]]
        self._snap_prev = (keys, out)
        return out


def _without_nodes(ls: LevelSet, nodes: Optional[np.ndarray]) -> LevelSet:
    """The level set without the vertices on a lattice edge with an end in ``nodes`` (bool, lattice
    shape; None: all kept) and the elements that use them; the vertices renumbered."""
    if nodes is None or ls.keys is None or not len(ls.vertices):
        return ls
    flat = nodes.ravel()
    m = flat.size
    keep = ~(flat[ls.keys // m] | flat[ls.keys % m])
    if keep.all():
        return ls
    new_index = np.cumsum(keep) - 1
    elements = ls.elements[keep[ls.elements].all(axis=1)]
    return LevelSet(ls.vertices[keep], new_index[elements], ls.keys[keep])


def _unit(g: np.ndarray) -> np.ndarray:
    sq = g[:, 0] * g[:, 0]  # |g|^2 as np.linalg.norm sums it (the same bits), without its temporaries
    for i in range(1, g.shape[1]):
        sq += g[:, i] * g[:, i]
    n = np.sqrt(sq)[:, None]
    return np.divide(g, n, out=np.zeros_like(g), where=n > 1e-12)


def _flag(p: Mapping[str, Any], key: str) -> bool:
    v = p[key]
    if not isinstance(v, (bool, np.bool_)):
        raise ValueError(f"{key} must be true or false, got {v!r}")
    return bool(v)


def _count(p: Mapping[str, Any], key: str) -> int:
    v = p[key]
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)) or v < 1:
        raise ValueError(f"{key} must be an integer >= 1, got {v!r}")
    return int(v)


def _factors(p: Mapping[str, Any], key: str) -> np.ndarray:
    v = p[key]
    try:
        f = np.asarray(v, dtype=float)
    except (TypeError, ValueError):
        f = None
    if f is None or f.ndim != 1 or not len(f) or not (np.isfinite(f).all() and (f > 0).all()):
        raise ValueError(f"{key} must be a non-empty list of finite numbers > 0, got {v!r}")
    return f


def _nonneg(p: Mapping[str, Any], key: str) -> float:
    v = float(p[key])
    if not (np.isfinite(v) and v >= 0):
        raise ValueError(f"{key} must be a finite number >= 0, got {p[key]}")
    return v
