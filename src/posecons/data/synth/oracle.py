"""The renderer's own depth as a prediction: what a perfect depth network would output for a
synthetic data set, so that evaluating it through the same pipeline gives each metric's floor
(the part due to resizing, LiDAR sampling and the crop, not to learning)."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ...errors import PoseconsError
from ..splits import SplitLine
from .generate import make_drive
from .profile import PROFILES
from .render import camera_depth_at
from .rig import Rig

_CAMERA = {"l": 2, "r": 3}


def oracle_disparities(data_path: str | Path, lines: Sequence[SplitLine], height: int, width: int) -> np.ndarray:
    """(N, height, width) float32 disparities 1/z of the exact camera depth at the pixel centres of a
    ``width`` × ``height`` image of each split line's frame (sky: 1e-3, i.e. 1 km)."""
    meta_file = Path(data_path) / "synth.json"
    if not meta_file.is_file():
        raise PoseconsError(f"{meta_file}: not found; the depth floor needs data written by `posecons synth`")
    meta = json.loads(meta_file.read_text())
    rig = Rig(width, height, PROFILES[meta.get("profile", "street")].focal)
    u, v = np.meshgrid(np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64))
    uv = np.stack([u.ravel(), v.ravel()], 1)
    drives, out = {}, []
    for line in lines:
        if line.folder not in drives:
            index = meta["drives"].index(line.folder)  # data from before profiles existed is "street"
            drives[line.folder] = make_drive(meta["seed"], index, meta["frames"], meta.get("profile", "street"))
        drive, cam = drives[line.folder], _CAMERA[line.side]
        depth = camera_depth_at(drive.prims, drive.camera_pose(rig, line.frame, cam), rig.k(cam), uv)
        out.append(np.where(depth > 0, 1 / np.maximum(depth, 1e-6), 1e-3).reshape(height, width))
    return np.stack(out).astype(np.float32)
