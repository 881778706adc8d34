"""TouchPlanner: one decision "where to touch next" from a GPIS variance map (ROS-free).

Used by the ``soc_planner`` node and by the offline exploration loop with the
same parameters (config/soc_planner.yaml, ``soc_planner: ros__parameters:``).

One decision: parse the map → free-space graph (μ ≥ margin) → attach each
candidate to the free node nearest its pre-touch point (candidate +
(standoff + tip radius)·n) → travel costs from the tip's node to every
candidate (one LMDP solve, or Dijkstra) → strategy scores → path of the chosen
target (greedy on the controlled transition, then shortcut) from the tip to
the pre-touch point. World frame, metres, seconds.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Any, Mapping

import numpy as np
import scipy.sparse.csgraph as csg

from tactile_common.finger_axis import EZ
from tactile_common.touch_geometry import APPROACH_BOX_INSET_M, MotionModel, TouchGeometry, rod_points
from tactile_common.wrist import PANDA_WRIST_BANDS_FLAT_M

from .graph import CLEARANCES, FreeSpaceGraph, build_free_graph
from .foot import foot_probes
from .fruitless import FruitlessTouches
from .maps import Candidates, MapError, parse_variance_map
from .pocket import closer_pretouch, pocket_entries
from .paths import path_length_m, shortcut
from .search import floating_base, object_lost, ring_radii_m, ring_search_map, search_map
from . import slides
from .tilt import TiltedEntries, TiltSettings, tilted_entries
from .wrist import WristCheck, bands_from_flat
from .strategies import INFO_TRAVEL_PER, SCORE_FORMS, STRATEGIES, SelectionContext, StrategyParams, score_candidates
from .travel import TRAVEL_LENGTHS, TravelError, make_backend


#: name -> (default, description): the node's ROS parameters, also the keys of ``from_params``.
PARAMETERS: dict[str, tuple[Any, str]] = {
    "mode": ("2d", "'2d' (plane z = plane height, 8-connected) or '3d' (26-connected); must match the map", {"choices": ("2d", "3d")}),
    "strategy": ("info_travel", f"one of {STRATEGIES}", {"choices": STRATEGIES}),
    "score_form": ("normalized", f"proposed strategy form: one of {SCORE_FORMS}", {"choices": SCORE_FORMS}),
    "alpha": (1.0, "uncertainty/travel trade-off of the proposed strategy (→∞: most uncertain, →0: nearest)", {"ge": 0.0}),
    "seed": (0, "seed of the planner's random generator (random strategy)", {"ge": 0}),
    "backend": ("lmdp", "travel costs: 'lmdp' (one linear solve) or 'dijkstra'", {"choices": ("lmdp", "dijkstra")}),
    "solver": ("auto", "LMDP linear solver: 'auto' (2D LU, 3D CG), 'lu' or 'cg'", {"choices": ("auto", "lu", "cg")}),
    "cost_rate_per_m": (200.0, "LMDP state cost per metre of travel (nats/m); larger = closer to shortest paths", {"gt": 0.0}),
    "max_rate_nats": (60.0, "numerics: the rate is scaled so that rate × graph bounding-box diagonal ≤ this (no underflow)", {"gt": 0.0}),
    "cg_max_rate_nats": (3.0, "numerics with CG (3D): rate × graph bounding-box diagonal ≤ this, so every cost stays within CG's accuracy", {"gt": 0.0}),
    "cg_rtol": (1e-14, "relative residual tolerance of the 3D conjugate gradients", {"gt": 0.0, "lt": 1.0}),
    "travel_length": ("expected", "path length the motion model times (travel_m): 'expected' (the LMDP's "
                      "expected path length ∂C/∂rate: one more solve) or 'shortest' (the free graph's shortest "
                      "path, nearer what the arm follows, but worse decisions measured)", {"choices": TRAVEL_LENGTHS}),
    "lattice_stride": (1, "use every n-th node of the estimator lattice per axis (coarser planning lattice)", {"ge": 1}),
    "shell_m": (0.03, "plan in a band (2D) / shell (3D) of nodes with clearance ≤ margin + shell (0 = all free space)", {"ge": 0.0}),
    "margin_m": (0.015, "minimum clearance of the tip centre from the estimated surface on paths", {"gt": 0.0}),
    "clearance": ("distance", "clearance measure: 'distance' (Euclidean, to the zero level set of the mean) or "
                              "'mean' (the GP mean μ, a distance only where |∇μ| ≈ 1)", {"choices": CLEARANCES}),
    "search_quantile": (0.1, "no estimated surface left (every touch missed), or none of its candidates can be "
                        "touched: probe the zero level set of μ − βσ, β the quantile of μ/σ that puts this "
                        "fraction of the lattice on its inside, where the object is most probable "
                        "(tactile_planner.search); 0 = stop with no_candidates / all_unreachable",
                        {"ge": 0.0, "lt": 1.0}),
    "search_ring_spacing_m": (0.02, "when the probability search has nothing left to probe: coverage rings around "
                              "the workspace centre (2D circles; 3D: search_rings_3d), one approach-length "
                              "apart, candidates this far apart on each, nearest ring first "
                              "(tactile_planner.search; 0 = off)", {"ge": 0.0}),
    "search_rings_3d": ("table", "3D coverage rings: 'table' (horizontal circles at the lowest probe height, "
                        "approached level towards the centre: every object on the table crosses that height) or "
                        "'hemisphere' (hemispheres on the table, approached towards its centre)",
                        {"choices": ("table", "hemisphere")}),
    "search_rings_first": (False, "a lost object: the coverage rings before the probability search (the 3D "
                           "default, with equality free-space observations: the probability search then follows "
                           "the kernel's extrapolation; docs/planner.md)"),
    "search_after_misses": (0, "also search for a lost object, coverage rings first, once this many touches "
                            "have met nothing and none has met the object yet (the request's "
                            "misses_before_contact): the estimate is still the prior, and the touches refute it "
                            "(0 = only when no estimated surface is left)", {"ge": 0}),
    "support_gap_m": (0.0, "3D: an estimate whose lowest inside node is more than this above the table floats "
                      "(an object on the table reaches it): probe under it first, on rings round its footprint "
                      "below it (tactile_planner.search.floating_base; 0 = off)", {"ge": 0.0}),
    "foot_probe_gap_m": (0.0, "3D: a wall whose estimate ends more than this above the lowest probe height gets a "
                         "horizontal probe at that height towards its line, beside the ordinary candidates (an "
                         "object on the table reaches the table; tactile_planner.foot; 0 = off)", {"ge": 0.0}),
    "p_inside_max": (1.0, "also drop nodes with P(inside) = Φ(−μ/σ) above this (1 = off)", {"gt": 0.0, "le": 1.0}),
    "min_tip_z_m": (0.015, "3D: lowest tip-centre height (table + table margin + tip radius)"),
    "standoff_m": (0.01, "gap between the tip surface and the candidate at the pre-touch pose", {"gt": 0.0}),
    "tip_radius_m": (0.01, "fingertip radius", {"gt": 0.0}),
    "max_depth_m": (0.03, "how far the finger's skin may go beyond the estimated surface (the commander's approach); an approach the safety box shortens must keep half of it", {"gt": 0.0}),
    "attach_reach": (2, "a candidate's pre-touch point attaches to a free node within this many lattice steps", {"ge": 0}),
    "pocket_entry_m": (0.03, "a pre-touch point inside the path margin (a pocket of the estimate) is entered along "
                       "its approach axis from up to this far out along the normal, keeping only the finger's "
                       "own clearance on that segment (tactile_planner.pocket; 0 = off)", {"ge": 0.0}),
    "pocket_gap_m": (0.002, "skin clearance from the estimated surface on a pocket's entry segment", {"ge": 0.0}),
    "pocket_link_m": (0.06, "2D: free space the estimate cuts off from the rest (a concavity whose mouth it narrows "
                      "below twice the margin) is joined to it by the shortest lattice path up to this long that "
                      "keeps the finger's own clearance, tip_radius_m + pocket_gap_m (tactile_planner.graph; 0 = off)",
                      {"ge": 0.0}),
    "narrow_penalty": (3.0, "2D: paths may also pass where the estimate leaves the finger its own clearance "
                       "(tip_radius_m + pocket_gap_m) but not the path margin (a slot it narrows); each metre of "
                       "such an edge counts this many metres of travel (tactile_planner.graph; 0 = off: the "
                       "margin is a wall, crossed only by pocket_link_m's bridges)", {"ge": 0.0}),
    "min_standoff_m": (0.002, "2D: a pre-touch point without the finger's own room (tip_radius_m + pocket_gap_m; "
                       "a side wall whose slot is narrower than standoff + radius + that room) moves in along its normal, "
                       "down to this standoff (tactile_planner.pocket.closer_pretouch; ≥ standoff_m = off)", {"ge": 0.0}),
    "shaft_clear": (True, "3D: no path, approach or slide puts the finger's rod (vertical, above the tip) into the "
                    "estimated object (docs/planner.md, \"The finger's shaft\"; false: the rod is not considered)"),
    "shaft_length_m": (0.16, "3D: the finger's rod above the tip centre, up to the flange (the commander's "
                       "tip_offset_m)", {"gt": 0.0}),
    "shaft_radius_m": (0.005, "3D: the finger rod's radius; on paths the rod keeps it plus the tip's skin "
                       "clearance (margin_m − tip_radius_m) from the estimated surface", {"gt": 0.0}),
    "shaft_gap_m": (0.002, "3D: on an approach or a slide, where the tip meets the surface, the rod keeps its "
                    "radius plus this from the estimated surface", {"ge": 0.0}),
    "wrist_bands_m": (list(PANDA_WRIST_BANDS_FLAT_M),
                      "3D: the links behind the flange as cylinders about the finger axis, [t0, t1, radius, ...]: "
                      "from t0 to t1 behind the flange, of that radius; a tilted finger keeps them off the table "
                      "and the estimate (tactile_planner.wrist; default: the Panda's link 7 and link 6)"),
    "wrist_gap_m": (0.01, "3D: the clearance a tilted finger's wrist keeps from the estimated object", {"ge": 0.0}),
    "tilt_max_rad": (0.0, "3D pokes: a candidate the vertical finger cannot touch (its rod would enter the estimate, "
                     "or the surface faces down) may be touched with the finger tilted up to this angle from "
                     "vertical, inserted along its own axis (tactile_planner.tilt; docs/planner.md, \"The tilted "
                     "finger\"; 0 = off: the finger stays vertical)", {"ge": 0.0, "le": 1.5708}),
    "tilt_insert_max_m": (0.06, "3D: the longest straight insertion of a tilted finger, from its entry point "
                          "(where it turns) to the pre-touch point", {"gt": 0.0}),
    "tilt_min_flange_z_m": (0.10, "3D: a tilted finger keeps its flange (the rod's far end) at least this high "
                            "above the table at the pre-touch point: the wrist is wider than the rod", {"ge": 0.0}),
    "tilt_turn_s_per_rad": (6.0, "3D: robot time a tilted finger takes to turn, per radian of tilt (each touch turns "
                            "there and back; the commander's plans for the Panda: 4.8–8 s/rad over 30–75°)", {"ge": 0.0}),
    "exclude_radius_m": (0.02, "skip candidates within this distance of targets reported unreachable", {"ge": 0.0}),
    "revisit_radius_m": (0.005, "skip candidates within this distance of a target already chosen (0 = off)", {"ge": 0.0}),
    "fruitless_radius_m": (0.0, "set aside candidates within this distance of the target of a touch after which the "
                           "map's variance there did not drop (the finger sensed elsewhere: tactile_planner.fruitless; "
                           "revisited only when nothing else is left; 0 = off, the default: measured no better, "
                           "docs/benchmarks.md)", {"ge": 0.0}),
    "fruitless_var_ratio": (0.9, "a touch is fruitless when the variance at its target is still at least this "
                            "fraction of what it was when it was chosen", {"gt": 0.0}),
    "min_normal_z": (-0.2, "3D: skip candidates whose outward normal points further down (a vertical "
                           "finger would touch them with its side); -1 = off", {"ge": -1.0, "le": 1.0}),
    "tip_speed_mps": (0.1, "free-space tip speed (motion model)", {"gt": 0.0}),
    "approach_speed_mps": (0.02, "approach/retract speed (motion model)", {"gt": 0.0}),
    "dwell_s": (0.5, "time at contact (motion model)", {"ge": 0.0}),
    "touch": ("poke", "'poke' (approach, retract) or 'slide' (approach, then follow the surface: tactile_planner.slides)",
              {"choices": ("poke", "slide")}),
    "slide_speed_mps": (0.05, "slide: tip speed along the surface (motion model; the servo's step = speed / rate)", {"gt": 0.0}),
    "slide_max_length_m": (0.6, "slide: longest planned slide (a closed contour also ends it: the servo's lap rule)", {"gt": 0.0}),
    "slide_min_length_m": (0.02, "slide: shortest planned slide", {"gt": 0.0}),
    "slide_trace_step_m": (0.003, "slide: step of the path traced along the estimated surface", {"gt": 0.0}),
    "slide_value": ("wrong_surface", "slide: what a metre of slide is worth: 'wrong_surface' (the chance "
                                     "2Φ(−τ/σ) that the surface there is off by more than known_tolerance_m) or "
                                     "'variance' (σ² along it; docs/benchmarks.md)", {"choices": slides.SLIDE_VALUES}),
    "slide_directions_3d": (4, "slide, 3D: start directions per candidate in its tangent plane: 2 = along the "
                            "horizontal band (±z × n), 4 = also up and down the surface, 8 = also the diagonals "
                            "(tactile_planner.slides; 4 measured best, docs/benchmarks.md)", {"choices": (2, 4, 8)}),
    "sequential_step_rad": (0.2, "sequential strategy: minimum angular step around the centroid", {"ge": 0.0}),
    "info_gain_length_scale_m": (0.03, "info_gain: correlation length of the approximate GP update", {"gt": 0.0}),
    "info_gain_noise_var_m2": (1e-6, "info_gain: contact noise variance", {"gt": 0.0}),
    "known_tolerance_m": (0.002, "info_travel: a touch is worth the chance that the surface there is more than "
                                 "this far from the estimate, P(|f| > τ) = 2Φ(−τ/σ)", {"gt": 0.0}),
    "info_travel_per": ("metre", "info_travel: value per 'metre' of travel (+ 2·standoff) or per 'second' of the "
                                 "touch (travel, approach, retract, dwell: robot time)", {"choices": INFO_TRAVEL_PER}),
    "smooth_path": (True, "shortcut the lattice path (never entering the margin)"),
}


#: Parameters of the node only (accepted and ignored by ``TouchPlanner.from_params``).
NODE_PARAMETERS: dict[str, tuple[Any, str]] = {
    "frame_id": ("world", "frame of the goal and path (the map's frame)"),
    "request_timeout_s": (30.0, "answer a request with status 'timeout' if no new enough map/tip pose arrives in time", {"gt": 0.0}),
}


#: The reason a candidate is excluded when its approach would put the vertical rod into the estimate.
SHAFT_REASON = "the finger's shaft would enter the estimate"
FRUITLESS_REASON = "near a touch that changed nothing"
# reasons that set a candidate aside but do not rule it out: revisited when nothing else is left
SOFT_REASONS = ("already targeted", FRUITLESS_REASON)
FOOT_PROBE_LIFT_M = 0.002  # a foot probe's and a table ring's height above the lowest tip height (off the graph's floor)
FOOT_PROBE_SLACK_M = 0.001  # its approach ends this much farther out than the rod's radius and gap need


@dataclass
class PlanResult:
    """Outcome of one decision (world frame, metres; index −1 and NaNs when no goal)."""

    status: str  # 'ok' | 'no_candidates' | 'all_unreachable' | 'bad_map' | 'no_free_space' | 'solver_failed'
    message: str
    index: int = -1
    target_xyz: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    normal_xyz: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    pretouch_xyz: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    path_xyz: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    scores: np.ndarray = field(default_factory=lambda: np.zeros(0))
    travel_costs: np.ndarray = field(default_factory=lambda: np.zeros(0))
    travel_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    time_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    path_length_m: float = float("nan")
    decision_ms: float = 0.0
    start_snapped: bool = False
    n_candidates: int = 0
    n_unreachable: int = 0
    n_excluded: int = 0
    n_nodes: int = 0
    backend_info: dict = field(default_factory=dict)
    slide_direction_xyz: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))  # touch 'slide': unit start tangent
    slide_length_m: float = float("nan")  # touch 'slide': planned length along the surface
    # the finger axis (unit, tip → flange) at each path point; empty: vertical all the way. A tilted touch
    # ends its path with the entry point twice (+z, then the axis: the finger turns there) and the
    # pre-touch point (tactile_planner.tilt).
    path_axes_xyz: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    # the map's variance of f at the target (m²), and the targets of the touches judged fruitless so far
    # (tactile_planner.fruitless): what the next request hands back to a restarted planner
    target_var_m2: float = float("nan")
    fruitless_xyz: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))

    @property
    def finger_axis_xyz(self) -> np.ndarray:
        """The finger axis of the approach (unit, world): +z unless the path ends tilted."""
        return self.path_axes_xyz[-1].copy() if len(self.path_axes_xyz) else EZ.copy()

    @property
    def ok(self) -> bool:
        return self.status == "ok"


class TouchPlanner:
    """Facade: ``plan(map_array, tip_xyz, excluded_targets) -> PlanResult``."""

    def __init__(self, params: Mapping[str, Any], seed: int) -> None:
        params = {k: v for k, v in params.items() if k not in NODE_PARAMETERS}
        unknown = set(params) - set(PARAMETERS)
        if unknown:
            raise ValueError(f"unknown planner parameter(s) {sorted(unknown)}")
        p = {k: entry[0] for k, entry in PARAMETERS.items()}
        p.update(params)
        if p["mode"] not in ("2d", "3d"):
            raise ValueError(f"mode must be '2d' or '3d', got '{p['mode']}'")
        if p["strategy"] not in STRATEGIES:
            raise ValueError(f"strategy must be one of {STRATEGIES}, got '{p['strategy']}'")
        if p["clearance"] not in CLEARANCES:
            raise ValueError(f"clearance must be one of {CLEARANCES}, got '{p['clearance']}'")
        if p["score_form"] not in SCORE_FORMS:
            raise ValueError(f"score_form must be one of {SCORE_FORMS}, got '{p['score_form']}'")
        wrist_bands_m = bands_from_flat(p["wrist_bands_m"], "wrist_bands_m")  # ValueError on a malformed list
        if p["info_travel_per"] not in INFO_TRAVEL_PER:
            raise ValueError(f"info_travel_per must be one of {INFO_TRAVEL_PER}, got '{p['info_travel_per']}'")
        for k in ("margin_m", "standoff_m", "tip_radius_m", "tip_speed_mps", "approach_speed_mps",
                  "info_gain_length_scale_m", "known_tolerance_m"):
            if not float(p[k]) > 0:
                raise ValueError(f"{k} must be positive, got {p[k]}")
        if int(p["lattice_stride"]) < 1:
            raise ValueError("lattice_stride must be ≥ 1")
        if float(p["margin_m"]) >= float(p["standoff_m"]) + float(p["tip_radius_m"]):
            raise ValueError("margin_m must be below standoff_m + tip_radius_m, or no pre-touch point is free")
        self.params = p
        self.wrist_bands_m = wrist_bands_m  # ((t0, t1, radius), ...): the tilted finger's wrist
        self.seed = int(seed)
        self.backend = make_backend(p["backend"], float(p["cost_rate_per_m"]), float(p["max_rate_nats"]),
                                    str(p["solver"]), float(p["cg_rtol"]),
                                    float(p["cg_max_rate_nats"]), str(p["travel_length"]))
        self.strategy_params = StrategyParams(
            alpha=float(p["alpha"]), score_form=str(p["score_form"]),
            sequential_step_rad=float(p["sequential_step_rad"]),
            info_gain_length_scale_m=float(p["info_gain_length_scale_m"]),
            info_gain_noise_var_m2=float(p["info_gain_noise_var_m2"]),
            known_tolerance_m=float(p["known_tolerance_m"]),
            info_travel_per=str(p["info_travel_per"]),
        )
        self.last_graph: FreeSpaceGraph | None = None
        self.last_why: dict[str, np.ndarray] = {}  # of the last candidate set planned on
        #: Targets chosen so far. Touching a place again teaches nothing when the
        #: finger cannot reach it (it lands on the same rim each time), so they
        #: are skipped; ``reset()`` forgets them. They are the planner's only
        #: memory: the k-th decision draws its random numbers from (seed, k).
        self.visited: list[np.ndarray] = []
        #: Targets of touches that changed nothing there (tactile_planner.fruitless), judged from the maps.
        self.fruitless = FruitlessTouches(float(p["fruitless_var_ratio"]), float(p["fruitless_radius_m"]))

    def reset(self) -> None:
        """Forget the chosen targets (a new exploration)."""
        self.visited = []
        self.fruitless.reset()

    @classmethod
    def from_params(cls, params: Mapping[str, Any], seed: int) -> "TouchPlanner":
        """Build from a dict keyed by the node's ROS parameter names (the YAML)."""
        return cls(params, seed)

    # ------------------------------------------------------------------
    def plan(self, map_array: np.ndarray, tip_xyz: np.ndarray,
             excluded_targets: np.ndarray | None = None,
             visited_targets: np.ndarray | None = None, misses_before_contact: int = 0,
             fruitless_targets: np.ndarray | None = None, last_target_var_m2: float | None = None) -> PlanResult:
        """Choose the next touch. Never raises on bad input: the status says why there is no goal.

        ``visited_targets`` ((K, 3), world): the targets chosen before this
        decision, which replace the planner's memory (a restarted planner told
        the run's history decides as the one that lived through it); None:
        what this planner remembers. The chosen target is appended.
        ``misses_before_contact``: how many touches met nothing while none has met the
        object yet (0 after the first contact; ``search_after_misses``).
        ``fruitless_targets`` ((F, 3)) and ``last_target_var_m2``: the rest of that memory, as the
        last answer gave them (``PlanResult.fruitless_xyz``, ``target_var_m2``; tactile_planner.fruitless).
        """
        t0 = time.perf_counter()
        if visited_targets is not None:
            self.visited = [row.copy() for row in np.asarray(visited_targets, dtype=float).reshape(-1, 3)]
        if fruitless_targets is not None or last_target_var_m2 is not None:
            self.fruitless.restore(fruitless_targets, last_target_var_m2, self.visited)
        try:
            res = self._plan(map_array, tip_xyz, excluded_targets, int(misses_before_contact))
        except MapError as exc:
            res = PlanResult("bad_map", f"bad variance map: {exc}")
        except TravelError as exc:
            res = PlanResult("solver_failed", f"travel-cost solve failed: {exc}")
        res.decision_ms = (time.perf_counter() - t0) * 1e3
        res.fruitless_xyz = self.fruitless.targets_xyz()
        return res

    def _plan(self, map_array, tip_xyz, excluded_targets, misses_before_contact: int = 0) -> PlanResult:
        p = self.params
        tip = np.asarray(tip_xyz, float).reshape(-1)
        if tip.shape != (3,) or not np.isfinite(tip).all():
            return PlanResult("bad_tip", f"fingertip position must be 3 finite numbers, got {tip_xyz!r}")
        lattice, cands = parse_variance_map(map_array)
        dim = 2 if p["mode"] == "2d" else 3
        if lattice.dim != dim:
            raise MapError(f"planner mode is {p['mode']} but the map lattice is {lattice.dim}D")
        s = int(p["lattice_stride"])
        if s > 1:
            sl = tuple(slice(None, None, s) for _ in range(dim))
            lattice = type(lattice)(tuple(a[::s] for a in lattice.axes), lattice.mean_m[sl],
                                    lattice.variance_m2[sl], lattice.plane_z_m)
        self.fruitless.note_map(lattice, self.visited)
        res = self._decide(lattice, cands, tip, excluded_targets, misses_before_contact)
        if res.ok:
            res.target_var_m2 = self.fruitless.aimed(len(self.visited) - 1, res.target_xyz, lattice)
        return res

    def _decide(self, lattice, cands, tip, excluded_targets, misses_before_contact: int) -> PlanResult:
        """The decision on a parsed map: a search for a lost object or its support, or the ordinary one."""
        p = self.params
        dim = lattice.dim
        q = float(p["search_quantile"])
        min_z = self._min_tip_z_m(dim)
        k = int(p["search_after_misses"])
        refuted = 0 < k <= misses_before_contact  # the prior, refuted by touches that all met nothing
        if q > 0 and (refuted or not len(cands) and object_lost(lattice, min_z)):  # search for it
            why = f"{misses_before_contact} touches met nothing, none met the object" if refuted else \
                "no estimated surface"
            searched = self._search(lattice, tip, excluded_targets, q, min_z, why, lost=True,
                                    rings_first=True if refuted else None)
            if searched is not None and (searched.ok or not len(cands)):
                return searched
        gap = float(p["support_gap_m"])
        if dim == 3 and gap > 0 and len(cands):
            floating = floating_base(lattice, min_z, gap)
            if floating is not None and (res := self._search_support(lattice, tip, excluded_targets, floating,
                                                                      min_z)) is not None:
                return res
        res = self._plan_with_foot_probes(lattice, cands, tip, excluded_targets, min_z)
        if res.status in ("all_unreachable", "no_candidates") and q > 0:
            # The estimate's surface cannot be touched any more (every candidate blocked, excluded or
            # in a pocket of free space the tip cannot leave), yet the object is somewhere in the
            # workspace: search for it rather than end the run.
            searched = self._search(lattice, tip, excluded_targets, q, min_z,
                                    f"{res.status} on the estimate: {res.message}")
            if searched is not None and searched.ok:
                return searched
        return res

    def _plan_with_foot_probes(self, lattice, cands, tip, excluded_targets, min_z: float) -> PlanResult:
        """The ordinary decision, with the foot probes of the candidates' walls among the candidates
        (``foot_probe_gap_m`` > 0, 3D pokes; tactile_planner.foot): their approach ends with the rod its
        radius and gap outside the wall's line, and the rod is checked down to the approach's end."""
        p = self.params
        gap = float(p["foot_probe_gap_m"])
        found = None
        geometry = TouchGeometry.from_params(p)
        if lattice.dim == 3 and gap > 0 and len(cands) and p["touch"] == "poke":  # a slide starts on the surface
            rod_m = float(p["shaft_radius_m"]) + float(p["shaft_gap_m"])
            end_m = geometry.max_depth_m - geometry.tip_radius_m + rod_m + FOOT_PROBE_SLACK_M
            found = foot_probes(lattice, cands, min_z + FOOT_PROBE_LIFT_M, gap, end_m)
        if found is None:
            return self._plan_on(lattice, cands, tip, excluded_targets, "")
        probes, wall, z_b = found
        m = len(cands)
        both = Candidates(*(np.concatenate([getattr(cands, f), getattr(probes, f)])
                            for f in ("xyz", "normal", "mean_m", "variance_m2")))
        past = np.r_[np.zeros(m), np.full(len(probes), geometry.max_depth_m)]
        res = self._plan_on(lattice, both, tip, excluded_targets, "", rod_past_contact_m=past)
        if res.ok and res.index >= m:
            k = res.index - m
            res.message += (f"; a probe at the foot of the wall of candidate {int(wall[k])} (its estimate ends "
                            f"{z_b[k]:.3f} m up)")
        return res

    def _shaft_graph_params(self, dim: int) -> tuple[float, float]:
        """(length, clearance) of the rod for :func:`build_free_graph`: on paths it keeps its radius plus the
        tip's skin clearance (margin_m − tip_radius_m); (0, 0) in 2D or without a shaft."""
        p = self.params
        if dim != 3 or not bool(p["shaft_clear"]):
            return 0.0, 0.0
        skin = max(float(p["margin_m"]) - float(p["tip_radius_m"]), 0.0)
        return float(p["shaft_length_m"]), float(p["shaft_radius_m"]) + skin

    def _shaft_check(self, graph, tip_radius_m: float):
        """Where the tip meets the surface (approach, slide): a function of (M, 3) tip centres, True where the
        rod above keeps ``shaft_radius_m + shaft_gap_m`` from the estimated surface; None without a shaft."""
        if graph.shaft_field_m is None:
            return None
        need = float(self.params["shaft_radius_m"]) + float(self.params["shaft_gap_m"])
        return lambda x: graph.rod_clearance_m(x, tip_radius_m) >= need  # the rod starts at the tip's top

    def _rod_clear_by_distance(self, graph, seg_xyz: np.ndarray, tip_radius_m: float) -> np.ndarray:
        """(P,) bool for (P, S, 3) tip centres along P approaches: the rod above every one keeps
        ``shaft_radius_m + shaft_gap_m`` from the estimate's zero level set by Euclidean distance (its
        lattice edge crossings; inside: negative). For a foot probe, whose rod ends its radius and gap
        outside a wall's line: μ there reads a few mm less than the distance (|∇μ| < 1 off the data),
        which refused nearly every probe of a wall."""
        p = self.params
        need = float(p["shaft_radius_m"]) + float(p["shaft_gap_m"])
        P, S = seg_xyz.shape[:2]
        rod = rod_points(seg_xyz.reshape(-1, 3), tip_radius_m, graph.shaft_length_m, 0.004)  # (P·S, R, 3)
        d = graph.surface_distance_at(rod.reshape(-1, 3), max_m=need + 1e-3)
        return (d >= need).reshape(P, S, -1).all(axis=(1, 2))

    def _tilted_entries(self, graph, why: dict, valid: np.ndarray, pretouch: np.ndarray, target: np.ndarray,
                        normal: np.ndarray, tip_radius_m: float) -> TiltedEntries | None:
        """Tilted entries (tactile_planner.tilt) for the candidates only the vertical finger rules out (its rod
        or a surface facing down); None when the tilt is off (``tilt_max_rad`` 0, 2D, slides, no shaft)."""
        p = self.params
        tilt = float(p["tilt_max_rad"])
        if tilt <= 0 or graph.shaft_field_m is None or p["touch"] != "poke":
            return None
        finger_only = np.zeros(len(valid), bool)
        for k in (SHAFT_REASON, "facing down"):
            finger_only |= why.get(k, False)
        other, _ = _combine({k: v for k, v in why.items() if k not in (SHAFT_REASON, "facing down")},
                            SOFT_REASONS, len(valid))
        ask = valid & finger_only & ~other
        m = len(valid)
        out = TiltedEntries(np.full((m, 3), np.nan), np.full((m, 3), np.nan), np.full(m, np.nan))
        if ask.any():
            skin = max(float(p["margin_m"]) - tip_radius_m, 0.0)
            wrist = WristCheck.on_lattice(graph.lattice, self.wrist_bands_m,
                                          float(graph.shaft_length_m), self._min_tip_z_m(3) - tip_radius_m,
                                          float(p["wrist_gap_m"]))  # the floor: table + table margin
            got = tilted_entries(graph, pretouch[ask], target[ask] + tip_radius_m * normal[ask], normal[ask],
                                 tip_radius_m, float(p["shaft_radius_m"]) + float(p["shaft_gap_m"]),
                                 float(p["shaft_radius_m"]) + skin, tilt,
                                 replace(TiltSettings(), insert_max_m=float(p["tilt_insert_max_m"]),
                                         min_flange_z_m=float(p["tilt_min_flange_z_m"])),
                                 float(p["min_normal_z"]), wrist)
            out.axis_xyz[ask], out.entry_xyz[ask], out.insert_m[ask] = got.axis_xyz, got.entry_xyz, got.insert_m
        return out

    def _min_tip_z_m(self, dim: int) -> float:
        """The lowest tip-centre height a touch may reach: ``min_tip_z_m`` in 3D, none in 2D (a section)."""
        return float(self.params["min_tip_z_m"]) if dim == 3 else -np.inf

    def _search(self, lattice, tip, excluded_targets, q: float, min_z: float, why: str,
                lost: bool = False, rings_first: bool | None = None) -> PlanResult | None:
        """Search for the object where it is most probable (:func:`~tactile_planner.search.search_map`);
        when that has nothing reachable left and the object is ``lost`` (no estimated surface at all),
        the coverage rings (:func:`~tactile_planner.search.ring_search_map`, nearest ring first; before
        the probability search with ``search_rings_first``). Not
        for a surface the tip cannot touch: the estimate says where the object is. The first plan
        that is ok, else the probability search's answer (None: no search surface at all)."""
        p = self.params
        spacing = float(p["search_ring_spacing_m"])
        geometry = TouchGeometry.from_params(p)

        rings_first = bool(p["search_rings_first"]) if rings_first is None else rings_first
        table = str(p["search_rings_3d"]) == "table"

        def probable() -> PlanResult | None:
            found = search_map(lattice, q, min_z)
            return None if found is None else self._plan_on(
                *found, tip, excluded_targets,
                f"search ({why}; probing the {q:.0%} of the lattice where the object is most probable): ")

        def rings() -> PlanResult | None:
            for radius in ring_radii_m(lattice, geometry.approach_length_m) if lost and spacing > 0 else ():
                # the pre-touch point must be on the lattice too
                ring = ring_search_map(lattice, radius, spacing, min_z, geometry.pretouch_offset_m,
                                       table_z_m=min_z + FOOT_PROBE_LIFT_M if table else None,
                                       cap_above_m=geometry.pretouch_offset_m)
                if ring is not None:
                    res = self._plan_on(*ring, tip, excluded_targets, f"search ({why}; coverage ring "
                                        f"r = {radius:.3f} m around the workspace centre): ")
                    if res.ok:
                        return res
            return None

        if rings_first and (res := rings()) is not None:
            return res
        first = probable()
        if first is not None and first.ok or rings_first:
            return first
        return rings() or first

    def _search_support(self, lattice, tip, excluded_targets, floating, min_z: float) -> PlanResult | None:
        """Probe under an estimate that floats above the table (``floating`` = (footprint centre,
        radius, lowest inside z), :func:`~tactile_planner.search.floating_base`): coverage rings
        round the footprint, the first a pre-touch offset outside it, the next one approach length
        further, their points from the lowest tip height up to a pre-touch offset below the
        estimate, each approached towards the footprint's centre; paths keep off both the ring and
        the estimate. The first plan that is ok, else None (every spot probed: the ordinary
        candidates)."""
        p = self.params
        spacing = float(p["search_ring_spacing_m"])
        if not spacing > 0:
            return None
        geometry = TouchGeometry.from_params(p)
        centre, radius, z_low = floating
        top = z_low - geometry.pretouch_offset_m
        for r in (radius + geometry.pretouch_offset_m, radius + geometry.pretouch_offset_m + geometry.approach_length_m):
            ring = ring_search_map(lattice, r, spacing, min_z, geometry.pretouch_offset_m, centre, top)
            if ring is None:
                continue
            ring_lattice, ring_cands = ring
            ring_lattice = replace(ring_lattice, mean_m=np.minimum(ring_lattice.mean_m, lattice.mean_m))
            res = self._plan_on(ring_lattice, ring_cands, tip, excluded_targets,
                                f"search under the estimate (it floats: its lowest point {z_low:.3f} m up; ring "
                                f"r = {r:.3f} m round its footprint): ")
            if res.ok:
                return res
        return None

    def _plan_on(self, lattice, cands, tip, excluded_targets, searching: str,
                 rod_past_contact_m: np.ndarray | None = None) -> PlanResult:
        """Choose among ``cands`` on ``lattice`` (the estimate's, or the search field's when
        ``searching`` says why): exclusions, free-space graph, travel costs, strategy, path.
        ``rod_past_contact_m`` (per candidate, default 0): how far past the expected contact the
        approach's rod check goes (a foot probe's: to the approach's end; these get no tilted entry)."""
        p = self.params
        dim = lattice.dim
        m = len(cands)
        if m == 0:
            why = ""
            if np.nanmin(lattice.mean_m) > 0:  # misses lifted the whole mean: the prior shape is gone
                why = (": no lattice point is estimated inside the object (the touches so far missed it); "
                       "give gpis_estimator a prior near the object (prior.type 'given', prior.centre_m, "
                       "prior.radius_m)")
            return PlanResult("no_candidates", "the map has no touch candidates" + why)
        normal = cands.normal.copy()
        if dim == 2:
            normal[:, 2] = 0.0
        nlen = np.linalg.norm(normal, axis=1)
        valid = np.isfinite(nlen) & (nlen > 1e-9) & np.isfinite(cands.xyz).all(axis=1) & np.isfinite(cands.variance_m2)
        normal = np.where(valid[:, None], normal / np.where(nlen > 1e-9, nlen, 1.0)[:, None], 0.0)
        target = cands.xyz.copy()
        if dim == 2:
            target[:, 2] = lattice.plane_z_m
            tip = np.array([tip[0], tip[1], lattice.plane_z_m])
        geometry = TouchGeometry.from_params(p)
        pretouch = geometry.pretouch_xyz(target, normal)

        # why a candidate cannot be chosen, by reason (a candidate may have several)
        why: dict[str, np.ndarray] = {}
        if excluded_targets is not None and len(np.asarray(excluded_targets).reshape(-1)):
            ex = np.asarray(excluded_targets, float).reshape(-1, 3)
            d = np.linalg.norm(target[:, None, :dim] - ex[None, :, :dim], axis=2)
            why["near a target reported unreachable"] = np.any(d <= float(p["exclude_radius_m"]), axis=1)
        if self.visited and float(p["revisit_radius_m"]) > 0:
            d = np.linalg.norm(target[:, None, :dim] - np.asarray(self.visited)[None, :, :dim], axis=2)
            near = np.count_nonzero(d <= float(p["revisit_radius_m"]), axis=1)
            why["already targeted"] = near >= 1
            # revisited once already: a third touch there is not made (a flat object's run revisited one
            # target whose path met the object at the same point, a duplicate contact, for 40 touches)
            why["targeted twice already"] = near >= 2
        if self.fruitless.targets:
            why[FRUITLESS_REASON] = self.fruitless.near(target, dim)
        if dim == 3:
            why["facing down"] = normal[:, 2] < float(p["min_normal_z"])
            # the shortest approach worth making (TouchGeometry.min_approach_m), and the commander's inset,
            # would end below the lowest tip height, the floor of the arm's safety box: the commander
            # refuses the touch (without the inset, targets 0.15 mm short were sent and refused)
            probe_z = pretouch[:, 2] - (geometry.min_approach_m + APPROACH_BOX_INSET_M) * normal[:, 2]
            why["touched below the lowest tip height"] = probe_z < float(p["min_tip_z_m"])
        # "already targeted" is a preference, not a wall: when only earlier targets are left
        # they are revisited rather than the run stopped with unconfirmed surface in reach
        revisit = np.zeros(m, bool)
        for k in SOFT_REASONS:
            if k in why:
                revisit |= why[k]
        hard, excluded = _combine(why, SOFT_REASONS, m)

        p_in = float(p["p_inside_max"])
        finger_m = float(p["tip_radius_m"]) + float(p["pocket_gap_m"])
        # 2D: passages the estimate narrows below the margin but not below the finger are paths at a price,
        # or (narrow_penalty 0) free space it cuts off behind a narrowed mouth is bridged (docs/planner.md)
        graph = build_free_graph(lattice, float(p["margin_m"]), float(p["shell_m"]),
                                 float(p["min_tip_z_m"]), p_in if p_in < 1.0 else None, str(p["clearance"]),
                                 finger_m, float(p["pocket_link_m"]) if dim == 2 else 0.0,
                                 float(p["narrow_penalty"]) if dim == 2 else 0.0,
                                 *self._shaft_graph_params(dim))
        self.last_graph = graph
        base = dict(n_candidates=m, n_excluded=int(excluded.sum()), n_nodes=graph.n_nodes)
        if graph.n_nodes == 0:
            return PlanResult("no_free_space", "no lattice node is outside the safety margin", **base)
        if dim == 2:  # a pre-touch point without the finger's room: nearer the surface, if that has it
            tight = valid & (graph.clearance_m(pretouch) < finger_m - 1e-9)
            if tight.any():
                pretouch[tight] = closer_pretouch(graph, target[tight], normal[tight], geometry.pretouch_offset_m,
                                                  geometry.tip_radius_m + float(p["min_standoff_m"]), finger_m)
        shaft_ok = self._shaft_check(graph, geometry.tip_radius_m)
        if shaft_ok is not None:  # the rod above the tip on the approach, down to the expected contact
            t = np.linspace(0.0, 1.0, 6)[None, :, None]
            end = target + geometry.tip_radius_m * normal
            if rod_past_contact_m is not None:
                end = end - rod_past_contact_m[:, None] * normal
            seg = pretouch[:, None, :] + t * (end - pretouch)[:, None, :]
            ask = valid & ~hard  # the others are out already
            blocked = np.zeros(m, bool)
            if ask.any():
                blocked[ask] = ~shaft_ok(seg[ask].reshape(-1, 3)).reshape(seg[ask].shape[:2]).all(axis=1)
            probe = ask & (rod_past_contact_m > 0) if rod_past_contact_m is not None else np.zeros(m, bool)
            if probe.any():  # their rod ends a few mm outside a wall: measured as a distance, not by μ
                blocked[probe] = ~self._rod_clear_by_distance(graph, seg[probe], geometry.tip_radius_m)
            why[SHAFT_REASON] = blocked
            hard |= blocked
            excluded |= blocked
        tilt_ok = valid if rod_past_contact_m is None else valid & (rod_past_contact_m == 0)
        tilted = self._tilted_entries(graph, why, tilt_ok, pretouch, target, normal, geometry.tip_radius_m)
        if tilted is not None and tilted.ok.any():  # these are touched with the finger tilted
            for k in (SHAFT_REASON, "facing down"):
                if k in why:
                    why[k] = why[k] & ~tilted.ok
            hard, excluded = _combine(why, SOFT_REASONS)
        travel_end = pretouch if tilted is None else np.where(tilted.ok[:, None], tilted.entry_xyz, pretouch)
        start = graph.nearest_node(tip)
        # outside the band/shell the tip joins the graph by a straight segment; it is
        # "snapped" when it is inside the margin or that segment is not free
        snapped = not bool(graph.segments_free(tip[None], graph.xyz[start][None])[0])
        lift = np.zeros((0, 3))  # 3D: where a snapped tip goes first, straight up (_lift_until_free)
        if snapped and dim == 3:
            lift_xyz, lift_node = _lift_until_free(graph, tip, finger_m)
            if lift_node >= 0:
                lift, start, snapped = lift_xyz[None], lift_node, False
        lift_m = float(np.linalg.norm(lift[0] - tip)) if len(lift) else 0.0
        term_node, term_len = graph.attach(travel_end, int(p["attach_reach"]))
        if tilted is not None:  # the insertion and the way back out are part of the touch's travel
            term_len = term_len + np.where(tilted.ok, 2.0 * tilted.insert_m, 0.0)
        _, comp = csg.connected_components(graph.length_m, directed=False)
        joined = _join_where_the_candidates_are(graph, comp, lift[0] if len(lift) else tip, start,
                                                term_node[valid & ~hard & (term_node >= 0)], finger_m)
        snapped, start = snapped or joined != start, joined
        why["invalid"] = ~valid
        why["no free pre-touch point"] = term_node < 0
        other = np.where(term_node >= 0, comp[np.maximum(term_node, 0)] != comp[start], False)
        why["in another free-space component than the tip"] = other
        reachable = valid & ~hard & (term_node >= 0) & ~other
        if reachable.any():
            node = np.maximum(term_node, 0)  # from a narrow node the finger's room will do
            # measured by distance: with clearance "mean", μ under-reads it off the data (graph.py), so the
            # pre-touch points of the surface the estimate has not confirmed fell inside the margin
            why["last segment not free"] = reachable & ~graph.segments_free(
                graph.xyz[node], travel_end, clearance_m=graph.node_clearance_m(node),
                euclidean=str(p["clearance"]) == "mean")
            reachable &= ~why["last segment not free"]
        # a pre-touch point in a pocket of the estimate: entered along its approach axis (tactile_planner.pocket)
        entry = np.full((m, 3), np.nan)
        pocket = valid & ~hard & ~reachable & (why["no free pre-touch point"] | why.get(
            "last segment not free", np.zeros(m, bool)))
        # 2D only: in 3D the vertical finger cannot follow (measured: the rig refused such goals until the
        # run ended on "10 unreachable goals in a row", docs/benchmarks.md)
        if dim == 2 and pocket.any() and float(p["pocket_entry_m"]) > 0:
            e_xyz, e_node, e_len = pocket_entries(graph, pretouch[pocket], normal[pocket], float(p["pocket_entry_m"]),
                                                  finger_m, int(p["attach_reach"]), allowed=comp == comp[start])
            got = e_node >= 0
            rows = np.flatnonzero(pocket)[got]
            entry[rows] = e_xyz[got]
            term_node[rows] = e_node[got]
            term_len[rows] = e_len[got] + np.linalg.norm(e_xyz[got] - pretouch[rows], axis=1)
            reachable[rows] = True
            for k in ("no free pre-touch point", "last segment not free", "in another free-space component than the tip"):
                if k in why:
                    why[k] = why[k] & ~reachable
        self.last_why = why  # per candidate, why it cannot be chosen (diagnostics; the message counts them)
        # a search probes each spot once: a miss there is already in the estimate
        revisiting = bool(reachable.any() and not (reachable & ~revisit).any()) and not searching
        if not revisiting:
            reachable &= ~revisit
        else:
            excluded = hard
            base["n_excluded"] = int(excluded.sum())
        base.update(start_snapped=snapped)
        snap_msg = " (tip inside the margin or blocked: snapped to the nearest free node)" if snapped else ""
        if len(lift):
            snap_msg += f" (tip inside the margin or blocked: lifted {lift_m:.3f} m straight up first)"
        if revisiting:
            snap_msg += "; every reachable candidate was targeted before: revisiting"
        if not reachable.any():
            reasons = ", ".join(f"{int(v.sum())} {k}" for k, v in why.items() if v.any())
            return PlanResult("all_unreachable",
                              f"all {m} candidates are unreachable or excluded ({int(excluded.sum())} excluded; "
                              f"{reasons}){snap_msg}",
                              n_unreachable=int(m - excluded.sum()), **base)
        # the motion-model time (travel length) is needed by the time-based scores only
        needs_time = p["strategy"] in ("info_gain", "info_travel") or (
            p["strategy"] == "proposed" and p["score_form"] == "ratio") or p["touch"] == "slide"
        sol = self.backend.solve(graph, start, term_node, term_len, reachable, want_travel_m=needs_time)
        reachable &= np.isfinite(sol.cost)
        if not reachable.any():
            return PlanResult("all_unreachable", f"no candidate has a finite travel cost{snap_msg}",
                              n_unreachable=int(m - excluded.sum()), **base)
        # expected touch: contact after the standoff, the same back (tactile_common.touch_geometry)
        travel_m = sol.travel_m + lift_m
        time_s = MotionModel.from_params(p).touch_time_s(travel_m, float(p["standoff_m"]))
        if tilted is not None:  # a tilted finger turns twice (there and back) about its tip
            tilt_rad = np.arccos(np.clip(np.nan_to_num(tilted.axis_xyz[:, 2], nan=1.0), -1.0, 1.0))
            time_s = time_s + 2.0 * float(p["tilt_turn_s_per_rad"]) * tilt_rad
        ctx = SelectionContext(xyz=target, variance_m2=cands.variance_m2, cost=sol.cost, time_s=time_s,
                               reachable=reachable, tip_xyz=tip, travel_m=travel_m,
                               approach_m=2.0 * float(p["standoff_m"]))
        rng = np.random.default_rng([self.seed, len(self.visited)])  # the k-th decision's draws: (seed, k)
        scores = score_candidates(p["strategy"], ctx, self.strategy_params, rng)
        idx = int(np.argmax(scores))
        slide = None
        if p["touch"] == "slide":  # the slide with the most variance removed per second (tactile_planner.slides)
            tip_ok = None if shaft_ok is None else (
                lambda x, n: shaft_ok(x + geometry.tip_radius_m * n))  # the rod above the sliding tip
            slide = slides.choose_slide(lattice, target, normal, reachable, travel_m, MotionModel.from_params(p),
                                        float(p["standoff_m"]), slides.SlideParams.from_params(p),
                                        self._min_tip_z_m(lattice.dim), tip_ok)
            if slide.index >= 0:
                idx, scores = slide.index, slide.scores.max(axis=1)
        nodes = sol.path_nodes(idx)
        via = entry[idx][None] if np.isfinite(entry[idx]).all() else np.zeros((0, 3))  # a pocket's entry point
        pts = np.vstack([lift, graph.xyz[nodes], via, travel_end[idx][None]])
        if bool(p["smooth_path"]):
            pts = shortcut(graph, pts) if len(lift) else shortcut(graph, np.vstack([tip[None], pts]))[1:]
        pts = np.vstack([tip[None], pts])  # a lift is kept: the graph's field does not see the way up as free
        pts = _dedupe(pts)
        axes = np.zeros((0, 3))
        tilt_msg = ""
        if tilted is not None and tilted.ok[idx]:  # at the entry: turn the finger, then insert it (tactile_planner.tilt)
            a = tilted.axis_xyz[idx]
            axes = np.vstack([np.tile(EZ, (len(pts), 1)), a, a])
            pts = np.vstack([pts, travel_end[idx][None], pretouch[idx][None]])
            tilt_msg = (f"; finger tilted {np.degrees(np.arccos(np.clip(a[2], -1.0, 1.0))):.0f} deg, "
                        f"inserted {tilted.insert_m[idx]:.3f} m")
        n_unreach = int(m - excluded.sum() - (reachable).sum())
        info = dict(getattr(self.backend, "last_info", {}))
        extra = ""
        if info.get("n_beyond_range"):
            extra += f"; {info['n_beyond_range']} costs beyond the solver's range (best-path bound used)"
        if info.get("path_fallback"):
            extra += "; path: shortest-path fallback"
        self.visited.append(target[idx].copy())
        return PlanResult(
            "ok",
            f"{searching}candidate {idx} of {m} ({p['strategy']}, {self.backend.name}); "
            f"path {path_length_m(pts):.3f} m, {n_unreach} unreachable, {int(excluded.sum())} excluded{snap_msg}"
            f"{tilt_msg}{extra}",
            index=idx, target_xyz=target[idx], normal_xyz=normal[idx], pretouch_xyz=pretouch[idx],
            path_xyz=pts, path_axes_xyz=axes, path_length_m=path_length_m(pts), scores=scores, travel_costs=sol.cost, travel_m=travel_m, time_s=time_s,
            n_unreachable=n_unreach, backend_info=info, **base,
            **({} if slide is None or slide.index < 0 else
               dict(slide_direction_xyz=slide.direction_xyz, slide_length_m=slide.length_m)),
        )


def _lift_until_free(graph: FreeSpaceGraph, tip: np.ndarray, room_m: float) -> tuple[np.ndarray, int]:
    """3D: the lowest point straight above ``tip`` (steps of the smallest lattice spacing) from which a
    free segment reaches its nearest free node: (that point, the node), or (tip, −1) when there is none
    below the lattice top or the column may not be taken. Why up: the vertical finger's rod fills the
    column above its tip, so that way is free whatever the estimate says (a tip the estimate puts inside
    the object, e.g. in a hole it does not know). The rod is thinner than the tip's ball, though: a tip
    outside the estimate goes up only where the column keeps the finger's room ``room_m`` from the
    estimated surface (by distance), else it leaves sideways (the snap). Beside a wall the estimate grew
    up past a lip, a lift grazing the wall met the lip's underside, backed off to where it began and
    was planned again: 77 touches on one spot (gen3d-029, docs/benchmarks.md)."""
    lat = graph.lattice
    top = float(lat.axes[2][-1])
    h = float(np.min(lat.spacing_m))
    z = np.arange(float(tip[2]) + h, top + 0.5 * h, h)
    column = np.column_stack([np.full_like(z, tip[0]), np.full_like(z, tip[1]), z])
    ok = graph.clearance_m(column) >= graph.margin_m  # the clearance of the column in one pass
    # the tip's and the column's distances in one query (beyond the room they read ±inf, signed)
    d = graph.surface_distance_at(np.vstack([np.asarray(tip, dtype=float)[None], column]), max_m=room_m + 1e-3)
    if d[0] >= 0.0:  # the tip is outside the estimate: the way up to each point keeps the finger's room
        ok &= np.minimum.accumulate(np.concatenate([[np.inf], d[1:-1]])) >= room_m - 1e-9
    for q in column[ok]:
        node = graph.nearest_node(q)
        if node >= 0 and bool(graph.segments_free(q[None], graph.xyz[node][None])[0]):
            return q, node
    return np.asarray(tip, dtype=float), -1


def _join_where_the_candidates_are(graph: FreeSpaceGraph, comp: np.ndarray, tip: np.ndarray, nearest: int,
                                   open_nodes: np.ndarray, room_m: float) -> int:
    """The tip joins the graph by a straight segment, at its nearest free node. When that node's component
    holds none of the open candidates' nodes (``open_nodes``), at the nearest node of the component holding
    the most whose straight segment keeps ``room_m`` (or the tip's own distance, if less) from the estimated
    surface by distance (a snap; never through the estimate into a closed cavity). A tip 4 cm out in free
    space beyond the shell, nearest to a lone node (a component of one), had every candidate "in another
    free-space component" and the run ended (gen3d-018, docs/benchmarks.md "The last segment by distance")."""
    if not len(open_nodes) or (comp[open_nodes] == comp[nearest]).any():
        return nearest
    count = np.bincount(comp[open_nodes])
    need = min(room_m, float(graph.surface_distance_at(tip[None])[0])) - 1e-9
    for c in np.argsort(-count, kind="stable")[: int((count > 0).sum())]:
        members = np.flatnonzero(comp == c)
        node = int(members[np.argmin(np.sum((graph.xyz[members] - tip) ** 2, axis=1))])
        if graph.segments_free(tip[None], graph.xyz[node][None], clearance_m=need, euclidean=True)[0]:
            return node
    return nearest


def _combine(why: dict, soft: tuple, m: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(hard, excluded) over the candidates: any reason not in ``soft``, any reason at all."""
    n = m if m is not None else len(next(iter(why.values())))
    hard, excluded = np.zeros(n, bool), np.zeros(n, bool)
    for k, mask in why.items():
        excluded |= mask
        if k not in soft:
            hard |= mask
    return hard, excluded


def _dedupe(pts: np.ndarray) -> np.ndarray:
    keep = np.ones(len(pts), bool)
    keep[1:] = np.linalg.norm(np.diff(pts, axis=0), axis=1) > 1e-12
    return pts[keep]


def load_params(yaml_path: str, node_name: str = "soc_planner") -> dict:
    """The parameters of ``node_name`` in a ROS parameter file (its section and
    ``/**``), numbers read as ROS reads them (``1e-12`` is a float)."""
    from pathlib import Path

    from tactile_common.params_file import node_params

    params = node_params([Path(yaml_path)], node_name)
    if not params:
        raise ValueError(f"{yaml_path} has no '{node_name}: ros__parameters:' section")
    return params
