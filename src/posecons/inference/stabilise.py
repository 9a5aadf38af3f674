"""Test-time scale stabilisation (SPEC §12): per-frame depth scale factors from the network's own
depth and pose only — never ground truth.

Conventions (see :mod:`posecons.geometry`): ``poses[i]`` is T_{i+1←i}, mapping points of frame i
into frame i+1 (what :class:`~posecons.inference.backend.StepChain` returns). If frame t's depth is
multiplied by s, its relative scale r_t becomes r_t / s, and the factor for frame t becomes × 1/s:
the factor multiplies the whole map, so it removes frame-to-frame jitter but cannot change a
map's shape (e.g. one that compresses far scenes).
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F

from ..geometry import check_tensor, project_depth

DEFAULT_TIME_CONSTANT = 30.0  # frames


def relative_scale(prev_depth: torch.Tensor, depth: torch.Tensor, T: torch.Tensor, K: torch.Tensor) -> float:
    """Median over co-visible pixels of r = z_warped / D_t(projected pixel), where z_warped is the
    depth in frame t of D_{t−1} back-projected and moved by T = T_{t←t−1}.

    prev_depth, depth: (H, W); T: (4, 4); K: pixel (3, 3) at that size. Returns NaN when no pixel
    of frame t−1 lands inside frame t with positive depth.
    """
    check_tensor("prev_depth", prev_depth, (None, None))
    check_tensor("depth", depth, tuple(prev_depth.shape))
    z, grid = project_depth(prev_depth[None, None], T[None].to(prev_depth), K[None].to(prev_depth))
    # bilinear: unbiased on smooth surfaces; pixels mixed across a depth edge are few, and the median ignores them
    sampled = F.grid_sample(depth[None, None], grid, mode="bilinear", align_corners=True)
    covisible = (grid.abs() <= 1).all(-1)[:, None] & (z > 0) & (sampled > 0)
    if not covisible.any():
        return math.nan
    return float((z[covisible] / sampled[covisible]).median())


class ScaleFilter:
    """Chains relative scales into per-frame factors with a bounded drift.

    In log space, ℓ_t = α (ℓ_{t−1} + log r_t) with α = exp(−1/τ), ℓ_0 = 0, factor = exp(ℓ_t). Without
    the leak (τ = ∞) errors in r would random-walk; with it the stabilised log-scale is an
    exponential moving average of the raw one over about τ frames, so jitter shrinks by about
    √(2τ) while any drift stays bounded. Causal, so predict can stream. A NaN ratio (no
    co-visible pixels) counts as 1.
    """

    def __init__(self, time_constant: float = DEFAULT_TIME_CONSTANT):
        if not time_constant > 0:
            raise ValueError(f"time_constant must be positive, got {time_constant}")
        self.alpha = math.exp(-1.0 / time_constant)
        self.log_scale = 0.0

    def step(self, ratio: float) -> float:
        """The next frame's relative scale → its factor."""
        log_ratio = 0.0 if math.isnan(ratio) else math.log(ratio)
        self.log_scale = self.alpha * (self.log_scale + log_ratio)
        return math.exp(self.log_scale)


class StreamStabiliser:
    """Factors for frames that arrive in batches (``predict`` streams): each frame's depth is compared
    with the previous frame's, across batch boundaries, and the ratios chained by :class:`ScaleFilter`.
    The first frame's factor is 1."""

    def __init__(self, K: torch.Tensor, time_constant: float = DEFAULT_TIME_CONSTANT):
        self.K = K
        self.chain = ScaleFilter(time_constant)
        self.previous: torch.Tensor | None = None

    def add(self, depths: torch.Tensor, steps: torch.Tensor) -> list[float]:
        """(B, H, W) next depths and the steps T_{i+1←i} into each of them that has a predecessor
        (B − 1 for the first batch, B after it) → their B factors."""
        first = self.previous is None
        check_tensor("steps", steps, (depths.shape[0] - first, 4, 4))
        factors, previous = ([1.0], depths[0]) if first else ([], self.previous)
        for depth, T in zip(depths[first:], steps):
            factors.append(self.chain.step(relative_scale(previous, depth, T, self.K)))
            previous = depth
        self.previous = depths[-1]
        return factors


def stabilise(
    depths: torch.Tensor, poses: torch.Tensor, K: torch.Tensor, time_constant: float = DEFAULT_TIME_CONSTANT
) -> list[float]:
    """(N, H, W) depths, (N−1, 4, 4) steps T_{i+1←i} and pixel K (3, 3) → N factors (the first 1)."""
    return StreamStabiliser(K, time_constant).add(depths, poses)
