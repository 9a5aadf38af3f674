"""Data sub-commands of the ``posecons`` CLI: synth, export-gt, prepare, prepare-rgbd, cache, build-split."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..errors import PoseconsError
from .arguments import (
    add_command,
    add_overrides,
    field_of_view,
    finite_float,
    fraction,
    non_negative_float,
    non_negative_int,
    output_file,
    output_folder,
    positive_float,
    positive_int,
)

GUESS_FOV = 60.0  # degrees: a typical dashcam's horizontal field of view (50–70°), when none is given
PIXEL_INTRINSICS = ("fx", "fy", "cx", "cy")

# The library modules are imported inside each command: `posecons --help` must not pay for torch or av.


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the data commands to the CLI's sub-command parser."""
    p = add_command(subparsers, "synth", _synth)
    p.add_argument(
        "--out", type=output_folder, required=True, help="output folder: new, empty, or an earlier synth output"
    )
    p.add_argument(
        "--drives", type=positive_int, default=4, help="number of drives (the last max(1, N//4) are test drives)"
    )
    p.add_argument(
        "--frames", type=positive_int, default=100, help="frames per drive (10 Hz, so 10 frames = 1 s of driving)"
    )
    p.add_argument("--seed", type=non_negative_int, default=0, help="random seed of scenes and motion")
    p.add_argument("--ext", choices=("png", "jpg"), default="png", help="image format of the raw tree")
    p.add_argument("--width", type=positive_int, default=1242, help="image width in pixels (KITTI: 1242)")
    p.add_argument("--height", type=positive_int, default=375, help="image height in pixels (KITTI: 375)")
    p.add_argument("--workers", type=positive_int, default=None, help="render processes (default: up to 2)")
    p.add_argument(
        "--neighbours",
        type=positive_int,
        default=1,
        help="training lines need frames ±N (for model.frame_ids [0, -N, N])",
    )
    p.add_argument(
        "--profile",
        choices=("street", "open", "sparse"),
        default="street",
        help="scene statistics: street (the studies' benchmark), open (a second benchmark: speed "
        "0.3–2 m a frame, sharper turns, façades 6–30 m away, more open lots) or sparse (a third: a "
        "wider camera, 0.75 × KITTI's focal length, little fine texture, 0.8–2.2 m a frame)",
    )

    p = add_command(subparsers, "export-gt", _export_gt)
    p.add_argument("--data-path", type=Path, required=True, help="KITTI raw root")
    p.add_argument("--split-file", type=Path, required=True, help="split file: <folder> <frame> <l|r> lines")
    p.add_argument("--out", type=output_file, required=True, help="output .npz")
    p.add_argument("--improved", action="store_true", help="use KITTI's improved ground-truth PNGs")
    p.add_argument(
        "--improved-root",
        type=Path,
        default=None,
        help="folder with <drive>/proj_depth/groundtruth/... (default: inside the raw tree)",
    )
    p.add_argument(
        "--depth",
        choices=("velo_x", "camera_z"),
        default="velo_x",
        help="LiDAR depth value: forward x (Eigen protocol) or camera z",
    )

    p = add_command(subparsers, "prepare", _prepare)
    p.add_argument("--input", type=Path, nargs="+", required=True, help="video files and/or folders of frames")
    p.add_argument("--out", type=output_folder, required=True, help="output dataset folder (new or empty)")
    _add_pixel_intrinsics(p)
    p.add_argument("--calib", type=Path, help="file with 'K: 9 numbers', 'P_rect_02:' or 'P2:' instead")
    p.add_argument(
        "--fov",
        type=field_of_view,
        help=f"or the horizontal field of view in degrees (fx = fy from it, centred principal point); "
        f"with none of these, {GUESS_FOV:g}° is assumed, with a warning",
    )
    p.add_argument(
        "--every",
        type=positive_int,
        default=1,
        help="keep one decoded frame in N (default 1): 25–30 fps video wants 2–3 to train at about 10 Hz",
    )
    p.add_argument("--width", type=positive_int, help="resize frames to this width in pixels (default: keep)")
    p.add_argument("--height", type=positive_int, help="resize frames to this height in pixels (default: keep)")
    p.add_argument(
        "--static-threshold",
        type=fraction,
        default=0.004,
        help="drop frames whose mean grey difference (0–1 scale) to the last kept one is below this "
        "(default 0.004: a standing camera; highway video at 12.5 fps differs by 0.006–0.017)",
    )

    p = add_command(subparsers, "prepare-rgbd", _prepare_rgbd)
    p.add_argument("--input", type=Path, required=True, help="folder of the sequence")
    p.add_argument("--out", type=output_folder, required=True, help="output dataset folder (new or empty)")
    p.add_argument(
        "--color",
        required=True,
        metavar="PATTERN",
        help="colour frames, e.g. 'frame-*.color.jpg' (7-Scenes) or 'rgb/*.png' (TUM RGB-D); sorted by name",
    )
    p.add_argument(
        "--depth", required=True, metavar="PATTERN", help="depth images (16-bit PNG), e.g. 'frame-*.depth.png'"
    )
    p.add_argument(
        "--depth-scale",
        type=positive_float,
        required=True,
        help="depth values per metre: 1000 for millimetres (Kinect, RealSense, 7-Scenes, ScanNet), 5000 for TUM RGB-D",
    )
    p.add_argument(
        "--invalid-depth",
        type=finite_float,
        nargs="+",
        metavar="V",
        help="depth values that mean no measurement (default: 0 65535)",
    )
    poses = p.add_mutually_exclusive_group()
    poses.add_argument(
        "--poses", metavar="PATTERN", help="a 4 × 4 camera → world matrix (metres) per frame, e.g. 'frame-*.pose.txt'"
    )
    poses.add_argument(
        "--tum-poses",
        type=Path,
        metavar="FILE",
        help="or a TUM trajectory file (t tx ty tz qx qy qz qw, camera → world)",
    )
    p.add_argument(
        "--max-time-difference",
        type=non_negative_float,
        metavar="S",
        help="names are timestamps (seconds): take the depth image and pose nearest in time, at most S away "
        "(TUM's associate.py: 0.02); default: the same name (--tum-poses: the same timestamp)",
    )
    _add_pixel_intrinsics(p)
    p.add_argument(
        "--calib", type=Path, help="a 3 × 3 intrinsics matrix file (7-Scenes' camera-intrinsics.txt) or 'K: 9 numbers'"
    )
    p.add_argument(
        "--every", type=positive_int, default=1, help="keep one frame in N (default 1), with its depth and pose"
    )
    p.add_argument(
        "--test-from",
        type=non_negative_int,
        metavar="FRAME",
        help="hold out the frames from this one on (counted in the sorted colour frames, before --every) as the "
        "test stretch: test split, ground truth and odometry view; default: train and test on every frame",
    )
    p.add_argument(
        "--gap",
        type=non_negative_int,
        default=20,
        metavar="FRAMES",
        help="with --test-from: frames left out before the test stretch (default 20), so that no training "
        "frame's neighbour is a test frame",
    )

    p = add_command(subparsers, "cache", _cache)
    p.add_argument("--data-path", type=Path, required=True, help="dataset root (KITTI raw layout, or odometry root)")
    p.add_argument("--config", required=True, help="preset file or bundled name (e.g. kitti/cycle)")
    add_overrides(p, "override a config value as for train, e.g. --set model.height=96")
    p.add_argument("--split-dir", type=Path, help="folder with train_files.txt/val_files.txt (as for train)")
    p.add_argument(
        "--out", type=output_folder, required=True, help="cache folder: new, empty, or an unfinished cache to complete"
    )
    p.add_argument("--workers", type=positive_int, default=None, help="decoding processes (default: up to 2)")

    p = add_command(subparsers, "build-split", _build_split)
    p.add_argument("--data-path", type=Path, required=True, help="KITTI raw root")
    p.add_argument("--out", type=output_folder, required=True, help="directory for train_files.txt and val_files.txt")
    p.add_argument("--static-frames", type=Path, help="SfMLearner static_frames.txt")
    p.add_argument("--test-scenes", type=Path, help="drives to exclude (test_scenes_eigen.txt)")
    p.add_argument("--val-fraction", type=fraction, default=0.1, help="share of the lines (0–1) that go to validation")
    p.add_argument("--seed", type=non_negative_int, default=0, help="seed of the train/val shuffle")
    p.add_argument("--ext", default=".png", help="image extension in the raw tree")


def _synth(args: argparse.Namespace) -> int:
    """write a synthetic KITTI-like dataset (raw + odometry + splits)"""
    from ..data.splits import read_split
    from ..data.synth import generate_synth

    info = generate_synth(
        args.out,
        args.drives,
        args.frames,
        args.seed,
        args.ext,
        args.width,
        args.height,
        args.workers,
        args.neighbours,
        args.profile,
    )
    lines = len(read_split(args.out / "splits" / "synth" / "train_files.txt"))
    print(
        f"wrote {len(info['drives'])} {args.profile} drives × {args.frames} frames to {args.out} "
        f"(test: {', '.join(info['test_drives'])}); {lines} training lines with frames ±{args.neighbours}: "
        f"enough for train.batch_size ≤ {lines} and model.frame_ids within ±{args.neighbours}"
    )
    return 0


def _export_gt(args: argparse.Namespace) -> int:
    """export the ground-truth depth of a split to .npz"""
    from ..data.gt import export_gt

    count = export_gt(args.data_path, args.split_file, args.out, args.improved, args.improved_root, args.depth)
    print(f"wrote {count} depth maps to {args.out}")
    return 0


def _add_pixel_intrinsics(p: argparse.ArgumentParser) -> None:
    for name in PIXEL_INTRINSICS:
        p.add_argument(
            f"--{name}",
            type=positive_float if name.startswith("f") else finite_float,
            help="intrinsics in pixels of the input frames",
        )


def _pixel_intrinsics(args: argparse.Namespace, alternative: str):
    """The (3, 3) K of --fx --fy --cx --cy, None when none of them is given; ``alternative`` is named
    when only some are."""
    import numpy as np

    given = [getattr(args, n) for n in PIXEL_INTRINSICS]
    if all(v is None for v in given):
        return None
    if any(v is None for v in given):
        raise PoseconsError(f"--fx --fy --cx --cy: give all four (pixels), or {alternative}")
    fx, fy, cx, cy = given
    return np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1]])


def _prepare(args: argparse.Namespace) -> int:
    """turn videos or frame folders into a KITTI-raw-layout dataset"""
    from ..data.calib import read_calib_intrinsics
    from ..data.prepare import prepare

    given = [getattr(args, n) for n in PIXEL_INTRINSICS]
    sources = ["--fx --fy --cx --cy" if any(v is not None for v in given) else "", "--calib" * (args.calib is not None)]
    sources = [s for s in sources + ["--fov" * (args.fov is not None)] if s]
    if len(sources) > 1:
        raise PoseconsError(f"give one of --fx --fy --cx --cy, --calib and --fov, not {' and '.join(sources)}")
    k, fov = _pixel_intrinsics(args, "--fov DEGREES"), args.fov
    if args.calib is not None:
        k = read_calib_intrinsics(args.calib)
    elif k is None and fov is None:
        fov = GUESS_FOV
    info = prepare(args.input, args.out, k, args.width, args.height, args.static_threshold, fov=fov, every=args.every)
    if not sources:  # after the work, so that it is the last thing the user reads
        print(
            f"posecons prepare: warning: no intrinsics given, so a {GUESS_FOV:g}° horizontal field of view "
            f"was assumed (fx = fy = {info['K'][0, 0]:.1f} px at the input size); depth and motion are "
            "only as right as that guess: pass --fov or --fx --fy --cx --cy when you know them",
            file=sys.stderr,
        )
    print(
        f"wrote {len(info['drives'])} drives ({sum(info['frames'])} frames; {info['train']} train / {info['val']} val lines) to {args.out}"
    )
    return 0


def _prepare_rgbd(args: argparse.Namespace) -> int:
    """turn an RGB-D sequence (colour, depth, poses) into a dataset with depth and pose ground truth

    The prepare layout of the colour frames, plus OUT/gt_depths.npz (their depth in metres, for
    evaluate-depth --gt-kind dense) and, with poses, OUT/odometry (for evaluate-pose). Patterns are
    relative to --input; their one * is the frame's name, which pairs a colour frame with its files."""
    from ..data.calib import read_intrinsics
    from ..data.rgbd import INVALID_DEPTH, RGBDSource, prepare_rgbd

    k = _pixel_intrinsics(args, "--calib FILE")
    if k is not None and args.calib is not None:
        raise PoseconsError("give one of --fx --fy --cx --cy and --calib, not both")
    if k is None and args.calib is None:
        raise PoseconsError("give the colour frames' intrinsics: --fx --fy --cx --cy (pixels) or --calib FILE")
    source = RGBDSource(args.input, args.color, args.depth, args.poses, args.tum_poses, args.max_time_difference)
    info = prepare_rgbd(
        source,
        args.out,
        read_intrinsics(args.calib) if k is None else k,
        args.depth_scale,
        INVALID_DEPTH if args.invalid_depth is None else args.invalid_depth,
        args.every,
        args.test_from,
        args.gap,
    )
    poses = f"; poses: {args.out}/odometry/poses/{info['odometry_sequence']}.txt" if info["odometry_sequence"] else ""
    print(
        f"wrote {len(info['frames'])} frames to {args.out} ({info['train']} train / {info['val']} val lines); "
        f"depth ground truth: {args.out}/{info['ground_truth']}{poses}"
    )
    return 0


def _cache(args: argparse.Namespace) -> int:
    """decode and resize once every frame a config's train and val splits need (data.cache_dir)

    Write the frames that `posecons train` with the same --config/--set/--split-dir reads, resized to
    model.height×model.width exactly as the loader does; train with --set data.cache_dir=CACHE. An
    interrupted build is finished by the same command."""
    import os

    from ..config import load_config, resolve_preset
    from ..data.cache_build import build_cache

    config = load_config(resolve_preset(args.config), args.overrides)
    workers = args.workers or min(2, os.cpu_count() or 1)
    info = build_cache(config, args.data_path, args.out, args.split_dir, workers)
    size = info["frames"] * info["bytes_per_frame"] / 1e9
    print(
        f"{args.out}: {info['frames']} frames at {info['width']}×{info['height']} ({info['written']} written now, "
        f"{size:.2f} GB); train with --set data.cache_dir={args.out}"
    )
    return 0


def _build_split(args: argparse.Namespace) -> int:
    """build a Zhou-style train/val split from a KITTI raw tree"""
    from ..data.splits import build_split, read_static_frames, read_test_scenes, write_split

    static = read_static_frames(args.static_frames) if args.static_frames else set()
    scenes = read_test_scenes(args.test_scenes) if args.test_scenes else set()
    train, val = build_split(args.data_path, static, scenes, args.val_fraction, args.seed, args.ext)
    write_split(args.out / "train_files.txt", train)
    write_split(args.out / "val_files.txt", val)
    print(f"wrote {len(train)} train / {len(val)} val lines to {args.out}")
    return 0
