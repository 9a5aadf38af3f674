"""Exact resume: the full training state that ``RUN/checkpoints/last.pt`` holds (weights and EMA,
optimiser, scheduler, scaler, position in the data, counters, RNG streams) and how a resumed run
reads it back, from ``last.pt`` or, where that does not load, the ``last.prev.pt`` it replaced,
once it is known to be a training state of the requested model. Kept apart from the trainer so
that its loop reads without this bookkeeping (as Lightning keeps it in a checkpoint connector):
these functions read and set the Trainer's attributes; when to save stays the Trainer's."""

from __future__ import annotations

import random
import sys
import time
from pathlib import Path
from typing import Any

import torch

from ..checkpoint import load_checkpoint
from ..config import without_retired
from ..errors import PoseconsError
from ..fileio import keep_copy, remove_temporaries
from .initial_weights import without_imagenet

PREVIOUS = "last.prev.pt"  # the full state before last.pt
COUNTERS = ("step", "epoch", "batch_in_epoch", "bad_steps", "skipped_steps")


def training_state(trainer) -> dict[str, Any]:
    """What ``last.pt`` holds of a :class:`~.trainer.Trainer`: all that an exact resume needs."""
    ema = {"raw_model": trainer.model.state_dict(), "ema_updates": int(trainer.ema.n_averaged)} if trainer.ema else {}
    return {
        "config": trainer.config.to_dict(),
        "model": trainer.eval_model.state_dict(),
        **ema,
        "weights": trainer.weights,
        "optimizer": trainer.optimizer.state_dict(),
        "scheduler": trainer.scheduler.state_dict(),
        "scaler": trainer.scaler.state_dict(),
        **{key: getattr(trainer, key) for key in COUNTERS},
        "best": trainer.best,
        "initialisation": trainer.initialisation,
        "train_seconds": trainer.seconds_before + time.time() - trainer.session_start,
        "rng": {
            "torch": torch.get_rng_state(),
            "python": random.getstate(),
            "cuda": torch.cuda.get_rng_state_all() if trainer.device.type == "cuda" else [],
        },
    }


def state_to_resume(folder: Path, device: torch.device, main: bool) -> tuple[Path, dict[str, Any]]:
    """``last.pt`` and its state or, where it does not load (e.g. a crash of the machine as it
    was written), the ``last.prev.pt`` it replaced, which then takes its place. The ``main`` rank
    reports the fallback and first removes a checkpoint being written when the run was killed."""
    if main:
        remove_temporaries(folder)
    last, previous = folder / "last.pt", folder / PREVIOUS
    try:
        return last, load_checkpoint(last, map_location=device)
    except PoseconsError as exc:
        if not previous.is_file():
            raise
        state = load_checkpoint(previous, map_location=device)
        if main:
            print(f"{exc}; resuming from {previous} (step {state.get('step')}) instead", file=sys.stderr)
            keep_copy(previous, last)
        return previous, state


def restore_training_state(trainer, path: Path, state: dict[str, Any]) -> None:
    """Set a :class:`~.trainer.Trainer` to the ``state`` read from ``path``, which must be a
    training state (not weights only) of the same model."""
    missing = [
        k for k in ("optimizer", "scheduler", "scaler", "step", "epoch", "batch_in_epoch", "rng") if k not in state
    ]
    if missing:
        raise PoseconsError(
            f"{path}: holds no training state ({', '.join(missing)} missing); --resume "
            "needs the checkpoints/last.pt that a run writes"
        )
    saved, requested = (
        without_imagenet(without_retired(state["config"]))["model"],  # a run from before a removal resumes
        without_imagenet(trainer.config.to_dict())["model"],
    )
    if saved != requested:
        raise PoseconsError(
            f"{path}: its model config {saved} differs from the requested "
            f"{requested}; resume with the run's own config.yaml"
        )
    trainer.config.model.pretrained = state["config"]["model"]["pretrained"]
    trainer.initialisation = state.get("initialisation", "not recorded (checkpoint predates the record)")
    try:
        trainer.model.load_state_dict(state.get("raw_model", state["model"]))
        if trainer.ema is not None:  # "model" is the EMA, or the raw weights of a run without one (0 updates)
            trainer.ema.module.load_state_dict(state["model"])
            trainer.ema.n_averaged.fill_(state.get("ema_updates", 0))
    except RuntimeError as exc:
        raise PoseconsError(f"{path}: weights do not fit the model: {str(exc).splitlines()[0]}") from exc
    trainer.optimizer.load_state_dict(state["optimizer"])
    trainer.scheduler.load_state_dict(state["scheduler"])
    trainer.scaler.load_state_dict(state["scaler"])
    for key in COUNTERS:
        setattr(trainer, key, int(state[key]))
    trainer.best = float(state["best"])
    trainer.seconds_before = float(state.get("train_seconds", 0.0))  # absent in checkpoints of older versions
    if trainer.env.world == 1:  # per-rank RNG streams are only saved for rank 0
        torch.set_rng_state(state["rng"]["torch"].cpu())
        random.setstate(_as_tuple(state["rng"]["python"]))
        if trainer.device.type == "cuda" and state["rng"]["cuda"]:
            torch.cuda.set_rng_state_all([s.cpu() for s in state["rng"]["cuda"]])


def _as_tuple(value):
    """Python's RNG state comes back from the checkpoint with lists where it had tuples."""
    return tuple(_as_tuple(v) for v in value) if isinstance(value, (list, tuple)) else value
