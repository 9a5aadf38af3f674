"""The synthetic data agrees with the model's geometry: warping a neighbour frame with the
renderer's exact depth and the true relative pose (through the dataset's own K) reproduces the
target frame far better than leaving it unwarped. If this fails, no network can learn on it."""

from pathlib import Path

import numpy as np
import pytest
import torch

from posecons.data.kitti_raw import KittiRawDataset
from posecons.data.synth import drive_folder, make_drive
from posecons.data.synth.render import camera_depth_at
from posecons.data.synth.rig import Rig
from posecons.geometry import scale_intrinsics, warp
from posecons.losses import photometric_error

W, H, FRAMES, SEED = 192, 64, 8, 5


@pytest.fixture(scope="module")
def data(make_synth) -> Path:
    return make_synth(2, FRAMES, W, H, SEED, "--neighbours", "2")


def test_training_lines_have_the_requested_neighbours(data):
    dataset = KittiRawDataset(data, data / "splits" / "synth" / "train_files.txt", H, W, frame_ids=(0, -2, 2))
    assert len(dataset) > 0 and all(2 <= line.frame <= FRAMES - 3 for line in dataset.lines)
    assert dataset[0]["frames"].shape == (3, 3, H, W)


@pytest.mark.parametrize("frame", [2, 5])
def test_true_depth_and_pose_explain_the_motion(data, frame):
    lines = [f"{drive_folder(0)} {frame} l"]
    sample = KittiRawDataset(data, lines, H, W, train=False)[0]  # frames 0, -1, +1 at native size
    K = scale_intrinsics(sample["intrinsics"][None], H, W)
    drive, rig = make_drive(SEED, 0, FRAMES), Rig(W, H)
    world_from_target = drive.camera_pose(rig, frame, 2)
    v, u = np.mgrid[0:H, 0:W]
    depth = camera_depth_at(drive.prims, world_from_target, rig.k(2), np.stack([u.ravel(), v.ravel()], 1))
    depth = torch.tensor(np.where(depth > 0, depth, 1e3), dtype=torch.float32).view(1, 1, H, W)  # sky: far
    target = sample["frames"][0:1]
    for i, offset in ((1, -1), (2, 1)):
        source = sample["frames"][i : i + 1]
        T = np.linalg.inv(drive.camera_pose(rig, frame + offset, 2)) @ world_from_target  # T_{source←target}
        warped = warp(source, depth, torch.tensor(T, dtype=torch.float32)[None], K)
        assert photometric_error(warped, target).mean() < 0.7 * photometric_error(source, target).mean()
