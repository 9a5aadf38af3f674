"""What every loss term is: a :class:`Term` subclass, and the :class:`StepContext` it reads."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, ClassVar

import torch

from ..config import Config
from ..pose_source import PairPoses


@dataclass
class StepContext:
    """What :meth:`PoseConsModel.forward` computed in a step, for the terms to read."""

    frames: torch.Tensor  # (B, F, 3, H, W) fp32 un-augmented frames, in the order of model.frame_ids
    K: torch.Tensor  # (B, 3, 3) normalised intrinsics
    logits: dict[int, torch.Tensor]  # the target's disparity logits by scale, (B, 1, H/2^s, W/2^s)
    disps: dict[int, torch.Tensor]  # their sigmoids
    poses: dict[int, torch.Tensor]  # the warping poses T_{f←0} (B, 4, 4) by source
    pairs: PairPoses | None  # the pose net's outputs by input pair; None where it did not run (known motion)
    source_disp: torch.Tensor | None  # the sources' scale-0 disparities (S·B, 1, H, W), where a term needs them
    motions: torch.Tensor | None  # batch['motions'] (B, S, 4, 4) in fp32, where a term or the pose source needs them
    photometric_error: Callable  # the model's losses.photometric_error (compiled with train.compile_losses)
    # (B, S, H, W) weights of each source's reprojection error in the view synthesis, which a term that
    # runs before it may set (SC-Depth's self-discovered mask)
    photometric_mask: torch.Tensor | None = None


class Term:
    """One named term of the training loss beyond view synthesis: ``weight × term(ctx)`` is added to
    the total. A subclass names itself, its weight's config field and what it needs from the step;
    an instance is made for a run's config, where :meth:`enabled`."""

    name: ClassVar[str]  # its key in the losses dict
    weight_key: ClassVar[str]  # the LossConfig field of its weight
    constraint: ClassVar[bool] = False  # one of the paper's constraints: none in validation (with_constraints=False)
    needs_source_depth: ClassVar[bool] = False  # the depth net runs on the sources too (ctx.source_disp)
    needs_motions: ClassVar[bool] = False  # batch['motions'] (ctx.motions)
    before_view_synthesis: ClassVar[bool] = False  # runs first, and may set ctx.photometric_mask

    def __init__(self, config: Config):
        self.config = config
        self.sources = config.model.frame_ids[1:]
        self.weight: float = getattr(config.loss, self.weight_key)

    @classmethod
    def enabled(cls, config: Config) -> bool:
        """Whether a run of ``config`` has this term: its weight is > 0."""
        return getattr(config.loss, cls.weight_key) > 0

    def active(self, step: int) -> bool:
        """Whether it counts at training step ``step``."""
        return True

    def pose_pairs(self) -> list[tuple[int, int]]:
        """The pose-net input pairs (a, b) it reads beyond the temporal ones."""
        return []

    def __call__(self, ctx: StepContext) -> torch.Tensor:
        """The term's value, a scalar."""
        raise NotImplementedError
