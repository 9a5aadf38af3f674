"""What the cycle constraint sees on a test sequence, for trained checkpoints (evaluation mode): the
rotation and translation parts of d(T_{i+2n←i}, T_{i+2n←i+n}·T_{i+n←i}) (geometry.pose_distance's two
terms), the skip pair's translation against a step's, |t_skip| / |t_step|, beside the ground truth's
ratio, and the mean step translation (docs/results.md §5).

    python tools/cycle_terms.py --odometry DATA/odometry --sequence 07 RUN/checkpoints/last.pt [...]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch

from posecons.data.kitti_odometry import list_sequence_frames
from posecons.data.trajectory_io import read_kitti_poses
from posecons.geometry import pose_vec_to_mat
from posecons.inference.backend import load_predictor, predict_batches
from posecons.inference.io import frames_from_paths


def cycle_terms(checkpoint: Path, odometry: Path, sequence: str, n: int) -> dict[str, float]:
    predictor = load_predictor(checkpoint, "cpu")
    frames = frames_from_paths(list_sequence_frames(odometry, sequence))
    images = torch.from_numpy(np.concatenate([x for _, x, _ in predict_batches(predictor, frames, 32, depth=False)]))
    a, b, c = images[: -2 * n], images[n:-n], images[2 * n :]
    with torch.no_grad():  # pose_net(x, y) is T_{y←x}
        first, second, skip = (pose_vec_to_mat(*predictor.model.pose_net(x, y)) for x, y in ((a, b), (b, c), (a, c)))
    composed = second @ first
    gt = read_kitti_poses(odometry / "poses" / f"{int(sequence):02d}.txt")
    true_step = np.linalg.norm((np.linalg.inv(gt[n:-n]) @ gt[: -2 * n])[:, :3, 3], axis=1)
    true_skip = np.linalg.norm((np.linalg.inv(gt[2 * n :]) @ gt[: -2 * n])[:, :3, 3], axis=1)
    step = first[:, :3, 3].norm(dim=-1).mean()
    return {
        "rotation_term": float(0.25 * (skip[:, :3, :3] - composed[:, :3, :3]).square().sum((-1, -2)).mean()),
        "translation_term": float((skip[:, :3, 3] - composed[:, :3, 3]).abs().sum(-1).mean()),
        "skip_over_step": float(skip[:, :3, 3].norm(dim=-1).mean() / step),
        "true_skip_over_step": float(true_skip.mean() / true_step.mean()),
        "step": float(step),
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("checkpoints", nargs="+", type=Path)
    p.add_argument("--odometry", type=Path, required=True, help="odometry root (sequences/, poses/)")
    p.add_argument("--sequence", required=True)
    p.add_argument("--offset", type=int, default=3, help="n: the frame offset of a step (the training offset)")
    args = p.parse_args()
    for ckpt in args.checkpoints:
        stats = cycle_terms(ckpt, args.odometry, args.sequence, args.offset)
        print(f"{ckpt}: " + ", ".join(f"{k} {v:.3g}" for k, v in stats.items()))


if __name__ == "__main__":
    main()
