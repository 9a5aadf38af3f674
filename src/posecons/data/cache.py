"""The frame cache: the training and validation frames of a config, decoded and resized once
(written by :func:`~posecons.data.cache_build.build_cache`, ``posecons cache``).

Layout::

    CACHE/manifest.json                              what the cache was made for, and whether it is complete
    CACHE/frames/<image path under DATA>.npy         (height, width, 3) uint8: load_resized of the image

A cached array is what :func:`~posecons.data.images.load_resized` returns for the image file; the
loader turns it into a sample exactly as it turns a freshly decoded one (``to_float``, then the
flip), so batches are bit-identical with and without the cache. Every file is written atomically,
so an interrupted build leaves whole frames and a manifest saying ``"complete": false``: the same
command finishes it. Training (``data.cache_dir``) refuses a cache made for another data path,
dataset, image extension, size, resize (and data.jpeg_draft), frame offsets or split file, naming what differs.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

import numpy as np

from ..config import Config
from ..errors import PoseconsError
from .images import JPEG_DRAFT, RESIZE, image_suffix

FORMAT = "posecons frame cache v1"
MANIFEST = "manifest.json"
# Manifest entries that must equal the run's, with the names users know them by.
_SETTINGS = {
    "format": "format",
    "data_path": "data path",
    "dataset": "data.dataset",
    "img_ext": "data.img_ext",
    "height": "model.height",
    "width": "model.width",
    "resize": "resize",
}


def cache_key(config: Config, data_path: str | Path, splits: dict[str, Path | None]) -> dict[str, Any]:
    """What a cache is made for: the settings that decide its pixels and the split files (by
    content) that decide its frames; ``splits``: role ("train", "val") → split file or None."""
    m, d = config.model, config.data
    return {
        "format": FORMAT,
        "data_path": str(Path(data_path).resolve()),
        "dataset": d.dataset,
        "img_ext": image_suffix(d.img_ext),
        "height": m.height,
        "width": m.width,
        "resize": RESIZE + (JPEG_DRAFT if d.jpeg_draft else ""),
        "frame_ids": list(m.frame_ids),
        "splits": {
            role: None if path is None else {"file": str(path), "sha256": _sha256(path)}
            for role, path in splits.items()
        },
    }


def _sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def differences(cached: dict[str, Any], wanted: dict[str, Any], exact: bool) -> list[str]:
    """What differs between a cache's manifest and ``wanted`` (a :func:`cache_key`), in words.
    ``exact=False`` (training): the cache may hold more frame offsets, and only the splits that
    ``wanted`` names are compared."""
    out = [
        f"{label} {cached.get(key)!r} (now {wanted[key]!r})"
        for key, label in _SETTINGS.items()
        if cached.get(key) != wanted[key]
    ]
    have, need = cached.get("frame_ids") or [], wanted["frame_ids"]
    if have != need if exact else not set(need) <= set(have):
        out.append(f"model.frame_ids {have} (now {need})")
    old_splits = cached.get("splits") or {}
    for role, split in wanted["splits"].items():
        old = old_splits.get(role)
        if (old or {}).get("sha256") != (split or {}).get("sha256") and (exact or split is not None):
            out.append(
                f"{role} split {old['file'] if old else 'none'} "
                f"(now {split['file'] if split else 'none'}{', other lines' if old and split else ''})"
            )
    return out


def read_manifest(folder: Path) -> dict[str, Any] | None:
    """A cache folder's manifest, or None when it has none that posecons wrote."""
    try:
        manifest = json.loads((Path(folder) / MANIFEST).read_text())
    except (OSError, ValueError):
        return None
    return (
        manifest
        if isinstance(manifest, dict) and manifest.get("format", "").startswith("posecons frame cache")
        else None
    )


class FrameCache:
    """Read access to a cache folder for the images of ``data_path``."""

    def __init__(self, folder: str | Path, data_path: str | Path):
        self.folder, self.data_path = Path(folder), Path(data_path)

    def file(self, image: Path) -> Path:
        """Where the frame of ``image`` (a path under the data path) is cached."""
        return self.folder / "frames" / Path(image).relative_to(self.data_path).with_suffix(".npy")

    def load(self, image: Path) -> np.ndarray:
        """(height, width, 3) uint8 of ``image``, as :func:`~posecons.data.images.load_resized` made it."""
        path = self.file(image)
        try:
            return np.load(path, allow_pickle=False)
        except FileNotFoundError:
            raise PoseconsError(
                f"{path}: the frame cache {self.folder} has no frame for {image}; build it again with `posecons cache`"
            ) from None
        except (OSError, ValueError) as exc:
            raise PoseconsError(f"{path}: unreadable cached frame ({exc})") from exc


def open_cache(folder: str | Path, config: Config, data_path: str | Path, split_file: Path, role: str) -> FrameCache:
    """The cache of ``folder`` for the ``role`` ("train" or "val") split ``split_file``, after
    checking that it is complete and was made for this config, data path and split."""
    folder = Path(folder)
    manifest = read_manifest(folder)
    if manifest is None:
        raise PoseconsError(
            f"{folder}: not a frame cache (no {MANIFEST} written by posecons); make one with "
            "`posecons cache --data-path DATA --config PRESET --out CACHE` or unset data.cache_dir"
        )
    if not manifest.get("complete"):
        raise PoseconsError(
            f"{folder}: incomplete frame cache (its build was interrupted or failed); "
            "run the same `posecons cache` command again to finish it"
        )
    diffs = differences(manifest, cache_key(config, data_path, {role: split_file}), exact=False)
    if diffs:
        raise PoseconsError(
            f"{folder}: frame cache made for another setting: {'; '.join(diffs)}; "
            "build one for this config with `posecons cache` into a new folder"
        )
    return FrameCache(folder, data_path)
