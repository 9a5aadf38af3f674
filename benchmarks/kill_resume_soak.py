"""Kill-and-resume soak: SIGKILL a short deterministic CPU run at random moments, resume it each
time, and check that its final weights equal those of an uninterrupted run.

    python benchmarks/kill_resume_soak.py --kills 10 --steps 40 [--data DIR] [--seed 0]

Not part of the test suite (it takes minutes). Kills land anywhere: during start-up, in a step,
while a checkpoint is written. After a kill the run is resumed from ``last.pt`` if one exists
(else started again), so the check covers atomic checkpoints, exact resume, metrics.jsonl
without repeated rows, and the removal on resume of a checkpoint temporary a kill left behind. Prints one JSON line; exit status 1 if the weights differ.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import torch

from posecons.checkpoint import load_checkpoint

SETTINGS = [
    "data.split=synth",
    "model.height=64",
    "model.width=192",
    "model.num_layers=10",
    "model.pretrained=false",
    "train.batch_size=2",
    "data.num_workers=0",
    "train.deterministic=true",
    "train.checkpoint_every=3",
    "train.val_every=4",
    "train.val_samples=2",
    "train.image_every=0",
    "loss.constraints=[fb,id,cyc]",
]


def command(data: Path, out: Path, steps: int, resume: bool) -> list[str]:
    sets = sum([["--set", s] for s in SETTINGS + [f"train.max_steps={steps}"]], [])
    return [
        sys.executable,
        "-m",
        "posecons.cli",
        "train",
        "--config",
        "kitti/baseline",
        "--data-path",
        str(data),
        "--out",
        str(out),
        "--quiet",
        *sets,
    ] + (["--resume"] if resume else [])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--kills", type=int, default=10)
    parser.add_argument("--steps", type=int, default=40, help="optimiser steps of the run")
    parser.add_argument("--data", type=Path, help="a `posecons synth` dataset (default: a small one, made here)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the kill moments")
    args = parser.parse_args()
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    rng = random.Random(args.seed)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        data = args.data or tmp / "data"
        if args.data is None:
            subprocess.run(
                [
                    sys.executable,
                    "-m",
                    "posecons.cli",
                    "synth",
                    "--out",
                    str(data),
                    "--drives",
                    "2",
                    "--frames",
                    "20",
                    "--width",
                    "192",
                    "--height",
                    "64",
                ],
                check=True,
                env=env,
                stdout=subprocess.DEVNULL,
            )
        start = time.time()
        subprocess.run(command(data, tmp / "reference", args.steps, False), check=True, env=env)
        training = json.loads((tmp / "reference" / "train_summary.json").read_text())["minutes"] * 60
        startup, per_step = time.time() - start - training, training / args.steps

        run, last, kills = tmp / "killed", tmp / "killed" / "checkpoints" / "last.pt", []
        targets = sorted(rng.uniform(0, args.steps) for _ in range(args.kills))  # progress at each kill
        while len(kills) < args.kills:
            proc = subprocess.Popen(command(data, run, args.steps, last.is_file()), env=env, stderr=subprocess.DEVNULL)
            ahead = targets[len(kills)] - (load_checkpoint(last)["step"] if last.is_file() else 0)
            # kill at the drawn progress, or at a random moment of the start-up when the run is past it
            delay = startup + ahead * per_step if ahead > 0 else rng.uniform(0, startup)
            try:
                proc.wait(timeout=delay)
                break  # finished before this kill
            except subprocess.TimeoutExpired:
                proc.send_signal(signal.SIGKILL)
                proc.wait()
            kills.append(
                {"after_s": round(delay, 1), "saved_step": load_checkpoint(last)["step"] if last.is_file() else None}
            )
        stray = sorted(p.name for p in last.parent.glob(".*")) if last.parent.is_dir() else []
        subprocess.run(command(data, run, args.steps, last.is_file()), check=True, env=env)

        reference = load_checkpoint(tmp / "reference" / "checkpoints" / "last.pt")["model"]
        resumed = load_checkpoint(last)["model"]
        identical = all(torch.equal(reference[k], resumed[k]) for k in reference)
        steps = [json.loads(line)["step"] for line in (run / "metrics.jsonl").read_text().splitlines()]
        print(
            json.dumps(
                {
                    "kills": len(kills),
                    "kill_points": kills,
                    "steps": args.steps,
                    "weights_identical": identical,
                    "metrics_rows_unique": len(steps) == len(set(steps)),
                    "temporaries_left_by_kills": stray,
                }
            )
        )
    return 0 if identical else 1


if __name__ == "__main__":
    sys.exit(main())
