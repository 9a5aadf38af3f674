"""Trajectory files: KITTI (12 numbers a line, 3×4 row-major camera → world; the odometry
``poses/NN.txt``), TUM (``timestamp tx ty tz qx qy qz qw``), the two formats the ``evo`` tool reads,
KITTI ``times.txt``, and one 4 × 4 camera → world matrix per frame (7-Scenes, ScanNet)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import PoseconsError
from ..fileio import atomic_write, require_file
from ..metrics.pose import quaternion_to_rotation, rotation_to_quaternion

KITTI_RATE_HZ = 10.0  # timestamps (frame index / 10 Hz) when no times file is given
RIGID_TOLERANCE = 1e-2  # largest |R·Rᵀ − I| entry accepted as a rotation: 7-Scenes' own poses reach 3.2e-4


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
    """(N ≥ 1, 4, 4) float64 camera → world poses from a KITTI pose file (for ``poses/NN.txt``:
    camera 0 → world); NaN/inf values are rejected."""
    path = require_file(Path(path), "pose file")
    rows = []
    for number, line in enumerate(path.read_text().splitlines(), start=1):
        if not line.strip():
            continue
        try:
            values = [float(v) for v in line.split()]
        except ValueError:
            values = []
        if len(values) != 12:
            raise PoseconsError(f"{path}:{number}: expected 12 numbers, got {line.strip()[:60]!r}")
        if not np.isfinite(values).all():
            raise PoseconsError(f"{path}:{number}: NaN or infinite number in a pose")
        rows.append(values)
    poses = np.tile(np.eye(4), (len(rows), 1, 1))
    poses[:, :3, :] = np.asarray(rows).reshape(-1, 3, 4)
    if len(poses) == 0:
        raise PoseconsError(f"{path}: no KITTI poses found")
    return poses


def check_rigid(pose: np.ndarray, source: str) -> np.ndarray:
    """``pose`` (4, 4) if it is a finite rigid transform — an orthonormal rotation with determinant +1 and
    the bottom row 0 0 0 1, each to :data:`RIGID_TOLERANCE` — else an error naming ``source``."""
    if not np.isfinite(pose).all():
        raise PoseconsError(f"{source}: NaN or infinite number in a pose")
    if np.abs(pose[3] - (0, 0, 0, 1)).max() > RIGID_TOLERANCE:
        raise PoseconsError(
            f"{source}: bottom row {' '.join(f'{v:g}' for v in pose[3])} is not 0 0 0 1 (not a rigid pose)"
        )
    rotation = pose[:3, :3]
    error = np.abs(rotation @ rotation.T - np.eye(3)).max()
    if error > RIGID_TOLERANCE or np.linalg.det(rotation) < 0:
        raise PoseconsError(
            f"{source}: the rotation is not orthonormal with determinant +1 (|R·Rᵀ − I| up to {error:.2g}, "
            f"det {np.linalg.det(rotation):.3g}): not a rigid pose"
        )
    return pose


def read_pose_matrix(path: str | Path) -> np.ndarray:
    """(4, 4) float64 camera → world pose from a file of four lines of four numbers (7-Scenes'
    ``frame-*.pose.txt``), checked by :func:`check_rigid`."""
    rows = _read_rows(path, 4, "pose matrix")
    if len(rows) != 4:
        raise PoseconsError(f"{path}: expected a 4 × 4 pose matrix (four lines of four numbers), got {len(rows)} lines")
    return check_rigid(rows, str(path))


def write_kitti_poses(path: str | Path, poses: np.ndarray) -> None:
    """Write (N, 4, 4) poses in the KITTI format (first 3 rows, row-major, 12 numbers a line)."""
    rows = np.asarray(poses)[:, :3, :].reshape(-1, 12)
    atomic_write(path, lambda tmp: np.savetxt(tmp, rows, fmt="%.9e"))


def read_times(path: str | Path) -> np.ndarray:
    """(N,) timestamps in seconds from a KITTI ``times.txt`` (one number a line)."""
    return _read_rows(path, 1, "timestamps")[:, 0]


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
