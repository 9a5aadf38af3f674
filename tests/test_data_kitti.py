"""Parsers, ground truth and datasets against the real KITTI files in ../shared/kitti (used in place)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image

from posecons.data.calib import raw_intrinsics, read_calib_file, velo_to_image
from posecons.data.gt import improved_gt_path, lidar_gt, load_velodyne, read_improved_gt, velo_to_depth_map
from posecons.data.images import load_resized, load_rgb, resize_uint8
from posecons.data.kitti_odometry import list_sequence_frames
from posecons.data.kitti_raw import KittiRawDataset
from posecons.data.oxts import oxts_to_poses, read_oxts
from posecons.data.splits import read_split, read_static_frames, read_test_scenes
from posecons.data.trajectory_io import read_kitti_poses
from posecons.errors import PoseconsError

DRIVE = "2011_09_26/2011_09_26_drive_0002_sync"


@pytest.mark.parametrize(
    "name, count",
    [
        ("eigen/test_files.txt", 697),
        ("eigen_zhou/train_files.txt", 39810),
        ("eigen_zhou/val_files.txt", 4424),
        ("eigen_benchmark/test_files.txt", 652),
        ("odom/test_files_09.txt", 1590),
        ("odom/test_files_10.txt", 1200),
    ],
)
def test_real_split_files_parse(kitti_dir: Path, name: str, count: int) -> None:
    lines = read_split(kitti_dir / "splits" / name)
    assert len(lines) == count
    assert {line.side for line in lines} <= {"l", "r"}
    if name.startswith("eigen/"):
        assert (lines[0].folder, lines[0].frame, lines[0].side) == (DRIVE, 69, "l")
    if name.startswith("odom/"):
        assert lines[0].folder in ("9", "10") and lines[-1].frame == count - 1


def test_sfmlearner_lists(kitti_dir: Path) -> None:
    static = read_static_frames(kitti_dir / "splits" / "sfmlearner" / "static_frames.txt")
    assert len(static) == 8044 and ("2011_09_26_drive_0009_sync", 386) in static
    scenes = read_test_scenes(kitti_dir / "splits" / "sfmlearner" / "test_scenes_eigen.txt")
    assert len(scenes) == 28 and "2011_09_26_drive_0117" in scenes


def test_real_calibration(kitti_dir: Path) -> None:
    calib = read_calib_file(kitti_dir / "calib" / "2011_09_26" / "calib_cam_to_cam.txt")
    assert calib["calib_time"] == "09-Jan-2012 13:57:47"
    p2 = calib["P_rect_02"].reshape(3, 4)
    assert (
        p2[0, 0] == pytest.approx(721.5377)
        and p2[0, 2] == pytest.approx(609.5593)
        and p2[1, 2] == pytest.approx(172.854)
    )
    k = raw_intrinsics(kitti_dir / "calib" / "2011_09_26")
    assert k[0, 0] == pytest.approx(721.5377 / 1242) and k[1, 1] == pytest.approx(721.5377 / 375)
    assert k[0, 2] == pytest.approx(609.5593 / 1242, rel=1e-6) and k[2, 2] == 1
    assert (
        read_calib_file(kitti_dir / "calib" / "2011_09_26" / "calib_velo_to_cam.txt")["calib_time"]
        == "15-Mar-2012 11:37:16"
    )


def test_real_odometry_poses(kitti_dir: Path) -> None:
    poses = read_kitti_poses(kitti_dir / "odometry" / "poses" / "09.txt")
    assert poses.shape == (1591, 4, 4)
    rot = poses[:, :3, :3]
    np.testing.assert_allclose(rot @ rot.transpose(0, 2, 1), np.broadcast_to(np.eye(3), rot.shape), atol=1e-5)
    np.testing.assert_allclose(np.linalg.det(rot), 1.0, atol=1e-5)
    np.testing.assert_allclose(poses[0], np.eye(4), atol=1e-9)


def test_real_lidar_projection(kitti_dir: Path) -> None:
    raw = kitti_dir / "raw_samples"
    x_map = lidar_gt(raw, DRIVE, 0)
    z_map = lidar_gt(raw, DRIVE, 0, depth="camera_z")
    valid = x_map > 0
    assert x_map.shape == (375, 1242) and 0.02 < valid.mean() < 0.08  # KITTI scans cover ~4 % of pixels
    assert 1.0 < x_map[valid].min() and x_map[valid].max() < 85.0
    assert np.nonzero(valid.any(axis=1))[0].min() > 100  # the 64 beams stay below the top third
    # the Velodyne sits ~0.27 m behind the camera: x − z is that offset everywhere
    both = valid & (z_map > 0)
    assert np.median(x_map[both] - z_map[both]) == pytest.approx(0.27, abs=0.02)
    # the smallest depth wins a pixel: no projected point is closer than the stored value
    scan = load_velodyne(raw / DRIVE / "velodyne_points" / "data" / "0000000000.bin")
    dense = velo_to_depth_map(scan, velo_to_image(raw / "2011_09_26"), 1242, 375)
    np.testing.assert_array_equal(dense, x_map)


def test_real_improved_gt_and_lidar_statistics(kitti_dir: Path) -> None:
    """Drive 0001 has no Velodyne scan for its annotated frames (SOURCES.md), so compare the
    annotated map's statistics with the projected scan of the adjacent drive 0002 instead."""
    raw = kitti_dir / "raw_samples"
    path = improved_gt_path(raw, "2011_09_26/2011_09_26_drive_0001_sync", 5, root=raw / "depth_annotated")
    improved = read_improved_gt(path)
    valid = improved > 0
    assert improved.shape == (375, 1242) and 0.15 < valid.mean() < 0.25
    assert 5.0 < improved[valid].min() and improved[valid].max() < 85.0
    lidar = lidar_gt(raw, DRIVE, 0)
    # same rig, same street: both cover the same image rows and similar depth ranges
    assert abs(np.nonzero(valid.any(1))[0].min() - np.nonzero((lidar > 0).any(1))[0].min()) < 25
    assert np.median(improved[valid]) == pytest.approx(np.median(lidar[lidar > 0]), rel=0.5)


def test_real_oxts_speed(kitti_dir: Path) -> None:
    paths = sorted((kitti_dir / "raw_samples" / DRIVE / "oxts" / "data").glob("*.txt"))
    packets = read_oxts(paths)
    poses = oxts_to_poses(packets)
    step = np.linalg.norm(np.diff(poses[:, :3, 3], axis=0), axis=1)
    stamps = (kitti_dir / "raw_samples" / DRIVE / "oxts" / "timestamps.txt").read_text().split("\n")[:10]
    seconds = np.array([float(s.split(":")[-1]) for s in stamps])
    speed = np.hypot(packets[:, 6], packets[:, 7])  # vn, ve in m/s
    np.testing.assert_allclose(step, (speed[:-1] + speed[1:]) / 2 * np.diff(seconds), rtol=0.05)


def test_real_raw_dataset(kitti_dir: Path) -> None:
    raw = kitti_dir / "raw_samples"
    ds = KittiRawDataset(raw, [f"{DRIVE} 5 l", f"{DRIVE} 5 r"], 96, 320, train=False)
    left, right = ds[0], ds[1]
    assert left["frames"].shape == (3, 3, 96, 320) and left["frames"].dtype == torch.float32
    assert 0 <= left["frames"].min() and left["frames"].max() <= 1
    assert left["intrinsics"][0, 0].item() == pytest.approx(721.5377 / 1242, rel=1e-6)
    assert not np.allclose(left["frames"].numpy(), right["frames"].numpy())
    assert (left["folder"], left["frame"], left["side"]) == (DRIVE, 5, "l")


def test_real_raw_dataset_gives_the_camera_motion_to_each_source(kitti_dir: Path) -> None:
    """Frames 4 and 7 seen from 5 on a drive going straight ahead: each motion's length is the OXTS
    speed times the time between the frames, and it is along the optical axis (a target point is
    further away in the earlier frame, nearer in the later one). The two cameras move alike."""
    raw = kitti_dir / "raw_samples"
    lines = [f"{DRIVE} 5 l", f"{DRIVE} 5 r"]
    ds = KittiRawDataset(raw, lines, 96, 320, frame_ids=(0, -1, 2), train=False, with_motion=True)
    stamps = (raw / DRIVE / "oxts" / "timestamps.txt").read_text().split("\n")[:10]
    seconds = np.array([float(s.split(":")[-1]) for s in stamps])
    speed = np.hypot(*read_oxts(sorted((raw / DRIVE / "oxts" / "data").glob("*.txt")))[:, 6:8].T)
    expected = [speed[4:6].mean() * (seconds[5] - seconds[4]), speed[5:8].mean() * (seconds[7] - seconds[5])]
    left, right = ds[0]["motions"].numpy(), ds[1]["motions"].numpy()
    np.testing.assert_allclose(np.linalg.norm(left[:, :3, 3], axis=1), expected, rtol=0.03)
    np.testing.assert_allclose(left[:, 2, 3] / expected, [1, -1], atol=0.05)
    np.testing.assert_allclose(right, left, atol=0.01)
    assert "motions" not in KittiRawDataset(raw, lines, 96, 320)[0]


def test_jpeg_draft_decodes_at_a_reduced_scale_only_where_it_serves(kitti_dir: Path, tmp_path: Path) -> None:
    """Real frames, also converted to JPEG as KITTI users do: the training loader's pixels are the
    evaluation's (full decode, then resize_uint8) bit for bit; data.jpeg_draft changes them only for
    a JPEG at under half its size, where the decode is a quarter of the frame."""
    raw, root = kitti_dir / "raw_samples", tmp_path / "raw"
    (root / DRIVE / "image_02/data").mkdir(parents=True)
    for name in ("calib_cam_to_cam.txt", "calib_velo_to_cam.txt", "calib_imu_to_velo.txt"):
        (root / DRIVE).parent.joinpath(name).write_bytes((raw / DRIVE).parent.joinpath(name).read_bytes())
    for frame in (4, 5, 6):
        png = raw / DRIVE / f"image_02/data/{frame:010d}.png"
        Image.open(png).convert("RGB").save(root / DRIVE / f"image_02/data/{frame:010d}.jpg", quality=95)
    png, jpg = raw / DRIVE / "image_02/data/0000000005.png", root / DRIVE / "image_02/data/0000000005.jpg"
    for path in (png, jpg):
        for h, w in ((64, 192), (192, 640)):
            assert np.array_equal(load_resized(path, h, w), resize_uint8(np.asarray(load_rgb(path)), h, w))
            if path == png or w == 640:  # a PNG, or a size above half of 1242×375: the same decode
                assert np.array_equal(load_resized(path, h, w, jpeg_draft=True), load_resized(path, h, w))
    assert load_rgb(jpg, draft=(192, 64)).size == (311, 94)  # 1242×375 / 4: the smallest scale ≥ 192×64
    datasets = [
        KittiRawDataset(root, [f"{DRIVE} 5 l"], 64, 192, img_ext=".jpg", train=False, jpeg_draft=d) for d in (0, 1)
    ]
    full, draft = (ds[0]["frames"].numpy() * 255 for ds in datasets)
    assert full.shape == draft.shape == (3, 3, 64, 192)
    assert np.array_equal(full[0], load_resized(jpg, 64, 192).transpose(2, 0, 1).astype(np.float32))
    assert 0.5 < np.abs(full - draft).mean() < 5  # other pixels, but the same image


def test_odometry_frames_are_found_as_png_or_converted_jpg_but_never_mixed(tmp_path):
    folder = tmp_path / "sequences" / "09" / "image_2"
    folder.mkdir(parents=True)
    for name in ("000001.jpg", "000000.jpg", "notes.jpg"):
        (folder / name).write_bytes(b"")
    assert [p.name for p in list_sequence_frames(tmp_path, 9)] == ["000000.jpg", "000001.jpg"]
    with pytest.raises(PoseconsError, match=r"image_2: no \*\.png frames"):
        list_sequence_frames(tmp_path, 9, img_ext=".png")
    (folder / "000002.png").write_bytes(b"")
    with pytest.raises(PoseconsError, match="both .png and .jpg"):
        list_sequence_frames(tmp_path, "09")
