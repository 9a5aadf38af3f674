"""SC-SfMLearner's depth consistency (loss.depth_consistency_weight; not in the paper)."""

from __future__ import annotations

import torch

from ..geometry import disp_to_depth, invert_pose, scale_intrinsics
from ..losses import depth_consistency_loss, depth_difference
from .base import StepContext, Term


class DepthConsistency(Term):
    """The target disparity's consistency with the sources', warped by T_{f←0}. In the sc_depth form
    (SC-Depth as published) the mean of that direction and the reverse one (each source's depth moved
    into the target by T_{0←f}), and the self-discovered mask 1 − D_diff of each source, detached,
    weights its photometric error: so it runs before the view synthesis. Scale 0 only: the
    full-resolution depth is the one evaluated, and the coarser scales, upsampled to that size, would
    repeat the same constraint at less detail for one more projection each."""

    name, weight_key = "dc", "depth_consistency_weight"
    needs_source_depth = True
    before_view_synthesis = True

    def __call__(self, ctx: StepContext) -> torch.Tensor:
        m = self.config.model
        depth, source_depth = (
            disp_to_depth(d.float(), m.min_depth, m.max_depth)[1] for d in (ctx.disps[0], ctx.source_disp)
        )
        depth = depth.repeat(len(self.sources), 1, 1, 1)
        T = torch.cat([ctx.poses[f] for f in self.sources])
        K = scale_intrinsics(ctx.K, m.height, m.width).repeat(len(self.sources), 1, 1)
        diff, inside = depth_difference(depth, source_depth, T, K)
        loss = diff.sum() / inside.sum().clamp(min=1)
        if self.config.loss.depth_consistency_form == "one_way":
            return loss
        reverse = depth_consistency_loss(source_depth, depth, invert_pose(T), K)
        ctx.photometric_mask = (1 - diff.detach()).view(len(self.sources), -1, *diff.shape[-2:]).transpose(0, 1)
        return (loss + reverse) / 2
