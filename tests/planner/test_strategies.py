"""Selection strategies: uncertainty = argmax σ², proposed limits, seeded random, sweep, info gain."""

import numpy as np
import pytest

from tactile_planner.strategies import SelectionContext, StrategyParams, score_candidates


def context(seed=0, m=30):
    rng = np.random.default_rng(seed)
    t = rng.uniform(0, 2 * np.pi, m)
    xyz = np.stack([0.5 + 0.05 * np.cos(t), 0.05 * np.sin(t), np.full(m, 0.06)], axis=1)
    var = 10 ** rng.uniform(-6, -3, m)
    cost = rng.uniform(1.0, 50.0, m)
    reach = np.ones(m, bool)
    reach[:3] = False
    cost[:3] = np.inf
    return SelectionContext(xyz=xyz, variance_m2=var, cost=cost, time_s=cost / 10 + 1.5, reachable=reach,
                            tip_xyz=np.array([0.4, 0.0, 0.06]))


def pick(name, ctx, seed=0, **kw):
    return int(np.argmax(score_candidates(name, ctx, StrategyParams(**kw), np.random.default_rng(seed))))


@pytest.mark.parametrize("seed", range(5))
def test_uncertainty_is_argmax_variance_among_reachable(seed):
    ctx = context(seed)
    ctx.variance_m2[0] = 1.0  # unreachable, must not win
    want = int(np.argmax(np.where(ctx.reachable, ctx.variance_m2, -1)))
    assert pick("uncertainty", ctx) == want


@pytest.mark.parametrize("form", ["normalized", "additive"])
@pytest.mark.parametrize("seed", range(5))
def test_proposed_limits(form, seed):
    ctx = context(seed)
    nearest = int(np.argmin(ctx.cost))
    most_uncertain = pick("uncertainty", ctx)
    assert pick("proposed", ctx, alpha=1e12, score_form=form) == most_uncertain
    assert pick("proposed", ctx, alpha=1e-12, score_form=form) == nearest


def test_normalized_form_is_scale_invariant():
    ctx = context(3)
    a = pick("proposed", ctx, alpha=1.0)
    ctx.variance_m2 *= 1e-4  # the posterior shrank everywhere: the decision must not change
    ctx.cost *= 7.0
    assert pick("proposed", ctx, alpha=1.0) == a


def test_ratio_form_is_variance_per_second():
    ctx = context(4)
    ok = ctx.reachable
    want = int(np.argmax(np.where(ok, ctx.variance_m2 / ctx.time_s, -np.inf)))
    assert pick("proposed", ctx, score_form="ratio") == want


def test_random_is_seeded_and_uniform_over_reachable():
    ctx = context(5)
    a = [pick("random", ctx, seed=s) for s in range(200)]
    assert a == [pick("random", ctx, seed=s) for s in range(200)]
    assert min(a) >= 3  # never an unreachable one
    assert len(set(a)) > 20


def test_sequential_sweeps_counter_clockwise_from_the_tip():
    m = 12
    t = np.arange(m) * 2 * np.pi / m
    xyz = np.stack([0.5 + 0.05 * np.cos(t), 0.05 * np.sin(t), np.zeros(m)], axis=1)
    ctx = SelectionContext(xyz=xyz, variance_m2=np.ones(m), cost=np.ones(m), time_s=np.ones(m),
                           reachable=np.ones(m, bool), tip_xyz=np.array([0.6, 0.001, 0.0]))  # angle ≈ 0
    order = []
    for _ in range(m):
        i = pick("sequential", ctx, sequential_step_rad=0.1)
        order.append(i)
        ctx.tip_xyz = xyz[i] * 1.0
    assert order == list(range(1, m)) + [0]


def test_info_gain_matches_the_written_out_formula():
    ctx = context(6, m=10)
    ell, noise = 0.03, 1e-6
    want = np.full(10, -np.inf)
    for c in range(10):  # independent: explicit sums
        if not ctx.reachable[c]:
            continue
        s = sum(np.exp(-np.sum((ctx.xyz[m] - ctx.xyz[c]) ** 2) / ell**2) * ctx.variance_m2[m] for m in range(10))
        want[c] = ctx.variance_m2[c] / (ctx.variance_m2[c] + noise) * s / ctx.time_s[c]
    got = score_candidates("info_gain", ctx, StrategyParams(info_gain_length_scale_m=ell,
                                                            info_gain_noise_var_m2=noise), np.random.default_rng(0))
    np.testing.assert_allclose(got[3:], want[3:], rtol=1e-12)
    assert np.all(np.isneginf(got[:3]))


def test_unknown_strategy_is_a_clear_error():
    with pytest.raises(ValueError, match="strategy must be one of"):
        score_candidates("nearest", context(), StrategyParams(), np.random.default_rng(0))


@pytest.mark.parametrize("per", ["metre", "second"])
def test_info_travel_is_wrong_surface_settled_per_metre_or_second_written_out(per):
    from math import erfc, exp, sqrt

    ctx = context(6)
    ctx.travel_m = ctx.cost / 100.0
    ctx.approach_m = 0.02
    tau, ell = 0.002, 0.03
    w = [erfc(tau / sqrt(v) / sqrt(2)) for v in ctx.variance_m2]  # 2Φ(−τ/σ)
    want = np.full(len(w), -np.inf)
    for c in range(len(w)):
        if not ctx.reachable[c]:
            continue
        settled = sum(exp(-float(np.sum((ctx.xyz[m] - ctx.xyz[c]) ** 2)) / ell**2) * w[m] for m in range(len(w)))
        cost = ctx.travel_m[c] + ctx.approach_m if per == "metre" else ctx.time_s[c]
        want[c] = w[c] * settled / cost
    got = score_candidates("info_travel", ctx, StrategyParams(known_tolerance_m=tau, info_gain_length_scale_m=ell,
                                                              info_travel_per=per), np.random.default_rng(0))
    np.testing.assert_allclose(got[ctx.reachable], want[ctx.reachable], rtol=1e-10)
    assert np.all(np.isneginf(got[~ctx.reachable]))


def test_info_travel_per_second_pays_a_touch_its_fixed_time():
    """A touch's approach, retract and dwell cost seconds however near it is: per second, a far
    candidate settling four times the wrong surface beats a near one; per metre the near one wins."""
    from tactile_common.touch_geometry import MotionModel

    ctx = context(8, m=2)
    ctx.xyz = np.array([[0.50, 0.0, 0.06], [0.70, 0.0, 0.06]])  # 20 cm apart: no shared surface
    ctx.reachable, ctx.cost = np.ones(2, bool), np.ones(2)
    ctx.travel_m, ctx.approach_m = np.array([0.01, 0.20]), 0.02
    motion = MotionModel(tip_speed_mps=0.1, approach_speed_mps=0.02, dwell_s=0.5)
    ctx.time_s = np.array([motion.touch_time_s(t, 0.01) for t in ctx.travel_m])  # 1.6 s and 3.5 s
    tau = 0.002
    # w = 2Φ(−τ/σ): 1/2 near (σ = τ/0.67449), 1 far (σ ≫ τ); value w_c·Σ ρ²w_m: 1/4 and 1.
    # Per metre 0.25/0.03 > 1/0.22; per second 0.25/1.6 s < 1/3.5 s.
    ctx.variance_m2 = np.array([(tau / 0.674490) ** 2, 1.0])
    assert pick("info_travel", ctx, known_tolerance_m=tau, info_travel_per="metre") == 0
    assert pick("info_travel", ctx, known_tolerance_m=tau, info_travel_per="second") == 1


def test_unknown_info_travel_per_is_a_clear_error():
    ctx = context(6)
    ctx.travel_m = ctx.cost / 100.0
    with pytest.raises(ValueError, match="info_travel_per must be one of"):
        score_candidates("info_travel", ctx, StrategyParams(info_travel_per="furlong"), np.random.default_rng(0))


def test_info_travel_prefers_far_unknown_surface_to_near_known_surface():
    ctx = context(7)
    ctx.travel_m = np.full(len(ctx.cost), 0.3)
    ctx.variance_m2[:] = (0.0005) ** 2  # known within 0.5 mm everywhere ...
    near = 10
    ctx.travel_m[near] = 0.0  # ... and the finger is right next to candidate 10
    far = 20
    ctx.variance_m2[far] = (0.004) ** 2  # one place where the surface may be 4 mm off
    assert pick("info_travel", ctx) == far
