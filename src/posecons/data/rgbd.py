"""``posecons prepare-rgbd``: an RGB-D sequence (colour frames, depth images and, if known, a camera pose
per frame, as Kinect, RealSense, TUM RGB-D, ScanNet or 7-Scenes record them) becomes the dataset of
:mod:`.prepare` plus its ground truth: the depth maps in metres for ``evaluate-depth --gt-kind dense``
and, with poses, a KITTI odometry view of the same frames for ``evaluate-pose``.

Files are found by patterns with one ``*`` standing for the frame's name, relative to the input folder
(7-Scenes: ``frame-*.color.jpg``, ``frame-*.depth.png``, ``frame-*.pose.txt``). The colour frames,
sorted by name (numerically when every name is a number), are the sequence; each one's depth image and
pose file have the same name. With ``max_time_difference`` the names are timestamps in seconds (TUM
RGB-D: ``rgb/*.png``, ``depth/*.png``), and each colour frame takes the depth image and pose of the
nearest timestamp no further away than that, as TUM's ``associate.py`` pairs them. Poses come from one
4 × 4 camera → world file per frame or from a TUM trajectory file (``t tx ty tz qx qy qz qw``).

Every frame is kept (no static-frame test: each has its ground truth) unless ``every`` keeps one in N;
a frame's depth image and pose are those of the colour frame it is. With ``test_from`` the sequence is
split in time: frames from that one on are the test stretch (its own drive folder, the test split, the
ground truth and the odometry view), the frames before it less a ``gap`` train and validate (another
drive folder), and the gap's frames are left out, so that no test frame is a training frame's neighbour.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import numpy as np

from ..errors import PoseconsError
from ..fileio import keep_copy, output_dir
from .calib import format_calib
from .gt import read_depth_image, write_gt
from .images import load_rgb
from .prepare import drive_folder, write_calibration, write_train_val
from .splits import SplitLine, write_split
from .trajectory_io import check_rigid, read_pose_matrix, read_tum, write_kitti_poses

INVALID_DEPTH = (0, 65535)  # what Kinect-style 16-bit depth PNGs hold where nothing was measured
GT_FILE = "gt_depths.npz"
SEQUENCE = "00"  # the odometry view's sequence number


def _check_pattern(pattern: str, option: str) -> None:
    if pattern.count("*") != 1 or any(c in pattern for c in "?[]"):
        raise PoseconsError(f"{option} {pattern!r}: needs exactly one * (the frame's name) and no other wildcard")


def _names(root: Path, pattern: str) -> dict[str, Path]:
    """{frame name: file} of the files under ``root`` that match ``pattern`` (its ``*`` is the name)."""
    prefix, suffix = pattern.split("*")
    found = {}
    for path in filter(Path.is_file, root.glob(pattern)):
        text = path.relative_to(root).as_posix()
        found[text[len(prefix) : len(text) - len(suffix)]] = path
    return found


def _seconds(names: Sequence[str], what: str) -> np.ndarray:
    """Frame names read as timestamps in seconds, for pairing files by time."""
    times = []
    for name in names:
        try:
            times.append(float(name))
        except ValueError:
            raise PoseconsError(
                f"{what} {name!r}: not a timestamp in seconds, which pairing by time needs "
                "(--max-time-difference, --tum-poses)"
            ) from None
    return np.array(times)


def nearest_within(targets: np.ndarray, times: np.ndarray, max_difference: float) -> list[Optional[int]]:
    """For each target time, the index of the nearest of ``times`` (any order), or None when even that
    one is more than ``max_difference`` away."""
    order = np.argsort(times)
    ordered = times[order]
    right = np.clip(np.searchsorted(ordered, targets), 0, len(times) - 1)
    left = np.clip(right - 1, 0, len(times) - 1)
    best = np.where(np.abs(ordered[left] - targets) <= np.abs(ordered[right] - targets), left, right)
    return [int(order[b]) if abs(ordered[b] - t) <= max_difference else None for b, t in zip(best, targets)]


def _partners(
    root: Path,
    frames: dict[str, Path],
    names: Sequence[str],
    pattern: str,
    option: str,
    what: str,
    max_difference: Optional[float],
) -> list[Path]:
    """The ``pattern`` file of each of the colour ``frames`` called ``names``: the one of the same
    name or, with ``max_difference``, of the nearest timestamp."""
    if max_difference is None:
        paths = [root / pattern.replace("*", name) for name in names]
        for name, path in zip(names, paths):
            if not path.is_file():
                raise PoseconsError(f"{path}: {what} of {frames[name].name} not found ({option} {pattern!r})")
        return paths
    files = _names(root, pattern)
    if not files:
        raise PoseconsError(f"{root / pattern}: no {what} files ({option})")
    keys = list(files)
    found = _nearest(
        names,
        _seconds(keys, what),
        max_difference,
        lambda name: f"{frames[name]}: no {what} within {max_difference:g} s (--max-time-difference)",
    )
    return [files[keys[i]] for i in found]


def _nearest(names: Sequence[str], stamps: np.ndarray, max_difference: float, missing) -> list[int]:
    """For each frame name (a time in seconds), the index of the stamp nearest to it within
    ``max_difference``; a frame with none is an error, ``missing(name)`` its message."""
    found = nearest_within(_seconds(names, "colour frame"), stamps, max_difference)
    for name, index in zip(names, found):
        if index is None:
            raise PoseconsError(missing(name))
    return found


@dataclass(frozen=True)
class RGBDSource:
    """Where a sequence's files are (module doc): its folder, the patterns of its colour frames, depth
    images and per-frame pose files, or a TUM trajectory file, and how names pair them."""

    root: Path
    color: str
    depth: str
    poses: Optional[str] = None
    tum_poses: Optional[Path] = None
    max_time_difference: Optional[float] = None

    def frames(self, every: int = 1) -> tuple[list[Path], list[Path], Optional[np.ndarray]]:
        """Every ``every``-th colour frame and its depth image and (N, 4, 4) camera → world pose (None
        without ``poses`` and ``tum_poses``): (colour files, depth files, poses), all checked to exist,
        the poses to be rigid."""
        root = Path(self.root)
        if not root.is_dir():
            raise PoseconsError(f"{root}: input folder not found")
        for pattern, option in ((self.color, "--color"), (self.depth, "--depth"), (self.poses, "--poses")):
            if pattern is not None:
                _check_pattern(pattern, option)
        frames = _names(root, self.color)
        if not frames:
            raise PoseconsError(f"{root / self.color}: no colour frames (--color)")
        try:
            names = sorted(frames, key=float)
        except ValueError:
            names = sorted(frames)
        names = names[::every]
        colors = [frames[name] for name in names]
        depths = _partners(root, frames, names, self.depth, "--depth", "depth image", self.max_time_difference)
        if self.poses is not None:
            files = _partners(root, frames, names, self.poses, "--poses", "pose file", self.max_time_difference)
            return colors, depths, np.stack([read_pose_matrix(f) for f in files])
        if self.tum_poses is None:
            return colors, depths, None
        stamps, trajectory = read_tum(self.tum_poses)
        when = f"within {self.max_time_difference:g} s of" if self.max_time_difference else "at"
        found = _nearest(
            names,
            stamps,
            self.max_time_difference or 0.0,
            lambda name: f"{self.tum_poses}: no pose {when} the time of {frames[name]}",
        )
        for index in found:
            check_rigid(trajectory[index], f"{self.tum_poses} (t = {stamps[index]:.6f})")
        return colors, depths, trajectory[found]


def prepare_rgbd(
    source: RGBDSource,
    out: Path,
    intrinsics: np.ndarray,
    depth_scale: float,
    invalid_depth: Sequence[float] = INVALID_DEPTH,
    every: int = 1,
    test_from: Optional[int] = None,
    gap: int = 20,
    val_fraction: float = 0.1,
    seed: int = 0,
) -> dict:
    """Write the dataset of the sequence ``source`` (module doc); ``intrinsics`` is the (3, 3) pixel K of the colour frames, ``depth_scale`` the depth
    images' values per metre (1000: millimetres), ``invalid_depth`` the values that mean no measurement.
    ``test_from`` and ``gap`` count frames of the source sequence (before ``every``), as its names do.
    Returns the description also written to ``rgbd.json``."""
    if not (np.isfinite(depth_scale) and depth_scale > 0):
        raise PoseconsError(f"--depth-scale {depth_scale}: must be a number > 0 (depth image values per metre)")
    k = np.asarray(intrinsics, dtype=np.float64)
    colors, depths, trajectory = source.frames(every)
    root = Path(source.root)
    stretches = _stretches(len(colors), every, test_from, gap, root / source.color)
    kept = [i for stretch in stretches for i in stretch]
    folders, size, maps = [drive_folder(d) for d in range(len(stretches))], None, []
    with output_dir(out) as tmp:
        frames = {}  # kept index → (drive folder, frame number in it)
        for folder, stretch in zip(folders, stretches):
            (tmp / folder / "image_02" / "data").mkdir(parents=True)
            frames.update({index: (folder, f) for f, index in enumerate(stretch)})
        for index in kept:
            color_file, depth_file = colors[index], depths[index]
            img = load_rgb(color_file, None if size is None else (colors[kept[0]], size))
            size = img.size
            gt = read_depth_image(depth_file, depth_scale, invalid_depth)
            if gt.shape != (size[1], size[0]):
                raise PoseconsError(
                    f"{depth_file}: depth image is {gt.shape[1]}×{gt.shape[0]} pixels but its colour frame "
                    f"{color_file} is {size[0]}×{size[1]}; ground truth must be registered to the colour frame"
                )
            folder, f = frames[index]
            img.save(tmp / folder / "image_02" / "data" / f"{f:010d}.png", compress_level=1)
            if folder == folders[-1]:
                maps.append(gt)
        write_calibration(tmp, k, size)
        lines = [
            [SplitLine(folder, f, "l") for f in range(len(stretch))] for folder, stretch in zip(folders, stretches)
        ]
        n_val = write_train_val(tmp, lines[0][1:-1], val_fraction, seed)  # lines with both neighbours
        write_split(tmp / "splits" / "custom" / "test_files.txt", lines[-1], frame_digits=10)
        write_gt(tmp / GT_FILE, maps, lines[-1])
        if trajectory is not None:
            sequence = tmp / "odometry" / "sequences" / SEQUENCE
            for f, line in enumerate(lines[-1]):
                keep_copy(
                    tmp / line.folder / "image_02" / "data" / f"{f:010d}.png", sequence / "image_2" / f"{f:06d}.png"
                )
            p2 = np.concatenate([k, np.zeros((3, 1))], axis=1)
            (sequence / "calib.txt").write_text(format_calib({"P2": p2.ravel()}, calib_time=None))
            write_kitti_poses(tmp / "odometry" / "poses" / f"{SEQUENCE}.txt", trajectory[stretches[-1]])
        info = {
            "source": str(root.resolve()),
            "frames": [colors[i].relative_to(root).as_posix() for i in kept],
            "depth_images": [depths[i].relative_to(root).as_posix() for i in kept],
            "poses": source.poses or (str(source.tum_poses) if source.tum_poses else None),
            "every": every,
            "max_time_difference": source.max_time_difference,
            "depth_scale": depth_scale,
            "invalid_depth": list(invalid_depth),
            "width": size[0],
            "height": size[1],
            "intrinsics_px": dict(zip(("fx", "fy", "cx", "cy"), k[[0, 1, 0, 1], [0, 1, 2, 2]].tolist())),
            "drive": folders[0],
            "test_drive": folders[-1],
            "test_from": test_from,
            "gap": gap if test_from is not None else None,
            "test_frames": [colors[i].relative_to(root).as_posix() for i in stretches[-1]],
            "train": len(stretches[0]) - 2 - n_val,
            "val": n_val,
            "test_split": "splits/custom/test_files.txt",
            "ground_truth": GT_FILE,
            "odometry_sequence": None if trajectory is None else SEQUENCE,
        }
        (tmp / "rgbd.json").write_text(json.dumps(info, indent=2) + "\n")
    return info


def _stretches(count: int, every: int, test_from: Optional[int], gap: int, where: Path) -> list[list[int]]:
    """The kept frames' indices as [all] or, with ``test_from``, [train stretch, test stretch]: kept
    frame i is source frame i · ``every``; the test stretch starts at source frame ``test_from``, the
    training one ends ``gap`` source frames before it."""
    if test_from is None:
        stretches = [list(range(count))]
    else:
        stretches = [
            [i for i in range(count) if i * every < test_from - gap],
            [i for i in range(count) if i * every >= test_from],
        ]
    names = ["frames kept"] if test_from is None else ["training frames (before --test-from less --gap)", "test frames"]
    for stretch, what in zip(stretches, names):
        if len(stretch) < 3:
            hint = "" if test_from is None else f" with --test-from {test_from} --gap {gap} of {count * every} frames"
            raise PoseconsError(f"{where}: only {len(stretch)} {what}{hint} (need at least 3)")
    return stretches
