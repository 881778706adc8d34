"""The soak analysis (ROS-free): per-touch curves from samples, line fits, growth verdicts."""

import numpy as np
import pytest
from scipy import stats

from tactile_bringup.soak_analysis import fit_line, format_table, judge_growth, per_touch, table_every


def test_per_touch_takes_the_peak_between_touch_ends_and_carries_gaps_forward():
    touches = [0, 0, 1, 1, 1, 3, 3, 4, 9]  # no sample while 2 touches were done; 9 is beyond the run
    values = [500, 600, 10, 12, 11, 30, np.nan, 40, 99]
    got = per_touch(touches, values, 5)
    np.testing.assert_array_equal(got, [12, 12, 30, 40, 40])  # start-up (0) and touch 9 not used


def test_per_touch_before_the_first_sample_is_nan_and_shapes_are_checked():
    got = per_touch([3, 3], [1.0, 2.0], 4)
    assert np.isnan(got[:2]).all() and list(got[2:]) == [2.0, 2.0]
    with pytest.raises(ValueError, match="one length"):
        per_touch([1, 2], [1.0], 3)
    with pytest.raises(ValueError, match="n_touches"):
        per_touch([1], [1.0], 0)


def test_fit_line_matches_scipy_linregress():
    rng = np.random.default_rng(0)
    x = np.arange(1, 101, dtype=float)
    y = 0.7 * x + 12 + rng.normal(0, 2.0, x.size)
    slope, intercept, r2 = fit_line(x, y)
    ref = stats.linregress(x, y)
    assert slope == pytest.approx(ref.slope, rel=1e-10)
    assert intercept == pytest.approx(ref.intercept, rel=1e-10)
    assert r2 == pytest.approx(ref.rvalue ** 2, rel=1e-10)
    assert np.isnan(fit_line([1, 2, 3], [5, 5, 5])[2])  # nothing to explain


def test_flat_noisy_memory_with_an_allocator_step_is_bounded():
    rng = np.random.default_rng(1)
    y = 150 + rng.normal(0, 0.5, 200)
    y[:3] = [90, 120, 140]  # start-up allocations, before the warm-up
    y[80:] += 6.0  # one arena step of 6 MB
    g = judge_growth(y, warmup=4, bound=20.0)
    assert g.verdict == "bounded" and g.first == 4 and g.last == 200
    assert 5.0 < g.peak_rise < 10.0 and 0 < g.growth < 10.0


def test_a_noisy_flat_time_with_spikes_is_bounded_and_the_end_can_be_left_out():
    rng = np.random.default_rng(3)
    y = 50 + rng.normal(0, 10, 200)
    y[[30, 90, 150]] = 250  # three slow decisions
    y[-1] = 5000  # the run's end (report, figure) in the last touch's interval
    g = judge_growth(y, warmup=20, bound=20.0, last=199)
    assert g.verdict == "bounded" and g.last == 199 and g.peak_rise > 150
    assert judge_growth(y, warmup=20, bound=20.0).verdict != "bounded"


def test_a_linear_leak_is_linear_with_its_slope():
    rng = np.random.default_rng(2)
    x = np.arange(1, 201)
    y = 100 + 0.7 * x + rng.normal(0, 0.3, x.size)  # 0.7 MB per touch, like an MCAP
    g = judge_growth(y, warmup=10, bound=0.5)
    assert g.verdict == "linear"
    assert g.slope == pytest.approx(0.7, abs=0.01) and g.r2 > 0.99


def test_quadratic_growth_is_superlinear_and_a_slowing_one_is_not():
    x = np.arange(1, 201, dtype=float)
    assert judge_growth(20 + 0.002 * x ** 2, warmup=10, bound=5.0).verdict == "superlinear"  # O(n²) state
    concave = judge_growth(20 + 30 * np.log(x), warmup=10, bound=5.0)
    assert concave.verdict == "linear" and concave.curvature < 0  # at most linear


def test_judge_growth_skips_nan_and_refuses_too_few_points_or_bad_arguments():
    y = np.array([1, 2, np.nan, 4, 5, np.nan, 7], dtype=float)
    g = judge_growth(y, warmup=1, bound=100.0)
    assert g.verdict == "bounded" and g.slope == pytest.approx(1.0)
    with pytest.raises(ValueError, match="at least 3"):
        judge_growth([1.0, 2.0, np.nan, np.nan], warmup=2, bound=1.0)
    with pytest.raises(ValueError, match="warmup"):
        judge_growth(y, warmup=0, bound=1.0)
    with pytest.raises(ValueError, match="bound"):
        judge_growth(y, warmup=1, bound=-1.0)


def test_table_every_ten_touches_means_times_and_samples_the_rest():
    n = 25
    curves = {"mcap_mb": np.arange(1, n + 1) * 0.5, "decision_ms": np.arange(1, n + 1, dtype=float)}
    rows = table_every(curves, 10)
    assert [r["touch"] for r in rows] == [10, 20, 25]
    assert [r["mcap_mb"] for r in rows] == [5.0, 10.0, 12.5]
    assert [r["decision_ms"] for r in rows] == [5.5, 15.5, 23.0]  # mean of touches 1-10, 11-20, 21-25
    text = format_table(rows)
    assert text.splitlines()[0].split() == ["touch", "mcap_mb", "decision_ms"] and len(text.splitlines()) == 4


def test_held_contacts_subtracts_the_estimators_duplicates_by_log_time(tmp_path):
    from tactile_bringup.soak import held_contacts

    logs = tmp_path / "logs"
    logs.mkdir()
    (logs / "explorer.log").write_text(
        "[INFO] [100.5] [explorer]: exploring 'ellipse'\n"
        + "".join(f"[INFO] [{101 + k}.0] [explorer]: touch   {k + 1}/4  contact\n" for k in range(4)))
    (logs / "gpis_estimator.log").write_text(
        "[WARN] [101.5] [gpis_estimator]: observation rejected (1 so far): duplicate: 0.1 mm from an earlier one\n"
        "[WARN] [103.5] [gpis_estimator]: observation rejected (2 so far): bad cloud: NaN\n"
        "[WARN] [103.9] [gpis_estimator]: observation rejected (3 so far): duplicate: 0.2 mm from an earlier one\n")
    outcomes = ["contact", "contact", "free_space", "contact"]
    # a touch is logged after its map, so a rejection of its contact comes before its line
    assert held_contacts(tmp_path, outcomes) == [1, 1, 1, 1]  # 1, 2-1, 2-1 (no contact), 3-2
