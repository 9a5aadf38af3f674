"""Depth, ego-motion and point clouds for an image, a folder of images or a video.

Frames stream through in batches: each is resized to the network size, its disparity is resized
bilinearly back to the original size and inverted, and the sequence's single scale is applied.
Scale calibration (if any) runs first over the first frames only, then the main pass writes
everything into a staging folder inside OUT that is moved into place at the end (see
:func:`posecons.fileio.output_dir`).

Output layout (``<name>`` is the image stem, or the 6-digit frame index of a video)::

    OUT/depth/<name>.npy         float32 (H, W) depth at the original size, scaled
    OUT/depth_png/<name>.png     uint16 depth × 256 (KITTI style, 0 = invalid)
    OUT/depth_color/<name>.jpg   colour-mapped disparity (one colour range for the sequence), JPEG
    OUT/pointcloud/<name>.ply    with pointcloud=True, every k-th frame
    OUT/video.mp4                video input: input | depth side by side
    OUT/trajectory_kitti.txt, trajectory_tum.txt, trajectory.png   camera → world poses
    OUT/scale.json, scale_drift.png (with ground truth), predict.json
"""

from __future__ import annotations

import json
import time
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from PIL import Image
from tqdm import tqdm

from ..data.calib import normalised_to_pixel
from ..data.gt import GroundTruth
from ..data.trajectory_io import write_kitti_poses, write_tum
from ..errors import PoseconsError
from ..fileio import output_dir
from ..metrics.depth import drift_stats, frame_scale, resize_disparity, valid_mask
from ..metrics.pose import global_from_relative
from ..plots import colorize, colour_range, plot_scale_drift, plot_trajectory_topview
from . import scale as scaling
from .backend import Predictor, StepChain, predict_batches
from .camera import resolve_intrinsics
from .media import DEFAULT_FPS, Frame, FrameSource, SideBySideWriter
from .pointcloud import depth_to_points, write_ply


@dataclass
class PredictOptions:
    batch_size: int = 4
    scale: float | None = None  # a known scale; else calibrate_gt, camera_height or none (1.0)
    calibrate_gt: str | None = None  # folder of 16-bit depth PNGs or export-gt NPZ
    calibrate_frames: int = 10  # frames (with GT, for calibrate_gt) used to calibrate
    camera_height: float | None = None  # metres above the ground
    intrinsics: str | None = None  # "fx,fy,cx,cy" in pixels of the input image
    calib: str | None = None  # KITTI calibration file
    pointcloud: bool = False
    every: int = 1  # point cloud of every k-th frame
    ascii_ply: bool = False
    trajectory: bool = True
    video: bool = True  # side-by-side MP4 for video input
    fps: float = DEFAULT_FPS  # timestamps of image folders
    progress: bool = True

    def check(self) -> PredictOptions:
        chosen = [n for n in ("scale", "calibrate_gt", "camera_height") if getattr(self, n) is not None]
        if len(chosen) > 1:
            raise PoseconsError(f"choose one way to set the scale, got {', '.join(chosen)}")
        for name in ("batch_size", "calibrate_frames", "every"):
            if getattr(self, name) < 1:
                raise PoseconsError(f"{name} must be at least 1, got {getattr(self, name)}")
        for name in ("scale", "camera_height", "fps"):
            value = getattr(self, name)
            if value is not None and not value > 0:
                raise PoseconsError(f"{name} must be positive, got {value}")
        return self


def full_size_depth(disparity: torch.Tensor, height: int, width: int) -> np.ndarray:
    """(1, h, w) scaled disparity → (height, width) float32 depth: bilinear resize, then invert."""
    return 1.0 / resize_disparity(disparity[0].float().cpu().numpy(), height, width)


def gt_scale(gt: np.ndarray, disparity: torch.Tensor) -> float:
    """The frame's median scale against (H, W) ground truth: every finite gt > 0, no crop and no cap
    (see :func:`~posecons.metrics.depth.frame_scale`)."""
    return frame_scale(gt, full_size_depth(disparity, *gt.shape), valid_mask(gt, "none"))


def calibrate(
    source: FrameSource, predictor: Predictor, options: PredictOptions, K_norm: np.ndarray, gt: GroundTruth | None
) -> scaling.ScaleResult:
    """The sequence's scale from the first frames (see :class:`PredictOptions`)."""
    if options.scale is not None:
        return scaling.ScaleResult("given", float(options.scale))
    if gt is None and options.camera_height is None:
        return scaling.ScaleResult("metric" if predictor.metric else "none", 1.0)
    names, scales = [], []
    for frames, _, disps in predict_batches(predictor, source, options.batch_size):
        for frame, disp in zip(frames, disps):
            if gt is not None:
                target = gt.get(frame.name, frame.index)
                if target is None:
                    continue
                scales.append(gt_scale(target, disp))
            else:
                depth = full_size_depth(disp, *frame.size)
                height = scaling.camera_height(depth, normalised_to_pixel(K_norm, *frame.size))
                scales.append(options.camera_height / height)
            names.append(frame.name)
            if len(names) == options.calibrate_frames:
                break
        if len(names) == options.calibrate_frames:
            break
    if gt is not None:
        return scaling.combine(
            "ground_truth", names, scales, f"no frame of {source.path} has valid ground truth in {gt.path}"
        )
    return scaling.combine("camera_height", names, scales, "no ground plane found")


def _write_frame(out: Path, frame: Frame, depth: np.ndarray, limits, writer, options: PredictOptions, K_norm) -> None:
    """Every output of one frame: depth .npy and PNGs, its side-by-side video frame, its point cloud."""
    # The 16-bit PNG at zlib level 1 instead of Pillow's 6: on real 960×540 depth 3.3× less time (94 against
    # 312 ms a frame for it and a colour PNG) for 12 % more bytes. The colour map, for viewing, as a JPEG:
    # 1.6 ms a 1242×375 frame whatever it shows, where a level-1 PNG takes 6 (smooth) to 30 ms (detailed).
    np.save(out / "depth" / f"{frame.name}.npy", depth.astype(np.float32))
    png = np.clip(np.round(depth * 256), 0, 65535).astype(np.uint16)
    Image.fromarray(png).save(out / "depth_png" / f"{frame.name}.png", compress_level=1)
    color = colorize(1.0 / depth, limits=limits)
    Image.fromarray(color).save(out / "depth_color" / f"{frame.name}.jpg", quality=90)
    if writer is not None:
        writer.write(frame.image, color)
    if options.pointcloud and frame.index % options.every == 0:
        K = normalised_to_pixel(K_norm, *frame.size)
        points = depth_to_points(depth, frame.image, K)
        write_ply(out / "pointcloud" / f"{frame.name}.ply", *points, binary=not options.ascii_ply)


def predict(predictor: Predictor, input: str | Path, out: str | Path, options: PredictOptions | None = None) -> dict:
    """Run ``predictor`` over ``input`` and write the outputs described in the module docstring.

    Returns the summary written to ``predict.json``.
    """
    options = (options or PredictOptions()).check()
    source = FrameSource(input, options.fps)
    first = next(iter(source))
    K_norm = resolve_intrinsics(options.intrinsics, options.calib, *first.size)
    gt = GroundTruth(options.calibrate_gt) if options.calibrate_gt else None
    do_pose = options.trajectory and predictor.has_pose
    start = time.perf_counter()
    result = calibrate(source, predictor, options, K_norm, gt)
    s = result.value
    fps = source.video_fps if source.is_video else options.fps

    with output_dir(out) as tmp:
        folders = ["depth", "depth_png", "depth_color"] + (["pointcloud"] if options.pointcloud else [])
        for name in folders:
            (tmp / name).mkdir()
        writer = SideBySideWriter(tmp / "video.mp4", fps) if source.is_video and options.video else None
        chain, times, drift, count, limits = StepChain(predictor), [], [], 0, None
        bar = tqdm(total=len(source) or None, unit="frame", disable=not options.progress)
        # One thread writes a batch's outputs while the next batch is decoded and run through the
        # networks (which release the GIL); waiting for it before handing it the next batch keeps
        # at most one batch in memory and the video's frames in order.
        with ThreadPoolExecutor(max_workers=1) as pool:
            written: list[Future] = []
            for frames, images, disps in predict_batches(predictor, source, options.batch_size):
                if do_pose:
                    chain.add(images)
                depths = [full_size_depth(disp, *frame.size) * np.float32(s) for frame, disp in zip(frames, disps)]
                if limits is None:  # one colour range for the sequence, from its first batch: no flicker
                    limits = colour_range(np.concatenate([1.0 / d.ravel() for d in depths]))
                for frame, disp in zip(frames, disps):
                    target = gt.get(frame.name, frame.index) if gt is not None else None
                    if target is not None:
                        drift.append((frame.index, frame.name, gt_scale(target, disp)))
                    times.append(frame.time)
                for job in written:
                    job.result()
                written = [
                    pool.submit(_write_frame, tmp, frame, depth, limits, writer, options, K_norm)
                    for frame, depth in zip(frames, depths)
                ]
                count += len(frames)
                bar.update(len(frames))
            for job in written:
                job.result()
        bar.close()
        if writer is not None:
            writer.close()

        outputs = folders + (["video.mp4"] if writer is not None else [])
        if do_pose:
            relative = chain.steps()
            relative[:, :3, 3] *= s  # the sequence scale applies to translations too
            poses = global_from_relative(relative)
            write_kitti_poses(tmp / "trajectory_kitti.txt", poses)
            write_tum(tmp / "trajectory_tum.txt", poses, np.asarray(times))
            plot_trajectory_topview(
                poses, tmp / "trajectory.png", metres=result.method in ("ground_truth", "camera_height")
            )
            outputs += ["trajectory_kitti.txt", "trajectory_tum.txt", "trajectory.png"]

        scale_info = result.to_dict()
        if drift:
            index, per_frame = np.array([d[0] for d in drift]), np.array([d[2] for d in drift])
            scale_info["drift"] = {**drift_stats(per_frame, s), "per_frame": {name: float(v) for _, name, v in drift}}
            plot_scale_drift(index, per_frame, s, index[: len(result.frames)], tmp / "scale_drift.png")
            outputs.append("scale_drift.png")
        (tmp / "scale.json").write_text(json.dumps(scale_info, indent=2))
        summary = {
            "input": str(source.path),
            "input_kind": source.kind,
            "model": predictor.name,
            "network_size": [predictor.height, predictor.width],
            "frames": count,
            "fps": fps,
            "scale": s,
            "intrinsics_normalised": K_norm.tolist(),
            "seconds": time.perf_counter() - start,
            "outputs": outputs + ["scale.json", "predict.json"],
            "options": asdict(options),
        }
        (tmp / "predict.json").write_text(json.dumps(summary, indent=2))
    return summary
