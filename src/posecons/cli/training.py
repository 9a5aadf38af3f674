"""`posecons train` and `posecons demo` (its steps are in :mod:`.demo`, imported when it runs: torch)."""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

from ..config import load_config, resolve_preset
from ..errors import PoseconsError
from .arguments import add_accelerator, add_command, add_overrides, non_negative_int, output_folder, positive_int


def register(subparsers: argparse._SubParsersAction) -> None:
    p = add_command(subparsers, "train", train_command)
    p.add_argument("--config", help="preset file or bundled name (e.g. kitti/cycle); default on --resume: the run's")
    p.add_argument("--data-path", required=True, help="dataset root (KITTI raw layout, or odometry root)")
    p.add_argument("--out", type=output_folder, required=True, help="run directory")
    p.add_argument("--split-dir", help="folder with train_files.txt/val_files.txt (default DATA/splits/<data.split>)")
    p.add_argument(
        "--max-steps", type=non_negative_int, help="stop after this many optimiser steps (default: train.max_steps)"
    )
    add_overrides(p, "override a config value, e.g. --set loss.constraints=[cyc]")
    p.add_argument("--resume", action="store_true", help="continue RUN/checkpoints/last.pt exactly")
    p.add_argument(
        "--init-from",
        metavar="CKPT",
        help="start from these weights only (a .pt or .safetensors checkpoint, or a Monodepth2 model folder, "
        "of the run's architecture) with a new optimiser, schedule and step count: fine-tuning (train.init_from)",
    )
    p.add_argument("--devices", type=positive_int, default=1, help="processes (one GPU each) per node")
    p.add_argument("--nodes", type=positive_int, default=1, help="machines taking part; each runs this command")
    p.add_argument("--rdzv-endpoint", help="HOST:PORT of the rendezvous for --nodes > 1")
    add_accelerator(p)
    p.add_argument(
        "--precision",
        choices=("32", "bf16", "16", "auto"),
        help="mixed precision: bf16 (GPU or CPU), 16 (GPU), or auto: bf16 where the device has it natively "
        "(default: train.precision)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")

    d = add_command(subparsers, "demo", demo_command)
    d.add_argument(
        "--out", type=output_folder, default="runs/demo", help="folder for data, run, evaluation and report.md"
    )
    d.add_argument("--seed", type=non_negative_int, default=0, help="seed of the synthetic data and of training")


def _config(args: argparse.Namespace):
    overrides = list(args.overrides)
    if args.max_steps is not None:
        overrides.append(f"train.max_steps={args.max_steps}")
    if args.precision:
        overrides.append(f"train.precision='{args.precision}'")
    if args.init_from is not None:
        if args.resume:
            raise PoseconsError("--init-from starts a new run; --resume continues one from its own last.pt")
        if not Path(args.init_from).exists():
            raise PoseconsError(f"--init-from {args.init_from}: no such checkpoint or folder")
    path = resolve_preset(args.config) if args.config else None
    if path is None:
        run_config = Path(args.out) / "config.yaml"
        if not (args.resume and run_config.is_file()):
            raise PoseconsError("--config is required (except with --resume of an existing run)")
        path = run_config
    config = load_config(path, overrides)
    if args.init_from is not None:  # set here, not through --set: a path need not be valid YAML
        config.train.init_from = str(args.init_from)
    return config


def _launch_torchrun(args: argparse.Namespace) -> int:
    """Re-run this command under torchrun with one process per device."""
    cmd = [sys.executable, "-m", "torch.distributed.run", f"--nproc-per-node={args.devices}", f"--nnodes={args.nodes}"]
    if args.nodes > 1:
        if not args.rdzv_endpoint:
            raise PoseconsError("--nodes > 1 needs --rdzv-endpoint HOST:PORT (the same on every node)")
        cmd += ["--rdzv-backend=c10d", f"--rdzv-endpoint={args.rdzv_endpoint}", "--rdzv-id=posecons"]
    else:
        cmd.append("--standalone")
    return subprocess.call(cmd + ["-m", "posecons.cli"] + args.argv)


def train_command(args: argparse.Namespace) -> int:
    """train depth and pose networks from a preset

    Train a run. Multi-GPU on one node: --devices N (torchrun is started for you); several nodes:
    --nodes M --rdzv-endpoint HOST:PORT on each node. Ctrl-C (or SIGTERM) saves the run's state at the
    end of the step; the same command with --resume continues it."""
    config = _config(args)  # validate before anything starts, also before launching workers
    if (args.devices > 1 or args.nodes > 1) and "WORLD_SIZE" not in os.environ:
        return _launch_torchrun(args)
    from ..training.trainer import train

    summary = train(
        config,
        args.data_path,
        args.out,
        split_dir=args.split_dir,
        resume=args.resume,
        accelerator=args.accelerator,
        quiet=args.quiet,
    )
    if int(os.environ.get("RANK", 0)) == 0:
        print(f"trained {summary['steps']} steps in {summary['minutes']:.1f} min → {args.out}")
    return 0


def demo_command(args: argparse.Namespace) -> int:
    """synthetic data → train on the CPU → evaluate → report with plots"""
    from .demo import run_demo

    summary = run_demo(Path(args.out), seed=args.seed)
    print(
        f"report: {Path(args.out) / 'report.md'}  abs_rel {summary['abs_rel']:.3f} "
        f"(untrained {summary['abs_rel_untrained']:.3f}), σ/μ {summary['scale_cv']:.3f}"
    )
    return 0
