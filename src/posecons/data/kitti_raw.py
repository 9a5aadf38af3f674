"""KITTI raw training data (also what ``synth`` and ``prepare`` write): see :mod:`.frames` for the
sample contract. No LiDAR is touched on this path."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .calib import raw_intrinsics
from .frames import FrameDataset
from .splits import SIDE_TO_CAMERA as CAMERA
from .splits import SplitLine


class KittiRawDataset(FrameDataset):
    """Split lines ``<date>/<drive>_sync <frame> <l|r>`` over a KITTI raw tree; l → image_02,
    r → image_03; K from each date's ``P_rect_02/03`` normalised by ``S_rect`` (cached per date).

    Arguments: ``(data_path, split, height, width, frame_ids=(0, -1, 1), img_ext=".png",
    train=True, calib_intrinsics=True, flip_prob=0.5, jitter_prob=0.5, seed=0, check_files=True)``.
    """

    def image_path(self, line: SplitLine, frame: int) -> Path:
        cam = CAMERA[line.side]
        return self.data_path / line.folder / f"image_0{cam}" / "data" / f"{frame:010d}{self.img_ext}"

    def calib_k(self, line: SplitLine) -> np.ndarray:
        date = line.folder.split("/")[0]
        return raw_intrinsics(self.data_path / date, CAMERA[line.side])
