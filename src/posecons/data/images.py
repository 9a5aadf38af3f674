"""Image files → RGB arrays at the network size: the one decode and the one resize of every frame
(training data, the frame cache, evaluation and inference)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image

from ..errors import PoseconsError
from ..fileio import require_file


def image_suffix(ext: str) -> str:
    """An image extension with its dot: "png" → ".png"."""
    return ext if ext.startswith(".") else f".{ext}"


def load_rgb(
    path: Path, like: tuple[Path, tuple[int, int]] | None = None, draft: tuple[int, int] | None = None
) -> Image.Image:
    """Open an image file as an RGB PIL image (decoded now, so errors surface here).

    ``like`` = (reference image, its (width, height)): the image must have that size, or the error
    names both files. ``draft`` = (width, height): a JPEG is decoded by libjpeg's DCT scaling at the
    smallest of 1/2, 1/4, 1/8 of its size that is still at least that large (other formats, and sizes
    above half the image, decode in full).
    """
    require_file(path, "image")
    try:
        with Image.open(path) as img:
            if like is not None and img.size != like[1]:
                raise PoseconsError(
                    f"{path}: image is {img.size[0]}×{img.size[1]} pixels but {like[0]} of the same "
                    f"drive and camera is {like[1][0]}×{like[1][1]}; a drive's frames share one size"
                )
            if draft is not None:
                img.draft("RGB", draft)
            return img.convert("RGB")
    except OSError as exc:
        raise PoseconsError(f"{path}: unreadable image ({exc})") from exc


RESIZE = "PIL bilinear (antialiased when shrinking) to uint8"  # what resize_uint8 does, for cache manifests
JPEG_DRAFT = "; JPEGs decoded at the smallest DCT scale that serves"  # RESIZE's addition with data.jpeg_draft


def _resize(image: Image.Image, height: int, width: int) -> np.ndarray:
    """The one resize of every frame (:data:`RESIZE`): PIL image → (height, width, 3) uint8."""
    return np.asarray(image.resize((width, height), Image.BILINEAR))


def resize_uint8(image: np.ndarray, height: int, width: int) -> np.ndarray:
    """(H, W, 3) uint8 → (height, width, 3) uint8, resized like the training data (:data:`RESIZE`)."""
    return _resize(Image.fromarray(image), height, width)


def load_resized(
    path: Path, height: int, width: int, like: tuple[Path, tuple[int, int]] | None = None, jpeg_draft: bool = False
) -> np.ndarray:
    """An image file → (height, width, 3) uint8 as the training data is made: the decoded image
    resized like :func:`resize_uint8` (the same pixels, without a full-size array in between), after
    a DCT-scaled JPEG decode with ``jpeg_draft`` (:func:`load_rgb`'s ``draft``)."""
    return _resize(load_rgb(path, like, (width, height) if jpeg_draft else None), height, width)


def to_float(image: np.ndarray) -> np.ndarray:
    """(h, w, 3) uint8 → (3, h, w) float32 in [0, 1]."""
    return np.asarray(image, dtype=np.float32).transpose(2, 0, 1) / 255.0


def resize_rgb(image: np.ndarray, height: int, width: int) -> np.ndarray:
    """(H, W, 3) uint8 → (3, height, width) float32 in [0, 1], resized like the training data
    (PIL bilinear, antialiased when shrinking)."""
    return to_float(resize_uint8(image, height, width))
