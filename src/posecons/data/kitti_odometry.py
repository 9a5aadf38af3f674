"""KITTI odometry: ``sequences/NN/{calib.txt,image_2,image_3}``; the ``poses/NN.txt`` and ``times.txt``
files are read by :mod:`.trajectory_io`."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image

from ..errors import PoseconsError
from ..fileio import require_file
from .calib import calib_matrix, pixel_to_normalised, read_calib_file, rectified_offset
from .frames import FrameDataset
from .splits import SIDE_TO_CAMERA, SplitLine
from .trajectory_io import read_kitti_poses


def sequence_dir(data_path: Path, sequence: int | str) -> Path:
    """``<data_path>/sequences/<NN>``."""
    return Path(data_path) / "sequences" / f"{int(sequence):02d}"


def read_odometry_projection(calib_path: Path, cam: int = 2) -> np.ndarray:
    """``P<cam>`` (3, 4) from a sequence's ``calib.txt`` (pixel units)."""
    calib_path = Path(calib_path)
    return calib_matrix(read_calib_file(calib_path), f"P{cam}", (3, 4), calib_path)


def list_sequence_frames(
    data_path: Path, sequence: int | str, side: str = "l", img_ext: str | None = None
) -> list[Path]:
    """Sorted image paths of one sequence's camera 2 (``l``) or 3 (``r``), for evaluation.

    ``img_ext`` None: whichever of .png (KITTI's own) and .jpg (converted, as Monodepth2 trains on)
    the folder holds; a folder holding both is refused rather than guessed.
    """
    folder = sequence_dir(data_path, sequence) / f"image_{SIDE_TO_CAMERA[side]}"
    exts = [img_ext] if img_ext else [".png", ".jpg"]
    found = {ext: sorted(p for p in folder.glob(f"*{ext}") if p.stem.isdigit()) for ext in exts}
    found = {ext: frames for ext, frames in found.items() if frames}
    if not found:
        raise PoseconsError(f"{folder}: no {' or '.join('*' + e for e in exts)} frames found")
    if len(found) > 1:
        raise PoseconsError(f"{folder}: holds both .png and .jpg frames; keep one kind")
    return next(iter(found.values()))


class KittiOdometryDataset(FrameDataset):
    """Odometry split lines ``<seq int> <frame> <l|r>`` (l → image_2, r → image_3, 6-digit names);
    K from ``calib.txt`` (P2 / P3). Same arguments and sample contract as
    :class:`~posecons.data.kitti_raw.KittiRawDataset`; ``data_path`` holds ``sequences/``.
    """

    def image_path(self, line: SplitLine, frame: int) -> Path:
        folder = sequence_dir(self.data_path, line.folder) / f"image_{SIDE_TO_CAMERA[line.side]}"
        return folder / f"{frame:06d}{self.img_ext}"

    def calib_k(self, line: SplitLine) -> np.ndarray:
        key = (int(line.folder), line.side)
        if key not in self._k_cache:  # the image size comes from one image header per camera
            image = require_file(self.image_path(line, line.frame), "image")
            with Image.open(image) as img:
                width, height = img.size
            calib = sequence_dir(self.data_path, line.folder) / "calib.txt"
            P = read_odometry_projection(calib, SIDE_TO_CAMERA[line.side])
            self._k_cache[key] = pixel_to_normalised(P, height, width).astype(np.float32)
        return self._k_cache[key]

    def camera_poses(self, line: SplitLine, frames: list[int]) -> np.ndarray:
        """Camera 0's ground-truth poses from ``<data_path>/poses/<NN>.txt`` (read once a sequence),
        carried to ``line``'s camera by its offset in ``calib.txt``."""
        sequence = int(line.folder)
        if sequence not in self._poses:
            path = require_file(Path(self.data_path) / "poses" / f"{sequence:02d}.txt", "odometry ground-truth poses")
            self._poses[sequence] = read_kitti_poses(path)
        known = self._poses[sequence]
        if max(frames) >= len(known):
            raise PoseconsError(f"{self.data_path}/poses/{sequence:02d}.txt: no pose for frame {max(frames)}")
        key = (sequence, line.side)
        if key not in self._offsets:  # camera 0 → this camera, read once a sequence and side
            calib = sequence_dir(self.data_path, line.folder) / "calib.txt"
            self._offsets[key] = np.linalg.inv(
                rectified_offset(read_odometry_projection(calib, SIDE_TO_CAMERA[line.side]))
            )
        return known[list(frames)] @ self._offsets[key]

    def __init__(self, *args, **kwargs) -> None:
        self._k_cache: dict[tuple[int, str], np.ndarray] = {}
        self._poses: dict[int, np.ndarray] = {}
        self._offsets: dict[tuple[int, str], np.ndarray] = {}
        super().__init__(*args, **kwargs)

    def check_files(self) -> None:
        for line in self.lines:
            if not line.folder.isdigit():
                raise PoseconsError(f"{line.where}: odometry sequence {line.folder!r} is not an integer")
        super().check_files()
