"""Which pixels Monodepth2's auto-mask drops, by their true depth: a trained checkpoint's training loss
is computed on synthetic training frames (no augmentation, evaluation mode) and, for bins of the
renderer's exact depth, the share of pixels where a warped source beats the unwarped ones (the pixels
that train the depth) is printed. A mask that drops far pixels more than near ones leaves far depth
to the network's prior, one explanation of the compression of far scenes (experiments/investigation.md §4).

    python experiments/tools/automask_depth.py runs/study_fast/runs/baseline/seed6/checkpoints/last.pt runs/study_fast/data --lines 96
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import DataLoader

from posecons.checkpoint import load_model
from posecons.data.datasets import build_dataset
from posecons.data.splits import SplitLine
from posecons.data.synth.oracle import oracle_disparities
from posecons.errors import PoseconsError

EDGES = (0.0, 10.0, 20.0, 40.0, 80.0, np.inf)  # metres; beyond 80: sky and the far ends of streets


def warped_share_by_depth(checkpoint: Path, data: Path, lines: int, entry: str) -> list[tuple[str, float, float]]:
    """[(depth bin, its share of the pixels, the share of its pixels the auto-mask keeps)] over
    ``lines`` training lines spread evenly over the synthetic training split."""
    model, config = load_model(checkpoint, "cpu", entry)
    split = data / "splits" / config.data.split / "train_files.txt"
    dataset = build_dataset(config, data, split, train=False)
    picked = np.linspace(0, len(dataset) - 1, lines).round().astype(int).tolist()
    loader = DataLoader(torch.utils.data.Subset(dataset, picked), batch_size=config.train.batch_size)
    kept, depth = [], []
    with torch.no_grad():
        for batch in loader:
            outputs = model(batch, with_constraints=False)[0]
            kept.append(outputs["automask"].reshape(len(batch["frame"]), -1).numpy())
            where = [SplitLine(f, int(i), s) for f, i, s in zip(batch["folder"], batch["frame"], batch["side"])]
            disp = oracle_disparities(data, where, config.model.height, config.model.width)
            depth.append(1.0 / disp.reshape(len(where), -1))
    kept, depth = np.concatenate(kept).ravel(), np.concatenate(depth).ravel()
    rows = []
    for lo, hi in zip(EDGES[:-1], EDGES[1:]):
        inside = (depth >= lo) & (depth < hi)
        rows.append((f"{lo:g}–{hi:g} m", float(inside.mean()), float(kept[inside].mean()) if inside.any() else np.nan))
    return rows


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("checkpoints", type=Path, nargs="+", help="checkpoints trained on the synthetic data")
    p.add_argument("data", type=Path, help="the synthetic data they trained on (`posecons synth` output)")
    p.add_argument("--lines", type=int, default=96, help="training lines to use (default 96)")
    p.add_argument("--entry", default="model", help="the checkpoint's weights: model (EMA) or raw_model")
    args = p.parse_args()
    if args.lines < 1:
        p.exit(2, f"error: --lines: must be at least 1, got {args.lines}\n")
    try:
        for checkpoint in args.checkpoints:
            rows = warped_share_by_depth(checkpoint, args.data, args.lines, args.entry)  # before any output
            print(
                f"{checkpoint} ({args.entry})\n| true depth | share of pixels | kept by the auto-mask |\n|---|---|---|"
            )
            for name, share, kept in rows:
                print(f"| {name} | {share:.3f} | {kept:.3f} |")
    except PoseconsError as exc:
        print(f"error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None


if __name__ == "__main__":
    main()
