"""Statistics of a multi-seed study: spread over seeds, paired differences against a reference
variant, and percentile-bootstrap intervals of their mean (numpy only).

Runs of different variants with the same seed share initial weights and data order, so the
difference of two variants is taken seed by seed (paired), which removes the seed's own effect
from the comparison; the bootstrap resamples those per-seed differences.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

MIN_SEEDS = 3  # below this many paired seeds a bootstrap interval says nothing useful


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


def bootstrap_interval(x: Sequence[float], n: int = 10_000, level: float = 0.95, seed: int = 0) -> tuple[float, float]:
    """Percentile-bootstrap interval of the mean of ``x`` (K,): ``n`` resamples of K values drawn with
    replacement, from a generator seeded with ``seed`` (the same numbers give the same interval)."""
    x = np.asarray(x, dtype=np.float64)
    if x.size == 0:
        return float("nan"), float("nan")
    rng = np.random.default_rng(seed)
    means = x[rng.integers(0, x.size, size=(n, x.size))].mean(axis=1)
    tail = 100 * (1 - level) / 2
    low, high = np.percentile(means, [tail, 100 - tail])
    return float(low), float(high)


def signs(x: Sequence[float]) -> str:
    """'− − +': the sign of each value, in order (0 for an exact zero)."""
    return " ".join("−" if v < 0 else "+" if v > 0 else "0" for v in x)


def verdict(low: float, high: float) -> str:
    """'lower' / 'higher' when the interval [low, high] excludes 0, else 'within noise'."""
    if high < 0:
        return "lower"
    if low > 0:
        return "higher"
    return "within noise"


def summarise_differences(diffs: Mapping[int, float], n: int = 10_000, level: float = 0.95, seed: int = 0) -> dict:
    """Mean of per-seed differences {seed: d}, its bootstrap interval, the signs in seed order, the
    verdict, and whether the interval is meaningful (at least :data:`MIN_SEEDS` seeds)."""
    x = [diffs[s] for s in sorted(diffs)]
    low, high = bootstrap_interval(x, n, level, seed)
    return {
        "n": len(x),
        "mean": float(np.mean(x)) if x else float("nan"),
        "low": low,
        "high": high,
        "level": level,
        "signs": signs(x),
        "verdict": verdict(low, high) if x else "no paired seeds",
        "meaningful": len(x) >= MIN_SEEDS,
    }
