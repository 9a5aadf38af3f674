"""Is the right depth in the images, and does the network's own motion explain them? For every fourth
frame of a synthetic study's test drives (or, with --drives train, of its training drives), at the network's size: the per-pixel minimum photometric error over the
sources ±stride (no auto-mask) with the renderer's exact depth and the true motion; with each run's
depth (scaled by the frame's median against the exact one) and the true motion; with its depth and its
own motion (translation scaled alike); with the exact depth and its motion; and the unwarped sources'.
By the exact depth's thirds: near (< --near m), middle, far (> --far m). Also: how many pixels of each
third the auto-mask would drop with the exact depth.

    python experiments/tools/far_signal.py --study OUT baseline/seed0 [steps2000/seed0 ...]

OUT is a `posecons study --out` folder of `posecons synth` data (its synth.json names the generator's
seed, profile, size and test drives, which the renderer repeats).
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

import numpy as np
import torch

from posecons.data.kitti_raw import KittiRawDataset
from posecons.data.synth import make_drive
from posecons.data.synth.render import camera_depth_at
from posecons.data.synth.rig import Rig
from posecons.errors import PoseconsError
from posecons.geometry import scale_intrinsics, warp
from posecons.inference.backend import load_predictor
from posecons.losses import photometric_error

DRIVE = re.compile(r"drive_(\d+)")


def min_error(frames: torch.Tensor, K: torch.Tensor, depth: np.ndarray, T: dict, valid: np.ndarray) -> np.ndarray:
    """Per valid pixel, the least photometric error of the sources (frames[:, 1:], offsets in T's order)
    warped into frames[:, 0] with ``depth`` (H, W) and T_{source←target}."""
    d = torch.from_numpy(np.asarray(depth, np.float32))[None, None]
    e = [photometric_error(warp(frames[:, i + 1], d, T_o, K), frames[:, 0]) for i, T_o in enumerate(T.values())]
    return torch.cat(e, 1).min(1).values[0].numpy()[valid]


def errors(study: Path, runs: list[str], stride: int, role: str) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Per valid pixel of the frames: each error named in the module docstring, and the exact depth."""
    info = json.loads((study / "data" / "synth.json").read_text())
    predictors = {run: load_predictor(study / "runs" / run / "checkpoints" / "last.pt", "cpu") for run in runs}
    m = next(iter(predictors.values())).model.config.model
    h, w = m.height, m.width
    rig = Rig(info["width"], info["height"])
    v, u = np.mgrid[0:h, 0:w]  # pixel centres of the network's image in the rendered image's pixels
    uv = np.stack([(u + 0.5) * info["width"] / w - 0.5, (v + 0.5) * info["height"] / h - 0.5], -1).reshape(-1, 2)
    out: dict[str, list[np.ndarray]] = {}

    def add(name: str, values: np.ndarray) -> None:
        out.setdefault(name, []).append(values)

    depths = []
    offsets = (-stride, stride)
    for folder in info[f"{role}_drives"]:
        drive = make_drive(info["seed"], int(DRIVE.search(folder).group(1)), info["frames"], info["profile"])
        lines = [f"{folder} {f} l" for f in range(stride, info["frames"] - stride, 4)]
        data = KittiRawDataset(study / "data", lines, h, w, frame_ids=(0, *offsets), train=False)
        for k, line in enumerate(lines):
            sample, f = data[k], int(line.split()[1])
            pose = {o: drive.camera_pose(rig, f + o, 2) for o in (0, *offsets)}
            exact = camera_depth_at(drive.prims, pose[0], rig.k(2), uv).reshape(h, w)
            valid = exact > 0
            frames = sample["frames"][None]
            K = scale_intrinsics(sample["intrinsics"][None], h, w)
            true = {o: torch.from_numpy(np.linalg.inv(pose[o]) @ pose[0]).float()[None] for o in offsets}

            filled = np.where(valid, exact, 1e3)
            add("exact depth and motion", min_error(frames, K, filled, true, valid))
            unwarped = [photometric_error(frames[:, i + 1], frames[:, 0]) for i in range(len(offsets))]
            add("unwarped sources", torch.cat(unwarped, 1).min(1).values[0].numpy()[valid])
            for run, predictor in predictors.items():
                with torch.no_grad():
                    depth = predictor.model.predict_depth(frames[:, 0])[1][0, 0].numpy()
                    own = {  # pairs in temporal order, as in training
                        o: predictor.model.predict_pose(frames[:, 0], frames[:, i + 1])
                        if o > 0
                        else torch.linalg.inv(predictor.model.predict_pose(frames[:, i + 1], frames[:, 0]))
                        for i, o in enumerate(offsets)
                    }
                scale = np.median(exact[valid]) / np.median(depth[valid])
                for T in own.values():
                    T[:, :3, 3] *= scale
                add(f"{run}: its depth, true motion", min_error(frames, K, depth * scale, true, valid))
                add(f"{run}: its depth and motion", min_error(frames, K, depth * scale, own, valid))
                add(f"{run}: exact depth, its motion", min_error(frames, K, filled, own, valid))
            depths.append(exact[valid])
    return {name: np.concatenate(v) for name, v in out.items()}, np.concatenate(depths)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--study", type=Path, required=True, help="a `posecons study --out` folder of synthetic data")
    p.add_argument("runs", nargs="+", help="VARIANT/seedK")
    p.add_argument("--stride", type=int, default=3, help="frame offset of the sources (the training offset)")
    p.add_argument("--drives", choices=("test", "train"), default="test", help="held-out drives, or trained ones")
    p.add_argument("--near", type=float, default=9.0, help="metres: the near third's upper bound")
    p.add_argument("--far", type=float, default=16.0, help="metres: the far third's lower bound")
    args = p.parse_args()
    try:
        errs, depth = errors(args.study, args.runs, args.stride, args.drives)
    except (OSError, KeyError, ValueError, PoseconsError) as exc:  # a missing run or file
        print(f"error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None
    band = np.digitize(depth, [args.near, args.far])
    names = [f"near < {args.near:g} m", "middle", f"far > {args.far:g} m"]
    exact, unwarped = errs["exact depth and motion"], errs["unwarped sources"]
    print(
        "auto-masked with the exact depth: "
        + ", ".join(f"{n} {(unwarped < exact)[band == i].mean():.0%}" for i, n in enumerate(names))
    )
    print("| error | " + " | ".join(f"{n} ({(band == i).mean():.0%})" for i, n in enumerate(names)) + " |")
    print("|---|" + "---:|" * len(names))
    for name, e in errs.items():
        print(f"| {name} | " + " | ".join(f"{e[band == i].mean():.4f}" for i in range(len(names))) + " |")


if __name__ == "__main__":
    main()
