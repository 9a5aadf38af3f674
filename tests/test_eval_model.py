"""The model path of the evaluation commands: a small untrained checkpoint on real KITTI frames."""

import json

import numpy as np
import pytest
from PIL import Image

from posecons.checkpoint import save_checkpoint
from posecons.cli import main
from posecons.config import load_config
from posecons.data.trajectory_io import read_kitti_poses, write_kitti_poses
from posecons.model import PoseConsModel

DRIVE = "2011_09_26/2011_09_26_drive_0002_sync"


@pytest.fixture
def checkpoint(tmp_path):
    cfg = load_config(overrides=["model.height=64", "model.width=192", "model.pretrained=false", "model.num_layers=10"])
    save_checkpoint(tmp_path / "m.pt", {"config": cfg.to_dict(), "model": PoseConsModel(cfg).state_dict()})
    return tmp_path / "m.pt"


def test_evaluate_depth_from_a_checkpoint(tmp_path, checkpoint, kitti_dir):
    split = tmp_path / "split.txt"
    split.write_text(f"{DRIVE} 0000000000 l\n{DRIVE} 0000000003 l\n")
    rc = main(
        [
            "evaluate-depth",
            "--checkpoint",
            str(checkpoint),
            "--data-path",
            str(kitti_dir / "raw_samples"),
            "--split-file",
            str(split),
            "--post-process",
            "--scaling",
            "sequence",
            "--device",
            "cpu",
            "--save-disps",
            str(tmp_path / "disps.npy"),
            "--json",
            str(tmp_path / "depth.json"),
        ]
    )
    assert rc == 0
    result = json.loads((tmp_path / "depth.json").read_text())
    assert result["n_frames"] == 2 and result["post_process"] and result["scaling"] == "sequence"
    assert np.isfinite([result[k] for k in ("abs_rel", "rmse", "scale_cv")]).all()
    assert np.load(tmp_path / "disps.npy").shape == (2, 64, 192)


def test_evaluate_pose_from_a_checkpoint(tmp_path, checkpoint, kitti_dir):
    # A six-frame "odometry sequence" made of raw frames, with the first six poses of 09 as GT.
    seq = tmp_path / "odom" / "sequences" / "09" / "image_2"
    seq.mkdir(parents=True)
    for i in range(6):
        with Image.open(kitti_dir / "raw_samples" / DRIVE / "image_02" / "data" / f"{i:010d}.png") as img:
            img.resize((310, 94)).save(seq / f"{i:06d}.png")
    write_kitti_poses(tmp_path / "gt.txt", read_kitti_poses(kitti_dir / "odometry" / "poses" / "09.txt")[:6])
    rc = main(
        [
            "evaluate-pose",
            "--checkpoint",
            str(checkpoint),
            "--data-path",
            str(tmp_path / "odom"),
            "--sequence",
            "9",
            "--gt-poses",
            str(tmp_path / "gt.txt"),
            "--batch-size",
            "4",
            "--device",
            "cpu",
            "--json",
            str(tmp_path / "pose.json"),
            "--out-dir",
            str(tmp_path / "out"),
        ]
    )
    assert rc == 0
    result = json.loads((tmp_path / "pose.json").read_text())
    assert result["n_snippets"] == 5 and np.isfinite(result["ate_mean"])
    assert read_kitti_poses(tmp_path / "out" / "trajectory_kitti.txt").shape == (6, 4, 4)
