"""Study statistics on hand-made numbers: spread over seeds, paired differences, the exact sign-flip
test, the t-interval, the minimal detectable effect, Holm, and a simulation with no true effect."""

import itertools
import math

import numpy as np
import pytest

from posecons.metrics.stats import (
    ALPHA,
    MIN_SEEDS,
    compare,
    holm,
    mean_std,
    minimal_detectable_effect,
    paired_differences,
    sign_flip_p,
    signs,
    summarise_differences,
    t_interval,
)


def test_mean_std_is_the_sample_std_of_the_finite_values():
    assert mean_std([1.0, 2.0, 3.0, math.nan]) == (2.0, 1.0)  # ddof=1: sqrt((1 + 0 + 1) / 2)
    mean, std = mean_std([4.0])
    assert mean == 4.0 and math.isnan(std)
    assert all(math.isnan(v) for v in mean_std([]))


def test_paired_differences_pair_seeds_and_drop_unpaired_or_missing_ones():
    values = {
        "ref": {0: 1.0, 1: 2.0, 2: 3.0, 4: 7.0},
        "a": {0: 1.5, 1: 1.0, 2: math.nan, 3: 9.0},  # seed 2 NaN, seed 3 has no reference
        "b": {2: 2.0, 4: 7.0},
    }
    assert paired_differences(values, "ref") == {"a": {0: 0.5, 1: -1.0}, "b": {2: -1.0, 4: 0.0}}


def test_sign_flip_p_is_exact_over_all_sign_assignments():
    """Same signs: 2/2ⁿ (n = 3: 0.25 at best; n = 6: 0.03125). A mixed case by hand: of the 16 sign
    assignments of |x| = (1, 2, 3, 4) the observed |sum| 8 (−1 + 2 + 3 + 4) is reached or passed by
    ±(1+2+3+4) = 10 and ±(−1+2+3+4) = 8 and ±(1−2+3+4) = 6 < 8 not, so p = 4/16.
    Mutations caught: a one-sided p (half), a t-test p, the median as statistic."""
    assert sign_flip_p([0.1, 0.2, 0.3]) == pytest.approx(0.25)
    assert sign_flip_p([-1, -2, -3, -4, -5, -6]) == pytest.approx(2 / 64)
    assert sign_flip_p([-1, 2, 3, 4]) == pytest.approx(4 / 16)
    x = np.array([0.3, -0.1, 0.7, 0.2, -0.4, 0.9, 0.05])  # brute force: every sign vector
    flipped = [abs(np.mean(np.array(s) * np.abs(x))) for s in itertools.product((-1, 1), repeat=x.size)]
    assert sign_flip_p(x) == pytest.approx(np.mean(np.array(flipped) >= abs(x.mean()) - 1e-12))
    assert sign_flip_p([0.5]) == 1.0 and sign_flip_p([0.0, 0.0]) == 1.0 and math.isnan(sign_flip_p([]))


def test_sign_flip_p_beyond_twenty_values_samples_assignments_in_bounded_memory():
    """30 per-run differences (a study's EMA against raw weights): 2^30 assignments at once needed
    8 GB and killed the process. Above 20 values the p comes from 2^20 random assignments: a mixed
    sample's p matches the exact one of the same values computed by halves (the distribution of the
    sum over all 2^30 sign vectors is the convolution of two 2^15 halves) to 0.002, the same call
    gives the same p, and 30 same-sign values give scipy's two-sided floor 2 / (2^20 + 1), not 0."""
    x = np.random.default_rng(3).normal(0.35, 1.0, 30)
    sums = [np.array([np.dot(s, np.abs(h)) for s in itertools.product((-1, 1), repeat=15)]) for h in (x[:15], x[15:])]
    total = np.sort(sums[1])
    reached = sum(  # |a + b| ≥ |sum(x)| for each half-sum a, counted over the sorted b's
        len(total) - np.searchsorted(total, abs(x.sum()) - a - 1e-9) + np.searchsorted(total, -abs(x.sum()) - a + 1e-9)
        for a in sums[0]
    )
    assert sign_flip_p(x) == pytest.approx(reached / 2**30, abs=0.002) and sign_flip_p(x) == sign_flip_p(x)
    assert sign_flip_p(np.linspace(0.1, 1.0, 30)) == pytest.approx(2 / (2**20 + 1))  # both tails


def test_t_interval_is_mean_plus_minus_t_times_the_standard_error():
    """(1, 2, 3): mean 2, s = 1, t_{0.975, 2} = 4.302653 → 2 ± 4.302653/√3. Caught: z = 1.96, ddof = 0."""
    low, high = t_interval([1.0, 2.0, 3.0])
    assert (low, high) == pytest.approx((2 - 4.302653 / math.sqrt(3), 2 + 4.302653 / math.sqrt(3)), abs=1e-6)
    assert t_interval([0.25] * 4) == (0.25, 0.25)
    assert all(math.isnan(v) for v in t_interval([1.0]))


def test_minimal_detectable_effect_against_the_normal_formula_and_by_simulation():
    """For many seeds it tends to (z_0.975 + z_0.8)·sd/√n = 2.8016·sd/√n; at n = 6 a t-test on
    simulated differences of that mean finds it 80 % of the time. Caught: z for t, power 0.5, √(n−1)."""
    assert minimal_detectable_effect(2.0, 400) == pytest.approx(2.8016 * 2.0 / 20, rel=0.01)
    mde = minimal_detectable_effect(1.0, 6)
    assert 2.8016 / math.sqrt(6) < mde < 1.6
    from scipy import stats

    x = np.random.default_rng(0).normal(mde, 1.0, size=(20_000, 6))
    found = stats.ttest_1samp(x, 0.0, axis=1).pvalue < ALPHA
    assert found.mean() == pytest.approx(0.8, abs=0.015)
    assert minimal_detectable_effect(0.0, 6) == 0.0 and math.isnan(minimal_detectable_effect(1.0, 1))


def test_holm_on_known_p_values():
    """Sorted 0.01, 0.03, 0.04 of m = 3 → 0.03, 0.06, max(0.06, 0.04) = 0.06, back in input order; NaN
    stays and does not count. Caught: Bonferroni (0.12), no monotone step (0.04)."""
    adjusted = holm([0.04, 0.01, math.nan, 0.03])
    assert adjusted[0] == pytest.approx(0.06) and adjusted[1] == pytest.approx(0.03)
    assert math.isnan(adjusted[2]) and adjusted[3] == pytest.approx(0.06)
    assert holm([0.5, 0.9]) == [1.0, 1.0]


def test_verdicts_need_six_seeds_and_the_corrected_p():
    six = {s: -0.01 - 0.001 * s for s in range(MIN_SEEDS)}  # all lower: p = 2/64
    five = dict(list(six.items())[:5])
    mixed = dict(enumerate([-1.0, 1.0, -2.0, 2.0, 0.5, -0.5]))
    alone = compare({"six": six})["six"]
    assert alone["p"] == pytest.approx(2 / 64) and alone["verdict"] == "lower" and alone["signs"] == "− " * 5 + "−"
    assert compare({"up": {k: -v for k, v in six.items()}})["up"]["verdict"] == "higher"
    assert compare({"five": five})["five"]["verdict"] == f"untestable (n < {MIN_SEEDS})"
    assert compare({"mixed": mixed})["mixed"]["verdict"] == "not shown"
    # in a family of two the same six seeds no longer pass: Holm gives 2 · 2/64 = 0.0625
    family = compare({"six": six, "again": dict(six)})
    assert family["six"]["p_holm"] == pytest.approx(0.0625) and family["six"]["verdict"] == "not shown"
    assert compare({"none": {}})["none"]["verdict"] == "no paired seeds"
    assert signs([-0.1, 0.0, 2.0]) == "− 0 +"


@pytest.mark.parametrize("n", [3, 6, 8])
def test_with_no_true_effect_at_most_five_percent_of_studies_get_a_verdict(n):
    """2000 studies of n paired seeds whose differences are seed noise only (σ/μ-sized, SD 0.005): the
    share called "lower" or "higher" stays ≤ 5 %, give or take two standard errors of a share of 2000
    (the bootstrap it replaced called 25 % at n = 3; a one-sided p calls about 9 % at n = 8)."""
    rng = np.random.default_rng(n)
    called = [
        compare({"v": dict(enumerate(rng.normal(0.0, 0.005, size=n)))})["v"]["verdict"] in ("lower", "higher")
        for _ in range(2000)
    ]
    assert np.mean(called) <= ALPHA + 2 * math.sqrt(ALPHA * (1 - ALPHA) / 2000)


def test_summary_fields():
    s = summarise_differences({3: 0.1, 1: 0.3})  # in seed order: 0.3, 0.1
    assert s["n"] == 2 and s["mean"] == pytest.approx(0.2) and s["signs"] == "+ +" and s["p"] == 0.5
    assert s["low"] < 0.2 < s["high"] and s["mde"] > 0
