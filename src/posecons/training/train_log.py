"""The run's TensorBoard log, ``RUN/tb/``, which the main rank writes: at step 1 and every
``train.log_every`` steps the losses, the learning rate of the step and the signs of a collapse
(:func:`~posecons.training.collapse.collapse_signs`); every ``train.image_every`` steps an input frame, its disparity and
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


def logs_scalars(t: TrainConfig, step: int) -> bool:
    """Whether step ``step`` logs its scalars: the first step and every ``train.log_every``-th."""
    return step % t.log_every == 0 or step == 1


def log_step(
    writer,
    t: TrainConfig,
    step: int,
    losses: dict[str, float],
    lr: float,
    batch: dict,
    outputs: dict,
    signs: dict[str, float] | None,
) -> None:
    """The scalars of training step ``step`` (with ``signs``, the collapse signs of a step that logs
    scalars) and, at the image interval, its images."""
    if signs is not None:
        for k, v in losses.items():
            writer.add_scalar(f"loss/{k}", v, step)
        writer.add_scalar("lr", lr, step)
        for k, v in signs.items():
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
