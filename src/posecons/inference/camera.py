"""Intrinsics of the input camera: ``--intrinsics fx,fy,cx,cy`` (pixels of the input image), a KITTI
calibration file, or KITTI's customary normalised K. Everything is kept normalised (row 0 / W,
row 1 / H) and scaled to each frame's size, so frames of another size reuse the same camera.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..data.calib import KITTI_FIXED_K, calib_matrix, read_calib_file
from ..errors import PoseconsError

CALIB_KEYS = ("P_rect_02", "P2")  # raw calib_cam_to_cam.txt, odometry calib.txt


def pixel_to_normalised(K: np.ndarray, height: int, width: int) -> np.ndarray:
    """(3, 3) pixel K of an image of height × width → normalised K."""
    K = np.array(K, dtype=np.float64)
    K[0] /= width
    K[1] /= height
    return K


def normalised_to_pixel(K_norm: np.ndarray, height: int, width: int) -> np.ndarray:
    """(3, 3) normalised K → pixel K of an image of height × width."""
    K = np.array(K_norm, dtype=np.float64)
    K[0] *= width
    K[1] *= height
    return K


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


def read_calib_intrinsics(path: str | Path) -> np.ndarray:
    """(3, 3) pixel K from a KITTI calib_cam_to_cam.txt (P_rect_02) or odometry calib.txt (P2)."""
    path = Path(path)
    calib = read_calib_file(path)
    for key in CALIB_KEYS:
        if key in calib:
            return calib_matrix(calib, key, (3, 4), path)[:, :3].astype(np.float64)
    raise PoseconsError(f"{path}: no {' or '.join(CALIB_KEYS)} entry (expected a KITTI calib_cam_to_cam.txt "
                        f"or odometry calib.txt)")


def resolve_intrinsics(intrinsics: str | None, calib: str | Path | None, height: int, width: int) -> np.ndarray:
    """Normalised (3, 3) K from the user's choice; pixel values refer to an image of height × width."""
    if intrinsics and calib:
        raise PoseconsError("give either --intrinsics or --calib, not both")
    if intrinsics:
        return pixel_to_normalised(parse_intrinsics(intrinsics), height, width)
    if calib:
        return pixel_to_normalised(read_calib_intrinsics(calib), height, width)
    return KITTI_FIXED_K.astype(np.float64)
