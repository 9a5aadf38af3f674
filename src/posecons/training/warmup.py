"""Learning-rate warm-up: the rate × (step / train.warmup_steps) during the first steps, on top of
the epoch schedule, which sees (and saves) only its own rate, so that a resume continues on the
ramp. From scratch, Adam's first updates are lr-sized on every weight at once: without warm-up the
pose net's translation grows fivefold in one step, far beyond the range where the photometric
gradient tells forward from backward (experiments/investigation.md §3). Kept apart from the trainer,
which only wraps its optimiser step in :func:`warmed_up` and logs the rate it used."""

from __future__ import annotations

import contextlib

import torch


def warmup_factor(step: int, warmup_steps: int) -> float:
    """The share of the scheduled learning rate that step ``step`` (counted from 1) uses."""
    return min(1.0, step / warmup_steps) if warmup_steps else 1.0


@contextlib.contextmanager
def warmed_up(optimizer: torch.optim.Optimizer, scheduler: torch.optim.lr_scheduler.LRScheduler, factor: float):
    """The scheduled rates × ``factor`` in ``optimizer`` while the block runs, then back."""
    if factor == 1.0:
        yield
        return
    groups, rates = optimizer.param_groups, scheduler.get_last_lr()
    for group, lr in zip(groups, rates):
        group["lr"] = lr * factor
    try:
        yield
    finally:
        for group, lr in zip(groups, rates):
            group["lr"] = lr
