"""KITTI calibration files: ``key: values`` lines (raw ``calib_*.txt`` and odometry ``calib.txt``).

Conventions (KITTI raw): ``[R|T]`` of ``calib_velo_to_cam`` maps Velodyne points into the unrectified
camera-0 frame, ``R_rect_00`` rotates them into the rectified camera-0 frame, and ``P_rect_0k``
projects rectified camera-0 points into camera k's image (its last column holds camera k's offset).
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Union

import numpy as np

from ..errors import PoseconsError
from ..fileio import require_file

CalibValue = Union[np.ndarray, str]
KITTI_FIXED_K = np.array([[0.58, 0, 0.5], [0, 1.92, 0.5], [0, 0, 1]], dtype=np.float32)
"""KITTI's customary normalised intrinsics (row 0 / W, row 1 / H), used when calibration is off."""


def parse_calib_text(text: str, source: str) -> dict[str, CalibValue]:
    """Parse ``key: values`` lines. Numeric values become float64 arrays; others stay text."""
    out: dict[str, CalibValue] = {}
    for number, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        key, sep, value = line.partition(":")
        key = key.strip()
        if not sep or not key or " " in key:
            raise PoseconsError(f"{source}:{number}: expected 'key: values', got {line.strip()[:60]!r}")
        try:
            out[key] = np.array([float(v) for v in value.split()], dtype=np.float64)
            if not np.isfinite(out[key]).all():
                raise PoseconsError(f"{source}:{number}: {key!r} holds a NaN or infinite number")
        except ValueError:
            if any(c.isdigit() for c in value) and _looks_numeric(value):
                raise PoseconsError(f"{source}:{number}: bad number in {key!r}: {value.strip()[:60]!r}") from None
            out[key] = value.strip()
    return out


def _looks_numeric(value: str) -> bool:
    """True when most tokens are numbers, i.e. a damaged numeric line rather than free text."""
    tokens = value.split()
    numeric = 0
    for tok in tokens:
        try:
            float(tok)
            numeric += 1
        except ValueError:
            pass
    return numeric > 0 and numeric >= len(tokens) / 2


def read_calib_file(path: Path) -> dict[str, CalibValue]:
    """Read a KITTI calibration file into ``{key: array | text}``."""
    path = require_file(Path(path), "calibration file")
    return parse_calib_text(path.read_text(), str(path))


def calib_matrix(calib: dict[str, CalibValue], key: str, shape: tuple[int, ...], source: Path) -> np.ndarray:
    """Fetch ``calib[key]`` reshaped to ``shape``, with an error naming the file when absent or wrong."""
    value = calib.get(key)
    if not isinstance(value, np.ndarray) or value.size != int(np.prod(shape)):
        raise PoseconsError(f"{source}: missing or malformed {key!r} (expected {int(np.prod(shape))} numbers)")
    return value.reshape(shape)


def rigid(calib: dict[str, CalibValue], source: Path) -> np.ndarray:
    """The (4, 4) transform ``[R|T]`` of a ``calib_velo_to_cam`` / ``calib_imu_to_velo`` file."""
    out = np.eye(4)
    out[:3, :3] = calib_matrix(calib, "R", (3, 3), source)
    out[:3, 3] = calib_matrix(calib, "T", (3,), source)
    return out


@functools.lru_cache(maxsize=64)
def cam_to_cam(date_dir: Path) -> dict[str, CalibValue]:
    """``<date>/calib_cam_to_cam.txt`` of a raw date folder, cached per folder."""
    return read_calib_file(Path(date_dir) / "calib_cam_to_cam.txt")


def raw_projection(date_dir: Path, cam: int = 2) -> tuple[np.ndarray, tuple[int, int]]:
    """``P_rect_0<cam>`` (3, 4) and the rectified image size (width, height) from ``S_rect_0<cam>``."""
    source = Path(date_dir) / "calib_cam_to_cam.txt"
    calib = cam_to_cam(Path(date_dir))
    p_rect = calib_matrix(calib, f"P_rect_0{cam}", (3, 4), source)
    width, height = calib_matrix(calib, f"S_rect_0{cam}", (2,), source)
    if width < 1 or height < 1 or p_rect[0, 0] <= 0 or p_rect[1, 1] <= 0:
        raise PoseconsError(
            f"{source}: S_rect_0{cam} ({width:g}×{height:g}) and the focal lengths of P_rect_0{cam} must be positive"
        )
    return p_rect, (int(round(width)), int(round(height)))


def pixel_to_normalised(K: np.ndarray, height: int, width: int) -> np.ndarray:
    """(3, 3) float64 K normalised by image size (row 0 / W, row 1 / H) from the pixel K of an image of
    height × width (the first three columns of a projection matrix are such a K).

    Arguments in (height, width) order, as torch and :func:`posecons.geometry.scale_intrinsics`.
    """
    K = np.array(K[:3, :3], dtype=np.float64)
    K[0] /= width
    K[1] /= height
    return K


def normalised_to_pixel(K_norm: np.ndarray, height: int, width: int) -> np.ndarray:
    """(3, 3) normalised K → float64 pixel K of an image of height × width (numpy twin of
    :func:`posecons.geometry.scale_intrinsics`)."""
    K = np.array(K_norm, dtype=np.float64)
    K[0] *= width
    K[1] *= height
    return K


PIXEL_K_KEYS = {"K": (3, 3), "P_rect_02": (3, 4), "P2": (3, 4)}  # plain K, raw cam_to_cam, odometry calib.txt


def read_calib_intrinsics(path: str | Path) -> np.ndarray:
    """(3, 3) float64 pixel K of the left colour camera from a ``key: values`` file: the first of ``K``
    (9 numbers), ``P_rect_02`` (KITTI raw calib_cam_to_cam.txt) or ``P2`` (odometry calib.txt)."""
    path = Path(path)
    calib = read_calib_file(path)
    for key, shape in PIXEL_K_KEYS.items():
        if key in calib:
            return calib_matrix(calib, key, shape, path)[:, :3].astype(np.float64)
    raise PoseconsError(
        f"{path}: no 'K', 'P_rect_02' or 'P2' entry (expected a file with 'K: 9 numbers', "
        f"a KITTI calib_cam_to_cam.txt or an odometry calib.txt)"
    )


def read_intrinsics(path: str | Path) -> np.ndarray:
    """(3, 3) float64 pixel K from a plain 3 × 3 matrix (three lines of three numbers, as 7-Scenes'
    ``camera-intrinsics.txt``) or, when the file has ``key: values`` lines, :func:`read_calib_intrinsics`."""
    path = require_file(Path(path), "intrinsics file")
    lines = [line.split() for line in path.read_text().splitlines() if line.strip()]
    if any(":" in line[0] for line in lines):
        return read_calib_intrinsics(path)
    try:
        k = np.array(lines, dtype=np.float64)
        ok = k.shape == (3, 3) and np.isfinite(k).all() and k[0, 0] > 0 and k[1, 1] > 0 and (k[2] == (0, 0, 1)).all()
    except ValueError:  # ragged rows or a word
        ok = False
    if not ok:
        raise PoseconsError(
            f"{path}: expected a 3 × 3 intrinsics matrix (fx 0 cx / 0 fy cy / 0 0 1, fx and fy > 0) or 'K: 9 numbers'"
        )
    return k


def raw_intrinsics(date_dir: Path, cam: int = 2) -> np.ndarray:
    """Normalised (3, 3) float32 K of rectified camera ``cam`` of a raw date folder."""
    p_rect, (width, height) = raw_projection(date_dir, cam)
    return pixel_to_normalised(p_rect, height, width).astype(np.float32)


def velo_to_image(date_dir: Path, cam: int = 2) -> np.ndarray:
    """(3, 4) P_velo→img = P_rect_0<cam> · R_rect_00 · [R|T]_velo→cam."""
    date_dir = Path(date_dir)
    source = date_dir / "calib_cam_to_cam.txt"
    p_rect, _ = raw_projection(date_dir, cam)
    r_rect = np.eye(4)
    r_rect[:3, :3] = calib_matrix(cam_to_cam(date_dir), "R_rect_00", (3, 3), source)
    velo_file = date_dir / "calib_velo_to_cam.txt"
    return p_rect @ r_rect @ rigid(read_calib_file(velo_file), velo_file)


def rectified_offset(p_rect: np.ndarray) -> np.ndarray:
    """(4, 4) rectified camera 0 → the rectified camera of projection ``p_rect`` = K [I | t]: a shift by t."""
    out = np.eye(4)
    out[:3, 3] = np.linalg.solve(p_rect[:, :3], p_rect[:, 3])
    return out


@functools.lru_cache(maxsize=64)
def imu_to_camera(date_dir: Path, cam: int = 2) -> np.ndarray:
    """(4, 4) GNSS/INS unit → rectified camera ``cam``: offset · R_rect_00 · [R|T]_velo→cam · [R|T]_imu→velo."""
    date_dir = Path(date_dir)
    r_rect = np.eye(4)
    r_rect[:3, :3] = calib_matrix(cam_to_cam(date_dir), "R_rect_00", (3, 3), date_dir / "calib_cam_to_cam.txt")
    velo, imu = date_dir / "calib_velo_to_cam.txt", date_dir / "calib_imu_to_velo.txt"
    velo_to_cam, imu_to_velo = rigid(read_calib_file(velo), velo), rigid(read_calib_file(imu), imu)
    return rectified_offset(raw_projection(date_dir, cam)[0]) @ r_rect @ velo_to_cam @ imu_to_velo


def format_calib(entries: dict, calib_time: str | None = "01-Jan-2020 00:00:00") -> str:
    """KITTI calibration text: optional ``calib_time`` then ``key: v v v`` lines (%e numbers)."""
    lines = [f"calib_time: {calib_time}"] if calib_time else []
    lines += [f"{key}: " + " ".join(f"{float(v):e}" for v in values) for key, values in entries.items()]
    return "\n".join(lines) + "\n"
