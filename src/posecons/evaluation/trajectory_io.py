"""Trajectory files: KITTI (12 numbers a line, 3×4 row-major camera → world) and TUM
(``timestamp tx ty tz qx qy qz qw``), the two formats the ``evo`` tool reads."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..data.kitti_odometry import read_poses, write_poses
from ..errors import PoseconsError
from ..fileio import atomic_write

write_kitti_poses = write_poses  # the data layer's KITTI writer (12 numbers a line)

KITTI_RATE_HZ = 10.0  # timestamps (frame index / 10 Hz) when no times file is given


def _read_rows(path: str | Path, columns: int, what: str) -> np.ndarray:
    """Numeric (N, columns) rows of a whitespace-separated text file; blank lines are ignored."""
    path = Path(path)
    if not path.is_file():
        raise PoseconsError(f"{path}: {what} file not found")
    rows = []
    for number, line in enumerate(path.read_text().splitlines(), start=1):
        fields = line.split()
        if not fields or fields[0].startswith("#"):
            continue
        if len(fields) != columns:
            raise PoseconsError(f"{path}:{number}: expected {columns} numbers per line ({what}), got {len(fields)}")
        try:
            rows.append([float(f) for f in fields])
        except ValueError as exc:
            raise PoseconsError(f"{path}:{number}: not a number ({exc})") from None
    if not rows:
        raise PoseconsError(f"{path}: no {what} found")
    values = np.asarray(rows)
    if not np.isfinite(values).all():
        raise PoseconsError(f"{path}: NaN or infinite values in {what}")
    return values


def read_kitti_poses(path: str | Path) -> np.ndarray:
    """(N ≥ 1, 4, 4) camera → world poses from a KITTI pose file; NaN/inf values are rejected."""
    poses = read_poses(Path(path))
    if len(poses) == 0:
        raise PoseconsError(f"{path}: no KITTI poses found")
    return poses


def read_times(path: str | Path) -> np.ndarray:
    """(N,) timestamps in seconds from a KITTI ``times.txt`` (one number a line)."""
    return _read_rows(path, 1, "timestamps")[:, 0]


def rotation_to_quaternion(R: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotations → (N, 4) unit quaternions (x, y, z, w) with w ≥ 0.

    Builds each quaternion from its largest component, which keeps the division well conditioned.
    """
    R = np.asarray(R, dtype=np.float64)
    trace = np.trace(R, axis1=1, axis2=2)
    # 4·q_k² for k = x, y, z, w; the largest is used as the pivot.
    sq = np.stack([1 + 2 * R[:, 0, 0] - trace, 1 + 2 * R[:, 1, 1] - trace, 1 + 2 * R[:, 2, 2] - trace, 1 + trace], 1)
    # Off-diagonal sums/differences: 4·q_i·q_j for the pairs (x,y), (x,z), (y,z), (w,x), (w,y), (w,z).
    xy, xz, yz = R[:, 0, 1] + R[:, 1, 0], R[:, 0, 2] + R[:, 2, 0], R[:, 1, 2] + R[:, 2, 1]
    wx, wy, wz = R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]
    products = np.stack([  # row k: 4·q_k·(x, y, z, w)
        np.stack([sq[:, 0], xy, xz, wx], 1),
        np.stack([xy, sq[:, 1], yz, wy], 1),
        np.stack([xz, yz, sq[:, 2], wz], 1),
        np.stack([wx, wy, wz, sq[:, 3]], 1),
    ], 1)
    pivot = np.argmax(sq, axis=1)
    q = products[np.arange(len(R)), pivot]
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return q * np.where(q[:, 3:] < 0, -1.0, 1.0)


def quaternion_to_rotation(q: np.ndarray) -> np.ndarray:
    """(N, 4) quaternions (x, y, z, w), normalised here → (N, 3, 3) rotations."""
    x, y, z, w = (np.asarray(q, dtype=np.float64) / np.linalg.norm(q, axis=1, keepdims=True)).T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], 1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], 1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], 1),
    ], 1)


def write_tum(path: str | Path, poses: np.ndarray, timestamps: np.ndarray | None = None) -> None:
    """Write (N, 4, 4) poses as TUM lines; timestamps (N,) default to frame index / 10 Hz."""
    if timestamps is None:
        timestamps = np.arange(len(poses)) / KITTI_RATE_HZ
    if len(timestamps) != len(poses):
        raise PoseconsError(f"{len(timestamps)} timestamps for {len(poses)} poses")
    rows = np.column_stack([timestamps, poses[:, :3, 3], rotation_to_quaternion(poses[:, :3, :3])])
    atomic_write(path, lambda tmp: np.savetxt(tmp, rows, fmt="%.9f"))


def read_tum(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """(N,) timestamps and (N, 4, 4) poses from a TUM trajectory file."""
    rows = _read_rows(path, 8, "TUM poses")
    poses = np.tile(np.eye(4), (len(rows), 1, 1))
    poses[:, :3, :3] = quaternion_to_rotation(rows[:, 4:8])
    poses[:, :3, 3] = rows[:, 1:4]
    return rows[:, 0], poses
