"""Small I/O helpers shared by the data layer: checked readers and all-or-nothing writers.

Every writer goes through a temporary path next to its target and is renamed at the end, so an
error never leaves partial output behind.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np
from PIL import Image

from ..errors import PoseconsError


def require_file(path: Path, what: str) -> Path:
    """Return ``path`` if it is a file, else raise naming it and what it should have been."""
    if not path.is_file():
        raise PoseconsError(f"{path}: {what} not found")
    return path


def load_rgb(path: Path) -> Image.Image:
    """Open an image file as an RGB PIL image (decoded now, so errors surface here)."""
    require_file(path, "image")
    try:
        with Image.open(path) as img:
            return img.convert("RGB")
    except OSError as exc:
        raise PoseconsError(f"{path}: unreadable image ({exc})") from exc


def load_velodyne(path: Path) -> np.ndarray:
    """Read a KITTI Velodyne scan: (N, 4) float32 rows of x, y, z, reflectance."""
    require_file(path, "Velodyne scan")
    size = path.stat().st_size
    if size % 16:
        raise PoseconsError(f"{path}: size {size} bytes is not a multiple of 16 (4 float32 per point)")
    return np.fromfile(path, dtype="<f4").reshape(-1, 4)


@contextlib.contextmanager
def atomic_dir(target: Path) -> Iterator[Path]:
    """Yield a temporary directory that becomes ``target`` on success and vanishes on error.

    ``target`` must not exist or be an empty directory.
    """
    target = Path(target)
    if target.exists() and (not target.is_dir() or any(target.iterdir())):
        raise PoseconsError(f"{target}: output directory exists and is not empty")
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent))
    try:
        yield tmp
        if target.exists():
            target.rmdir()
        os.replace(tmp, target)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


@contextlib.contextmanager
def atomic_file(target: Path) -> Iterator[Path]:
    """Yield a temporary file path (same suffix) that replaces ``target`` on success only."""
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(prefix=f".{target.stem}.", suffix=target.suffix, dir=target.parent)
    os.close(fd)
    tmp = Path(name)
    try:
        yield tmp
        os.replace(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def resize_rgb(image: np.ndarray, height: int, width: int) -> np.ndarray:
    """(H, W, 3) uint8 → (3, height, width) float32 in [0, 1], resized like the training data
    (PIL bilinear, antialiased when shrinking)."""
    img = Image.fromarray(image).resize((width, height), Image.BILINEAR)
    return np.asarray(img, dtype=np.float32).transpose(2, 0, 1) / 255.0
