"""Study statistics on hand-made numbers: spread over seeds, paired differences, bootstrap intervals."""

import math

import numpy as np
import pytest

from posecons.metrics.stats import (
    bootstrap_interval,
    mean_std,
    paired_differences,
    signs,
    summarise_differences,
    verdict,
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


def test_constant_differences_give_a_zero_width_interval_at_that_value():
    low, high = bootstrap_interval([0.25] * 5)
    assert low == pytest.approx(0.25) and high == pytest.approx(0.25)
    s = summarise_differences({0: -0.1, 1: -0.1, 2: -0.1})
    assert s["mean"] == pytest.approx(-0.1) and s["verdict"] == "lower" and s["signs"] == "− − −"


def test_mixed_signs_give_an_interval_around_zero():
    s = summarise_differences(dict(enumerate([-1.0, 1.0, -2.0, 2.0, 0.5, -0.5])))
    assert s["mean"] == pytest.approx(0.0) and s["low"] < 0 < s["high"]
    assert s["verdict"] == "within noise" and s["signs"] == "− + − + + −" and s["meaningful"]


def test_interval_matches_the_normal_approximation_and_narrows_with_level():
    """For many values the bootstrap interval of the mean is mean ± z·s/√n (z = 1.96 at 95 %)."""
    x = np.random.default_rng(1).normal(3.0, 2.0, size=400)
    low, high = bootstrap_interval(x, n=4000)
    half = 1.96 * x.std() / np.sqrt(x.size)
    assert (low + high) / 2 == pytest.approx(x.mean(), abs=0.1 * half)
    assert (high - low) / 2 == pytest.approx(half, rel=0.1)
    low50, high50 = bootstrap_interval(x, n=4000, level=0.5)
    assert (high50 - low50) / 2 == pytest.approx(0.674 * x.std() / np.sqrt(x.size), rel=0.1)


def test_interval_is_reproducible_from_its_seed_and_stays_within_the_data():
    x = [0.3, -0.1, 0.2, 0.05]
    assert bootstrap_interval(x, seed=7) == bootstrap_interval(x, seed=7)
    low, high = bootstrap_interval(x)
    assert min(x) <= low < np.mean(x) < high <= max(x)


def test_verdict_signs_and_few_seeds():
    assert (verdict(-2, -1), verdict(1, 2), verdict(-1, 1), verdict(0, 1)) == (
        "lower",
        "higher",
        "within noise",
        "within noise",
    )
    assert signs([-0.1, 0.0, 2.0]) == "− 0 +"
    two = summarise_differences({0: 0.1, 5: 0.3})
    assert two["n"] == 2 and not two["meaningful"] and two["mean"] == pytest.approx(0.2)
    assert summarise_differences({})["verdict"] == "no paired seeds"
