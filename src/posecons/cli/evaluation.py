"""Sub-commands ``evaluate-depth``, ``evaluate-pose`` and ``compare``: argument checks and printing
over :mod:`posecons.evaluation.evaluate` and :mod:`posecons.evaluation.compare`."""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from ..errors import PoseconsError
from ..fileio import atomic_write, write_json, write_text

# metrics are light (numpy); the evaluation runs, torch and the data layer load inside the commands.
from ..metrics import depth, pose
from .arguments import (
    add_command,
    device_name,
    non_negative_int,
    output_file,
    output_folder,
    positive_float,
    positive_int,
)


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the evaluation sub-commands to the ``posecons`` parser."""
    p = add_command(subparsers, "evaluate-depth", evaluate_depth_command)
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument(
        "--pred-disps", type=Path, metavar="P.npy", help="(N, h, w) float32 scaled disparities, split order"
    )
    src.add_argument("--checkpoint", type=Path, metavar="CKPT", help="model checkpoint (.pt or .safetensors)")
    p.add_argument(
        "--gt",
        type=Path,
        metavar="GT.npz",
        help="exported ground truth, or Monodepth2's gt_depths.npz with its --split-file (required with "
        "--pred-disps; with --checkpoint it is exported on the fly when missing)",
    )
    p.add_argument("--data-path", type=Path, help="KITTI raw root (with --checkpoint)")
    p.add_argument("--split-file", type=Path, help="split lines; gives the sequences (default: the GT's lines)")
    p.add_argument(
        "--scaling", choices=depth.SCALINGS, default="frame", help="median scaling per frame, per sequence, or none"
    )
    p.add_argument(
        "--scale-factor",
        type=positive_float,
        metavar="F",
        help="with --scaling none: multiply every depth by F (Monodepth2's 5.4 for stereo-trained models)",
    )
    p.add_argument(
        "--gt-kind",
        choices=tuple(depth.CROP_FOR_GT_KIND),
        help="lidar (default): Garg crop, 1e-3 < gt < 80 m; improved (default with --eigen-to-benchmark): "
        "gt > 0, no crop; dense (an RGB-D camera's depth images, e.g. the gt_depths.npz of prepare-rgbd): "
        "no crop, --min-depth < gt < --max-depth",
    )
    p.add_argument(
        "--min-depth",
        type=positive_float,
        metavar="M",
        help="metres: evaluate only ground truth above M, clamp predictions to at least M (default 1e-3)",
    )
    p.add_argument(
        "--max-depth",
        type=positive_float,
        metavar="M",
        help="metres: evaluate only ground truth below M, clamp predictions to at most M (default 80, KITTI's; "
        "--gt-kind dense needs it, e.g. 10 indoors)",
    )
    p.add_argument(
        "--eigen-to-benchmark",
        action="store_true",
        help="--pred-disps holds the Eigen test split's frames: score those of the GT's lines "
        "(eigen_benchmark) against the improved ground truth",
    )
    p.add_argument("--post-process", action="store_true", help="average with the flipped image's prediction")
    p.add_argument("--save-disps", type=output_file, metavar="OUT.npy", help="save the model's disparities")
    _add_model_options(p)
    p.add_argument("--json", type=output_file, metavar="OUT", help="write the results as JSON")
    p.add_argument("--plots", type=output_folder, metavar="DIR", help="plots (PNG), with --data-path also examples.png")

    p = add_command(subparsers, "evaluate-pose", evaluate_pose_command)
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--pred-poses", type=Path, metavar="P.txt", help="KITTI pose file, camera → world")
    src.add_argument("--checkpoint", type=Path, metavar="CKPT", help="model checkpoint (.pt or .safetensors)")
    p.add_argument("--gt-poses", type=Path, required=True, metavar="G.txt", help="KITTI ground-truth pose file")
    p.add_argument("--data-path", type=Path, help="KITTI odometry root with sequences/ (with --checkpoint)")
    p.add_argument("--sequence", type=non_negative_int, help="odometry sequence, e.g. 09 (with --checkpoint)")
    p.add_argument("--times", type=Path, help="times.txt (seconds) for the TUM timestamps (default: frame / 10 Hz)")
    p.add_argument(
        "--const-velocity",
        choices=pose.CONST_VELOCITY_MODES,
        default="first",
        help="baseline: repeat the first GT step, or the previous GT step",
    )
    p.add_argument(
        "--align",
        choices=pose.ALIGNMENTS,
        default="7dof",
        help="alignment before t_err / r_err: Sim(3) (monocular), SE(3) (metric: the devkit's own numbers) or "
        "scale (one factor fitted on the positions, kitti-odom-eval's --align scale)",
    )
    _add_model_options(p)
    p.add_argument("--json", type=output_file, metavar="OUT", help="write the results as JSON")
    p.add_argument(
        "--out-dir", type=output_folder, metavar="DIR", help="write trajectories (KITTI, TUM) and a top-view plot"
    )

    p = add_command(subparsers, "compare", compare_command)
    p.add_argument("results", nargs="+", type=Path, metavar="RUN_OR_JSON")
    p.add_argument("--names", nargs="+", help="row names (default: run directory or file name)")
    p.add_argument("--out", type=output_file, metavar="FILE", help="also write the table to FILE")


def _add_model_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--batch-size", type=positive_int, default=8, help="images per forward pass (with --checkpoint)")
    p.add_argument(
        "--device", type=device_name, default=None, help="torch device (default: cuda if available, else cpu)"
    )


def _require(args: argparse.Namespace, *names: str) -> None:
    missing = [f"--{n.replace('_', '-')}" for n in names if getattr(args, n) is None]
    if missing:
        raise PoseconsError(f"--checkpoint needs {' and '.join(missing)}")


def _predictor(args: argparse.Namespace):
    from ..inference.backend import load_predictor

    return load_predictor(args.checkpoint, args.device or "auto")


def _ground_truth(args: argparse.Namespace, tmp: Path) -> tuple[list[np.ndarray], list[str] | None, Path]:
    """GT depth maps, their split lines (None: Monodepth2's file, which has none) and the file they
    came from (exported into tmp if needed)."""
    from ..data.gt import export_gt, load_gt

    gt_path = args.gt
    if gt_path is None:
        gt_path = tmp / "gt_depths.npz"
        export_gt(args.data_path, args.split_file, gt_path, improved=args.gt_kind == "improved")
    gts, lines = load_gt(gt_path)
    if lines is None and args.split_file is None:
        raise PoseconsError(
            f"{gt_path}: Monodepth2's ground truth names no frames; pass --split-file, the test_files.txt it was made from"
        )
    return list(gts), lines, gt_path


def evaluate_depth_command(args: argparse.Namespace) -> int:
    """KITTI depth metrics (Eigen protocol) and scale consistency

    Evaluate predicted disparities (or a model) against ground-truth depth."""
    from ..checkpoint import describe_checkpoint
    from ..data.splits import read_split
    from ..evaluation import compare, evaluate

    if args.checkpoint is None and args.gt is None:
        raise PoseconsError("--pred-disps needs --gt (an exported ground-truth .npz)")
    if args.scale_factor is not None and args.scaling != "none":
        raise PoseconsError("--scale-factor needs --scaling none (it replaces median scaling)")
    if args.eigen_to_benchmark and args.checkpoint is not None:
        raise PoseconsError(
            "--eigen-to-benchmark picks from saved Eigen predictions (--pred-disps); with --checkpoint "
            "pass --split-file eigen_benchmark/test_files.txt --gt-kind improved"
        )
    if args.eigen_to_benchmark and args.gt_kind not in (None, "improved"):
        raise PoseconsError(
            f"--eigen-to-benchmark scores against the improved ground truth, not --gt-kind {args.gt_kind}"
        )
    gt_kind = args.gt_kind or ("improved" if args.eigen_to_benchmark else "lidar")
    if gt_kind == "dense" and args.gt is None:
        raise PoseconsError("--gt-kind dense needs --gt (depth maps, e.g. the gt_depths.npz of prepare-rgbd)")
    if gt_kind == "dense" and args.max_depth is None:
        raise PoseconsError("--gt-kind dense needs --max-depth: the camera's depth range (metres, e.g. 10 indoors)")
    depth_range = None
    if args.min_depth is not None or args.max_depth is not None:
        depth_range = (args.min_depth or depth.MIN_DEPTH, args.max_depth or depth.MAX_DEPTH)
        if depth_range[0] >= depth_range[1]:
            raise PoseconsError(f"--min-depth {depth_range[0]:g} must be below --max-depth {depth_range[1]:g}")
    if args.checkpoint is not None:
        _require(args, "data_path", "split_file")
    with tempfile.TemporaryDirectory() as tmp:
        gts, gt_lines, gt_path = _ground_truth(args, Path(tmp))
    split = read_split(args.split_file if args.split_file else gt_lines)
    if len(split) != len(gts):
        raise PoseconsError(f"{args.split_file} has {len(split)} lines but {gt_path} has {len(gts)} frames")
    for line, stored in zip(split, read_split(gt_lines or [])):  # the same frames in the same order, not just as many
        if str(line) != str(stored):
            raise PoseconsError(
                f"{line.where}: '{line}' does not match line '{stored}' that {gt_path} was "
                "exported for; pass the split file the ground truth was exported from"
            )
    if args.checkpoint is not None:
        disps = evaluate.model_disparities(_predictor(args), args.data_path, split, args.batch_size, args.post_process)
        pred_name = str(args.checkpoint)
        if args.save_disps:
            atomic_write(args.save_disps, lambda tmp: np.save(tmp, disps))
    else:
        disps, pred_name = evaluate.load_pred_disps(args.pred_disps), str(args.pred_disps)
        if args.eigen_to_benchmark:
            disps = evaluate.eigen_to_benchmark(disps, split, pred_name)

    result = evaluate.evaluate_depth(
        disps,
        gts,
        split,
        gt_kind,
        pred_name,
        scaling=args.scaling,
        gt_name=str(gt_path),
        scale_factor=args.scale_factor or 1.0,
        depth_range=depth_range,
    )
    if args.checkpoint is not None:
        result.update(checkpoint=describe_checkpoint(args.checkpoint))
    result.update(
        ground_truth=str(args.gt or "exported on the fly"),
        post_process=bool(args.checkpoint and args.post_process),
        eigen_to_benchmark=args.eigen_to_benchmark,
    )
    print(compare.results_table([result], [Path(pred_name).stem], bold=False), end="")
    print(
        f"{result['n_frames']} frames, scaling {result['scaling']}"
        + (f" × {result['scale_factor']:g}" if result["scale_factor"] != 1 else "")
        + (f", depth range {depth_range[0]:g}–{depth_range[1]:g} m" if depth_range else "")
        + f", {result['n_skipped']} skipped (no valid GT); "
        f"scales: median {result['scale_median']:.3f}, std/median {result['scale_std_over_median']:.3f}, "
        f"σ/μ pooled {result['scale_cv_pooled']:.3f}"
    )
    if args.json:
        write_json(args.json, result)
    if args.plots:
        evaluate.write_depth_plots(result, split, args.plots)
        if args.data_path is not None:  # the images are there: three frames beside their ground truth
            evaluate.write_depth_examples(result, disps, gts, split, args.data_path, args.plots)
    return 0


def evaluate_pose_command(args: argparse.Namespace) -> int:
    """snippet ATE, full ATE, KITTI t_err / r_err and a constant-velocity baseline

    Evaluate predicted ego-motion against KITTI odometry poses."""
    from ..data import trajectory_io
    from ..evaluation import compare, evaluate

    gt = trajectory_io.read_kitti_poses(args.gt_poses)
    n_gt_poses = len(gt)
    times = trajectory_io.read_times(args.times) if args.times else None
    if times is not None and len(times) != len(gt):
        raise PoseconsError(f"{args.times} has {len(times)} timestamps but {args.gt_poses} has {len(gt)} poses")
    if args.checkpoint is not None:
        from ..checkpoint import describe_checkpoint
        from ..data.kitti_odometry import list_sequence_frames

        _require(args, "data_path", "sequence")
        paths = list_sequence_frames(args.data_path, args.sequence)
        if len(paths) != len(gt):
            raise PoseconsError(
                f"{len(paths)} images in sequence {args.sequence} but {len(gt)} poses in {args.gt_poses}"
            )
        steps = evaluate.model_steps(_predictor(args), paths, args.batch_size)
        estimate, source = pose.global_from_relative(steps), str(args.checkpoint)
        checkpoint = describe_checkpoint(args.checkpoint)
    else:
        estimate, source = trajectory_io.read_kitti_poses(args.pred_poses), str(args.pred_poses)
        if len(estimate) > len(gt):
            raise PoseconsError(f"{args.pred_poses} has {len(estimate)} poses but {args.gt_poses} has {len(gt)}")
        if len(estimate) < len(gt):  # kitti-odom-eval scores the frames a prediction has
            print(
                f"scoring the first {len(estimate)} of the {len(gt)} poses of {args.gt_poses}: "
                f"{args.pred_poses} has {len(estimate)} (as kitti-odom-eval does)"
            )
            gt = gt[: len(estimate)]
            times = None if times is None else times[: len(estimate)]
        checkpoint = None

    result = evaluate.evaluate_pose(estimate, gt, args.const_velocity, source, str(args.gt_poses), args.align)
    result.update(n_gt_poses=n_gt_poses)  # of which the first n_frames were scored
    if checkpoint:
        result.update(checkpoint=checkpoint)
        print(f"weights: {compare.checkpoint_note(checkpoint)}")
    for name, r in (("prediction", result), (f"const. velocity ({args.const_velocity})", result["const_velocity"])):
        print(
            f"{name:>26}: snippet ATE {r['ate_mean']:.4f} ± {r['ate_std']:.4f} ({r['n_snippets']} snippets) | "
            f"full ATE (Sim3) {r['ate_full_rmse']:.3f} m | t_err {r['t_err']:.2f} % r_err {r['r_err']:.2f} °/100 m"
        )
    print(f"t_err / r_err: {evaluate.segments_note(result)}")
    if args.json:
        write_json(args.json, result)
    if args.out_dir:
        evaluate.write_trajectories(args.out_dir, estimate, gt, times)
    return 0


def compare_command(args: argparse.Namespace) -> int:
    """Markdown table (paper's Table 1 layout) from depth JSONs

    Compare depth evaluations; a run directory means <run>/eval/depth.json."""
    from ..evaluation import compare

    results = [compare.load_result(path) for path in args.results]
    names = args.names or [compare.default_name(path) for path in args.results]
    table = compare.results_table(results, names)
    print(table, end="")
    if args.out:
        write_text(args.out, table)
    return 0
