"""A small RGB-D sequence written in 7-Scenes' layout (``frame-NNNNNN.{color.png,depth.png,pose.txt}``),
for the prepare-rgbd tests."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image


def write_sequence(folder: Path, count: int = 3, width: int = 16, height: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """Random colour frames, 16-bit depth in millimetres (500–4000, with some 0 and 65535 pixels) and
    camera → world poses turning 10° a frame about z; returns the raw depth (count, H, W) and the poses."""
    rng = np.random.default_rng(0)
    folder.mkdir(parents=True)
    depth = rng.integers(500, 4000, (count, height, width)).astype(np.uint16)
    depth[:, 0, :3], depth[:, 1, :2] = 0, 65535
    poses = np.tile(np.eye(4), (count, 1, 1))
    for i in range(count):
        c, s = np.cos(np.radians(10 * i)), np.sin(np.radians(10 * i))
        poses[i, :2, :2] = [[c, -s], [s, c]]
        poses[i, :3, 3] = [0.1 * i, 0.0, 0.05 * i]
        colour = (rng.random((height, width, 3)) * 255).astype(np.uint8)
        Image.fromarray(colour).save(folder / f"frame-{i:06d}.color.png")
        Image.fromarray(depth[i]).save(folder / f"frame-{i:06d}.depth.png")
        np.savetxt(folder / f"frame-{i:06d}.pose.txt", poses[i])
    return depth, poses
