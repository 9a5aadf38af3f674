"""The paper's three pose constraints (SPEC §5), each in the reading order of its equation."""

from __future__ import annotations

import torch

from ..config import Config
from ..losses import cycle_loss, forward_backward_loss, identity_loss
from ..pose_source import cycle_ids, temporal
from .base import StepContext, Term


class PoseConstraint(Term):
    """On where loss.constraints names it, from loss.constraint_start_step on."""

    constraint = True

    @classmethod
    def enabled(cls, config: Config) -> bool:
        return cls.name in config.loss.constraints

    def active(self, step: int) -> bool:
        return step >= self.config.loss.constraint_start_step


class ForwardBackward(PoseConstraint):
    """d(T_{f←0}, inverse(T_{0←f} from the reversed pair)) for each source."""

    name, weight_key = "fb", "fb_weight"

    def pose_pairs(self) -> list[tuple[int, int]]:
        return [temporal(f)[::-1] for f in self.sources]

    def __call__(self, ctx: StepContext) -> torch.Tensor:
        P = ctx.pairs
        return forward_backward_loss(
            torch.cat([P.T(f, 0, input=temporal(f)) for f in self.sources]),
            torch.cat([P.T(0, f, input=temporal(f)[::-1]) for f in self.sources]),
        )


class Identity(PoseConstraint):
    """‖e‖₁ + ‖t‖₁ of pose(I_0, I_0), on a random loss.identity_fraction of batches (SPEC §5)."""

    name, weight_key = "id", "id_weight"

    def active(self, step: int) -> bool:
        fraction = self.config.loss.identity_fraction
        return super().active(step) and (fraction >= 1 or bool(torch.rand(()) < fraction))

    def pose_pairs(self) -> list[tuple[int, int]]:
        return [(0, 0)]

    def __call__(self, ctx: StepContext) -> torch.Tensor:
        return identity_loss(*ctx.pairs.vector(0, 0))


class Cycle(PoseConstraint):
    """d(T_{+n←−n}, T_{+n←0} · T_{0←−n})."""

    name, weight_key = "cyc", "cyc_weight"

    def pose_pairs(self) -> list[tuple[int, int]]:
        return [cycle_ids(self.config.model.frame_ids)]

    def __call__(self, ctx: StepContext) -> torch.Tensor:
        P, (prev, nxt) = ctx.pairs, cycle_ids(self.config.model.frame_ids)
        return cycle_loss(
            P.T(nxt, prev, input=(prev, nxt)), P.T(nxt, 0, input=temporal(nxt)), P.T(0, prev, input=temporal(prev))
        )
