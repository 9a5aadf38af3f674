"""Statistics of a multi-seed study: paired differences of each variant from a reference, an exact
sign-flip test of each, a t-interval of the mean difference, the minimal detectable effect, and
Holm's correction across the comparisons that share a verdict.

Runs of different variants with the same seed share initial weights and data order, so two variants
are compared seed by seed (paired), which removes the seed's own effect from the comparison. The test
asks whether the per-seed differences are symmetric about zero: under that null each of the 2ⁿ sign
assignments is equally likely, so the exact p-value needs no normality. Its smallest two-sided value is
2/2ⁿ, so no verdict at α = 0.05 is possible below :data:`MIN_SEEDS` seeds. (The percentile bootstrap
used before is [min, max] of three differences at n = 3, a 75 % interval.)
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np
from scipy import optimize, stats

ALPHA = 0.05  # two-sided level of every test, after Holm's correction
POWER = 0.8  # the power at which the minimal detectable effect is given
MIN_SEEDS = 6  # the fewest paired seeds whose exact two-sided p can fall below ALPHA: 2/2⁶ = 0.031


def mean_std(values: Sequence[float]) -> tuple[float, float]:
    """Mean and sample standard deviation (ddof=1) of the finite values; std is NaN for fewer than 2,
    both NaN for none."""
    x = np.asarray(values, dtype=np.float64)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return float("nan"), float("nan")
    return float(x.mean()), float(x.std(ddof=1)) if x.size > 1 else float("nan")


def paired_differences(
    values_by_variant_seed: Mapping[str, Mapping[int, float]], reference: str
) -> dict[str, dict[int, float]]:
    """variant → {seed: value[variant][seed] − value[reference][seed]} for every other variant, over the
    seeds (in increasing order) where both values exist and are finite."""
    ref = values_by_variant_seed.get(reference, {})
    out = {}
    for variant, values in values_by_variant_seed.items():
        if variant == reference:
            continue
        seeds = sorted(s for s in values if s in ref and np.isfinite(values[s]) and np.isfinite(ref[s]))
        out[variant] = {s: float(values[s] - ref[s]) for s in seeds}
    return out


EXACT_SIGN_FLIPS = 20  # up to 2^20 sign assignments enumerated; beyond, that many random ones
BATCH = 2**16  # assignments evaluated at once: memory stays near 2^16 × n floats, not 2^n × n


def sign_flip_p(x: Sequence[float]) -> float:
    """Two-sided p-value of the paired sign-flip (permutation) test of mean 0: the mean of ``x``
    against its values under all 2ⁿ sign assignments (scipy.stats.permutation_test), exact up to
    n = 20 (every seed comparison); above, from 2^20 random assignments with a fixed generator, whose
    p (scipy's (count + 1) / (2^20 + 1)) is within about 0.001 of the exact one."""
    x = np.asarray(x, dtype=np.float64)
    if x.size == 0:
        return float("nan")
    if x.size == 1 or not x.any():  # both sign assignments (or all) are as far from 0
        return 1.0
    exact = x.size <= EXACT_SIGN_FLIPS
    result = stats.permutation_test(
        (x,),
        np.mean,
        permutation_type="samples",
        n_resamples=np.inf if exact else 2**EXACT_SIGN_FLIPS,
        alternative="two-sided",
        vectorized=True,
        batch=BATCH,
        rng=None if exact else np.random.default_rng(0),
    )
    return float(result.pvalue)


def t_interval(x: Sequence[float], level: float = 1 - ALPHA) -> tuple[float, float]:
    """Student-t interval of the mean of ``x`` (NaN for fewer than 2 values)."""
    x = np.asarray(x, dtype=np.float64)
    if x.size < 2:
        return float("nan"), float("nan")
    if not np.ptp(x):
        return float(x[0]), float(x[0])
    low, high = stats.ttest_1samp(x, 0.0).confidence_interval(level)
    return float(low), float(high)


def minimal_detectable_effect(sd: float, n: int, alpha: float = ALPHA, power: float = POWER) -> float:
    """The smallest true mean difference that a two-sided paired t-test at ``alpha`` finds with
    probability ``power``, for ``n`` seeds whose differences have standard deviation ``sd`` (from the
    noncentral t distribution; NaN below 2 seeds)."""
    if n < 2 or not math.isfinite(sd):
        return float("nan")
    if sd == 0:
        return 0.0
    df, critical = n - 1, stats.t.ppf(1 - alpha / 2, n - 1)

    def shortfall(effect: float) -> float:
        shift = effect * math.sqrt(n) / sd
        # P(T < −critical) as the upper tail of −T: scipy's lower tail turns NaN far out
        return stats.nct.sf(critical, df, shift) + stats.nct.sf(critical, df, -shift) - power

    # Twice the textbook approximation (t quantiles in place of the normal ones) overshoots the root.
    upper = 2 * (critical + stats.t.ppf(power, df)) * sd / math.sqrt(n)
    return float(optimize.brentq(shortfall, 0.0, upper))


def holm(pvalues: Sequence[float]) -> list[float]:
    """Holm's step-down adjustment of ``pvalues`` (NaN entries are left out and stay NaN): the k-th
    smallest of m is multiplied by m − k + 1, made monotone and capped at 1."""
    p = np.asarray(pvalues, dtype=np.float64)
    adjusted = np.full(p.shape, np.nan)
    finite = np.flatnonzero(np.isfinite(p))
    order = finite[np.argsort(p[finite], kind="stable")]
    running = 0.0
    for k, i in enumerate(order):
        running = max(running, min(1.0, (len(order) - k) * p[i]))
        adjusted[i] = running
    return adjusted.tolist()


def signs(x: Sequence[float]) -> str:
    """'− − +': the sign of each value, in order (0 for an exact zero)."""
    return " ".join("−" if v < 0 else "+" if v > 0 else "0" for v in x)


def summarise_differences(diffs: Mapping[int, float]) -> dict:
    """Per-seed differences {seed: d} → n, mean, sd, t-interval (low, high), exact sign-flip p,
    minimal detectable effect and the signs in seed order; :func:`verdict` decides after correction."""
    x = [diffs[s] for s in sorted(diffs)]
    mean, sd = mean_std(x)
    low, high = t_interval(x)
    return {
        "n": len(x),
        "mean": mean,
        "sd": sd,
        "low": low,
        "high": high,
        "level": 1 - ALPHA,
        "p": sign_flip_p(x),
        "mde": minimal_detectable_effect(sd, len(x)),
        "signs": signs(x),
    }


def verdict(summary: Mapping, p_adjusted: float) -> str:
    """'lower' / 'higher' when the corrected p is below :data:`ALPHA`; else why not."""
    n = summary["n"]
    if n == 0:
        return "no paired seeds"
    if n < MIN_SEEDS:
        return f"untestable (n < {MIN_SEEDS})"
    if p_adjusted < ALPHA:
        return "lower" if summary["mean"] < 0 else "higher"
    return "not shown"


def compare(differences: Mapping[str, Mapping[int, float]]) -> dict[str, dict]:
    """Each comparison's summary, its Holm-corrected p (over all of ``differences``: one family) and
    its verdict."""
    summaries = {name: summarise_differences(d) for name, d in differences.items()}
    adjusted = holm([s["p"] for s in summaries.values()])
    return {name: {**s, "p_holm": p, "verdict": verdict(s, p)} for (name, s), p in zip(summaries.items(), adjusted)}


if __name__ == "__main__":  # python -m posecons.metrics.stats d1 d2 …: one paired comparison
    import sys

    values = [float(v) for v in sys.argv[1:]]
    summary = compare({"differences": dict(enumerate(values))})["differences"]
    print(", ".join(f"{k} {v}" for k, v in summary.items()))
