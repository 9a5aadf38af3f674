"""The model path of the evaluation commands: a small untrained checkpoint on real KITTI frames."""

import json

import numpy as np
import pytest
import torch
from PIL import Image

from posecons.checkpoint import save_checkpoint
from posecons.cli import main
from posecons.config import load_config
from posecons.evaluation.predict import post_process_disparity, predict_steps
from posecons.evaluation.trajectory_io import read_kitti_poses, write_kitti_poses
from posecons.model import PoseConsModel

DRIVE = "2011_09_26/2011_09_26_drive_0002_sync"


@pytest.fixture
def checkpoint(tmp_path):
    cfg = load_config(overrides=["model.height=64", "model.width=192", "model.pretrained=false",
                                 "model.num_layers=10"])
    save_checkpoint(tmp_path / "m.pt", {"config": cfg.to_dict(), "model": PoseConsModel(cfg).state_dict()})
    return tmp_path / "m.pt"


def test_post_process_blends_towards_the_mirrored_prediction_at_the_left_border():
    W = 100
    disp, mirrored = torch.ones(1, 1, 2, W), torch.full((1, 1, 2, W), 3.0)
    out = post_process_disparity(disp, mirrored)[0, 0, 0]
    assert out[0] == 3.0 and out[-1] == 1.0  # each border comes from the prediction that saw it inside
    assert out[50] == pytest.approx(2.0)  # the middle is the mean
    assert torch.equal(post_process_disparity(disp, disp), disp)


class _MeanPoseModel:
    """Stands in for the pose net: T_{b←a} = [I | (mean a, mean b, 0)] shows which frames were paired."""

    def predict_pose(self, a, b):
        T = torch.eye(4).repeat(len(a), 1, 1)
        T[:, 0, 3], T[:, 1, 3] = a.mean((1, 2, 3)), b.mean((1, 2, 3))
        return T


@pytest.mark.parametrize("batch_size", [1, 2, 4, 7])
def test_predict_steps_pairs_consecutive_frames_across_batches(tmp_path, batch_size):
    paths = []
    for i in range(7):
        paths.append(tmp_path / f"{i:06d}.png")
        Image.new("RGB", (8, 4), (20 * i,) * 3).save(paths[-1])
    steps = predict_steps(_MeanPoseModel(), paths, 4, 8, batch_size)
    levels = 20 * np.arange(7) / 255
    assert np.allclose(steps[:, 0, 3], levels[:-1]) and np.allclose(steps[:, 1, 3], levels[1:])


def test_evaluate_depth_from_a_checkpoint(tmp_path, checkpoint, kitti_dir):
    split = tmp_path / "split.txt"
    split.write_text(f"{DRIVE} 0000000000 l\n{DRIVE} 0000000003 l\n")
    rc = main(["evaluate-depth", "--checkpoint", str(checkpoint), "--data-path", str(kitti_dir / "raw_samples"),
               "--split-file", str(split), "--post-process", "--scaling", "sequence", "--device", "cpu",
               "--save-disps", str(tmp_path / "disps.npy"), "--json", str(tmp_path / "depth.json")])
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
    rc = main(["evaluate-pose", "--checkpoint", str(checkpoint), "--data-path", str(tmp_path / "odom"),
               "--sequence", "9", "--gt-poses", str(tmp_path / "gt.txt"), "--batch-size", "4", "--device", "cpu",
               "--json", str(tmp_path / "pose.json"), "--out-dir", str(tmp_path / "out")])
    assert rc == 0
    result = json.loads((tmp_path / "pose.json").read_text())
    assert result["n_snippets"] == 5 and np.isfinite(result["ate_mean"])
    assert read_kitti_poses(tmp_path / "out" / "trajectory_kitti.txt").shape == (6, 4, 4)
