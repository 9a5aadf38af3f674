"""View synthesis of the cycle's skip pair (loss.skip_weight; not in the paper)."""

from __future__ import annotations

import torch

from ..geometry import disp_to_depth, scale_intrinsics, warp
from ..losses import min_reprojection
from ..pose_source import cycle_ids
from .base import StepContext, Term


class SkipSynthesis(Term):
    """Mean auto-masked photometric error of frame +n warped into frame −n with −n's own depth and
    T_{+n←−n}: the skip pair's pose learns the motion over 2n frames from the images, as each step's
    does, instead of from the cycle constraint alone. Scale 0 only, as the depth consistency."""

    name, weight_key = "skip", "skip_weight"
    needs_source_depth = True

    def pose_pairs(self) -> list[tuple[int, int]]:
        return [cycle_ids(self.config.model.frame_ids)]

    def __call__(self, ctx: StepContext) -> torch.Tensor:
        m, lo = self.config.model, self.config.loss
        prev, nxt = cycle_ids(m.frame_ids)
        T_skip = ctx.pairs.T(nxt, prev, input=(prev, nxt))
        b, index = ctx.frames.shape[0], self.sources.index(prev)
        depth = disp_to_depth(ctx.source_disp[index * b : (index + 1) * b].float(), m.min_depth, m.max_depth)[1]
        target, source = ctx.frames[:, m.frame_ids.index(prev)], ctx.frames[:, m.frame_ids.index(nxt)]
        K = scale_intrinsics(ctx.K, m.height, m.width)
        reprojection = ctx.photometric_error(warp(source, depth, T_skip, K), target, lo.ssim_weight)
        identity = ctx.photometric_error(source, target, lo.ssim_weight) if lo.automask else None
        return min_reprojection(reprojection, identity)[0].mean()
