"""Metric scale without LiDAR on a study's held-out drives: each run's last weights predict the test
drives, and each drive's scale is set once from the camera's height above the road fitted in its
first N frames (what ``predict --camera-height`` does), then abs rel is measured with that one scale
and no ground-truth scaling, beside per-frame and per-drive median scaling. The true height is the
same fit on the ground truth of the same frames, so the method's error is the network's, not the fit's.
With --windows, every frame is also scaled by its own road plane (the predicted height a centred median
over K frames, against that one true height): the σ/μ left after it, and its abs rel with no
ground-truth scaling. (The column with the test-time stabiliser before calibrating went with the
stabiliser; the tool at commit 085f365 has it.)

    python experiments/tools/camera_height.py study/synth_fast runs/study_fast baseline/0 cyc/0 [--frames 10]
"""

from __future__ import annotations

import argparse
import itertools
from pathlib import Path

import numpy as np

from posecons.cli.arguments import positive_int
from posecons.data.calib import normalised_to_pixel, raw_intrinsics
from posecons.data.gt import load_gt
from posecons.data.splits import SIDE_TO_CAMERA
from posecons.errors import PoseconsError
from posecons.evaluation import evaluate
from posecons.inference.backend import load_predictor
from posecons.inference.scale import camera_height
from posecons.study.runner import prepare_data
from posecons.study.spec import load_spec


def frame_heights(disps: np.ndarray, gts: list[np.ndarray], lines, data_path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(N,) camera height above the road fitted on each frame's ground truth and on its prediction
    (NaN where no plane is found)."""

    def height(depth: np.ndarray, k: np.ndarray) -> float:
        try:
            return camera_height(depth, normalised_to_pixel(k, *depth.shape))
        except PoseconsError:
            return np.nan

    true, predicted = np.full(len(lines), np.nan), np.full(len(lines), np.nan)
    for i, line in enumerate(lines):
        k = raw_intrinsics(Path(data_path) / Path(line.folder).parent, SIDE_TO_CAMERA[line.side])
        true[i], predicted[i] = height(gts[i], k), height(1.0 / disps[i], k)
    return true, predicted


def drive_scales(true: np.ndarray, predicted: np.ndarray, lines, frames: int, window: int | None) -> np.ndarray:
    """(N,) factor on each frame's predicted depth. Each drive's camera height is the median of the
    heights fitted on the ground truth of its first ``frames`` frames (what a user would measure once).
    window None: one factor per drive, the median over those frames of true / predicted height (what
    ``predict --camera-height`` does); window K: each frame's own factor, that height over the median
    predicted height of the K frames centred on it (K = 1: the frame alone)."""
    factors = np.ones(len(lines))
    for _, group in itertools.groupby(range(len(lines)), key=lambda i: lines[i].folder):
        index = np.array(list(group))
        if window is None:
            factors[index] = np.nanmedian(true[index[:frames]] / predicted[index[:frames]])
            continue
        h = np.nanmedian(true[index[:frames]])
        for j, i in enumerate(index):
            factors[i] = h / np.nanmedian(predicted[index[max(0, j - window // 2) : j + window // 2 + 1]])
    return factors


def camera_height_row(
    spec: str, study: Path, variant: str, seed: int, frames: int, windows: list[int]
) -> dict[str, float]:
    data = prepare_data(load_spec(spec), study)
    predictor = load_predictor(study / "runs" / variant / f"seed{seed}" / "checkpoints" / "last.pt")
    gts, _ = load_gt(data.gt)
    disps = evaluate.model_disparities(predictor, data.train_path, data.split)

    def scored(d: np.ndarray, scaling: str) -> dict:
        return evaluate.evaluate_depth(d, gts, data.split, data.gt_kind, scaling=scaling, depth_range=data.depth_range)

    true, predicted = frame_heights(disps, gts, data.split, data.train_path)
    camera = drive_scales(true, predicted, data.split, frames, None)
    frame = scored(disps, "frame")
    scales, names = np.asarray(frame["scales"]), np.array([line.folder for line in data.split])
    drives = [names == name for name in dict.fromkeys(names)]
    row = {
        "abs_rel_frame": frame["abs_rel"],
        "abs_rel_drive": scored(disps, "sequence")["abs_rel"],
        "abs_rel_camera": scored(disps / camera[:, None, None].astype(np.float32), "none")["abs_rel"],
        # each drive's calibrated scale over its median ground-truth scale (1: exact), averaged
        "camera_over_median": float(np.mean([camera[i].mean() / np.nanmedian(scales[i]) for i in drives])),
        "sigma_mu": frame["scale_cv"],
    }
    for window in windows:  # every frame scaled by its own road plane: σ/μ of what is left, and metric abs rel
        rescaled = disps / drive_scales(true, predicted, data.split, frames, window)[:, None, None].astype(np.float32)
        row[f"sigma_mu_camera_w{window}"] = scored(rescaled, "frame")["scale_cv"]
        row[f"abs_rel_camera_w{window}"] = scored(rescaled, "none")["abs_rel"]
    return row


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("spec", help="the study's spec, e.g. study/synth_fast")
    p.add_argument("study", type=Path, help="the study folder (its data/ and runs/)")
    p.add_argument("runs", nargs="+", help="VARIANT/SEED, e.g. baseline/0")
    p.add_argument("--frames", type=int, default=10, help="frames of each drive the height is fitted on")
    p.add_argument(
        "--windows",
        type=positive_int,
        nargs="*",
        default=[1, 9],
        help="also scale every frame by its own road plane, the predicted height a median over this many frames",
    )
    args = p.parse_args()
    for run in args.runs:
        variant, _, seed = run.partition("/")
        if not seed.isdigit():
            p.exit(2, f"error: {run}: give a run as VARIANT/SEED, e.g. baseline/0\n")
        try:
            row = camera_height_row(args.spec, args.study, variant, int(seed), args.frames, args.windows)
        except PoseconsError as exc:  # e.g. a run whose checkpoint is not on this machine
            p.exit(2, f"error: {exc}\n")
        print(f"{run}: " + ", ".join(f"{k} {v:.4f}" for k, v in row.items()), flush=True)


if __name__ == "__main__":
    main()
