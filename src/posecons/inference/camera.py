"""Intrinsics of the input camera: ``--intrinsics fx,fy,cx,cy`` (pixels of the input image), a KITTI
calibration file, or KITTI's customary normalised K. Everything is kept normalised (row 0 / W,
row 1 / H) and scaled to each frame's size, so frames of another size reuse the same camera.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..data.calib import KITTI_FIXED_K, pixel_to_normalised, read_calib_intrinsics
from ..errors import PoseconsError


def parse_intrinsics(text: str) -> np.ndarray:
    """``"fx,fy,cx,cy"`` in pixels → (3, 3) pixel K."""
    try:
        fx, fy, cx, cy = (float(v) for v in text.split(","))
    except ValueError:
        raise PoseconsError(f"--intrinsics expects four comma-separated numbers fx,fy,cx,cy, got {text!r}") from None
    if not np.isfinite([fx, fy, cx, cy]).all():
        raise PoseconsError(f"--intrinsics: NaN or infinite value in {text!r}")
    if fx <= 0 or fy <= 0:
        raise PoseconsError(f"--intrinsics: focal lengths must be positive, got fx={fx}, fy={fy}")
    return np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1]], dtype=np.float64)


def resolve_intrinsics(intrinsics: str | None, calib: str | Path | None, height: int, width: int) -> np.ndarray:
    """Normalised (3, 3) K from the user's choice; pixel values refer to an image of height × width."""
    if intrinsics and calib:
        raise PoseconsError("give either --intrinsics or --calib, not both")
    if intrinsics:
        return pixel_to_normalised(parse_intrinsics(intrinsics), height, width)
    if calib:
        return pixel_to_normalised(read_calib_intrinsics(calib), height, width)
    return KITTI_FIXED_K.astype(np.float64)
