"""Sub-commands ``evaluate-depth``, ``evaluate-pose`` and ``compare``: thin wrappers that read
files, call the library functions of this package and write JSON / plots / trajectories."""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from ..cli import device_name, non_negative_int, output_file, output_folder, positive_int
from ..errors import PoseconsError
from ..fileio import atomic_write, write_json, write_text

# depth and pose are light (numpy); plots, torch and the data layer load inside the commands.
from . import depth, pose


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the evaluation sub-commands to the ``posecons`` parser."""
    p = subparsers.add_parser("evaluate-depth", help="KITTI depth metrics (Eigen protocol) and scale consistency",
                              description="Evaluate predicted disparities (or a model) against ground-truth depth.")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--pred-disps", type=Path, metavar="P.npy",
                     help="(N, h, w) float32 scaled disparities, split order")
    src.add_argument("--checkpoint", type=Path, metavar="CKPT", help="model checkpoint (.pt or .safetensors)")
    p.add_argument("--gt", type=Path, metavar="GT.npz", help="exported ground truth (required with --pred-disps; "
                   "with --checkpoint it is exported on the fly when missing)")
    p.add_argument("--data-path", type=Path, help="KITTI raw root (with --checkpoint)")
    p.add_argument("--split-file", type=Path, help="split lines; gives the sequences (default: the GT's lines)")
    p.add_argument("--scaling", choices=depth.SCALINGS, default="frame",
                   help="median scaling per frame, per sequence, or none")
    p.add_argument("--gt-kind", choices=tuple(depth.CROP_FOR_GT_KIND), default="lidar",
                   help="lidar: Garg crop, 1e-3 < gt < 80 m; improved: gt > 0, no crop")
    p.add_argument("--post-process", action="store_true", help="average with the flipped image's prediction")
    p.add_argument("--save-disps", type=output_file, metavar="OUT.npy", help="save the model's disparities")
    _add_model_options(p)
    p.add_argument("--json", type=output_file, metavar="OUT", help="write the results as JSON")
    p.add_argument("--plots", type=output_folder, metavar="DIR", help="write scale and error plots (PNG)")
    p.set_defaults(func=evaluate_depth_command)

    p = subparsers.add_parser("evaluate-pose", help="snippet ATE, full ATE / RPE and a constant-velocity baseline",
                              description="Evaluate predicted ego-motion against KITTI odometry poses.")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--pred-poses", type=Path, metavar="P.txt", help="KITTI pose file, camera → world")
    src.add_argument("--checkpoint", type=Path, metavar="CKPT", help="model checkpoint (.pt or .safetensors)")
    p.add_argument("--gt-poses", type=Path, required=True, metavar="G.txt", help="KITTI ground-truth pose file")
    p.add_argument("--data-path", type=Path, help="KITTI odometry root with sequences/ (with --checkpoint)")
    p.add_argument("--sequence", type=non_negative_int, help="odometry sequence, e.g. 09 (with --checkpoint)")
    p.add_argument("--times", type=Path, help="times.txt (seconds) for the TUM timestamps (default: frame / 10 Hz)")
    p.add_argument("--const-velocity", choices=pose.CONST_VELOCITY_MODES, default="first",
                   help="baseline: repeat the first GT step, or the previous GT step")
    _add_model_options(p)
    p.add_argument("--json", type=output_file, metavar="OUT", help="write the results as JSON")
    p.add_argument("--out-dir", type=output_folder, metavar="DIR",
                   help="write trajectories (KITTI, TUM) and a top-view plot")
    p.set_defaults(func=evaluate_pose_command)

    p = subparsers.add_parser("compare", help="Markdown table (paper's Table 1 layout) from depth JSONs",
                              description="Compare depth evaluations; a run directory means <run>/eval/depth.json.")
    p.add_argument("results", nargs="+", type=Path, metavar="RUN_OR_JSON")
    p.add_argument("--names", nargs="+", help="row names (default: run directory or file name)")
    p.add_argument("--out", type=output_file, metavar="FILE", help="also write the table to FILE")
    p.set_defaults(func=compare_command)


def _add_model_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--batch-size", type=positive_int, default=8, help="images per forward pass (with --checkpoint)")
    p.add_argument("--device", type=device_name, default=None,
                   help="torch device (default: cuda if available, else cpu)")


def _require(args: argparse.Namespace, *names: str) -> None:
    missing = [f"--{n.replace('_', '-')}" for n in names if getattr(args, n) is None]
    if missing:
        raise PoseconsError(f"--checkpoint needs {' and '.join(missing)}")


def _load_model(args: argparse.Namespace):
    """(model, config, device) from --checkpoint on --device."""
    import torch

    from ..checkpoint import load_model

    device = args.device or ("cuda" if torch.cuda.is_available() else "cpu")
    if device.startswith("cuda") and not torch.cuda.is_available():
        raise PoseconsError(f"--device {device}: CUDA is not available on this machine")
    model, config = load_model(args.checkpoint, map_location=device)
    return model, config, device


def load_pred_disps(path: Path) -> np.ndarray:
    """Disparities from a ``.npy`` file (no pickles)."""
    if not path.is_file():
        raise PoseconsError(f"{path}: predictions file not found")
    try:
        return np.load(path, allow_pickle=False)
    except (ValueError, OSError):  # numpy's own text suggests unpickling, which is never wanted here
        raise PoseconsError(f"{path}: not a .npy array of numbers (damaged, or not written by numpy.save)") from None


def _ground_truth(args: argparse.Namespace, tmp: Path) -> tuple[list[np.ndarray], list[str], Path]:
    """GT depth maps, their split lines and the file they came from (exported into tmp if needed)."""
    from ..data.gt import export_gt, load_gt

    gt_path = args.gt
    if gt_path is None:
        gt_path = tmp / "gt_depths.npz"
        export_gt(args.data_path, args.split_file, gt_path, improved=args.gt_kind == "improved")
    gts, lines = load_gt(gt_path)
    return list(gts), [str(line) for line in lines], gt_path


def evaluate_depth_command(args: argparse.Namespace) -> int:
    from ..data.splits import read_split
    from . import compare, plots

    if args.checkpoint is None and args.gt is None:
        raise PoseconsError("--pred-disps needs --gt (an exported ground-truth .npz)")
    if args.checkpoint is not None:
        _require(args, "data_path", "split_file")
    with tempfile.TemporaryDirectory() as tmp:
        gts, gt_lines, gt_path = _ground_truth(args, Path(tmp))
    split = read_split(args.split_file if args.split_file else gt_lines)
    if args.checkpoint is not None:
        from .predict import predict_disparities, split_image_paths

        model, config, device = _load_model(args)
        disps = predict_disparities(model, split_image_paths(args.data_path, split), config.model.height,
                                    config.model.width, args.batch_size, args.post_process, device)
        pred_name = str(args.checkpoint)
        if args.save_disps:
            atomic_write(args.save_disps, lambda tmp: np.save(tmp, disps))
    else:
        disps, pred_name = load_pred_disps(args.pred_disps), str(args.pred_disps)
    if len(split) != len(gts):
        raise PoseconsError(f"{args.split_file} has {len(split)} lines but {gt_path} has {len(gts)} frames")

    result = depth.evaluate_depth(disps, gts, [s.folder for s in split], scaling=args.scaling,
                                  crop=depth.CROP_FOR_GT_KIND[args.gt_kind], pred_name=pred_name,
                                  gt_name=str(gt_path))
    result.update(gt_kind=args.gt_kind, predictions=pred_name, ground_truth=str(args.gt or "exported on the fly"),
                  post_process=bool(args.checkpoint and args.post_process),
                  skipped_lines=[str(split[i]) for i in result["skipped"]])
    print(compare.markdown_table([result], [Path(pred_name).stem], bold=False), end="")
    print(f"{result['n_frames']} frames, scaling {result['scaling']}, {result['n_skipped']} skipped (no valid GT); "
          f"scales: median {result['scale_median']:.3f}, std/median {result['scale_std_over_median']:.3f}, "
          f"σ/μ pooled {result['scale_cv_pooled']:.3f}")
    if args.json:
        write_json(args.json, result)
    if args.plots:
        seqs, frames = [s.folder for s in split], [s.frame for s in split]
        plots.plot_scale_boxplot(result["scales"], seqs, args.plots / "scale_boxplot.png")
        plots.plot_scale_over_time(result["scales"], seqs, frames, args.plots / "scale_over_time.png")
        plots.plot_error_histogram(result["per_frame_abs_rel"], args.plots / "abs_rel_histogram.png")
    return 0


def evaluate_pose_command(args: argparse.Namespace) -> int:
    from . import plots, trajectory_io

    gt = trajectory_io.read_kitti_poses(args.gt_poses)
    times = trajectory_io.read_times(args.times) if args.times else None
    if times is not None and len(times) != len(gt):
        raise PoseconsError(f"{args.times} has {len(times)} timestamps but {args.gt_poses} has {len(gt)} poses")
    if args.checkpoint is not None:
        from ..data.kitti_odometry import list_sequence_frames
        from .predict import predict_steps

        _require(args, "data_path", "sequence")
        paths = list_sequence_frames(args.data_path, args.sequence)
        if len(paths) != len(gt):
            raise PoseconsError(f"{len(paths)} images in sequence {args.sequence} but "
                                f"{len(gt)} poses in {args.gt_poses}")
        model, config, device = _load_model(args)
        steps = predict_steps(model, paths, config.model.height, config.model.width, args.batch_size, device)
        estimate, source = pose.global_from_relative(steps), str(args.checkpoint)
    else:
        estimate, source = trajectory_io.read_kitti_poses(args.pred_poses), str(args.pred_poses)
        if len(estimate) != len(gt):
            raise PoseconsError(f"{args.pred_poses} has {len(estimate)} poses but {args.gt_poses} has {len(gt)}")

    result = pose.evaluate_pose(estimate, gt, args.const_velocity)
    result.update(predictions=source, ground_truth=str(args.gt_poses))
    for name, r in (("prediction", result), (f"const. velocity ({args.const_velocity})", result["const_velocity"])):
        print(f"{name:>26}: snippet ATE {r['ate_mean']:.4f} ± {r['ate_std']:.4f} ({r['n_snippets']} snippets) | "
              f"full ATE (Sim3) {r['ate_full_rmse']:.3f} m | RPE {r['rpe_trans']:.2f} % {r['rpe_rot']:.4f} deg/m")
    if args.json:
        write_json(args.json, result)
    if args.out_dir:
        trajectory_io.write_kitti_poses(args.out_dir / "trajectory_kitti.txt", estimate)
        trajectory_io.write_tum(args.out_dir / "trajectory_tum.txt", estimate, times)
        trajectory_io.write_tum(args.out_dir / "gt_tum.txt", gt, times)
        aligned, _ = pose.align_trajectory(estimate, gt)
        plots.plot_trajectory_topview(gt, aligned, args.out_dir / "trajectory.png", "prediction (Sim(3)-aligned)")
    return 0


def compare_command(args: argparse.Namespace) -> int:
    from . import compare

    results = [compare.load_result(path) for path in args.results]
    names = args.names or [compare.default_name(path) for path in args.results]
    table = compare.markdown_table(results, names)
    print(table, end="")
    if args.out:
        write_text(args.out, table)
    return 0
