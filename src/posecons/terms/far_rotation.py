"""The pose net's rotation taught by the far pixels (loss.far_rotation_weight; not in the paper)."""

from __future__ import annotations

import torch

from ..geometry import disp_to_depth, resize_image, scale_intrinsics
from ..losses import far_rotation_loss
from .base import StepContext, Term


class FarRotation(Term):
    """losses.far_rotation_loss of the sources warped by the rotation of T_{f←0}, averaged over the
    scales, each at its native size: a turn of 0.1–0.25 rad between frames ±3 moves the far pixels
    by 10–30 px at 192×64, which the coarsest scale sees as 1–4 px. From loss.far_rotation_start_step on."""

    name, weight_key = "far_rotation", "far_rotation_weight"

    def active(self, step: int) -> bool:
        return step >= self.config.loss.far_rotation_start_step

    def __call__(self, ctx: StepContext) -> torch.Tensor:
        m, lo, frames = self.config.model, self.config.loss, ctx.frames
        rotations = torch.stack([ctx.poses[f][:, :3, :3] for f in self.sources], 1)
        terms = []
        for s in m.scales:
            hs, ws = ctx.disps[s].shape[-2:]
            images = resize_image(frames.flatten(0, 1), hs, ws).view(*frames.shape[:3], hs, ws)
            depth = disp_to_depth(ctx.disps[s].float(), m.min_depth, m.max_depth)[1]
            K = scale_intrinsics(ctx.K, hs, ws)
            terms.append(
                far_rotation_loss(
                    images[:, 0], images[:, 1:], rotations, K, depth, lo.far_rotation_fraction, lo.ssim_weight
                )
            )
        return torch.stack(terms).mean()
