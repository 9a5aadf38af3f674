"""Does a frame's depth scale follow its pose net's? For each moving test frame i of a synthetic study,
the depth's scale s = median(LiDAR)/median(prediction) (the study's per-frame scales) beside the pose
net's r = |t_true| / |t_pred| for the pair (i, i + stride): both are metres per network unit, and the
photometric loss ties them in training. Printed: the spread of log s and log r, how much of log s's
variance log r explains, and each one's correlation with the frame's median LiDAR depth (the
compression of far scenes, experiments/investigation.md §4, §13). Frames whose true motion over the
pair is under --min-motion metres (stops) have no scale in t and are left out.

    python experiments/tools/pose_scale.py --study OUT baseline/seed0 [anchor/seed4 ...]
    python experiments/tools/pose_scale.py --study OUT --by-drive vel01/seed0   # every drive, trained ones too

``--by-drive`` prints, for every drive's moving pairs, the sd of log r and the median r: whether the
pose net's scale holds within and across the drives it was trained on and the held-out ones.

OUT is a `posecons study --out` folder of synthetic data (`posecons synth` writes each drive's
odometry sequence under the drive's number).
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

import numpy as np
import torch

from posecons.data.gt import load_gt
from posecons.data.kitti_odometry import list_sequence_frames
from posecons.data.splits import read_split
from posecons.data.trajectory_io import read_kitti_poses
from posecons.errors import PoseconsError
from posecons.inference.backend import load_predictor, predict_batches
from posecons.inference.media import frames_from_paths

DRIVE = re.compile(r"drive_(\d+)")


def load_run(study: Path, run: str):
    variant, _, seed = run.partition("/seed")
    if not seed.isdigit():
        raise PoseconsError("expected VARIANT/seedK, e.g. baseline/seed0")
    result = json.loads((study / "results" / f"{variant}_seed{seed}.json").read_text())
    return result, load_predictor(study / "runs" / run / "checkpoints" / "last.pt", "cpu")


def pair_ratios(predictor, odometry: Path, sequence: str, stride: int) -> tuple[np.ndarray, np.ndarray]:
    """For the pairs (i, i + stride) of a drive: the true distance |t_true| and r = |t_true| / |t_pred|."""
    frames = frames_from_paths(list_sequence_frames(odometry, sequence))
    images = torch.from_numpy(np.concatenate([x for _, x, _ in predict_batches(predictor, frames, 32, depth=False)]))
    poses = read_kitti_poses(odometry / "poses" / f"{sequence}.txt")
    true = np.linalg.norm((np.linalg.inv(poses[stride:]) @ poses[:-stride])[:, :3, 3], axis=1)
    with torch.no_grad():
        t = predictor.model.pose_net(images[:-stride], images[stride:])[1][:, 0].double().numpy()
    return true, true / np.linalg.norm(t, axis=1)


def by_drive(study: Path, run: str, stride: int, min_motion: float) -> str:
    _, predictor = load_run(study, run)
    odometry = study / "data" / "odometry"
    cells = []
    for sequence in sorted(p.stem for p in (odometry / "poses").glob("*.txt")):
        true, r = pair_ratios(predictor, odometry, sequence, stride)
        log_r = np.log(r[true >= min_motion])
        cells.append(f"{log_r.std():.3f} / {np.exp(np.median(log_r)):.0f}")
    return f"| {run} | " + " | ".join(cells) + " |"


def pose_scale(study: Path, run: str, stride: int, min_motion: float) -> dict[str, float]:
    result, predictor = load_run(study, run)
    split = read_split(study / "data" / "splits" / "synth" / "test_files.txt")
    scales = np.asarray(result["depth"]["frame"]["scales"])
    gts, _ = load_gt(study / "gt" / "test_depth.npz")
    if not len(scales) == len(split) == len(gts):
        raise PoseconsError(f"{run}: {len(scales)} frame scales for {len(split)} test frames and {len(gts)} depth maps")
    by_sequence: dict[str, list[int]] = {}  # the test frames of each drive, by its odometry sequence
    for k, line in enumerate(split):
        drive = int(DRIVE.search(line.folder).group(1))
        by_sequence.setdefault(f"{drive:02d}", []).append(k)
    odometry = study / "data" / "odometry"
    log_s, log_r, log_gt = [], [], []
    for sequence, rows in by_sequence.items():
        true, r = pair_ratios(predictor, odometry, sequence, stride)  # r[i]: the pair (i, i + stride)
        for k in rows:
            i = split[k].frame
            if i < len(r) and true[i] >= min_motion:
                log_s.append(np.log(scales[k]))
                log_r.append(np.log(r[i]))
                log_gt.append(np.log(np.median(gts[k][gts[k] > 0])))
    s, r, g = map(np.asarray, (log_s, log_r, log_gt))
    corr = np.corrcoef(s, r)[0, 1]
    return {
        "frames": len(s),
        "sd_log_s": s.std(),
        "sd_log_r": r.std(),
        "corr_s_r": corr,
        "explained": corr**2,
        "corr_s_gt": np.corrcoef(s, g)[0, 1],
        "corr_r_gt": np.corrcoef(r, g)[0, 1],
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--study", type=Path, required=True, help="a `posecons study --out` folder")
    p.add_argument("runs", nargs="+", help="VARIANT/seedK")
    p.add_argument("--stride", type=int, default=3, help="frame offset of the pairs (the training offset)")
    p.add_argument("--min-motion", type=float, default=0.5, help="metres over a pair below which a frame is a stop")
    p.add_argument("--by-drive", action="store_true", help="sd of log r / median r on every drive instead")
    args = p.parse_args()
    if args.by_drive:
        drives = sorted(p.stem for p in (args.study / "data" / "odometry" / "poses").glob("*.txt"))
        print("| run | " + " | ".join(f"drive {d}: sd log r / median r" for d in drives) + " |")
        print("|---|" + "---:|" * len(drives))
    else:
        print("| run | moving frames | sd log s | sd log r | corr(log s, log r) | corr with log median LiDAR: s, r |")
        print("|---|---:|---:|---:|---:|---:|")
    for run in args.runs:
        try:
            if args.by_drive:
                print(by_drive(args.study, run, args.stride, args.min_motion))
                continue
            st = pose_scale(args.study, run, args.stride, args.min_motion)
        except (OSError, KeyError, ValueError, PoseconsError) as exc:  # a missing run or file, a bad name
            print(f"error: {run}: {exc}", file=sys.stderr)
            raise SystemExit(2) from None
        print(
            f"| {run} | {st['frames']} | {st['sd_log_s']:.3f} | {st['sd_log_r']:.3f} | {st['corr_s_r']:+.2f} "
            f"({100 * st['explained']:.0f} %) | {st['corr_s_gt']:+.2f}, {st['corr_r_gt']:+.2f} |"
        )


if __name__ == "__main__":
    main()
