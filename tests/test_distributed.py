"""Two CPU processes (gloo) train one run, as `--devices 2` does: the main rank validates while the
other waits for it at the validation barrier, not in its next step's collective."""

from __future__ import annotations

import datetime
import os
import socket
import sys
import time
from pathlib import Path

import pytest
import torch.distributed as dist
import torch.multiprocessing as mp

from posecons.config import load_config

sys.path.insert(0, str(Path(__file__).parent))
from tiny import TINY_MODEL  # noqa: E402

# Seconds: the training collectives' timeout, shorter than one validation. Both ranks must still reach
# each step's collectives within it while set-up and checkpoints make rank 0 the slower: at 4 s the
# first all_reduce timed out on a loaded 2-core machine, so the margins are wide.
COLLECTIVE_TIMEOUT = 20
VALIDATION_SECONDS = 30


def _rank(rank: int, port: int, data: str, out: str, errors) -> None:
    from posecons.training import trainer, validation

    os.environ.update(RANK=str(rank), LOCAL_RANK=str(rank), WORLD_SIZE="2", MASTER_ADDR="127.0.0.1")
    os.environ["MASTER_PORT"] = str(port)
    dist.init_process_group("gloo", timeout=datetime.timedelta(seconds=COLLECTIVE_TIMEOUT))
    run = validation.Validator.run

    def slow(self, model, step):  # a validation set far larger than this one
        time.sleep(VALIDATION_SECONDS)
        return run(self, model, step)

    validation.Validator.run = slow
    config = load_config(overrides=[*TINY_MODEL, "train.val_samples=2", "train.max_steps=2", "train.val_every=1"])
    try:
        trainer.train(config, data, out, accelerator="cpu", quiet=True)
    except Exception as exc:  # the other process reports it
        errors.put(f"rank {rank}: {type(exc).__name__}: {exc}"[:300])


@pytest.mark.slow
@pytest.mark.timeout(300)  # a hung collective fails here, not at the suite's 15 minutes
def test_a_validation_longer_than_the_collective_timeout_keeps_the_other_rank_waiting(make_synth, tmp_path):
    """Caught mutation: no barrier after validation (rank 1 times out in its next all_reduce)."""
    data, out = make_synth(2, 16, 192, 64, 3), tmp_path / "run"
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    errors = mp.get_context("spawn").SimpleQueue()
    mp.start_processes(_rank, args=(port, str(data), str(out), errors), nprocs=2, start_method="spawn")
    assert errors.empty(), errors.get()
    assert sorted(p.name for p in (out / "metrics").glob("step_*.json")) == ["step_000001.json", "step_000002.json"]
