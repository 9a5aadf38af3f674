"""The processes of a run: the rank and device of this one, read from what ``torchrun`` sets
(``RANK``/``WORLD_SIZE``/``LOCAL_RANK``), the process group they join, the wait of the other ranks
while the main rank validates, and the group's end. One CPU or GPU is a world of one, which never
joins a group. Kept apart from the trainer, which asks only whether it is the main rank (the one
that saves, logs and validates) and how many ranks share a batch."""

from __future__ import annotations

import datetime
import os
from dataclasses import dataclass

import torch
import torch.distributed as dist

from ..errors import PoseconsError

VALIDATION_WAIT = datetime.timedelta(hours=2)  # how long the other ranks wait for the main rank's validation


@dataclass
class Dist:
    rank: int = 0
    world: int = 1
    local_rank: int = 0

    @classmethod
    def from_environment(cls) -> Dist:
        return cls(
            int(os.environ.get("RANK", 0)), int(os.environ.get("WORLD_SIZE", 1)), int(os.environ.get("LOCAL_RANK", 0))
        )

    @property
    def main(self) -> bool:
        return self.rank == 0


def init_distributed(accelerator: str) -> tuple[Dist, torch.device]:
    """Join the process group torchrun describes (if any) and pick this process's device."""
    env = Dist.from_environment()
    use_cuda = accelerator == "cuda" or (accelerator == "auto" and torch.cuda.is_available())
    if use_cuda and not torch.cuda.is_available():
        raise PoseconsError("--accelerator cuda was asked for, but no CUDA device is visible")
    device = torch.device("cuda", env.local_rank) if use_cuda else torch.device("cpu")
    if use_cuda:
        torch.cuda.set_device(device)
    if env.world > 1 and not dist.is_initialized():
        dist.init_process_group("nccl" if use_cuda else "gloo")
    return env, device


def validation_group(env: Dist) -> dist.ProcessGroup | None:
    """A group of its own, whose timeout is sized for a validation, not a step, in which the other
    ranks wait while the main rank validates; None for a single process. Every rank makes it."""
    return dist.new_group(backend="gloo", timeout=VALIDATION_WAIT) if env.world > 1 else None


def wait_for_validation(group: dist.ProcessGroup | None) -> None:
    """Hold every rank of ``group`` until the main rank has validated (a long validation would
    otherwise reach the training collectives' timeout, NCCL's 10 minutes, in their next step)."""
    if group is not None:
        dist.monitored_barrier(group, timeout=VALIDATION_WAIT)


def finish_distributed() -> None:
    """Leave the process group once every rank is done."""
    if dist.is_initialized():
        dist.barrier()
        dist.destroy_process_group()
