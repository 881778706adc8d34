"""Touch selection strategies behind one interface: ``select(ctx, rng) -> scores``.

The candidate with the highest score among the reachable ones is chosen (ties:
the lowest index). Every strategy receives the planner's seeded
``numpy.random.Generator``.

- ``proposed`` (Matsubara & Shibata 2017): trade-off uncertainty vs travel.
  ``score_form``:
    * ``normalized`` (default): α·σ²/max σ² − C/max C over the reachable
      candidates. Scale-invariant per decision: σ² shrinks by orders of
      magnitude as contacts accumulate, and a fixed α in the paper's form
      drifts towards "nearest" (DESIGN §5).
    * ``additive``: the paper's α·σ² − C (σ² in m², C in backend units).
    * ``ratio``: σ² / time (variance per second of touch).
  α → ∞ gives ``uncertainty``; α → 0 gives the nearest candidate.
- ``uncertainty`` (Björkman et al.): argmax σ².
- ``random``: uniform over the reachable candidates.
- ``sequential``: passive sweep: the next candidate counter-clockwise (about
  world +z through the centroid of the candidates) from the fingertip's angle,
  at least ``sequential_step_rad`` further.
- ``info_gain`` (ours): expected reduction of the summed posterior variance
  over the candidate set per second of touch. The posterior covariance is
  approximated as cov(m, c) ≈ ρ(|m − c|)·σ_m·σ_c with a squared-exponential
  correlation ρ(r) = exp(−r²/2ℓ²) (ℓ = ``info_gain_length_scale_m``); a contact
  at c with noise σ_n² reduces Σ_m σ_m² by σ_c²/(σ_c² + σ_n²)·Σ_m ρ²σ_m². Time
  = travel/tip speed + 2·standoff/approach speed + dwell.
- ``info_travel`` (ours, the default): the wrong surface a touch settles per
  metre of travel. w = P(|f| > τ) = 2Φ(−τ/σ) is the chance that the surface
  at a candidate lies more than τ = ``known_tolerance_m`` from the estimate;
  value(c) = w_c·Σ_m exp(−|m − c|²/ℓ²)·w_m; score = value / (travel_m +
  2·standoff) (``info_travel_per: metre``) or value / time of the touch
  (``second``: travel/tip speed + approach and retract + dwell, the robot time
  the benchmark also reports). w saturates where σ ≫ τ and vanishes where σ ≪ τ: the value
  does not span the orders of magnitude of σ², and a touch where the shape is
  known within τ is worth ≈ 0 however near the finger is.
"""


from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import ndtr

#: The one list of strategy names (the planner, the node, the benchmark and the launcher read it here).
STRATEGY_NAMES = ("proposed", "uncertainty", "random", "sequential", "info_gain", "info_travel")
STRATEGIES = STRATEGY_NAMES
SCORE_FORMS = ("normalized", "additive", "ratio")
#: What ``info_travel`` divides its value by: the touch's travel (m) or its robot time (s).
INFO_TRAVEL_PER = ("metre", "second")


@dataclass
class SelectionContext:
    """What a strategy sees for one decision (world frame; unreachable candidates have inf cost)."""

    xyz: np.ndarray  # (M, 3) candidate positions (m)
    variance_m2: np.ndarray  # (M,)
    cost: np.ndarray  # (M,) backend travel cost (inf = unreachable)
    time_s: np.ndarray  # (M,) time of the touch (travel + approach + retract + dwell)
    reachable: np.ndarray  # (M,) bool
    tip_xyz: np.ndarray  # (3,)
    travel_m: np.ndarray | None = None  # (M,) expected path length to the pre-touch point (m)
    approach_m: float = 0.02  # approach + retract of a touch that meets the estimate (m)


@dataclass
class StrategyParams:
    alpha: float = 1.0
    score_form: str = "normalized"
    sequential_step_rad: float = 0.2
    info_gain_length_scale_m: float = 0.03
    info_gain_noise_var_m2: float = 1e-6
    known_tolerance_m: float = 0.002
    info_travel_per: str = "metre"


def _norm(v: np.ndarray, mask: np.ndarray) -> np.ndarray:
    m = float(np.max(np.abs(v[mask]))) if mask.any() else 0.0
    return v / m if m > 0 else np.zeros_like(v)


def _sqdist(xyz: np.ndarray) -> np.ndarray:
    return np.sum((xyz[:, None, :] - xyz[None, :, :]) ** 2, axis=2)


def wrong_probability(var_m2: np.ndarray, tolerance_m: float) -> np.ndarray:
    """P(|f| > τ) = 2Φ(−τ/σ) at a point of the estimated surface (μ = 0, f ~ N(0, σ²)): the
    chance that the true surface lies more than τ away there (f ≈ signed distance)."""
    sd = np.sqrt(np.maximum(var_m2, 1e-300))
    return 2.0 * ndtr(-tolerance_m / sd)


def wrong_surface_corrected(xyz: np.ndarray, var_m2: np.ndarray, tolerance_m: float,
                            length_scale_m: float) -> np.ndarray:
    """Value of a touch at each candidate c: w_c·Σ_m ρ(|m − c|)²·w_m, w = P(|f| > τ)
    (:func:`wrong_probability`), ρ² = exp(−r²/ℓ²): about how many candidates that may be
    wrong by more than τ a contact at c settles. w saturates at 1 where σ ≫ τ and tends to
    0 where σ ≪ τ, so a touch where the surface is already known within τ is worth ~0 however
    near it is, and the value no longer spans the orders of magnitude of σ². O(M²)."""
    w = wrong_probability(var_m2, tolerance_m)
    return w * (np.exp(-_sqdist(xyz) / length_scale_m**2) @ w)


def variance_reduction_m2(xyz: np.ndarray, var_m2: np.ndarray, length_scale_m: float,
                          noise_var_m2: float) -> np.ndarray:
    """Expected reduction of Σ_m σ_m² over the candidates by one contact at each candidate c:
    σ_c²/(σ_c² + σ_n²)·Σ_m ρ(|m − c|)²σ_m², ρ(r) = exp(−r²/2ℓ²) (the approximate covariance
    cov(m, c) ≈ ρσ_mσ_c). O(M²) memory and time."""
    rho2 = np.exp(-_sqdist(xyz) / length_scale_m**2)  # ρ² = exp(−r²/ℓ²)
    return var_m2 / (var_m2 + noise_var_m2) * (rho2 @ var_m2)


def score_candidates(name: str, ctx: SelectionContext, params: StrategyParams,
                     rng: np.random.Generator) -> np.ndarray:
    """Scores (M,), −inf for unreachable candidates."""
    ok = ctx.reachable & np.isfinite(ctx.cost)
    var = np.maximum(ctx.variance_m2, 0.0)
    if name == "proposed":
        if params.score_form == "normalized":
            s = params.alpha * _norm(var, ok) - _norm(np.where(ok, ctx.cost, 0.0), ok)
        elif params.score_form == "additive":
            s = params.alpha * var - ctx.cost
        elif params.score_form == "ratio":
            s = var / np.maximum(ctx.time_s, 1e-9)
        else:
            raise ValueError(f"score_form must be one of {SCORE_FORMS}, got '{params.score_form}'")
    elif name == "uncertainty":
        s = var.copy()
    elif name == "random":
        s = rng.random(len(var))
    elif name == "sequential":
        c = ctx.xyz[ok].mean(axis=0) if ok.any() else np.zeros(3)
        ang = np.arctan2(ctx.xyz[:, 1] - c[1], ctx.xyz[:, 0] - c[0])
        tip = np.arctan2(ctx.tip_xyz[1] - c[1], ctx.tip_xyz[0] - c[0])
        ahead = np.mod(ang - tip - params.sequential_step_rad, 2 * np.pi)
        s = -ahead
    elif name == "info_gain":
        gain = variance_reduction_m2(ctx.xyz, var, params.info_gain_length_scale_m, params.info_gain_noise_var_m2)
        s = gain / np.maximum(ctx.time_s, 1e-9)
    elif name == "info_travel":
        if ctx.travel_m is None:
            raise ValueError("info_travel needs the travel length of every candidate (travel_m)")
        gain = wrong_surface_corrected(ctx.xyz, var, params.known_tolerance_m, params.info_gain_length_scale_m)
        if params.info_travel_per == "second":
            s = gain / np.maximum(np.where(ok, ctx.time_s, np.inf), 1e-9)
        elif params.info_travel_per == "metre":
            s = gain / np.maximum(np.where(ok, ctx.travel_m, np.inf) + ctx.approach_m, 1e-9)
        else:
            raise ValueError(f"info_travel_per must be one of {INFO_TRAVEL_PER}, got '{params.info_travel_per}'")
    else:
        raise ValueError(f"strategy must be one of {STRATEGIES}, got '{name}'")
    return np.where(ok, s, -np.inf)
