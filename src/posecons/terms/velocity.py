"""Velocity supervision (loss.velocity_weight; PackNet-SfM's, not in the paper, not self-supervised)."""

from __future__ import annotations

import torch

from ..losses import velocity_loss
from ..pose_source import temporal
from .base import StepContext, Term


class Velocity(Term):
    """Each temporal pair's translation against the metres travelled to its source (batch['motions'])."""

    name, weight_key = "velocity", "velocity_weight"
    needs_motions = True

    def __call__(self, ctx: StepContext) -> torch.Tensor:
        d = ctx.motions[..., :3, 3].norm(dim=-1)  # (B, S) metres to each source
        translations = torch.cat([ctx.pairs.vector(*temporal(f))[1] for f in self.sources])  # source-major
        return velocity_loss(translations, d.t().reshape(-1))
