"""``synth`` end to end: the generated KITTI files agree with the generator's own geometry."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from posecons.cli import main
from posecons.data.calib import raw_intrinsics, velo_to_image
from posecons.data.gt import load_gt, load_velodyne
from posecons.data.kitti_odometry import KittiOdometryDataset, list_sequence_frames
from posecons.data.kitti_raw import KittiRawDataset
from posecons.data.oxts import oxts_to_poses, read_oxts
from posecons.data.splits import build_split, read_split
from posecons.data.synth import drive_folder, make_drive
from posecons.data.synth.oracle import oracle_disparities
from posecons.data.synth.render import camera_depth_at
from posecons.data.synth.rig import Rig
from posecons.data.trajectory_io import read_kitti_poses
from posecons.errors import PoseconsError
from posecons.geometry import invert_pose, mirror_pose, scale_intrinsics, warp

W, H, FRAMES, SEED = 312, 96, 12, 3


@pytest.fixture(scope="module")
def synth(make_synth) -> Path:
    return make_synth(2, FRAMES, W, H, SEED, "--workers", "1")


def test_layout_and_description(synth: Path) -> None:
    info = json.loads((synth / "synth.json").read_text())
    assert info["seed"] == SEED and (info["width"], info["height"]) == (W, H)
    assert info["test_drives"] == [drive_folder(1)] and info["train_drives"] == [drive_folder(0)]
    assert info["stereo_baseline_m"] == pytest.approx(0.533, abs=0.01)
    drive = synth / drive_folder(1)
    for sub, pattern in (
        ("image_02/data", "*.png"),
        ("image_03/data", "*.png"),
        ("velodyne_points/data", "*.bin"),
        ("oxts/data", "*.txt"),
    ):
        assert len(list((drive / sub).glob(pattern))) == FRAMES
    assert len(list_sequence_frames(synth / "odometry", 1)) == FRAMES
    assert len(read_split(synth / "splits" / "synth_odom" / "test_files_01.txt")) == FRAMES - 1
    test_lines = (synth / "splits" / "synth" / "test_files.txt").read_text().splitlines()
    assert test_lines[0] == f"{drive_folder(1)} 0000000000 l" and len(test_lines) == FRAMES
    train = read_split(synth / "splits" / "synth" / "train_files.txt") + read_split(
        synth / "splits" / "synth" / "val_files.txt"
    )
    assert {line.folder for line in train} == {drive_folder(0)} and all(1 <= line.frame <= FRAMES - 2 for line in train)
    scan = load_velodyne(drive / "velodyne_points" / "data" / "0000000000.bin")
    assert scan.shape[1] == 4 and len(scan) > 10000 and np.linalg.norm(scan[:, :3], axis=1).max() <= 120.0 + 1e-3


def test_intrinsics_scale_with_size(synth: Path) -> None:
    k = raw_intrinsics(synth / "2020_01_01")
    np.testing.assert_allclose(
        k[:2], np.array([[721.5377 / 1242, 0, 609.5593 / 1242], [0, 721.5377 / 375, 172.854 / 375]]), rtol=1e-5
    )


def test_lidar_gt_matches_renderer_depth(synth: Path, tmp_path: Path) -> None:
    """camera_z ground truth equals the renderer's exact depth along each winning point's ray."""
    gt_file = tmp_path / "gt.npz"
    split = synth / "splits" / "synth" / "test_files.txt"
    assert (
        main(
            [
                "export-gt",
                "--data-path",
                str(synth),
                "--split-file",
                str(split),
                "--out",
                str(gt_file),
                "--depth",
                "camera_z",
            ]
        )
        == 0
    )
    maps, lines = load_gt(gt_file)
    assert len(maps) == FRAMES and lines[3] == f"{drive_folder(1)} 3 l" and maps[0].shape == (H, W)
    drive, rig = make_drive(SEED, 1, FRAMES), Rig(W, H)
    p_velo_img = velo_to_image(synth / "2020_01_01")
    errors = []
    for frame in (0, FRAMES - 1):
        scan = load_velodyne(synth / drive_folder(1) / "velodyne_points" / "data" / f"{frame:010d}.bin")
        proj = np.c_[scan[scan[:, 0] >= 0, :3], np.ones((scan[:, 0] >= 0).sum())] @ p_velo_img.T
        uv, z = proj[:, :2] / proj[:, 2:], proj[:, 2]
        col, row = np.round(uv[:, 0]).astype(int) - 1, np.round(uv[:, 1]).astype(int) - 1
        inside = (z > 0) & (col >= 0) & (row >= 0) & (col < W) & (row < H)
        order = np.argsort(z[inside])  # the nearest point of each pixel is the one exported
        pixel = (row * W + col)[inside][order]
        _, first = np.unique(pixel, return_index=True)
        winners = np.nonzero(inside)[0][order][first]
        stored = maps[frame].reshape(-1)[pixel[first]]
        np.testing.assert_allclose(stored, z[winners], rtol=1e-5)
        assert (maps[frame] > 0).sum() == len(first)
        rendered = camera_depth_at(drive.prims, drive.camera_pose(rig, frame, 2), rig.k(2), uv[winners])
        errors.append(np.abs(stored - rendered) / stored)
    errors = np.concatenate(errors)
    assert len(errors) > 500 and np.median(errors) < 1e-3
    # the default Eigen depth is LiDAR x: about 0.27 m more than camera z (the sensor sits behind)
    velo_file = tmp_path / "gt_velo.npz"
    assert main(["export-gt", "--data-path", str(synth), "--split-file", str(split), "--out", str(velo_file)]) == 0
    velo, _ = load_gt(velo_file)
    both = (velo[0] > 0) & (maps[0] > 0)
    assert np.median(velo[0][both] - maps[0][both]) == pytest.approx(0.27, abs=0.02)


def test_oxts_and_odometry_poses_reproduce_trajectory(synth: Path) -> None:
    drive, rig = make_drive(SEED, 0, FRAMES), Rig(W, H)
    true_imu = drive.trajectory.imu_poses
    packets = read_oxts(sorted((synth / drive_folder(0) / "oxts" / "data").glob("*.txt")))
    assert packets.shape == (FRAMES, 30)
    np.testing.assert_allclose(oxts_to_poses(packets), _relative_world(true_imu), atol=1e-5)
    speed = np.hypot(packets[:, 6], packets[:, 7]) / 10  # m/s at 10 Hz → m per frame
    assert 0.4 < speed.mean() < 1.6
    cam0 = np.stack([drive.camera_pose(rig, i, 0) for i in range(FRAMES)])
    np.testing.assert_allclose(
        read_kitti_poses(synth / "odometry" / "poses" / "00.txt"), np.linalg.inv(cam0[0]) @ cam0, atol=1e-6
    )


def _relative_world(poses: np.ndarray) -> np.ndarray:
    """OXTS poses keep the world axes (east, north, up) and move the origin to the first position."""
    out = poses.copy()
    out[:, :3, 3] -= poses[0, :3, 3]
    return out


def test_raw_dataset_sizes_flip_and_determinism(synth: Path) -> None:
    split = synth / "splits" / "synth" / "train_files.txt"
    plain = KittiRawDataset(synth, split, H // 2, W // 2, train=False)
    sample = plain[0]
    assert sample["frames"].shape == (3, 3, H // 2, W // 2) and sample["frames"].dtype == torch.float32
    np.testing.assert_allclose(
        sample["intrinsics"].numpy(), raw_intrinsics(synth / "2020_01_01", 2 if sample["side"] == "l" else 3)
    )
    assert sample["color_aug"].tolist() == [1, 1, 1, 0]
    flipped = KittiRawDataset(synth, split, H // 2, W // 2, flip_prob=1.0, jitter_prob=0.0)[0]
    assert torch.equal(flipped["frames"], sample["frames"].flip(-1))
    # integer pixel centres: cx ↦ W − 1 − cx in pixels at the network width
    assert flipped["intrinsics"][0, 2].item() * (W // 2) == pytest.approx(
        W // 2 - 1 - sample["intrinsics"][0, 2].item() * (W // 2), abs=1e-4
    )
    assert not torch.equal(sample["frames"][1], sample["frames"][0])  # the neighbour frames differ
    augmented = KittiRawDataset(synth, split, H // 2, W // 2, seed=7, flip_prob=0.5, jitter_prob=1.0)
    draws = [augmented[i]["color_aug"] for i in range(3)]
    again = KittiRawDataset(synth, split, H // 2, W // 2, seed=7, flip_prob=0.5, jitter_prob=1.0)
    assert all(torch.equal(a, again[i]["color_aug"]) for i, a in enumerate(draws))
    assert all(0.8 <= v <= 1.2 for d in draws for v in d[:3].tolist()) and all(abs(d[3].item()) <= 0.1 for d in draws)
    assert torch.equal(again[(0, 0)]["color_aug"], draws[0]) and not torch.equal(again[(1, 0)]["color_aug"], draws[0])


def test_odometry_dataset(synth: Path) -> None:
    lines = [f"1 {f} l" for f in range(1, FRAMES - 1)]
    ds = KittiOdometryDataset(synth / "odometry", lines, H, W, train=False)
    sample = ds[0]
    assert sample["frames"].shape == (3, 3, H, W) and sample["folder"] == "1"
    np.testing.assert_allclose(sample["intrinsics"].numpy(), raw_intrinsics(synth / "2020_01_01"), rtol=1e-5)
    raw = KittiRawDataset(synth, [f"{drive_folder(1)} 1 l"], H, W, train=False)[0]
    assert torch.equal(sample["frames"], raw["frames"])


def test_motions_are_the_generators_true_camera_motions(synth: Path, tmp_path: Path) -> None:
    """T_{f←0} = C_f⁻¹ C_0 of the split line's own camera (2 for l, 3 for r), from the odometry
    poses and from the raw OXTS through the date's calibration; a mirror image gets M·T·M."""
    drive, rig, ids = make_drive(SEED, 1, FRAMES), Rig(W, H), (0, -2, 1)

    def true_motion(cam: int) -> np.ndarray:
        c = np.stack([drive.camera_pose(rig, i, cam) for i in range(FRAMES)])
        return np.linalg.inv(c[[1, 4]]) @ c[3]

    odom = KittiOdometryDataset(synth / "odometry", ["1 3 l", "1 3 r"], H, W, ids, train=False, with_motion=True)
    np.testing.assert_allclose(odom[0]["motions"].numpy(), true_motion(2), atol=2e-5)
    np.testing.assert_allclose(odom[1]["motions"].numpy(), true_motion(3), atol=2e-5)
    raw = KittiRawDataset(synth, [f"{drive_folder(1)} 3 r"], H, W, frame_ids=ids, with_motion=True, flip_prob=1.0)
    mirror = np.diag([-1.0, 1, 1, 1])
    np.testing.assert_allclose(raw[0]["motions"].numpy(), mirror @ true_motion(3) @ mirror, atol=2e-5)
    assert "motions" not in KittiRawDataset(synth, [f"{drive_folder(1)} 3 r"], H, W, frame_ids=ids)[0]
    (tmp_path / "sequences").symlink_to(synth / "odometry" / "sequences")
    with pytest.raises(PoseconsError, match=r"poses/01.txt: odometry ground-truth poses not found .*known_motion"):
        KittiOdometryDataset(tmp_path, ["1 3 l"], H, W, frame_ids=ids, with_motion=True)


@pytest.fixture(scope="module")
def turning(make_synth) -> Path:
    """Seed 1's first open drive turns by 2–5° a frame: a mirrored motion differs from the motion."""
    return make_synth(2, FRAMES, 192, 64, 1, "--profile", "open", "--workers", "1")


@pytest.mark.parametrize("flip", [False, True])
def test_motions_warp_the_exact_depth_onto_each_source(turning: Path, flip: bool) -> None:
    """The renderer's depth of the target, warped with each sample motion, reproduces that source
    frame (also in the mirrored sample); the inverse motion, or the unmirrored one, does not."""
    line, h, w = f"{drive_folder(0)} 5 l", 64, 192
    ds = KittiRawDataset(turning, [line], h, w, (0, -2, 1), with_motion=True, flip_prob=float(flip), jitter_prob=0)
    sample = ds[0]
    depth = torch.from_numpy(1 / oracle_disparities(turning, read_split([line]), h, w))[None]
    depth = depth.flip(-1) if flip else depth
    K = scale_intrinsics(sample["intrinsics"][None], h, w)
    frames = sample["frames"]

    def error(T: torch.Tensor, source: int) -> float:
        return (warp(frames[source][None], depth, T[None], K) - frames[0]).abs()[..., 4:-4, 4:-4].mean().item()

    for i, T in enumerate(sample["motions"]):
        assert np.degrees(np.arccos((T[:3, :3].trace().item() - 1) / 2)) > 2  # the premise: it turns
        right = error(T, i + 1)
        assert right < 0.5 * error(invert_pose(T[None])[0], i + 1)
        assert right < 0.5 * error(mirror_pose(T), i + 1)


def test_build_split_on_synth(synth: Path) -> None:
    train, val = build_split(
        synth, test_scenes={drive_folder(1).split("/")[1].removesuffix("_sync")}, val_fraction=0.25
    )
    assert len(train) + len(val) == 2 * (FRAMES - 2)  # both cameras, frames with both neighbours
    assert {line.folder for line in train + val} == {drive_folder(0)}


@pytest.mark.slow
def test_synth_is_deterministic(synth: Path, tmp_path: Path) -> None:
    out = tmp_path / "again"
    assert (
        main(
            [
                "synth",
                "--out",
                str(out),
                "--drives",
                "2",
                "--frames",
                str(FRAMES),
                "--seed",
                str(SEED),
                "--width",
                str(W),
                "--height",
                str(H),
                "--workers",
                "2",
            ]
        )
        == 0
    )
    for rel in (
        f"{drive_folder(0)}/image_02/data/0000000005.png",
        f"{drive_folder(1)}/velodyne_points/data/0000000007.bin",
        "odometry/poses/01.txt",
        "splits/synth/train_files.txt",
        "synth.json",
    ):
        assert (out / rel).read_bytes() == (synth / rel).read_bytes(), rel


def test_training_frames_are_decoded_and_resized_as_evaluation_does(tmp_path: Path) -> None:
    # A JPEG at KITTI size read at a quarter of it: JPEG draft (DCT) decoding would differ here.
    from PIL import Image

    from posecons.inference.backend import Predictor, predict_batches
    from posecons.inference.media import frames_from_paths

    rng = np.random.default_rng(0)
    drive = tmp_path / "2011_09_26" / "2011_09_26_drive_0001_sync" / "image_02" / "data"
    drive.mkdir(parents=True)
    for frame in range(3):
        pixels = rng.integers(0, 256, (375, 1242, 3), dtype=np.uint8)
        Image.fromarray(pixels).save(drive / f"{frame:010d}.jpg", quality=90)
    calib = Path(__file__).resolve().parents[1].parent / "shared" / "kitti" / "calib" / "2011_09_26"
    (tmp_path / "2011_09_26" / "calib_cam_to_cam.txt").write_text((calib / "calib_cam_to_cam.txt").read_text())
    split = ["2011_09_26/2011_09_26_drive_0001_sync 1 l"]
    sample = KittiRawDataset(tmp_path, split, 96, 320, img_ext=".jpg", train=False)[0]
    predictor = Predictor()  # the prediction path only needs the network size here
    predictor.height, predictor.width = 96, 320
    ((_, images, _),) = predict_batches(predictor, frames_from_paths([drive / "0000000001.jpg"]), 1, depth=False)
    assert torch.equal(sample["frames"][0], torch.from_numpy(images[0]))


def test_the_open_profile_varies_speed_turns_and_scene_depth_more_than_the_street():
    """Eight drives of each profile, read from the generator's own trajectory and scene: the open
    profile's speeds leave the street's 0.5–1.5 m range, its turns are sharper than the street's
    0.035 /m, and its façades stand further from the road, over a wider range. Caught: the profile not
    reaching the trajectory, the scene, or either (then both profiles draw the same drives)."""
    from posecons.data.synth.motion import extended_path
    from posecons.data.synth.primitives import Box
    from posecons.data.synth.scene import FACADE

    def stats(profile: str) -> tuple[np.ndarray, float, np.ndarray]:
        speeds, turns, setbacks = [], [], []
        for index in range(8):
            drive = make_drive(SEED, index, 100, profile)
            speed, yaw = drive.trajectory.speed, np.unwrap(drive.trajectory.rpy[:, 2])
            moving = speed[:-1] > 0.05
            speeds.append(speed[speed > 0])
            turns.append(np.abs(np.diff(yaw)[moving] / speed[:-1][moving]).max())
            track = extended_path(drive.trajectory)[0]  # the path the street is laid along
            for prim in drive.prims:
                if isinstance(prim, Box) and prim.material == FACADE:
                    setbacks.append(np.linalg.norm(track - prim.center[:2], axis=1).min() - prim.half[1])
        return np.concatenate(speeds), max(turns), np.array(setbacks)

    street, open_ = stats("street"), stats("open")
    assert open_[0].max() > 1.6 and street[0].max() <= 1.5 + 1e-9
    assert open_[1] > 0.04 > street[1]
    assert np.median(open_[2]) > np.median(street[2]) + 3 and np.ptp(open_[2]) > 2 * np.ptp(street[2])
