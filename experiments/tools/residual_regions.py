"""Where in the image a frame's scale comes from. For each LiDAR point of the evaluated pixels (Garg
crop, as `evaluate-depth`), r = log(gt / pred) less the median r over the whole test split, so that
0 is the split's one scale and a frame's log scale is about its points' median r. Printed: the median
r of each region (image column fifths, four row bands of the crop, LiDAR depth bins), averaged over
blocks of the split's lines in order (pick --block so that none straddles two drives; the synthetic
test drives have 100 frames), with each region's share of the points. A block whose r departs in one
region only points at what the network misjudges there (experiments/investigation.md §20).

    python experiments/tools/residual_regions.py STUDY RUN/checkpoints/last.pt [--block 10] [--depth-bins 8 16 32]
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from depth_floor import study_inputs  # the sibling tool's checks of a study folder

from posecons.errors import PoseconsError
from posecons.evaluation.evaluate import model_disparities
from posecons.inference.backend import load_predictor
from posecons.metrics.depth import garg_crop_bounds, resize_disparity, valid_mask


def point_residuals(disp: np.ndarray, gt: np.ndarray) -> dict[str, np.ndarray]:
    """One frame's evaluated LiDAR points: column and row as fractions of the crop, depth, log(gt/pred)."""
    mask = valid_mask(gt, "garg")
    pred = 1 / resize_disparity(disp, *gt.shape)
    top, bottom, left, right = garg_crop_bounds(*gt.shape)
    rows, cols = np.nonzero(mask)
    return {
        "column": (cols - left) / (right - left),
        "row": (rows - top) / (bottom - top),
        "depth": gt[mask],
        "r": np.log(gt[mask] / pred[mask]),
    }


def region_table(frames: Sequence[dict], block: int, edges: dict[str, Sequence[float]]) -> dict[str, np.ndarray]:
    """{region kind: (blocks, bins, 2) of [mean over the block's frames of the bin's median r, its share
    of the frame's points]}; r less the median over every frame; NaN where a block has no point in a bin."""
    centre = np.median(np.concatenate([f["r"] for f in frames]))
    out = {}
    for kind, bounds in edges.items():
        table = np.full((int(np.ceil(len(frames) / block)), len(bounds) - 1, 2), np.nan)
        for b in range(table.shape[0]):
            for k, (lo, hi) in enumerate(zip(bounds[:-1], bounds[1:])):
                inside = [(f["r"], (f[kind] >= lo) & (f[kind] < hi)) for f in frames[b * block : (b + 1) * block]]
                medians = [np.median(r[m]) - centre for r, m in inside if m.any()]
                if medians:
                    table[b, k] = np.mean(medians), np.mean([m.mean() for _, m in inside])
        out[kind] = table
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("study", type=Path, help="a study folder on synthetic data (data/, gt/test_depth.npz)")
    p.add_argument("checkpoints", nargs="+", type=Path)
    p.add_argument("--block", type=int, default=10, help="consecutive test frames averaged in a row (default 10)")
    p.add_argument("--depth-bins", type=float, nargs="+", default=[8, 16, 32], help="LiDAR depth bin edges, m")
    args = p.parse_args()
    edges = {
        "column": np.linspace(0, 1, 6),
        "row": np.linspace(0, 1, 5),
        "depth": [0, *args.depth_bins, np.inf],
    }
    edges["column"][-1] = edges["row"][-1] = 1 + 1e-9  # the crop's last pixel in its last bin
    try:
        if args.block < 1:
            raise PoseconsError(f"--block {args.block}: must be at least 1")
        if min(args.depth_bins) <= 0 or sorted(set(args.depth_bins)) != args.depth_bins:
            raise PoseconsError(f"--depth-bins {args.depth_bins}: must be positive and increasing")
        split, gts = study_inputs(args.study, args.checkpoints)
        for checkpoint in args.checkpoints:
            disps = model_disparities(load_predictor(checkpoint, "cpu"), args.study / "data", split)
            table = region_table([point_residuals(d, g) for d, g in zip(disps, gts)], args.block, edges)
            print(f"\n{checkpoint}: median log(gt/pred) less the split's, by block of {args.block} frames")
            for kind, bounds in edges.items():
                heads = " | ".join(f"{lo:g}–{hi:.3g}" for lo, hi in zip(bounds[:-1], bounds[1:]))
                print(f"\n| {kind}: frames | {heads} |\n|---|" + "---:|" * (len(bounds) - 1))
                for b, row in enumerate(table[kind]):
                    cells = " | ".join(f"{r:+.3f} ({share:.2f})" for r, share in row)
                    print(f"| {b * args.block}–{min((b + 1) * args.block, len(gts)) - 1} | {cells} |")
    except PoseconsError as exc:
        print(f"error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None


if __name__ == "__main__":
    main()
