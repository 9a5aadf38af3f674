"""Samples/s of the real training loop — loading, augmentation, forward, losses, backward, Adam —
on KITTI-size synthetic JPEG data, for the baseline, each pose constraint and all three; and the
loader's own samples/s with the model removed.

    python benchmarks/train_loop.py --data /tmp/bench_jpg                      # paper setting, CPU
    python benchmarks/train_loop.py --data /tmp/bench_jpg --set train.precision=bf16
    python benchmarks/train_loop.py --data /tmp/bench_jpg --preset synth/demo --set data.split=synth
    python benchmarks/train_loop.py --data /tmp/bench_jpg --device cuda --set data.num_workers=8

``--data`` is created with ``posecons synth --ext jpg`` at full KITTI size when it does not exist.
A step's time is the wait for its batch plus its compute; the table gives medians over ``--steps``
steps after ``--warmup``, with the machine, the PyTorch build and the commit. Run it on an
otherwise idle machine: a second process on the cores invalidates the timings.
"""

from __future__ import annotations

import argparse
import platform
import resource
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

import torch

from posecons.config import load_config, resolve_preset
from posecons.data.synth import generate_synth
from posecons.training.trainer import Trainer

VARIANTS = {"baseline": [], "fb": ["fb"], "id": ["id"], "cyc": ["cyc"], "all": ["fb", "id", "cyc"]}


def _sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def measure(args: argparse.Namespace, constraints: list[str] | None) -> dict:
    """Median data wait and compute of training steps (``constraints`` None: the loader alone)."""
    # Settings that both this and older commits accept, so the same script can time them side by side.
    sets = [
        "model.pretrained=false",
        f"train.val_every={10**9}",
        f"train.checkpoint_every={10**9}",
        "train.image_every=0",
        f"train.log_every={10**9}",
        f"loss.constraints=[{','.join(constraints or [])}]",
        *args.set,
    ]
    config = load_config(resolve_preset(args.preset), sets)
    with tempfile.TemporaryDirectory() as out:
        trainer = Trainer(config, args.data, Path(out) / "run", accelerator=args.device, quiet=True)
        device = trainer.device
        waits, computes = [], []
        batches = iter(trainer._loader(0, 0))
        for i in range(args.warmup + args.steps):
            start = time.perf_counter()
            batch = next(batches)
            loaded = time.perf_counter()
            if constraints is not None:
                trainer._micro_step(batch, last=True)
                _sync(device)
            if i >= args.warmup:
                waits.append(loaded - start)
                computes.append(time.perf_counter() - loaded)
        peak = torch.cuda.max_memory_allocated(device) / 2**30 if device.type == "cuda" else None
    step = statistics.median([w + c for w, c in zip(waits, computes)])
    return {
        "wait": statistics.median(waits),
        "compute": statistics.median(computes),
        "step": step,
        "samples_per_s": config.train.batch_size / step,
        "gpu_peak_gib": peak,
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", type=Path, required=True, help="synthetic KITTI-size JPEG data (made if missing)")
    p.add_argument("--preset", default="kitti/baseline")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="config override (repeatable)")
    p.add_argument("--device", default="auto", choices=("auto", "cpu", "cuda"))
    p.add_argument("--steps", type=int, default=5)
    p.add_argument("--warmup", type=int, default=2)
    p.add_argument("--variants", nargs="*", default=list(VARIANTS), choices=list(VARIANTS))
    p.add_argument("--no-loader-only", action="store_true", help="skip the loader-alone row")
    args = p.parse_args()
    if not args.data.exists():
        print(f"writing {args.data} (4 drives × 60 frames, 1242×375 JPEG) ...", flush=True)
        generate_synth(args.data, drives=4, frames=60, ext="jpg")
    args.set = ["data.img_ext=.jpg", "data.split=synth", *args.set]
    commit = (
        subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=Path(__file__).parent
        ).stdout.strip()
        or "unknown"
    )
    print(
        f"{platform.processor() or platform.machine()}, {torch.get_num_threads()} threads, torch "
        f"{torch.__version__}, commit {commit}, preset {args.preset} {' '.join(args.set)}; "
        f"median of {args.steps} steps after {args.warmup}"
    )
    print("| variant | data wait (s) | compute (s) | step (s) | samples/s | overhead | GPU peak (GiB) |")
    print("|---|---|---|---|---|---|---|")
    base = None
    for name in args.variants:
        r = measure(args, VARIANTS[name])
        base = r["step"] if name == "baseline" else base
        overhead = f"{100 * (r['step'] / base - 1):+.1f} %" if base and name != "baseline" else "—"
        peak = f"{r['gpu_peak_gib']:.1f}" if r["gpu_peak_gib"] is not None else "—"
        print(
            f"| {name} | {r['wait']:.3f} | {r['compute']:.3f} | {r['step']:.3f} | {r['samples_per_s']:.2f} | "
            f"{overhead} | {peak} |",
            flush=True,
        )
    if not args.no_loader_only:
        r = measure(args, None)
        print(f"| loader alone | {r['wait']:.3f} | — | {r['step']:.3f} | {r['samples_per_s']:.2f} | — | — |")
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
    print(f"peak resident memory of this process: {rss:.1f} GiB (loader workers not counted)")


if __name__ == "__main__":
    main()
