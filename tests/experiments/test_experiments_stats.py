"""Statistics of the trial runner against scipy and hand-computed values."""

import math

import numpy as np
import pytest
from scipy import stats

from embodied_adhoc.experiments.stats import (
    identify_step,
    mean_curve,
    normalised_entropies,
    pairwise_welch,
    summarise_sample,
    welch_test,
)


def test_confidence_interval_by_hand():
    summary = summarise_sample([1, 2, 3, 4, 5])
    assert summary.n == 5 and summary.mean == 3.0
    assert summary.sd == pytest.approx(math.sqrt(2.5))
    # t_{0.975, 4} = 2.776445105; half width = t * sd / sqrt(n)
    half = 2.776445105 * math.sqrt(2.5) / math.sqrt(5)
    assert summary.ci_low == pytest.approx(3.0 - half, abs=1e-8)
    assert summary.ci_high == pytest.approx(3.0 + half, abs=1e-8)


def test_confidence_interval_matches_scipy():
    values = np.random.default_rng(0).normal(12.0, 2.0, size=32)
    summary = summarise_sample(values)
    low, high = stats.t.interval(0.95, len(values) - 1, loc=values.mean(), scale=stats.sem(values))
    assert (summary.ci_low, summary.ci_high) == pytest.approx((low, high))


def test_degenerate_samples():
    assert math.isnan(summarise_sample([]).mean)
    single = summarise_sample([7])
    assert single.mean == 7 and math.isnan(single.sd) and math.isnan(single.ci_low)
    constant = summarise_sample([11, 11, 11])
    assert constant.ci_low == constant.ci_high == 11


def test_welch_matches_scipy_and_hand_value():
    a = [12, 13, 11, 14, 12, 15]
    b = [20, 25, 18, 30, 22]
    t, p = welch_test(a, b)
    reference = stats.ttest_ind(a, b, equal_var=False)
    assert (t, p) == pytest.approx((reference.statistic, reference.pvalue))
    # by hand: t = (mean_a - mean_b) / sqrt(var_a / n_a + var_b / n_b)
    va, vb = np.var(a, ddof=1), np.var(b, ddof=1)
    assert t == pytest.approx((np.mean(a) - np.mean(b)) / math.sqrt(va / 6 + vb / 5))


def test_welch_undefined_cases_are_nan():
    assert all(math.isnan(v) for v in welch_test([3, 3, 3], [3, 3, 3]))
    assert all(math.isnan(v) for v in welch_test([1], [2, 3]))
    t, p = welch_test([11, 11, 11, 11], [12, 14, 13, 15])  # one constant side is fine
    assert t < 0 and 0 < p < 0.05


def test_pairwise_welch_covers_every_pair_in_order():
    tests = pairwise_welch({"a": [1, 2, 3], "b": [2, 3, 4], "c": [5, 6, 8]}, "steps")
    assert [(t.first, t.second) for t in tests] == [("a", "b"), ("a", "c"), ("b", "c")]


def test_normalised_entropy():
    assert normalised_entropies(np.array([0.5, 0.5])) == pytest.approx([1.0])
    assert normalised_entropies(np.array([1.0, 0.0])) == pytest.approx([0.0])
    assert normalised_entropies(np.array([0.25] * 4)) == pytest.approx([1.0])
    stack = normalised_entropies(np.array([[0.5, 0.5], [0.9, 0.1]]))
    expected = -(0.9 * math.log(0.9) + 0.1 * math.log(0.1)) / math.log(2)
    assert stack == pytest.approx([1.0, expected])


@pytest.mark.parametrize(
    ("trace", "true_task", "expected"),
    [
        ([[0.5, 0.5], [0.4, 0.6], [0.2, 0.8]], 1, 1),  # leads from step 1 on
        ([[0.5, 0.5], [0.6, 0.4], [0.4, 0.6], [0.3, 0.7]], 1, 2),  # lost the lead at step 1
        ([[0.5, 0.5], [0.3, 0.7], [0.6, 0.4], [0.2, 0.8]], 1, 3),  # led, lost it, regained it
        ([[0.5, 0.5], [0.3, 0.7], [0.6, 0.4]], 1, None),  # wrong at the end: never identified
        ([[0.5, 0.5], [0.5, 0.5]], 0, None),  # a tie is not identification
        ([[1.0, 0.0], [1.0, 0.0]], 0, 0),  # known from the start
        ([[0.2, 0.3, 0.5], [0.2, 0.5, 0.3], [0.1, 0.6, 0.3]], 1, 1),
    ],
)
def test_identify_step_metric_2(trace, true_task, expected):
    assert identify_step(np.array(trace), true_task) == expected


def test_mean_curve_holds_last_value_of_finished_trials():
    curve = mean_curve([[1.0, 0.5], [1.0, 0.8, 0.2, 0.0]])
    assert list(curve["step"]) == [0, 1, 2, 3]
    assert curve["mean"] == pytest.approx([1.0, 0.65, 0.35, 0.25])
    assert curve["low"][0] == pytest.approx(1.0) and curve["high"][0] == pytest.approx(1.0)
    assert np.all(curve["low"] <= curve["mean"]) and np.all(curve["mean"] <= curve["high"])
