"""``prepare-rgbd``: an RGB-D sequence becomes the prepare layout with depth and pose ground truth, on real
7-Scenes frames (read in place from ../shared/real/7scenes) and on hand-made sequences with known answers.
Bad input: tests/test_bad_inputs.py."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from posecons.cli import main
from posecons.data.calib import raw_intrinsics
from posecons.data.gt import load_gt
from posecons.data.kitti_raw import KittiRawDataset
from posecons.data.splits import read_split
from posecons.data.trajectory_io import read_kitti_poses
from rgbd_sequence import write_sequence

SEVEN_SCENES = Path(__file__).resolve().parents[2] / "shared" / "real" / "7scenes"
SEVEN_SCENES_ARGS = [
    "--color",
    "frame-*.color.jpg",
    "--depth",
    "frame-*.depth.png",
    "--poses",
    "frame-*.pose.txt",
    "--depth-scale",
    "1000",
    "--calib",
    str(SEVEN_SCENES / "camera-intrinsics.txt"),
]
DRIVE = Path("custom") / "custom_drive_0000_sync"


def _prepare(source: Path, out: Path, *args: str) -> None:
    assert main(["prepare-rgbd", "--input", str(source), "--out", str(out), *args]) == 0


@pytest.fixture(scope="module")
def seven_scenes(tmp_path_factory) -> Path:
    """Frames 0, 200, 400 and 600 of the real sequence (--every 200), prepared once."""
    if not SEVEN_SCENES.is_dir():
        pytest.fail(f"the real 7-Scenes frames are expected at {SEVEN_SCENES}")
    out = tmp_path_factory.mktemp("rgbd") / "data"
    _prepare(SEVEN_SCENES, out, *SEVEN_SCENES_ARGS, "--every", "200")
    return out


def test_real_frames_keep_their_depth_and_pose_when_subsampled(seven_scenes):
    """Output frame k is source frame 200·k: its pixels, its depth in metres and its pose. The known pixel:
    frame-000000.depth.png holds 1382 (mm) at row 240, column 320 → 1.382 m; 0 and 65535 (10.8 % of that
    frame) become 0. Caught: the depth scale forgotten or inverted, depth or poses not subsampled with the
    frames, 65535 kept as 65.5 m."""
    gts, lines = load_gt(seven_scenes / "gt_depths.npz")
    assert lines == [f"{DRIVE.as_posix()} {k} l" for k in range(4)]
    assert int(np.asarray(Image.open(SEVEN_SCENES / "frame-000000.depth.png"))[240, 320]) == 1382
    assert gts[0][240, 320] == pytest.approx(1.382, abs=1e-6)
    poses = read_kitti_poses(seven_scenes / "odometry" / "poses" / "00.txt")
    for k in range(4):
        source = f"frame-{200 * k:06d}"
        raw = np.asarray(Image.open(SEVEN_SCENES / f"{source}.depth.png"))
        invalid = (raw == 0) | (raw == 65535)
        assert gts[k].shape == (480, 640) and np.array_equal(gts[k] == 0, invalid)
        np.testing.assert_allclose(gts[k][~invalid], raw[~invalid] / 1000, rtol=1e-6)
        np.testing.assert_allclose(poses[k], np.loadtxt(SEVEN_SCENES / f"{source}.pose.txt"), atol=1e-9)
        colour = np.asarray(Image.open(seven_scenes / DRIVE / "image_02" / "data" / f"{k:010d}.png"))
        assert np.array_equal(colour, np.asarray(Image.open(SEVEN_SCENES / f"{source}.color.jpg").convert("RGB")))
    assert 0.10 < (gts[0] == 0).mean() < 0.11
    info = json.loads((seven_scenes / "rgbd.json").read_text())
    assert info["frames"] == [f"frame-{200 * k:06d}.color.jpg" for k in range(4)] and info["every"] == 200


def test_real_frames_make_a_dataset_that_trains_and_an_odometry_sequence(seven_scenes):
    """The intrinsics of camera-intrinsics.txt (585, 585, 320, 240 on 640 × 480), every frame with both
    neighbours in train/val, every frame in the test split, the odometry images the same files."""
    np.testing.assert_allclose(
        raw_intrinsics(seven_scenes / "custom"), [[585 / 640, 0, 0.5], [0, 585 / 480, 0.5], [0, 0, 1]], rtol=1e-6
    )
    splits = seven_scenes / "splits" / "custom"
    trained = read_split(splits / "train_files.txt") + read_split(splits / "val_files.txt")
    assert sorted(line.frame for line in trained) == [1, 2]
    assert [line.frame for line in read_split(splits / "test_files.txt")] == [0, 1, 2, 3]
    sample = KittiRawDataset(seven_scenes, splits / "train_files.txt", 48, 64, train=False)[0]
    assert sample["frames"].shape == (3, 3, 48, 64)
    odometry = sorted((seven_scenes / "odometry" / "sequences" / "00" / "image_2").iterdir())
    assert [p.name for p in odometry] == [f"{k:06d}.png" for k in range(4)]
    assert odometry[1].read_bytes() == (seven_scenes / DRIVE / "image_02" / "data" / "0000000001.png").read_bytes()


def test_a_model_is_evaluated_on_the_real_depth_and_poses(seven_scenes, tmp_path, capsys):
    """An untrained tiny checkpoint through evaluate-depth (dense GT, 0.1–10 m) and evaluate-pose (the
    odometry view): every frame evaluated, the numbers finite."""
    from posecons.checkpoint import save_checkpoint
    from posecons.config import load_config
    from posecons.model import PoseConsModel

    config = load_config(
        overrides=["model.height=64", "model.width=96", "model.num_layers=10", "model.pretrained=false"]
    )
    checkpoint = tmp_path / "model.pt"
    save_checkpoint(checkpoint, {"config": config.to_dict(), "model": PoseConsModel(config).state_dict()})
    depth = ["evaluate-depth", "--checkpoint", str(checkpoint), "--data-path", str(seven_scenes)]
    depth += ["--split-file", str(seven_scenes / "splits" / "custom" / "test_files.txt")]
    depth += ["--gt", str(seven_scenes / "gt_depths.npz"), "--gt-kind", "dense", "--min-depth", "0.1"]
    assert main([*depth, "--max-depth", "10", "--device", "cpu", "--json", str(tmp_path / "depth.json")]) == 0
    result = json.loads((tmp_path / "depth.json").read_text())
    assert (result["n_frames"], result["n_skipped"], result["depth_range"]) == (4, 0, [0.1, 10.0])
    assert np.isfinite([result["abs_rel"], result["scale_cv"]]).all()
    odometry = seven_scenes / "odometry"
    pose = ["evaluate-pose", "--checkpoint", str(checkpoint), "--data-path", str(odometry), "--sequence", "0"]
    pose += ["--gt-poses", str(odometry / "poses" / "00.txt"), "--device", "cpu"]
    assert main([*pose, "--json", str(tmp_path / "pose.json")]) == 0
    result = json.loads((tmp_path / "pose.json").read_text())
    assert result["n_frames"] == 4 and result["n_snippets"] == 3 and np.isfinite(result["ate_full_rmse"])
    capsys.readouterr()


def test_depth_scale_and_invalid_values_as_given(tmp_path):
    """--depth-scale 5000 (TUM's) and --invalid-depth 0 65535 1234: raw 2500 → 0.5 m, the named values → 0."""
    raw, _ = write_sequence(tmp_path / "seq")
    raw[1, 5, 5] = 1234
    Image.fromarray(raw[1]).save(tmp_path / "seq" / "frame-000001.depth.png")
    out = tmp_path / "out"
    args = ["--color", "frame-*.color.png", "--depth", "frame-*.depth.png", "--fx", "20", "--fy", "20"]
    args += ["--cx", "8", "--cy", "6", "--depth-scale", "5000", "--invalid-depth", "0", "65535", "1234"]
    _prepare(tmp_path / "seq", out, *args)
    gts, _ = load_gt(out / "gt_depths.npz")
    invalid = np.isin(raw, (0, 65535, 1234))
    assert np.array_equal(np.stack(gts) == 0, invalid) and invalid[1, 5, 5]
    np.testing.assert_allclose(np.stack(gts)[~invalid], raw[~invalid] / 5000, rtol=1e-6)
    assert not (out / "odometry").exists()  # no poses, no odometry view


def test_tum_names_pair_by_the_nearest_time_and_quaternions_become_rotations(tmp_path):
    """TUM RGB-D: colour rgb/<t>.png at 1.003, 1.103, 1.203 s; each depth image 5 ms away (later, earlier,
    later) with a decoy 15 ms away on the other side; a 100 Hz trajectory whose pose at 1.10 s (3 ms before
    the second frame, 1.11 s is 7 ms after) is q = (x, y, z, w) = (0, 0, sin 45°, cos 45°), a quarter turn
    about z: R = [[0, −1, 0], [1, 0, 0], [0, 0, 1]], t = (1, 2, 3). Caught: the quaternion read as
    (w, x, y, z), always the next (or the previous) timestamp taken, depth paired by order."""
    seq = tmp_path / "tum"
    (seq / "rgb").mkdir(parents=True)
    (seq / "depth").mkdir()
    for i, t in enumerate((1.003, 1.103, 1.203)):
        side = 1 if i % 2 == 0 else -1
        Image.new("RGB", (16, 12), (40 * i, 0, 0)).save(seq / "rgb" / f"{t:.6f}.png")
        depth, decoy = np.full((12, 16), 1000 * (i + 1), np.uint16), np.full((12, 16), 9000, np.uint16)
        Image.fromarray(depth).save(seq / "depth" / f"{t + 0.005 * side:.6f}.png")
        Image.fromarray(decoy).save(seq / "depth" / f"{t - 0.015 * side:.6f}.png")
    stamps = np.arange(95, 126) / 100
    rows = [[t, 0, 0, 0, 0, 0, 0, 1] for t in stamps]
    rows[15] = [1.1, 1, 2, 3, 0, 0, np.sin(np.pi / 4), np.cos(np.pi / 4)]
    np.savetxt(seq / "groundtruth.txt", rows, fmt="%.6f")
    out = tmp_path / "out"
    args = ["--color", "rgb/*.png", "--depth", "depth/*.png", "--tum-poses", str(seq / "groundtruth.txt")]
    args += ["--max-time-difference", "0.02", "--depth-scale", "5000", "--fx", "20", "--fy", "20", "--cx", "8"]
    _prepare(seq, out, *args, "--cy", "6")
    poses = read_kitti_poses(out / "odometry" / "poses" / "00.txt")
    expected = np.array([[0, -1, 0, 1], [1, 0, 0, 2], [0, 0, 1, 3], [0, 0, 0, 1]])
    np.testing.assert_allclose(poses[1], expected, atol=1e-6)
    np.testing.assert_allclose(poses[[0, 2]], np.eye(4)[None].repeat(2, 0), atol=1e-9)
    gts, _ = load_gt(out / "gt_depths.npz")
    assert [float(g[0, 0]) for g in gts] == pytest.approx([0.2, 0.4, 0.6])


def test_a_later_stretch_is_held_out_for_testing_with_a_gap(tmp_path):
    """--every 2 --test-from 8 --gap 2 of 16 frames: source frames 0, 2, 4 (before 8 − 2) train, 6 is in
    the gap, 8–14 are the test stretch — its own drive folder, the only frames of the test split, the
    ground truth and the odometry poses. Caught: the gap or --test-from counted in kept frames instead of
    source frames, the test split or the ground truth or the poses taken from the whole sequence."""
    raw, poses = write_sequence(tmp_path / "seq", count=16)
    out = tmp_path / "out"
    args = ["--color", "frame-*.color.png", "--depth", "frame-*.depth.png", "--poses", "frame-*.pose.txt"]
    args += ["--depth-scale", "1000", "--fx", "20", "--fy", "20", "--cx", "8", "--cy", "6", "--every", "2"]
    _prepare(tmp_path / "seq", out, *args, "--test-from", "8", "--gap", "2")
    info = json.loads((out / "rgbd.json").read_text())
    assert info["frames"] == [f"frame-{i:06d}.color.png" for i in (0, 2, 4, 8, 10, 12, 14)]
    assert info["test_frames"] == info["frames"][3:] and (info["test_from"], info["gap"]) == (8, 2)
    train_drive, test_drive = DRIVE, Path("custom") / "custom_drive_0001_sync"
    assert (info["drive"], info["test_drive"]) == (train_drive.as_posix(), test_drive.as_posix())
    gts, lines = load_gt(out / "gt_depths.npz")
    assert lines == [f"{test_drive.as_posix()} {k} l" for k in range(4)]
    assert [str(line) for line in read_split(out / "splits" / "custom" / "test_files.txt")] == lines
    np.testing.assert_allclose(np.stack(gts), raw[8::2] / 1000 * ~np.isin(raw[8::2], (0, 65535)), rtol=1e-6)
    np.testing.assert_allclose(read_kitti_poses(out / "odometry" / "poses" / "00.txt"), poses[8::2], atol=1e-9)
    for k, source in enumerate((8, 10, 12, 14)):
        test_image = out / test_drive / "image_02" / "data" / f"{k:010d}.png"
        colour = np.asarray(Image.open(tmp_path / "seq" / f"frame-{source:06d}.color.png"))
        assert np.array_equal(np.asarray(Image.open(test_image)), colour)
        odometry_image = out / "odometry" / "sequences" / "00" / "image_2" / f"{k:06d}.png"
        assert odometry_image.read_bytes() == test_image.read_bytes()
    assert sorted(p.name for p in (out / train_drive / "image_02" / "data").iterdir()) == [
        f"{k:010d}.png" for k in range(3)
    ]
    splits = out / "splits" / "custom"
    trained = read_split(splits / "train_files.txt") + read_split(splits / "val_files.txt")
    assert [(line.folder, line.frame) for line in trained] == [(train_drive.as_posix(), 1)]
