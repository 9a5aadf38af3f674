"""Evaluation runs, the library behind ``evaluate-depth`` / ``evaluate-pose`` and the demo: a model's
predictions (through the one prediction path of :mod:`posecons.inference.backend`) or saved ones →
the metrics of :mod:`posecons.metrics` with their provenance → JSON, plots and trajectory files.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..data.gt import load_gt
from ..data.images import load_rgb
from ..data.kitti_odometry import list_sequence_frames
from ..data.kitti_raw import split_image_paths
from ..data.splits import SplitLine, SplitSource, read_split
from ..data.trajectory_io import read_kitti_poses, write_kitti_poses, write_tum
from ..errors import PoseconsError
from ..inference.backend import Predictor, StepChain, load_predictor, predict_batches
from ..inference.media import frames_from_paths
from ..metrics.depth import (
    CROP_FOR_GT_KIND,
    MAX_DEPTH,
    MIN_DEPTH,
    depth_metrics,
    resize_disparity,
    scale_factors,
)
from ..metrics.pose import align_trajectory, global_from_relative, pose_metrics
from ..plots import (
    plot_depth_examples,
    plot_error_histogram,
    plot_scale_boxplot,
    plot_scale_over_time,
    plot_trajectory_topview,
)


def model_disparities(
    predictor: Predictor, data_path: str | Path, split: SplitSource, batch_size: int = 8, post_process: bool = False
) -> np.ndarray:
    """(N, h, w) float32 scaled disparities at network size of each split line's KITTI raw image."""
    frames = frames_from_paths(split_image_paths(data_path, split))
    batches = predict_batches(predictor, frames, batch_size, post_process=post_process)
    return np.concatenate([disps[:, 0].float().cpu().numpy() for _, _, disps in batches])


def model_steps(predictor: Predictor, paths: Sequence[Path], batch_size: int = 8) -> np.ndarray:
    """(N−1, 4, 4) float64 relative poses T_{i+1←i} of N consecutive images from the pose net."""
    if len(paths) < 2:
        raise PoseconsError(f"pose evaluation needs at least 2 frames, got {len(paths)}")
    chain = StepChain(predictor)
    for _, images, _ in predict_batches(predictor, frames_from_paths(paths), batch_size, depth=False):
        chain.add(images)
    return chain.steps()


def load_pred_disps(path: Path) -> np.ndarray:
    """Disparities from a ``.npy`` file (no pickles)."""
    if not path.is_file():
        raise PoseconsError(f"{path}: predictions file not found")
    try:
        return np.load(path, allow_pickle=False)
    except (ValueError, OSError):  # numpy's own text suggests unpickling, which is never wanted here
        raise PoseconsError(f"{path}: not a .npy array of numbers (damaged, or not written by numpy.save)") from None


def evaluate_depth(
    disps: np.ndarray,
    gts: Sequence[np.ndarray],
    lines: Sequence[SplitLine],
    gt_kind: str = "lidar",
    pred_name: str = "predictions",
    **options: Any,
) -> dict:
    """:func:`~posecons.metrics.depth.depth_metrics` of (N, h, w) disparities against N GT maps of the
    N split ``lines`` (which give the sequences), with the crop of ``gt_kind`` and its other
    ``options`` (``scaling``, ``gt_name``, ``scale_factor``, ``depth_range``); ``gt_kind``, ``predictions`` and
    ``skipped_lines`` added."""
    sequences = [s.folder for s in lines]
    result = depth_metrics(disps, gts, sequences, crop=CROP_FOR_GT_KIND[gt_kind], pred_name=pred_name, **options)
    result.update(gt_kind=gt_kind, predictions=pred_name, skipped_lines=[str(lines[i]) for i in result["skipped"]])
    return result


def eigen_to_benchmark(disps: np.ndarray, lines: Sequence[SplitLine], pred_name: str = "predictions") -> np.ndarray:
    """The disparities of the bundled Eigen test split (all its frames, in its order) that belong to
    ``lines``, in their order — the 652 eigen_benchmark frames, scored against the improved ground
    truth, as Monodepth2's ``--eval_eigen_to_benchmark``."""
    eigen = {str(line): i for i, line in enumerate(read_split("eigen"))}
    if len(disps) != len(eigen):
        raise PoseconsError(f"{pred_name} has {len(disps)} frames, not the {len(eigen)} of the Eigen test split")
    for line in lines:
        if str(line) not in eigen:
            raise PoseconsError(f"{line.where}: '{line}' is not a frame of the Eigen test split")
    return disps[[eigen[str(line)] for line in lines]]


def evaluate_pose(
    estimate: np.ndarray,
    gt: np.ndarray,
    const_velocity: str = "first",
    pred_name: str = "predictions",
    gt_name: str = "ground truth",
    alignment: str = "7dof",
) -> dict:
    """:func:`~posecons.metrics.pose.pose_metrics` of (N, 4, 4) camera → world poses, with provenance."""
    result = pose_metrics(estimate, gt, const_velocity, alignment)
    result.update(predictions=pred_name, ground_truth=gt_name)
    return result


def segments_note(result: dict) -> str:
    """How a pose result's t_err / r_err were measured, in words: alignment, segment count and lengths."""
    lengths = result["segment_lengths"]
    if not lengths:
        return f"{result['alignment']} alignment, no segment (the ground truth never moves)"
    kind = "the devkit's" if result["devkit_lengths"] else "10–80 % of a path under 100 m, not the devkit's"
    return (
        f"{result['alignment']} alignment, {result['n_segments']} segments of "
        f"{lengths[0]:.4g}–{lengths[-1]:.4g} m ({kind} lengths)"
    )


def _loaded(weights: str | Path | Predictor) -> tuple[Predictor, str]:
    """(predictor, the name its results carry) of networks already loaded, or of a path loaded here."""
    if isinstance(weights, Predictor):
        return weights, weights.name
    return load_predictor(weights, "auto"), str(weights)


def checkpoint_depth(
    checkpoint: str | Path | Predictor,
    data_path: Path,
    split: Sequence[SplitLine],
    gt_path: Path,
    scalings: Sequence[str] = ("frame",),
    gt_kind: str = "lidar",
    depth_range: tuple[float, float] | None = None,
) -> dict[str, dict]:
    """{scaling: :func:`evaluate_depth`} of a checkpoint's disparities (predicted once) on the ``split``
    lines against the ground truth in ``gt_path`` (exported LiDAR, or ``gt_kind`` "dense" with its
    ``depth_range``; ``checkpoint``: a path, or networks already loaded)."""
    gts, _ = load_gt(gt_path)
    predictor, name = _loaded(checkpoint)
    disps = model_disparities(predictor, data_path, split)
    return {
        s: evaluate_depth(
            disps, gts, split, gt_kind, scaling=s, pred_name=name, gt_name=str(gt_path), depth_range=depth_range
        )
        for s in scalings
    }


def checkpoint_pose(
    checkpoint: str | Path | Predictor, odometry: Path, sequence: str, out_dir: Path | None = None
) -> dict:
    """:func:`evaluate_pose` (snippet ATE, full ATE, t_err / r_err, constant-velocity baseline) of a checkpoint's
    chained steps on odometry ``sequence`` (ground truth ``odometry/poses/<NN>.txt``); with ``out_dir``
    also its trajectory files and top view (:func:`write_trajectories`)."""
    gt_file = Path(odometry) / "poses" / f"{int(sequence):02d}.txt"
    gt = read_kitti_poses(gt_file)
    predictor, name = _loaded(checkpoint)
    steps = model_steps(predictor, list_sequence_frames(odometry, sequence))
    estimate = global_from_relative(steps)
    if out_dir is not None:
        write_trajectories(out_dir, estimate, gt)
    return evaluate_pose(estimate, gt, pred_name=name, gt_name=str(gt_file))


def write_depth_plots(result: dict, lines: Sequence[SplitLine], out_dir: Path) -> None:
    """Scale box plot, scale over time and abs rel histogram of a depth result into ``out_dir``."""
    seqs, frames = [s.folder for s in lines], [s.frame for s in lines]
    plot_scale_boxplot(result["scales"], seqs, out_dir / "scale_boxplot.png")
    plot_scale_over_time(result["scales"], seqs, frames, out_dir / "scale_over_time.png")
    plot_error_histogram(result["per_frame_abs_rel"], out_dir / "abs_rel_histogram.png")


def write_depth_examples(
    result: dict,
    disps: np.ndarray,
    gts: Sequence[np.ndarray],
    lines: Sequence[SplitLine],
    data_path: str | Path,
    out_dir: Path,
) -> None:
    """``examples.png``: the evaluated frames of lowest, median and highest abs rel, each as its image,
    its ground truth and the prediction with the result's scaling (clamped to its depth range)."""
    abs_rel = np.asarray(result["per_frame_abs_rel"])
    ranked = [int(i) for i in np.argsort(np.nan_to_num(abs_rel, nan=np.inf)) if np.isfinite(abs_rel[i])]
    picks = list(dict.fromkeys((ranked[0], ranked[len(ranked) // 2], ranked[-1])))
    factors = scale_factors(
        np.asarray(result["scales"]), [s.folder for s in lines], result["scaling"], result["scale_factor"]
    )
    paths = split_image_paths(data_path, [lines[i] for i in picks])
    rows = []
    for i, path in zip(picks, paths):
        gt = np.asarray(gts[i], dtype=np.float32)
        pred = np.clip(
            factors[i] / resize_disparity(disps[i], *gt.shape), *(result["depth_range"] or (MIN_DEPTH, MAX_DEPTH))
        )
        title = f"{lines[i]}: abs rel {abs_rel[i]:.3f}"
        rows.append({"title": title, "image": np.asarray(load_rgb(path)), "gt": gt, "pred": pred})
    plot_depth_examples(rows, out_dir / "examples.png")


def write_trajectories(out_dir: Path, estimate: np.ndarray, gt: np.ndarray, times: np.ndarray | None = None) -> None:
    """(N, 4, 4) estimate (KITTI and TUM), GT (TUM) and a top view of the Sim(3)-aligned estimate."""
    out_dir.mkdir(parents=True, exist_ok=True)
    write_kitti_poses(out_dir / "trajectory_kitti.txt", estimate)
    write_tum(out_dir / "trajectory_tum.txt", estimate, times)
    write_tum(out_dir / "gt_tum.txt", gt, times)
    aligned, _ = align_trajectory(estimate, gt)
    plot_trajectory_topview(aligned, out_dir / "trajectory.png", gt, "prediction (Sim(3)-aligned)")
