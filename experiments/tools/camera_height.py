"""Metric scale without LiDAR on a study's held-out drives: each run's last weights predict the test
drives, and each drive's scale is set once from the camera's height above the road fitted in its
first N frames (what ``predict --camera-height`` does), then abs rel is measured with that one scale
and no ground-truth scaling, beside per-frame and per-drive median scaling, and with the test-time
stabiliser applied before calibrating ("calibrate once + stabilise"). The true height is the same fit
on the ground truth of the same frames, so the method's error is the network's, not the fit's.

    python experiments/tools/camera_height.py study/synth_fast runs/study_fast baseline/0 cyc/0 [--frames 10]
"""

from __future__ import annotations

import argparse
import itertools
from pathlib import Path

import numpy as np

from posecons.data.calib import normalised_to_pixel, raw_intrinsics
from posecons.data.gt import load_gt
from posecons.data.splits import SIDE_TO_CAMERA
from posecons.errors import PoseconsError
from posecons.evaluation import evaluate
from posecons.inference.backend import load_predictor
from posecons.inference.scale import camera_height
from posecons.study.runner import prepare_data
from posecons.study.spec import load_spec


def drive_scales(disps: np.ndarray, gts: list[np.ndarray], lines, data_path: Path, frames: int) -> np.ndarray:
    """(N,) factor on each frame's predicted depth: per drive, the median over its first ``frames``
    frames of (height fitted on the ground truth) / (height fitted on the prediction)."""
    factors = np.ones(len(lines))
    for _, group in itertools.groupby(range(len(lines)), key=lambda i: lines[i].folder):
        index = list(group)
        line = lines[index[0]]
        k = raw_intrinsics(Path(data_path) / Path(line.folder).parent, SIDE_TO_CAMERA[line.side])
        ratios = [
            camera_height(gts[i], normalised_to_pixel(k, *gts[i].shape))
            / camera_height(1.0 / disps[i], normalised_to_pixel(k, *disps.shape[1:]))
            for i in index[:frames]
        ]
        factors[index] = np.median(ratios)
    return factors


def camera_height_row(spec: str, study: Path, variant: str, seed: int, frames: int) -> dict[str, float]:
    data = prepare_data(load_spec(spec), study)
    predictor = load_predictor(study / "runs" / variant / f"seed{seed}" / "checkpoints" / "last.pt")
    gts, _ = load_gt(data.gt)
    disps = evaluate.model_disparities(predictor, data.train_path, data.split)
    stable, _ = evaluate.stabilised_disparities(predictor, data.train_path, data.split, disps)

    def scored(d: np.ndarray, scaling: str) -> dict:
        return evaluate.evaluate_depth(d, gts, data.split, data.gt_kind, scaling=scaling, depth_range=data.depth_range)

    camera = drive_scales(disps, gts, data.split, data.train_path, frames)
    camera_stable = drive_scales(stable, gts, data.split, data.train_path, frames)
    frame = scored(disps, "frame")
    scales, names = np.asarray(frame["scales"]), np.array([line.folder for line in data.split])
    drives = [names == name for name in dict.fromkeys(names)]
    return {
        "abs_rel_frame": frame["abs_rel"],
        "abs_rel_drive": scored(disps, "sequence")["abs_rel"],
        "abs_rel_camera": scored(disps / camera[:, None, None].astype(np.float32), "none")["abs_rel"],
        "abs_rel_camera_stabilised": scored(stable / camera_stable[:, None, None].astype(np.float32), "none")[
            "abs_rel"
        ],
        # each drive's calibrated scale over its median ground-truth scale (1: exact), averaged
        "camera_over_median": float(np.mean([camera[i].mean() / np.nanmedian(scales[i]) for i in drives])),
        "sigma_mu": frame["scale_cv"],
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("spec", help="the study's spec, e.g. study/synth_fast")
    p.add_argument("study", type=Path, help="the study folder (its data/ and runs/)")
    p.add_argument("runs", nargs="+", help="VARIANT/SEED, e.g. baseline/0")
    p.add_argument("--frames", type=int, default=10, help="frames of each drive the height is fitted on")
    args = p.parse_args()
    for run in args.runs:
        variant, _, seed = run.partition("/")
        if not seed.isdigit():
            p.exit(2, f"error: {run}: give a run as VARIANT/SEED, e.g. baseline/0\n")
        try:
            row = camera_height_row(args.spec, args.study, variant, int(seed), args.frames)
        except PoseconsError as exc:  # e.g. a run whose checkpoint is not on this machine
            p.exit(2, f"error: {exc}\n")
        print(f"{run}: " + ", ".join(f"{k} {v:.4f}" for k, v in row.items()), flush=True)


if __name__ == "__main__":
    main()
