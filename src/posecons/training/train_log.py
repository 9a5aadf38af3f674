"""The run's TensorBoard log, ``RUN/tb/``, which the main rank writes: at step 1 and every
``train.log_every`` steps the losses, the learning rate of the step and the signs of a collapse
(:func:`collapse_signs`); every ``train.image_every`` steps an input frame, its disparity and
auto-mask; after each validation its finite metrics. Kept apart from the trainer, which says when
to log and not how, and so that only the main rank imports TensorBoard."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import torch

from ..config import TrainConfig


def open_log(out: Path):
    """The ``SummaryWriter`` of ``out/tb``."""
    from torch.utils.tensorboard import SummaryWriter

    return SummaryWriter(out / "tb")


def log_step(
    writer, t: TrainConfig, step: int, losses: dict[str, float], lr: float, batch: dict, outputs: dict
) -> None:
    """The scalars of training step ``step`` and, at the image interval, its images."""
    if step % t.log_every == 0 or step == 1:
        for k, v in losses.items():
            writer.add_scalar(f"loss/{k}", v, step)
        writer.add_scalar("lr", lr, step)
        for k, v in collapse_signs(outputs).items():
            writer.add_scalar(f"mask/{k}", v, step)
    if t.image_every and step % t.image_every == 0:
        writer.add_image("input", batch["frames"][0, 0], step)
        disp = outputs["disp"][0][0].detach().float()
        # floored: a disparity collapsed to 0 everywhere shows black instead of NaN
        writer.add_image("disparity", disp / disp.max().clamp_min(torch.finfo(disp.dtype).tiny), step)
        writer.add_image("automask", outputs["automask"][0:1].float(), step)


def log_validation(writer, step: int, metrics: dict[str, Any]) -> None:
    """The validation ``metrics`` of ``step`` that are finite numbers."""
    for k, v in metrics.items():
        if isinstance(v, (int, float)) and math.isfinite(v):
            writer.add_scalar(f"val/{k}", v, step)


def collapse_signs(outputs: dict) -> dict[str, float]:
    """The signs of a run collapsing from scratch (experiments/investigation.md §3, §27), from the model's
    outputs: the share of pixels where a warped source beat the unwarped one (the auto-mask hiding the
    rest from the loss), and the shares of full-scale disparities pinned at the far end (sigmoid < 0.01)
    and at the near end (sigmoid > 0.99, every pixel at ``model.min_depth``): a saturated sigmoid passes
    almost no gradient, so a run pinned at either end stays there."""
    disp = outputs["disp"][0].detach()
    return {
        "warped_fraction": float(outputs["automask"].float().mean()),
        "far_fraction": float((disp < 0.01).float().mean()),
        "near_fraction": float((disp > 0.99).float().mean()),
    }
