"""``posecons cache``: write the frame cache (:mod:`.cache`) of a config's train and val splits."""

from __future__ import annotations

import copy
import io
from pathlib import Path
from typing import Any

import numpy as np

from ..config import Config
from ..errors import PoseconsError
from ..fileio import atomic_write, make_dirs, remove_temporaries, write_json
from .cache import MANIFEST, FrameCache, cache_key, differences, read_manifest
from .datasets import build_dataset, split_files
from .images import load_resized
from .parallel import fork_map


def _cache_frame(job: tuple[Path, tuple[Path, tuple[int, int]], Path, int, int, bool]) -> None:
    source, like, target, height, width, jpeg_draft = job
    pixels = load_resized(source, height, width, like, jpeg_draft)
    atomic_write(target, lambda tmp: np.save(tmp, pixels, allow_pickle=False))


def build_cache(
    config: Config, data_path: str | Path, out: str | Path, split_dir: str | Path | None = None, workers: int = 1
) -> dict[str, Any]:
    """Cache every frame (all ``model.frame_ids`` offsets) of the train and val splits that
    training with ``config`` reads; returns the manifest plus ``written`` (frames made now).

    A folder holding an earlier, interrupted build for the same setting is completed (whole
    frames are kept, leftover temporaries removed); one made for another setting, or holding
    other files, is refused. Nothing is written before every frame of every split line is found.
    """
    config = copy.deepcopy(config)
    config.data.cache_dir = None  # read the images themselves
    out = Path(out)
    train_file, val_file = split_files(config, data_path, split_dir)
    splits = {"train": train_file, "val": val_file}
    images: dict[Path, tuple[Path, tuple[int, int]]] = {}  # image → its drive's reference (size check)
    for role, split in splits.items():
        if split is not None:
            dataset = build_dataset(config, data_path, split, train=role == "train")
            for line in dataset.lines:
                for offset in dataset.frame_ids:
                    images.setdefault(dataset.image_path(line, line.frame + offset), dataset.reference_size(line))
    key = cache_key(config, data_path, splits)
    if out.exists() and any(out.iterdir()):
        old = read_manifest(out)
        if old is None:
            raise PoseconsError(f"{out}: folder is not empty and holds no frame cache; choose a new or empty --out")
        diffs = differences(old, key, exact=True)
        if diffs:
            raise PoseconsError(
                f"{out}: holds a frame cache made for another setting: {'; '.join(diffs)}; choose a new --out"
            )
    cache = FrameCache(out, data_path)
    targets = {image: cache.file(image) for image in images}
    manifest = {**key, "frames": len(images), "bytes_per_frame": _npy_bytes(config), "complete": False}
    write_json(out / MANIFEST, manifest)
    for folder in [out, *sorted({target.parent for target in targets.values()})]:
        make_dirs(folder)
        remove_temporaries(folder)  # what a killed build was writing
    todo = [
        (image, images[image], target, config.model.height, config.model.width, config.data.jpeg_draft)
        for image, target in targets.items()
    ]
    todo = [job for job in todo if not job[2].is_file()]
    fork_map(_cache_frame, todo, workers)
    manifest["complete"] = True
    write_json(out / MANIFEST, manifest)
    return {**manifest, "written": len(todo)}


def _npy_bytes(config: Config) -> int:
    """Size of one cached frame file: the .npy header plus height·width·3 bytes."""
    buffer = io.BytesIO()
    np.save(buffer, np.zeros((config.model.height, config.model.width, 3), np.uint8))
    return buffer.tell()
