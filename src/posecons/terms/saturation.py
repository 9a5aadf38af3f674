"""A wall on the depth net's disparity logits (loss.saturation_weight; not in the paper)."""

from __future__ import annotations

import torch

from ..losses import saturation_loss
from .base import StepContext, Term


class Saturation(Term):
    """losses.saturation_loss of the target's logits at every scale, beyond ±loss.saturation_bound."""

    name, weight_key = "saturation", "saturation_weight"

    def __call__(self, ctx: StepContext) -> torch.Tensor:
        return saturation_loss(list(ctx.logits.values()), self.config.loss.saturation_bound)
