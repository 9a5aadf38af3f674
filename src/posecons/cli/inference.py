"""`posecons predict`, `posecons export` and `posecons import-monodepth2`: thin wrappers over
:mod:`posecons.inference.predict`, :mod:`posecons.inference.export` and
:mod:`posecons.monodepth2`."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from ..inference.media import DEFAULT_FPS
from .arguments import (
    add_command,
    device_name,
    new_output_file,
    non_negative_float,
    output_folder,
    positive_float,
    positive_int,
)


def register(subparsers: argparse._SubParsersAction) -> None:
    p = add_command(subparsers, "predict", predict_command)
    p.add_argument(
        "--checkpoint",
        required=True,
        type=Path,
        help="checkpoint (.pt / .safetensors), an export directory or its depth.onnx",
    )
    p.add_argument("--input", required=True, type=Path, help="an image, a folder of images or a video")
    p.add_argument(
        "--out",
        type=output_folder,
        default="predictions",
        help="output folder: new, empty, or an earlier predict output",
    )
    p.add_argument("--batch-size", type=positive_int, default=4, help="frames per forward pass")
    p.add_argument("--device", type=device_name, default="cpu", help="cpu, cuda or cuda:N")
    group = p.add_mutually_exclusive_group()
    group.add_argument("--scale", type=positive_float, help="multiply every depth and translation by this factor")
    group.add_argument(
        "--calibrate-gt",
        metavar="DIR|NPZ",
        help="scale = median over the first frames of median(gt)/median(pred); a folder of 16-bit "
        "depth PNGs named like the frames, or an export-gt .npz",
    )
    group.add_argument(
        "--camera-height",
        type=positive_float,
        metavar="METRES",
        help="scale from the camera's height above the ground plane fitted in the first frames",
    )
    p.add_argument("--calibrate-frames", type=positive_int, default=10, metavar="N", help="frames used to calibrate")
    p.add_argument("--intrinsics", metavar="fx,fy,cx,cy", help="pixel intrinsics of the input images")
    p.add_argument("--calib", type=Path, help="KITTI calib_cam_to_cam.txt (P_rect_02) or odometry calib.txt (P2)")
    p.add_argument("--pointcloud", action="store_true", help="write a coloured PLY per frame")
    p.add_argument("--every", type=positive_int, default=1, metavar="K", help="point cloud of every K-th frame")
    p.add_argument("--ascii-ply", action="store_true", help="ASCII instead of binary PLY")
    p.add_argument("--no-trajectory", action="store_true", help="skip the pose network")
    p.add_argument("--no-video", action="store_true", help="no side-by-side MP4 for video input")
    p.add_argument(
        "--fps", type=positive_float, default=DEFAULT_FPS, help="frame rate of image folders in Hz (timestamps)"
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")

    e = add_command(subparsers, "export", export_command)
    e.add_argument("--checkpoint", required=True, type=Path, help="checkpoint (.pt or .safetensors)")
    e.add_argument("--out", required=True, type=output_folder, help="output folder: new, empty, or an earlier export")
    e.add_argument(
        "--tolerance",
        type=non_negative_float,
        default=1e-4,
        help="largest accepted |ONNX Runtime − PyTorch| on sample inputs (disparity / pose units)",
    )

    m = add_command(subparsers, "import-monodepth2", import_monodepth2_command)
    m.add_argument("folder", type=Path, help="Monodepth2 model folder, e.g. models/mono_640x192")
    m.add_argument(
        "--out",
        required=True,
        type=new_output_file,
        help="checkpoint to write, a new file: .safetensors writes safetensors, any other name a .pt checkpoint",
    )


def predict_command(args: argparse.Namespace) -> int:
    """depth, ego-motion and point clouds for images or a video

    Depth for every frame (.npy, 16-bit PNG, colour PNG, side-by-side MP4 for video), a trajectory
    (KITTI and TUM) and optional point clouds. Outputs are staged inside OUT and moved into place at the
    end."""
    from ..inference.backend import load_predictor
    from ..inference.predict import PredictOptions, predict

    options = PredictOptions(
        batch_size=args.batch_size,
        scale=args.scale,
        calibrate_gt=args.calibrate_gt,
        calibrate_frames=args.calibrate_frames,
        camera_height=args.camera_height,
        intrinsics=args.intrinsics,
        calib=str(args.calib) if args.calib else None,
        pointcloud=args.pointcloud,
        every=args.every,
        ascii_ply=args.ascii_ply,
        trajectory=not args.no_trajectory,
        video=not args.no_video,
        fps=args.fps,
        progress=not args.quiet,
    ).check()
    summary = predict(load_predictor(args.checkpoint, args.device), args.input, args.out, options)
    uses_k = [name for name, on in (("--camera-height", args.camera_height), ("--pointcloud", args.pointcloud)) if on]
    if uses_k and not (args.intrinsics or args.calib):  # after the work: the last thing the user reads
        print(
            f"posecons predict: warning: {' and '.join(uses_k)} used KITTI's intrinsics (fx = 0.58 × width, "
            "fy = 1.92 × height), as neither --intrinsics nor --calib was given: pass the camera's, e.g. "
            "--calib DATA/custom/calib_cam_to_cam.txt from `posecons prepare`",
            file=sys.stderr,
        )
    print(f"{summary['frames']} frames → {args.out} (scale {summary['scale']:.6g}, {summary['seconds']:.1f} s)")
    return 0


def export_command(args: argparse.Namespace) -> int:
    """depth and pose networks to ONNX (verified) and safetensors"""
    from ..inference.export import export_model

    info = export_model(args.checkpoint, args.out, tolerance=args.tolerance)
    print(json.dumps(info["max_abs_diff"], indent=2))
    print(f"exported to {args.out} (max |ONNX − PyTorch| within {args.tolerance:g})")
    return 0


def import_monodepth2_command(args: argparse.Namespace) -> int:
    """a Monodepth2 model folder → a posecons checkpoint (same networks, same outputs)

    Read a Monodepth2 model folder (encoder.pth, depth.pth, and pose_encoder.pth + pose.pth of a mono or
    mono+stereo model) into a posecons checkpoint (.pt) or safetensors file (.safetensors) for
    evaluate-depth, evaluate-pose, predict, export or train --init-from. A stereo-only model gives its
    depth network only."""
    from ..monodepth2 import import_monodepth2

    print(f"imported {import_monodepth2(args.folder, args.out)} → {args.out}")  # says when only depth is
    return 0
