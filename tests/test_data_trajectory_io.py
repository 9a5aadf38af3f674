"""KITTI and TUM trajectory files: round trips and bad input (quaternions: test_metrics_pose)."""

import re
from pathlib import Path

import numpy as np
import pytest

from posecons.data.trajectory_io import (
    read_kitti_poses,
    read_pose_matrix,
    read_times,
    read_tum,
    write_kitti_poses,
    write_tum,
)
from posecons.errors import PoseconsError
from posecons.metrics.pose import quaternion_to_rotation


def _random_poses(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    q = rng.standard_normal((n, 4))
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, :3, :3] = quaternion_to_rotation(q)
    poses[:, :3, 3] = rng.standard_normal((n, 3)) * 50
    return poses


def test_kitti_round_trip_and_real_file(tmp_path, kitti_dir):
    poses = _random_poses(20)
    write_kitti_poses(tmp_path / "p.txt", poses)
    assert np.allclose(read_kitti_poses(tmp_path / "p.txt"), poses, atol=1e-7)
    real = read_kitti_poses(kitti_dir / "odometry" / "poses" / "09.txt")
    assert real.shape == (1591, 4, 4) and np.allclose(real[0], np.eye(4), atol=1e-9)


def test_tum_round_trip_with_times(tmp_path, kitti_dir):
    poses = _random_poses(30)
    times = read_times(kitti_dir / "odometry" / "sequences" / "00" / "times.txt")[:30]
    assert times[1] == pytest.approx(0.1037359)
    write_tum(tmp_path / "t.txt", poses, times)
    t, back = read_tum(tmp_path / "t.txt")
    assert np.allclose(t, times) and np.allclose(back, poses, atol=1e-7)
    write_tum(tmp_path / "d.txt", poses)  # default timestamps: frame / 10 Hz
    assert np.allclose(read_tum(tmp_path / "d.txt")[0], np.arange(30) / 10)


def test_bad_files_name_file_and_line(tmp_path):
    bad = tmp_path / "bad.txt"
    bad.write_text("1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1\n")
    with pytest.raises(PoseconsError, match=r"bad\.txt:2: expected 12 numbers"):
        read_kitti_poses(bad)
    bad.write_text("1 0 0 0 0 1 0 0 0 0 1 nan\n")
    with pytest.raises(PoseconsError, match=r"bad\.txt:1: NaN or infinite"):
        read_kitti_poses(bad)
    with pytest.raises(PoseconsError, match="missing.txt: pose file not found"):
        read_kitti_poses(tmp_path / "missing.txt")


def test_pose_matrix_files_of_7scenes_are_rigid_and_bad_ones_are_named(tmp_path):
    """All 800 real 7-Scenes poses pass the rigidity check (their rotations are orthonormal to 3.2e-4, under
    the 1e-2 tolerance); a scaled rotation, a reflection, a wrong bottom row, a NaN or a 3 × 4 matrix do not."""
    real = Path(__file__).resolve().parents[2] / "shared" / "real" / "7scenes"
    poses = np.stack([read_pose_matrix(real / f"frame-{i:06d}.pose.txt") for i in range(800)])
    assert poses.shape == (800, 4, 4) and poses[0, 0, 0] == pytest.approx(0.9093129)
    bad = {
        "scaled": (np.diag([1.1, 1.1, 1.1, 1.0]), "rotation is not orthonormal"),
        "mirrored": (np.diag([1.0, 1.0, -1.0, 1.0]), "determinant +1"),
        "row": (np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 1.0]]), "bottom row 0 0 1 1 is not"),
        "nan": (np.where(np.eye(4) == 1, np.nan, 0), "NaN"),
        "short": (np.eye(4)[:3], "expected a 4 × 4 pose matrix"),
    }
    for name, (matrix, message) in bad.items():
        np.savetxt(tmp_path / f"{name}.txt", matrix)
        with pytest.raises(PoseconsError, match=rf"{name}\.txt.*{re.escape(message)}"):
            read_pose_matrix(tmp_path / f"{name}.txt")
