"""Median wall time of one full training step (forward, all losses, backward, Adam) for the
baseline, each pose constraint alone, and all three together.

    python benchmarks/train_step.py --height 192 --width 640 --batch 12 --device cuda
    python benchmarks/train_step.py --height 96 --width 320 --batch 4 --layers 18   # CPU-sized

Prints a Markdown table; the overhead column is relative to the baseline.
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch

from posecons.config import Config, load_config, resolve_preset
from posecons.data.augment import jitter_batch
from posecons.model import PoseConsModel
from posecons.training.precision import adam

VARIANTS = {"baseline": [], "fb": ["fb"], "id": ["id"], "cyc": ["cyc"], "all": ["fb", "id", "cyc"]}


def setting(constraints: list[str], args: argparse.Namespace) -> Config:
    """The benchmark's configuration: the preset (or the defaults, the paper's), then the size, batch
    and encoder depth given on the command line, random initial weights and these constraints."""
    given = {"model.height": args.height, "model.width": args.width, "model.num_layers": args.layers}
    given["train.batch_size"] = args.batch
    given["train.compile_losses"] = "true" if args.compile_losses else None
    overrides = [f"{key}={value}" for key, value in given.items() if value is not None]
    overrides += ["model.pretrained=false", f"loss.constraints=[{','.join(constraints)}]"]
    return load_config(resolve_preset(args.preset) if args.preset else None, overrides)


def make_model(cfg: Config, device: torch.device) -> PoseConsModel:
    """The model of the benchmark from fixed random weights."""
    torch.manual_seed(0)
    return PoseConsModel(cfg).to(device).train()


def make_batch(cfg: Config, device: torch.device) -> dict:
    """Random frames with KITTI's normalised K and one colour jitter."""
    m, batch = cfg.model, cfg.train.batch_size
    return {
        "frames": torch.rand(batch, len(m.frame_ids), 3, m.height, m.width, device=device),
        "intrinsics": torch.tensor([[0.58, 0, 0.5], [0, 1.92, 0.5], [0, 0, 1]], device=device)
        .expand(batch, 3, 3)
        .contiguous(),
        "color_aug": torch.tensor([1.1, 0.9, 1.05, 0.02], device=device).expand(batch, 4).contiguous(),
    }


def time_steps(constraints: list[str], args: argparse.Namespace) -> float:
    device, cfg = torch.device(args.device), setting(constraints, args)
    model, batch = make_model(cfg, device), make_batch(cfg, device)
    optim = adam(model.parameters(), 1e-4, device)  # the trainer's optimiser
    times = []
    for i in range(args.warmup + args.steps):
        if device.type == "cuda":
            torch.cuda.synchronize()
        start = time.perf_counter()
        optim.zero_grad(set_to_none=True)
        with torch.autocast(device.type, dtype=torch.bfloat16, enabled=args.bf16):
            _, losses = model(jitter_batch(batch), step=i)
        losses["total"].backward()
        optim.step()
        if device.type == "cuda":
            torch.cuda.synchronize()
        if i >= args.warmup:
            times.append(time.perf_counter() - start)
    return statistics.median(times)


def setting_arguments(p: argparse.ArgumentParser) -> None:
    """The preset, size, batch, encoder depth and device of a benchmark (the paper's setting by default)."""
    p.add_argument("--preset", help="a bundled preset or preset file, e.g. synth/study (default: the paper's setting)")
    p.add_argument("--height", type=int, help="default: the preset's (paper: 192)")
    p.add_argument("--width", type=int, help="default: the preset's (paper: 640)")
    p.add_argument("--batch", type=int, help="default: the preset's (paper: 12)")
    p.add_argument("--layers", type=int, help="ResNet depth; default: the preset's (paper: 18)")
    p.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    p.add_argument("--compile-losses", action="store_true", help="train.compile_losses=true (torch.compile)")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    setting_arguments(p)
    p.add_argument("--steps", type=int, default=10)
    p.add_argument("--warmup", type=int, default=3)
    p.add_argument("--bf16", action="store_true", help="autocast the networks to bfloat16")
    p.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    args = p.parse_args()
    m, batch = (cfg := setting([], args)).model, cfg.train.batch_size
    print(
        f"{args.preset or 'paper setting'}: ResNet-{m.num_layers}, {m.height}×{m.width}, batch {batch}, {args.device}, "
        f"torch {torch.__version__}, {torch.get_num_threads()} threads, median of {args.steps} steps"
    )
    print("| variant | step (s) | overhead vs baseline |\n|---|---|---|")
    base = None
    for name in args.variants:
        t = time_steps(VARIANTS[name], args)
        base = t if name == "baseline" else base
        overhead = f"{100 * (t / base - 1):+.1f} %" if base and name != "baseline" else "—"
        print(f"| {name} | {t:.3f} | {overhead} |", flush=True)


if __name__ == "__main__":
    main()
