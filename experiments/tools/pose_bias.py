"""How a checkpoint's pose net moves on a test sequence: whether its translation follows the true
motion (correlation of |t| with the true distance, cosine with the true direction), whether its
rotation does (correlation of the angle with the true angle, their mean ratio, cosine of the axes,
also weighted by the angles, and the slope of the yaw on the true yaw: what hand-held, rotation-heavy
motion and turns test), and whether its
mirror-odd outputs — sideways translation t_x, yaw and roll — flip sign for mirrored frames, as they
must for a horizontally symmetric world. A pose net that outputs the same t_x for a pair and for its
mirror image has learnt a constant bias, not motion (docs/results.md). For the depth net: the mean
disparity of the left and right image halves, and how far the depth of the mirrored frame, mirrored
back, is from the frame's own (0 for a mirror-symmetric network). For the cycle constraint: the
rotation and translation parts of d(T_{i+2s←i}, T_{i+2s←i+s}·T_{i+s←i}) (geometry.pose_distance's two
terms) and the skip pair's translation against a step's, beside the ground truth's ratio
(experiments/investigation.md §5).

    python experiments/tools/pose_bias.py --odometry DATA/odometry --sequence 05 RUN/checkpoints/last.pt [...]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from posecons.data.kitti_odometry import list_sequence_frames
from posecons.data.trajectory_io import read_kitti_poses
from posecons.geometry import pose_distance_terms, pose_vec_to_mat
from posecons.inference.backend import load_predictor, predict_batches
from posecons.inference.media import frames_from_paths


def pose_bias(checkpoint: Path, odometry: Path, sequence: str, stride: int) -> dict[str, float]:
    """Statistics of T_{i+stride←i} from the pose net against the ground truth, for the frames and
    their mirror images."""
    predictor = load_predictor(checkpoint, "cpu")
    frames = frames_from_paths(list_sequence_frames(odometry, sequence))
    images = torch.from_numpy(np.concatenate([x for _, x, _ in predict_batches(predictor, frames, 32, depth=False)]))
    gt = read_kitti_poses(odometry / "poses" / f"{int(sequence):02d}.txt")
    relative = np.linalg.inv(gt[stride:]) @ gt[:-stride]  # T_{i+s←i}
    true, true_rot = relative[:, :3, 3], Rotation.from_matrix(relative[:, :3, :3]).as_rotvec()
    a, b = images[:-stride], images[stride:]
    with torch.no_grad():
        rot, t = (x[:, 0].double().numpy() for x in predictor.model.pose_net(a, b))
        rot_m, t_m = (x[:, 0].double().numpy() for x in predictor.model.pose_net(a.flip(-1), b.flip(-1)))
        disp = predictor.model.depth_net(images)[0]
        disp_m = predictor.model.depth_net(images.flip(-1))[0].flip(-1)
    norm = np.linalg.norm(t, axis=1)
    angle, true_angle = np.linalg.norm(rot, axis=1), np.linalg.norm(true_rot, axis=1)
    cycle = cycle_terms(predictor.model.pose_net, images, gt, stride)
    half = disp.shape[-1] // 2
    return {
        "corr_speed": float(np.corrcoef(norm, np.linalg.norm(true, axis=1))[0, 1]),
        "cos_direction": float(np.mean((t * true).sum(1) / norm / np.linalg.norm(true, axis=1))),
        "tx_over_t": float(np.mean(t[:, 0] / norm)),
        "tx_over_t_mirrored": float(np.mean(t_m[:, 0] / np.linalg.norm(t_m, axis=1))),
        "corr_angle": float(np.corrcoef(angle, true_angle)[0, 1]),
        "angle_over_true": float(angle.mean() / true_angle.mean()),
        "cos_axis": float(np.mean((rot * true_rot).sum(1) / angle / true_angle)),
        # Weighted by the angles: on a straight drive the mean above is over axes of near-zero turns
        "cos_axis_weighted": float((rot * true_rot).sum() / (angle * true_angle).sum()),
        "yaw_slope": float(np.polyfit(true_rot[:, 1], rot[:, 1], 1)[0]),  # 1: the true yaw, turn for turn
        "yaw_mrad": 1e3 * float(rot[:, 1].mean()),
        "yaw_mrad_mirrored": 1e3 * float(rot_m[:, 1].mean()),
        "disp_left": float(disp[..., :half].mean()),
        "disp_right": float(disp[..., half:].mean()),
        "disp_mirror_gap": float((disp - disp_m).abs().mean()),
        **cycle,
    }


def cycle_terms(pose_net, images: torch.Tensor, gt: np.ndarray, n: int) -> dict[str, float]:
    """The cycle distance's two terms over the sequence's triplets (i, i+n, i+2n), the skip pair's
    mean translation over a step's, the true ratio, and the mean step translation."""
    a, b, c = images[: -2 * n], images[n:-n], images[2 * n :]
    with torch.no_grad():  # pose_net(x, y) is T_{y←x}
        first, second, skip = (pose_vec_to_mat(*pose_net(x, y)) for x, y in ((a, b), (b, c), (a, c)))
    rotation, translation = pose_distance_terms(skip, second @ first)
    true_step = np.linalg.norm((np.linalg.inv(gt[n:-n]) @ gt[: -2 * n])[:, :3, 3], axis=1)
    true_skip = np.linalg.norm((np.linalg.inv(gt[2 * n :]) @ gt[: -2 * n])[:, :3, 3], axis=1)
    step = first[:, :3, 3].norm(dim=-1).mean()
    return {
        "cycle_rotation_term": float(rotation.mean()),
        "cycle_translation_term": float(translation.mean()),
        "skip_over_step": float(skip[:, :3, 3].norm(dim=-1).mean() / step),
        "true_skip_over_step": float(true_skip.mean() / true_step.mean()),
        "step": float(step),
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("checkpoints", nargs="+", type=Path)
    p.add_argument("--odometry", type=Path, required=True, help="odometry root (sequences/, poses/)")
    p.add_argument("--sequence", required=True)
    p.add_argument("--stride", type=int, default=3, help="frame offset of the pairs (the training offset)")
    args = p.parse_args()
    for ckpt in args.checkpoints:
        stats = pose_bias(ckpt, args.odometry, args.sequence, args.stride)
        print(f"{ckpt}: " + ", ".join(f"{k} {v:+.3g}" for k, v in stats.items()))


if __name__ == "__main__":
    main()
