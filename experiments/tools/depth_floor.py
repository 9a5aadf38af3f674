"""How hard a network's test depths press against the near end of its depth range (model.min_depth):
the share of predicted pixels within 1.2× that floor, the predicted depths' 95th over 5th percentile
beside the LiDAR's, and the share of LiDAR points nearer than the floor once each frame is scaled by
its median ratio, which the network cannot place where they are. A depth net pinned at its floor
compresses near scenes, and a frame's scale then follows its scene's depth (experiments/investigation.md §11).

    python experiments/tools/depth_floor.py STUDY RUN/checkpoints/last.pt [...]
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch

from posecons.data.gt import load_gt
from posecons.data.splits import read_split
from posecons.errors import PoseconsError
from posecons.evaluation.evaluate import model_disparities
from posecons.inference.backend import load_predictor


def floor_stats(depths: np.ndarray, gts: Sequence[np.ndarray], min_depth: float) -> dict[str, float]:
    """``depths`` (N, h, w) predicted at network size, ``gts`` N LiDAR maps (0 where none)."""
    below = []
    for depth, gt in zip(depths, gts):
        full = torch.nn.functional.interpolate(torch.from_numpy(depth)[None, None], size=gt.shape, mode="bilinear")
        pred, lidar = full[0, 0].numpy()[gt > 0], gt[gt > 0]
        scale = np.median(lidar) / np.median(pred)
        below.append(np.mean(lidar < min_depth * scale))
    near = float(np.mean(depths < 1.2 * min_depth))
    lidar = np.concatenate([gt[gt > 0] for gt in gts])
    spans = [np.percentile(x, 95) / np.percentile(x, 5) for x in (depths.ravel(), lidar)]
    return {
        "near_floor": near,
        "pred_span": spans[0],
        "lidar_span": spans[1],
        "lidar_below_floor": float(np.mean(below)),
    }


def study_inputs(study: Path, checkpoints: Sequence[Path]) -> tuple[list, list[np.ndarray]]:
    """The test split and LiDAR maps of a synthetic ``study`` folder, once every checkpoint is found."""
    if not (study / "gt" / "test_depth.npz").is_file():
        raise PoseconsError(f"{study}: not a study folder with synthetic data (no gt/test_depth.npz)")
    for checkpoint in checkpoints:
        if not checkpoint.is_file():
            raise PoseconsError(f"checkpoint {checkpoint} does not exist")
    gts, _ = load_gt(study / "gt" / "test_depth.npz")
    return read_split(study / "data" / "splits" / "synth" / "test_files.txt"), gts


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("study", type=Path, help="a study folder on synthetic data (data/, gt/test_depth.npz)")
    p.add_argument("checkpoints", nargs="+", type=Path)
    args = p.parse_args()
    try:
        split, gts = study_inputs(args.study, args.checkpoints)
        print("| checkpoint | min_depth | pixels within 1.2× it | depth span p95/p5 (LiDAR) | LiDAR below the floor |")
        print("|---|---:|---:|---:|---:|")
        for checkpoint in args.checkpoints:
            predictor = load_predictor(checkpoint, "cpu")
            depths = 1 / model_disparities(predictor, args.study / "data", split)
            floor = predictor.config.model.min_depth
            s = floor_stats(depths, gts, floor)
            print(
                f"| {checkpoint} | {floor:g} | {s['near_floor']:.1%} | {s['pred_span']:.2f} ({s['lidar_span']:.2f}) "
                f"| {s['lidar_below_floor']:.1%} |"
            )
    except PoseconsError as exc:
        print(f"error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None


if __name__ == "__main__":
    main()
