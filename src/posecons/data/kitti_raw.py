"""KITTI raw training data (also what ``synth`` and ``prepare`` write): see :mod:`.frames` for the
sample contract. No LiDAR is touched on this path."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import PoseconsError
from .calib import imu_to_camera, raw_intrinsics
from .frames import FrameDataset
from .oxts import oxts_to_poses, read_oxts
from .splits import SIDE_TO_CAMERA, SplitLine, SplitSource, read_split

IMAGE_EXTENSIONS = (".png", ".jpg")  # what split_image_paths looks for: KITTI's PNGs or a JPEG copy


def raw_image_path(data_path: Path, line: SplitLine, frame: int, ext: str) -> Path:
    """``D/<folder>/image_0{2,3}/data/<frame:010d><ext>``: camera 2 for side l, 3 for r."""
    return Path(data_path) / line.folder / f"image_0{SIDE_TO_CAMERA[line.side]}" / "data" / f"{frame:010d}{ext}"


def split_image_paths(data_path: str | Path, split: SplitSource) -> list[Path]:
    """The existing image (.png, else .jpg) of each split line's own frame, for evaluation."""
    paths = []
    for line in read_split(split):
        candidates = [raw_image_path(data_path, line, line.frame, ext) for ext in IMAGE_EXTENSIONS]
        found = next((p for p in candidates if p.is_file()), None)
        if found is None:
            raise PoseconsError(f"{candidates[0].with_suffix('')}.png / .jpg: image not found")
        paths.append(found)
    return paths


class KittiRawDataset(FrameDataset):
    """Split lines ``<date>/<drive>_sync <frame> <l|r>`` over a KITTI raw tree; l → image_02,
    r → image_03; K from each date's ``P_rect_02/03`` normalised by ``S_rect`` (cached per date).

    Arguments: ``(data_path, split, height, width, frame_ids=(0, -1, 1), img_ext=".png",
    train=True, calib_intrinsics=True, flip_prob=0.5, jitter_prob=0.5, seed=0, check_files=True)``.
    """

    def image_path(self, line: SplitLine, frame: int) -> Path:
        return raw_image_path(self.data_path, line, frame, self.img_ext)

    def calib_k(self, line: SplitLine) -> np.ndarray:
        date = line.folder.split("/")[0]
        return raw_intrinsics(self.data_path / date, SIDE_TO_CAMERA[line.side])

    def camera_poses(self, line: SplitLine, frames: list[int]) -> np.ndarray:
        """The GNSS/INS unit's poses from ``<folder>/oxts/data/<frame:010d>.txt`` carried to the
        camera through the date's ``calib_imu_to_velo``, ``calib_velo_to_cam`` and ``calib_cam_to_cam``."""
        folder = self.data_path / line.folder / "oxts" / "data"
        imu = oxts_to_poses(read_oxts([folder / f"{f:010d}.txt" for f in frames]))
        date_dir = self.data_path / line.folder.split("/")[0]
        return imu @ np.linalg.inv(imu_to_camera(date_dir, SIDE_TO_CAMERA[line.side]))
