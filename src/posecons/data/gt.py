"""Ground-truth depth for evaluation: LiDAR projection and KITTI's improved PNGs.

Stored as one ``.npz`` without pickles: float32 (H, W) maps under keys ``000000``, ``000001``, …
in split order (0 = no ground truth; sizes may differ between dates) and a unicode array
``lines`` holding the split lines (``<folder> <frame> <side>``).

Monodepth2's ``export_gt_depth.py`` writes ``np.savez_compressed(out, data=np.array(maps))``: the
maps in its split's order and no lines. :func:`load_gt` reads that too; maps of several sizes make
``data`` an array of arrays, stored as a pickle, which it unpickles allowing numpy arrays only.
"""

from __future__ import annotations

import pickle
import zipfile
from collections.abc import Sequence
from pathlib import Path
from typing import Literal, Optional

import numpy as np
from PIL import Image

from ..errors import PoseconsError
from ..fileio import atomic_file, require_file
from .calib import raw_projection, velo_to_image
from .splits import SIDE_TO_CAMERA, SplitLine, SplitSource, read_split

DepthKind = Literal["velo_x", "camera_z"]


def load_velodyne(path: Path) -> np.ndarray:
    """Read a KITTI Velodyne scan: (N, 4) float32 rows of x, y, z, reflectance."""
    require_file(path, "Velodyne scan")
    size = path.stat().st_size
    if size % 16:
        raise PoseconsError(f"{path}: size {size} bytes is not a multiple of 16 (4 float32 per point)")
    return np.fromfile(path, dtype="<f4").reshape(-1, 4)


def velo_to_depth_map(
    points: np.ndarray, p_velo_img: np.ndarray, width: int, height: int, depth: DepthKind = "velo_x"
) -> np.ndarray:
    """Project a scan into a sparse depth map following the KITTI devkit convention.

    points: (N, ≥3) Velodyne x, y, z[, reflectance]; p_velo_img: (3, 4). Keeps points with x ≥ 0
    (and in front of the camera), pixel = round(u) − 1, round(v) − 1, inside (width, height); the
    value is the LiDAR forward x (Eigen protocol) or the camera z; the smallest value wins a pixel.
    Returns float32 (height, width), 0 where no point landed.
    """
    if depth not in ("velo_x", "camera_z"):
        raise PoseconsError(f"unknown depth kind {depth!r} (velo_x or camera_z)")
    pts = points[points[:, 0] >= 0, :3].astype(np.float64)
    proj = np.concatenate([pts, np.ones((len(pts), 1))], axis=1) @ p_velo_img.T
    front = proj[:, 2] > 0  # a point behind the camera has no pixel (never the case in real scans)
    pts, proj = pts[front], proj[front]
    col = np.round(proj[:, 0] / proj[:, 2]).astype(np.int64) - 1
    row = np.round(proj[:, 1] / proj[:, 2]).astype(np.int64) - 1
    value = pts[:, 0] if depth == "velo_x" else proj[:, 2]
    inside = (col >= 0) & (row >= 0) & (col < width) & (row < height)
    out = np.full(height * width, np.inf)
    np.minimum.at(out, row[inside] * width + col[inside], value[inside])
    out[np.isinf(out)] = 0.0
    return out.reshape(height, width).astype(np.float32)


def read_depth_image(
    path: Path, scale: float, invalid: Sequence[float] = (0,), what: str = "depth image"
) -> np.ndarray:
    """A single-channel depth image (a 16-bit PNG) holding ``scale`` values per metre → float32 (H, W)
    metres; pixels holding one of the ``invalid`` values (or ≤ 0, NaN) become 0, no ground truth."""
    require_file(Path(path), what)
    try:
        with Image.open(path) as img:
            raw = np.asarray(img)
    except OSError as exc:
        raise PoseconsError(f"{path}: unreadable PNG ({exc})") from exc
    if raw.ndim != 2:
        raise PoseconsError(f"{path}: expected a single-channel 16-bit PNG, got shape {raw.shape}")
    depth = raw.astype(np.float64) / scale
    depth[np.isin(raw, invalid) | ~(depth > 0)] = 0.0
    return depth.astype(np.float32)


def read_improved_gt(path: Path) -> np.ndarray:
    """KITTI improved (annotated) depth PNG: uint16 / 256 metres, 0 = invalid → float32 (H, W)."""
    return read_depth_image(path, 256.0, what="improved ground-truth PNG")


def lidar_gt(data_path: Path, folder: str, frame: int, side: str = "l", depth: DepthKind = "velo_x") -> np.ndarray:
    """Depth map of one raw frame from its Velodyne scan and its date's calibration."""
    date_dir = Path(data_path) / folder.split("/")[0]
    _, (width, height) = raw_projection(date_dir, SIDE_TO_CAMERA[side])
    scan = load_velodyne(Path(data_path) / folder / "velodyne_points" / "data" / f"{frame:010d}.bin")
    return velo_to_depth_map(scan, velo_to_image(date_dir, SIDE_TO_CAMERA[side]), width, height, depth)


def improved_gt_path(data_path: Path, folder: str, frame: int, side: str = "l", root: Optional[Path] = None) -> Path:
    """``<data_path>/<folder>/proj_depth/…`` or, with ``root`` (KITTI's depth_annotated layout),
    ``<root>/<drive>/proj_depth/groundtruth/image_0k/<frame:010d>.png``."""
    base = Path(data_path) / folder if root is None else Path(root) / Path(folder).name
    return base / "proj_depth" / "groundtruth" / f"image_0{SIDE_TO_CAMERA[side]}" / f"{frame:010d}.png"


def export_gt(
    data_path: Path,
    split: SplitSource,
    out: Path,
    improved: bool = False,
    improved_root: Optional[Path] = None,
    depth: DepthKind = "velo_x",
) -> int:
    """Write the ground truth of every split line to ``out`` (.npz, see module doc); returns the count."""
    lines = read_split(split)
    maps = [
        read_improved_gt(improved_gt_path(data_path, line.folder, line.frame, line.side, improved_root))
        if improved
        else lidar_gt(data_path, line.folder, line.frame, line.side, depth)
        for line in lines
    ]
    write_gt(out, maps, lines)
    return len(lines)


def write_gt(out: Path, maps: Sequence[np.ndarray], lines: Sequence[SplitLine]) -> None:
    """Write (H, W) depth maps in metres (0 = none) and their split lines as an ``.npz`` (module doc)."""
    arrays = {f"{i:06d}": np.asarray(m, dtype=np.float32) for i, m in enumerate(maps)}
    arrays["lines"] = np.array([str(line) for line in lines], dtype=np.str_)
    with atomic_file(Path(out)) as tmp, open(tmp, "wb") as f:
        np.savez_compressed(f, **arrays)


def load_gt(path: Path) -> tuple[list[np.ndarray], list[str] | None]:
    """Read an exported ground-truth file: (list of float32 (H, W) maps, list of split lines), or
    Monodepth2's ``gt_depths.npz`` (module doc): (its maps, None), the lines being its split file's."""
    path = require_file(Path(path), "ground-truth file")
    try:
        with np.load(path, allow_pickle=False) as data:
            if data.files == ["data"]:
                return _monodepth2_maps(path, data), None
            lines = [str(s) for s in data["lines"]]
            maps = [data[f"{i:06d}"] for i in range(len(lines))]
    except KeyError as exc:
        raise PoseconsError(f"{path}: not a posecons ground-truth file (no entry {exc})") from exc
    except (OSError, ValueError) as exc:  # numpy's own text suggests unpickling, which is never wanted here
        raise PoseconsError(f"{path}: not a posecons ground-truth file (not an .npz written by export-gt)") from exc
    return maps, lines


class _ArraysOnly(pickle.Unpickler):
    """Unpickles numpy arrays and refuses every other class: an array of depth maps needs no other."""

    ALLOWED = {
        ("numpy", "ndarray"),
        ("numpy", "dtype"),
        ("numpy.core.multiarray", "_reconstruct"),  # the name numpy 1 wrote, numpy 2's numpy._core
        ("numpy._core.multiarray", "_reconstruct"),
    }

    def find_class(self, module: str, name: str):
        if (module, name) not in self.ALLOWED:
            raise pickle.UnpicklingError(f"refused to unpickle {module}.{name}")
        return super().find_class(module, name)


def _monodepth2_maps(path: Path, data) -> list[np.ndarray]:
    """The (H, W) maps of a Monodepth2 ``gt_depths.npz`` (``data``: it opened without pickles)."""
    try:
        maps = list(data["data"])  # maps of one size: one float array
    except ValueError:  # maps of several sizes: an array of arrays, which only unpickling reads
        maps = _unpickled_arrays(path)
    if not maps or any(m.ndim != 2 or not np.issubdtype(m.dtype, np.floating) for m in maps):
        raise PoseconsError(f"{path}: its 'data' holds no (H, W) depth maps, as Monodepth2's export_gt_depth.py writes")
    return [m.astype(np.float32) for m in maps]


def _unpickled_arrays(path: Path) -> list[np.ndarray]:
    try:
        with zipfile.ZipFile(path) as archive, archive.open("data.npy") as f:
            version = np.lib.format.read_magic(f)
            (np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0)(f)
            data = _ArraysOnly(f, encoding="latin1").load()  # latin1: as numpy reads Python 2 pickles
    except (pickle.UnpicklingError, EOFError, ValueError, OSError) as exc:
        raise PoseconsError(f"{path}: not Monodepth2 ground truth ({exc})") from exc
    return [np.asarray(m) for m in data] if isinstance(data, np.ndarray) else []


class GroundTruth:
    """Per-frame depth ground truth (metres, 0 = invalid): a folder of 16-bit KITTI-style PNGs
    (value / 256) named like the input frames, or an export-gt NPZ (keys 000000, 000001, … by
    frame index, plus ``lines``)."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.npz = None
        if self.path.is_file() and self.path.suffix == ".npz":
            try:
                self.npz = np.load(self.path, allow_pickle=False)
                self.keys = set(self.npz.files)
            except (OSError, ValueError) as exc:
                raise PoseconsError(f"{self.path}: not a readable ground-truth NPZ ({exc})") from exc
        elif not self.path.is_dir():
            raise PoseconsError(f"{self.path}: ground truth must be a folder of 16-bit PNGs or an .npz file")

    def get(self, name: str, index: int) -> np.ndarray | None:
        """(H, W) float32 depth of the frame called ``name`` at ``index``, or None if there is none."""
        if self.npz is not None:
            key = f"{index:06d}"
            return self.npz[key].astype(np.float32) if key in self.keys else None
        png = self.path / f"{name}.png"
        return read_improved_gt(png) if png.is_file() else None
