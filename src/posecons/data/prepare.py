"""``posecons prepare``: turn videos or folders of frames into a dataset in the KITTI raw layout.

Each input becomes one drive ``custom/custom_drive_NNNN_sync/image_02/data/<frame:010d>.png``;
``custom/calib_cam_to_cam.txt`` holds the given intrinsics as ``P_rect_02``/``S_rect_02`` (scaled
to the written size), and ``splits/custom/{train,val}_files.txt`` list every frame with both
neighbours, so :class:`~posecons.data.kitti_raw.KittiRawDataset` reads the result directly.
Frames that hardly differ from the previous kept frame (a standing camera) are dropped; ``every``
keeps one decoded frame in N first (25–30 fps video has too little motion between frames for this
kind of training, which wants about 10 Hz). Without a calibration, a horizontal field of view gives
the intrinsics: fx = fy = (W/2)/tan(fov/2), the principal point in the centre.
"""

from __future__ import annotations

import math
import random
from collections.abc import Iterator
from pathlib import Path
from typing import Optional

import av
import numpy as np
from PIL import Image

from ..errors import PoseconsError
from ..fileio import output_dir
from .calib import format_calib
from .images import load_rgb
from .splits import SplitLine, write_split

DATE = "custom"
IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg", ".bmp"}


def iter_frames(source: Path) -> Iterator[Image.Image]:
    """RGB frames of a video file (decoded with PyAV) or of a folder of images (sorted by name)."""
    if source.is_dir():
        files = sorted(p for p in source.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
        if not files:
            raise PoseconsError(f"{source}: no image files ({', '.join(sorted(IMAGE_SUFFIXES))})")
        for path in files:
            yield load_rgb(path)
        return
    if not source.is_file():
        raise PoseconsError(f"{source}: input not found")
    try:
        with av.open(str(source)) as container:
            if not container.streams.video:
                raise PoseconsError(f"{source}: no video stream")
            for frame in container.decode(video=0):
                yield frame.to_image().convert("RGB")
    except av.FFmpegError as exc:
        raise PoseconsError(f"{source}: unreadable video ({exc})") from exc


def _signature(img: Image.Image) -> np.ndarray:
    """A small grey thumbnail (float32, [0, 1]) for the frame-difference test."""
    return np.asarray(img.convert("L").resize((64, 48), Image.BILINEAR), dtype=np.float32) / 255.0


def fov_intrinsics(fov_degrees: float, width: int, height: int) -> np.ndarray:
    """The pixel K of a ``width`` × ``height`` pinhole camera with that horizontal field of view,
    square pixels and the principal point in the centre."""
    f = width / 2 / math.tan(math.radians(fov_degrees) / 2)
    return np.array([[f, 0, width / 2], [0, f, height / 2], [0, 0, 1]], dtype=np.float64)


def drive_folder(index: int) -> str:
    """The folder of input ``index``'s frames, relative to the dataset: ``custom/custom_drive_NNNN_sync``."""
    return f"{DATE}/{DATE}_drive_{index:04d}_sync"


def write_calibration(out: Path, k: np.ndarray, size: tuple[int, int]) -> None:
    """``out/custom/calib_cam_to_cam.txt``: the pixel K of frames of ``size`` (width, height) as
    ``P_rect_02``/``S_rect_02``, what :class:`~posecons.data.kitti_raw.KittiRawDataset` reads."""
    p_rect = np.concatenate([k, np.zeros((3, 1))], axis=1)
    entries = {"S_rect_02": list(size), "R_rect_00": np.eye(3).ravel(), "P_rect_02": p_rect.ravel()}
    (out / DATE / "calib_cam_to_cam.txt").write_text(format_calib(entries, calib_time=None))


def write_train_val(out: Path, lines: list[SplitLine], val_fraction: float = 0.1, seed: int = 0) -> int:
    """Shuffle ``lines`` (with ``seed``) into ``out/splits/custom/{train,val}_files.txt``, a
    ``val_fraction`` for validation; returns the validation count."""
    random.Random(seed).shuffle(lines)
    n_val = int(round(len(lines) * val_fraction))
    write_split(out / "splits" / "custom" / "train_files.txt", lines[n_val:])
    write_split(out / "splits" / "custom" / "val_files.txt", lines[:n_val])
    return n_val


def prepare(
    inputs: list[Path],
    out: Path,
    intrinsics: Optional[np.ndarray] = None,
    width: Optional[int] = None,
    height: Optional[int] = None,
    static_threshold: float = 0.004,
    val_fraction: float = 0.1,
    seed: int = 0,
    fov: Optional[float] = None,
    every: int = 1,
) -> dict:
    """Write the dataset; ``intrinsics`` is the (3, 3) pixel K of the inputs' native size, or else
    ``fov`` the horizontal field of view in degrees.

    Of the decoded frames every ``every``-th is considered; one is kept when its mean absolute grey
    difference to the last kept frame is at least ``static_threshold``. All inputs must share one
    native size (one calibration per dataset).
    Returns {"drives": [...], "frames": [...], "train": n, "val": n, "K": native K}.
    """
    if (intrinsics is None) == (fov is None):
        raise ValueError("give exactly one of intrinsics and fov")
    if not inputs:
        raise PoseconsError("prepare: no inputs given")
    lines, counts, native = [], [], None
    with output_dir(out) as tmp:
        for index, source in enumerate(map(Path, inputs)):
            folder = drive_folder(index)
            data = tmp / folder / "image_02" / "data"
            data.mkdir(parents=True)
            kept, last = 0, None
            for decoded, img in enumerate(iter_frames(source)):
                if decoded % every:
                    continue
                if native is None:
                    native = img.size
                if img.size != native:
                    raise PoseconsError(f"{source}: frame size {img.size} differs from the first input's {native}")
                signature = _signature(img)
                if last is not None and np.abs(signature - last).mean() < static_threshold:
                    continue
                last = signature
                size = (width or native[0], height or native[1])
                (img if img.size == size else img.resize(size, Image.BILINEAR)).save(
                    data / f"{kept:010d}.png", compress_level=1
                )
                kept += 1
            if kept < 3:
                raise PoseconsError(f"{source}: only {kept} moving frames (need at least 3)")
            lines += [SplitLine(folder, f, "l") for f in range(1, kept - 1)]
            counts.append(kept)
        size = (width or native[0], height or native[1])
        native_k = fov_intrinsics(fov, *native) if intrinsics is None else np.array(intrinsics, dtype=np.float64)
        k = native_k.copy()
        k[0] *= size[0] / native[0]
        k[1] *= size[1] / native[1]
        write_calibration(tmp, k, size)
        n_val = write_train_val(tmp, lines, val_fraction, seed)
    return {
        "drives": [drive_folder(i) for i in range(len(counts))],
        "frames": counts,
        "train": len(lines) - n_val,
        "val": n_val,
        "K": native_k,
    }
