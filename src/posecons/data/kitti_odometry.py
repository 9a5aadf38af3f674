"""KITTI odometry: ``sequences/NN/{calib.txt,times.txt,image_2,image_3}`` and ``poses/NN.txt``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image

from ..errors import PoseconsError
from ..fileio import atomic_write
from .calib import calib_matrix, normalised_k, read_calib_file
from .frames import FrameDataset
from .io import require_file
from .splits import SIDE_TO_CAMERA as CAMERA
from .splits import SplitLine


def sequence_dir(data_path: Path, sequence: int | str) -> Path:
    """``<data_path>/sequences/<NN>``."""
    return Path(data_path) / "sequences" / f"{int(sequence):02d}"


def read_odometry_projection(calib_path: Path, cam: int = 2) -> np.ndarray:
    """``P<cam>`` (3, 4) from a sequence's ``calib.txt`` (pixel units)."""
    calib_path = Path(calib_path)
    return calib_matrix(read_calib_file(calib_path), f"P{cam}", (3, 4), calib_path)


def read_poses(path: Path) -> np.ndarray:
    """``poses/NN.txt`` → (N, 4, 4) float64 camera-0 → world poses (12 numbers a line, row-major 3×4)."""
    path = require_file(Path(path), "pose file")
    rows = []
    for number, line in enumerate(path.read_text().splitlines(), start=1):
        if not line.strip():
            continue
        try:
            values = [float(v) for v in line.split()]
        except ValueError:
            values = []
        if len(values) != 12:
            raise PoseconsError(f"{path}:{number}: expected 12 numbers, got {line.strip()[:60]!r}")
        if not np.isfinite(values).all():
            raise PoseconsError(f"{path}:{number}: NaN or infinite number in a pose")
        rows.append(values)
    poses = np.tile(np.eye(4), (len(rows), 1, 1))
    poses[:, :3, :] = np.asarray(rows).reshape(-1, 3, 4)
    return poses


def write_poses(path: Path, poses: np.ndarray) -> None:
    """Write (N, 4, 4) poses in the KITTI format (first 3 rows, row-major, 12 numbers a line)."""
    rows = np.asarray(poses)[:, :3, :].reshape(-1, 12)
    atomic_write(path, lambda tmp: np.savetxt(tmp, rows, fmt="%.9e"))


def list_sequence_frames(data_path: Path, sequence: int | str, side: str = "l", img_ext: str = ".png") -> list[Path]:
    """Sorted image paths of one sequence's camera 2 (``l``) or 3 (``r``), for evaluation."""
    folder = sequence_dir(data_path, sequence) / f"image_{CAMERA[side]}"
    frames = sorted(p for p in folder.glob(f"*{img_ext}") if p.stem.isdigit())
    if not frames:
        raise PoseconsError(f"{folder}: no *{img_ext} frames found")
    return frames


class KittiOdometryDataset(FrameDataset):
    """Odometry split lines ``<seq int> <frame> <l|r>`` (l → image_2, r → image_3, 6-digit names);
    K from ``calib.txt`` (P2 / P3). Same arguments and sample contract as
    :class:`~posecons.data.kitti_raw.KittiRawDataset`; ``data_path`` holds ``sequences/``.
    """

    def image_path(self, line: SplitLine, frame: int) -> Path:
        folder = sequence_dir(self.data_path, line.folder) / f"image_{CAMERA[line.side]}"
        return folder / f"{frame:06d}{self.img_ext}"

    def calib_k(self, line: SplitLine) -> np.ndarray:
        key = (int(line.folder), line.side)
        if key not in self._k_cache:  # the image size comes from one image header per camera
            image = require_file(self.image_path(line, line.frame), "image")
            with Image.open(image) as img:
                width, height = img.size
            calib = sequence_dir(self.data_path, line.folder) / "calib.txt"
            self._k_cache[key] = normalised_k(read_odometry_projection(calib, CAMERA[line.side]), width, height)
        return self._k_cache[key]

    def __init__(self, *args, **kwargs) -> None:
        self._k_cache: dict[tuple[int, str], np.ndarray] = {}
        super().__init__(*args, **kwargs)

    def check_files(self) -> None:
        for line in self.lines:
            if not line.folder.isdigit():
                raise PoseconsError(f"{line.where}: odometry sequence {line.folder!r} is not an integer")
        super().check_files()
