"""Inference and export: outputs per frame at the original size, scale handling, trajectories,
point clouds, ONNX parity and clear errors for bad input (small model, tiny frames)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import av
import numpy as np
import onnxruntime as ort
import pytest
import torch
from PIL import Image

from posecons.checkpoint import load_checkpoint, load_model, save_checkpoint
from posecons.cli import main
from posecons.config import PRESETS, load_config
from posecons.data.calib import read_calib_intrinsics
from posecons.data.images import resize_rgb
from posecons.data.synth import drive_folder, generate_synth
from posecons.data.trajectory_io import read_kitti_poses, read_tum
from posecons.fileio import MANIFEST
from posecons.geometry import backproject, pose_vec_to_mat
from posecons.inference.backend import Predictor, load_predictor
from posecons.inference.camera import resolve_intrinsics
from posecons.inference.export import export_model
from posecons.inference.media import FrameSource
from posecons.inference.pointcloud import depth_to_points, read_ply, write_ply
from posecons.inference.predict import PredictOptions, gt_scale, predict
from posecons.inference.scale import camera_height
from posecons.model import PoseConsModel

SMALL = ["model.height=64", "model.width=96", "model.pretrained=false", "model.num_layers=10"]
FRAMES, H, W = 6, 60, 100  # original size: not the network's 64×96, not a multiple of 32


@pytest.fixture(scope="module")
def synth(tmp_path_factory) -> Path:
    """A tiny synthetic KITTI-format dataset: 2 drives × 6 frames of 100×60."""
    root = tmp_path_factory.mktemp("synth") / "data"
    generate_synth(root, drives=2, frames=FRAMES, width=W, height=H, workers=1)
    return root


def _drive(synth: Path, index: int) -> Path:
    return synth / drive_folder(index)


def _frames(synth: Path, index: int) -> np.ndarray:
    """(FRAMES, H, W, 3) uint8 left-camera frames of one synthetic drive."""
    return np.stack(
        [
            np.asarray(Image.open(p).convert("RGB"))
            for p in sorted((_drive(synth, index) / "image_02" / "data").iterdir())
        ]
    )


@pytest.fixture(scope="module")
def ckpt(synth, tmp_path_factory) -> Path:
    """A checkpoint after two optimiser steps on frame triplets (0, −1, +1) of drive 0."""
    torch.manual_seed(0)
    cfg = load_config(overrides=SMALL)
    model = PoseConsModel(cfg)
    seq = torch.from_numpy(np.stack([resize_rgb(f, 64, 96) for f in _frames(synth, 0)]))
    K = resolve_intrinsics(None, _drive(synth, 0).parent / "calib_cam_to_cam.txt", H, W)
    batch = {
        "frames": torch.stack([seq[[1, 0, 2]], seq[[3, 2, 4]]]),
        "intrinsics": torch.tensor(K).float().expand(2, 3, 3),
    }
    opt = torch.optim.Adam(model.parameters(), 1e-3)
    for _ in range(2):
        opt.zero_grad()
        model(batch)[1]["total"].backward()
        opt.step()
    path = tmp_path_factory.mktemp("ckpt") / "model.pt"
    save_checkpoint(path, {"config": cfg.to_dict(), "model": model.state_dict()})
    return path


@pytest.fixture(scope="module")
def frames_dir(synth) -> Path:
    return _drive(synth, 1) / "image_02" / "data"


@pytest.fixture(scope="module")
def video(synth, tmp_path_factory) -> Path:
    """Drive 1's frames as a 10 fps H.264 MP4."""
    path = tmp_path_factory.mktemp("video") / "clip.mp4"
    with av.open(str(path), "w") as container:
        stream = container.add_stream("libx264", rate=10)
        stream.width, stream.height, stream.pix_fmt = W, H, "yuv420p"
        for img in _frames(synth, 1):
            container.mux(stream.encode(av.VideoFrame.from_ndarray(img, format="rgb24")))
        container.mux(stream.encode())
    return path


@pytest.fixture(scope="module")
def base_run(ckpt, frames_dir, tmp_path_factory) -> Path:
    """Unscaled prediction over the frame folder, shared by the tests that compare against it."""
    out = tmp_path_factory.mktemp("base")
    assert (
        main(
            [
                "predict",
                "--checkpoint",
                str(ckpt),
                "--input",
                str(frames_dir),
                "--out",
                str(out),
                "--quiet",
                "--batch-size",
                "2",
            ]
        )
        == 0
    )
    return out


def _leftovers(out: Path) -> list[str]:
    return sorted(p.name for p in out.iterdir()) if out.exists() else []


# ----------------------------------------------------------------------------- predict


def test_predict_folder_writes_every_frame_at_original_size(base_run):
    names = [f"{i:010d}" for i in range(FRAMES)]
    for name in names:
        depth = np.load(base_run / "depth" / f"{name}.npy")
        assert depth.dtype == np.float32 and depth.shape == (H, W)
        assert np.isfinite(depth).all() and (depth > 0).all()
        png = np.asarray(Image.open(base_run / "depth_png" / f"{name}.png"))
        assert png.dtype == np.uint16 and png.shape == (H, W)
        np.testing.assert_array_equal(png, np.clip(np.round(depth * 256), 0, 65535).astype(np.uint16))
        color = Image.open(base_run / "depth_color" / f"{name}.jpg")
        assert color.size == (W, H) and color.mode == "RGB" and color.format == "JPEG"
    assert sorted(p.stem for p in (base_run / "depth").iterdir()) == names
    poses = read_kitti_poses(base_run / "trajectory_kitti.txt")
    stamps, tum = read_tum(base_run / "trajectory_tum.txt")
    assert poses.shape == (FRAMES, 4, 4) and tum.shape == (FRAMES, 4, 4)
    np.testing.assert_allclose(poses[0], np.eye(4), atol=1e-9)
    np.testing.assert_allclose(tum[:, :3, 3], poses[:, :3, 3], atol=1e-8)
    np.testing.assert_allclose(stamps, np.arange(FRAMES) / 10)  # default 10 fps for folders
    summary = json.loads((base_run / "predict.json").read_text())
    assert summary["frames"] == FRAMES and summary["network_size"] == [64, 96]
    assert not [n for n in _leftovers(base_run) if n.startswith(".partial")]


def test_trajectory_chains_the_pose_net_steps(ckpt, frames_dir, base_run):
    """G_{i+1} = G_i · inv(T_{i+1←i}) with T from the pair (I_i, I_{i+1})."""
    predictor = load_predictor(ckpt)

    images = np.stack([resize_rgb(f.image, 64, 96) for f in FrameSource(frames_dir)])
    steps = predictor.pose(images[:-1], images[1:])
    poses = read_kitti_poses(base_run / "trajectory_kitti.txt")
    for i, step in enumerate(steps):
        np.testing.assert_allclose(poses[i + 1], poses[i] @ np.linalg.inv(step), atol=1e-6)


def test_predict_video_streams_frames_and_writes_side_by_side(ckpt, video, tmp_path):
    out = tmp_path / "out"
    assert (
        main(
            [
                "predict",
                "--checkpoint",
                str(ckpt),
                "--input",
                str(video),
                "--out",
                str(out),
                "--quiet",
                "--batch-size",
                "4",
            ]
        )
        == 0
    )
    assert sorted(p.name for p in (out / "depth").iterdir()) == [f"{i:06d}.npy" for i in range(FRAMES)]
    assert np.load(out / "depth" / "000005.npy").shape == (H, W)
    with av.open(str(out / "video.mp4")) as container:
        decoded = [f.to_ndarray(format="rgb24") for f in container.decode(video=0)]
    assert len(decoded) == FRAMES and decoded[0].shape == (H, 2 * W, 3)
    stamps, poses = read_tum(out / "trajectory_tum.txt")
    assert len(poses) == FRAMES
    np.testing.assert_allclose(stamps, np.arange(FRAMES) / 10, atol=1e-6)  # from the video's timestamps


def test_scale_multiplies_depth_and_translations(ckpt, frames_dir, base_run, tmp_path):
    out = tmp_path / "out"
    assert (
        main(
            [
                "predict",
                "--checkpoint",
                str(ckpt),
                "--input",
                str(frames_dir),
                "--out",
                str(out),
                "--quiet",
                "--batch-size",
                "2",
                "--scale",
                "2.5",
            ]
        )
        == 0
    )
    for i in range(FRAMES):
        base = np.load(base_run / "depth" / f"{i:010d}.npy")
        np.testing.assert_array_equal(np.load(out / "depth" / f"{i:010d}.npy"), base * np.float32(2.5))
    base_poses, poses = (read_kitti_poses(d / "trajectory_kitti.txt") for d in (base_run, out))
    np.testing.assert_allclose(poses[:, :3, 3], 2.5 * base_poses[:, :3, 3], rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(poses[:, :3, :3], base_poses[:, :3, :3], atol=1e-12)
    info = json.loads((out / "scale.json").read_text())
    assert info["method"] == "given" and info["value"] == 2.5


def test_calibration_from_ground_truth_recovers_a_known_scale(ckpt, frames_dir, base_run, tmp_path):
    """GT = k × the model's own prediction → scale k and zero drift; frames without GT are skipped."""
    k = 7.3
    gt = {f"{i:06d}": k * np.load(base_run / "depth" / f"{i:010d}.npy") for i in range(FRAMES) if i != 1}
    np.savez(tmp_path / "gt.npz", lines=np.array(["seq 0 l"]), **gt)
    out = tmp_path / "out"
    assert (
        main(
            [
                "predict",
                "--checkpoint",
                str(ckpt),
                "--input",
                str(frames_dir),
                "--out",
                str(out),
                "--quiet",
                "--batch-size",
                "2",
                "--calibrate-gt",
                str(tmp_path / "gt.npz"),
                "--calibrate-frames",
                "2",
            ]
        )
        == 0
    )
    info = json.loads((out / "scale.json").read_text())
    assert info["method"] == "ground_truth" and info["frames_used"] == ["0000000000", "0000000002"]
    assert info["value"] == pytest.approx(k, rel=1e-5)
    assert info["drift"]["frames"] == FRAMES - 1
    assert info["drift"]["cv"] < 1e-5 and info["drift"]["max_rel_deviation"] < 1e-5
    assert (out / "scale_drift.png").is_file()
    np.testing.assert_allclose(np.load(out / "depth" / "0000000003.npy"), gt["000003"], rtol=1e-4)


def test_calibration_scale_uses_every_valid_pixel_without_crop_or_cap():
    """predict's ground truth may come from any camera: no Garg crop and no 80 m cap (see frame_scale)."""
    gt = np.zeros((10, 20), np.float32)
    gt[0, :3] = [4.0, 6.0, 200.0]  # the top row lies outside the Garg crop; 200 m is beyond the cap
    disparity = torch.full((1, 5, 10), 0.5)  # depth 2 everywhere once resized
    assert gt_scale(gt, disparity) == pytest.approx(6.0 / 2.0)


def test_calibration_from_16bit_png_folder(ckpt, frames_dir, base_run, tmp_path):
    """KITTI-style PNGs (depth × 256, 0 invalid) named like the frames; quantisation limits accuracy."""
    k = 40.0
    gt_dir = tmp_path / "gt"
    gt_dir.mkdir()
    for i in (2, 3, 4):
        depth = k * np.load(base_run / "depth" / f"{i:010d}.npy")
        png = np.round(depth * 256).astype(np.uint16)
        png[:5] = 0  # invalid rows are ignored
        Image.fromarray(png).save(gt_dir / f"{i:010d}.png")
    out = tmp_path / "out"
    assert (
        main(
            [
                "predict",
                "--checkpoint",
                str(ckpt),
                "--input",
                str(frames_dir),
                "--out",
                str(out),
                "--quiet",
                "--calibrate-gt",
                str(gt_dir),
                "--calibrate-frames",
                "1",
            ]
        )
        == 0
    )
    info = json.loads((out / "scale.json").read_text())
    assert info["frames_used"] == ["0000000002"] and info["value"] == pytest.approx(k, rel=1e-3)
    assert info["drift"]["frames"] == 3 and info["drift"]["max_rel_deviation"] < 1e-3


def _plane_depth(h: int, w: int, K: np.ndarray, height: float) -> np.ndarray:
    """Depth of a flat ground ``height`` below a level camera, a wall at 30 where the ray misses it."""
    v = np.arange(h, dtype=np.float64)[:, None].repeat(w, 1)
    down = (v - K[1, 2]) / K[1, 1]  # y / z of each pixel's ray
    with np.errstate(divide="ignore"):
        depth = np.where(down > 0, height / down, np.inf)
    return np.minimum(depth, 30.0)


def test_camera_height_fit_recovers_a_known_height():
    h, w = 120, 400
    K = np.array([[0.58 * w, 0, 0.5 * w], [0, 1.92 * h, 0.5 * h], [0, 0, 1]])
    depth = _plane_depth(h, w, K, 1.65) / 4.0  # the model's unknown scale: 4
    depth *= 1 + 0.002 * np.random.default_rng(0).standard_normal(depth.shape)
    depth[100:, 150:190] = 1.0  # an obstacle inside the ground region: RANSAC ignores it
    assert camera_height(depth, K) == pytest.approx(1.65 / 4.0, rel=0.01)


class PlanePredictor(Predictor):
    """Stands in for a network: the disparity of a flat ground 0.5 below the camera at network size."""

    name, height, width, has_pose = "plane", 64, 96, False

    def disparity(self, images: np.ndarray) -> torch.Tensor:
        K = np.array([[0.58 * self.width, 0, 0.5 * self.width], [0, 1.92 * self.height, 0.5 * self.height], [0, 0, 1]])
        disp = 1.0 / _plane_depth(self.height, self.width, K, 0.5)
        return torch.from_numpy(np.repeat(disp[None, None], len(images), 0).astype(np.float32))


class ApproachingWallPredictor(Predictor):
    """A wall whose disparity grows by a fifth of its first value each frame, a nearer stripe on it."""

    name, height, width, has_pose = "wall", 32, 48, False
    calls = 0

    def disparity(self, images: np.ndarray) -> torch.Tensor:
        out = []
        for _ in images:
            disp = np.full((self.height, self.width), 0.1 * (1 + 0.2 * self.calls), np.float32)
            disp[:, :8] *= 4
            out.append(disp[None])
            self.calls += 1
        return torch.from_numpy(np.stack(out))


def test_colour_range_is_one_for_the_sequence(frames_dir, tmp_path):
    """A wall that comes closer each frame gets another colour in each frame of the first batch, whose
    range colours the sequence; per-frame normalisation (the flicker users saw) paints them all alike. Caught by mutation:
    colour_range of each frame."""
    predict(ApproachingWallPredictor(), frames_dir, tmp_path / "out", PredictOptions(batch_size=4, progress=False))
    colours = [np.asarray(Image.open(p))[:, -1] for p in sorted((tmp_path / "out" / "depth_color").glob("*.jpg"))]
    assert len(colours) >= 4 and all(not np.array_equal(a, b) for a, b in zip(colours[:4], colours[1:4]))


def test_camera_height_calibration_in_predict(frames_dir, tmp_path):
    """Frames of any size: K (normalised KITTI default) is scaled to the original image."""
    summary = predict(
        PlanePredictor(),
        frames_dir,
        tmp_path / "out",
        PredictOptions(camera_height=1.5, calibrate_frames=3, progress=False),
    )
    info = json.loads((tmp_path / "out" / "scale.json").read_text())
    assert info["method"] == "camera_height" and len(info["frames_used"]) == 3
    assert info["value"] == pytest.approx(3.0, rel=0.03) and summary["scale"] == info["value"]
    assert not (tmp_path / "out" / "trajectory_kitti.txt").exists()  # no pose network


def test_intrinsics_from_flags_and_calibration_files(tmp_path):
    K = resolve_intrinsics("700,710,320,100", None, 200, 640)
    np.testing.assert_allclose(K, [[700 / 640, 0, 0.5], [0, 710 / 200, 0.5], [0, 0, 1]])
    (tmp_path / "calib.txt").write_text(
        "P0: 7 0 6 0 0 7 1 0 0 0 1 0\nP2: 718.9 0 607.2 45.4 0 718.9 185.2 -0.1 0 0 1 0\n"
    )
    np.testing.assert_allclose(
        read_calib_intrinsics(tmp_path / "calib.txt"), [[718.9, 0, 607.2], [0, 718.9, 185.2], [0, 0, 1]]
    )
    np.testing.assert_allclose(
        resolve_intrinsics(None, None, 10, 10), [[0.58, 0, 0.5], [0, 1.92, 0.5], [0, 0, 1]], rtol=1e-6
    )


# ----------------------------------------------------------------------------- point clouds


@pytest.mark.parametrize("binary", [True, False])
def test_ply_has_one_vertex_per_valid_pixel(tmp_path, binary):
    rng = np.random.default_rng(1)
    depth = rng.uniform(1, 10, (6, 9)).astype(np.float32)
    depth[0, :4] = 0
    depth[2, 3] = np.inf
    image = rng.integers(0, 256, (6, 9, 3), dtype=np.uint8)
    K = np.array([[5.0, 0, 4], [0, 6, 3], [0, 0, 1]])
    points, colors = depth_to_points(depth, image, K)
    write_ply(tmp_path / "c.ply", points, colors, binary=binary)
    back, back_colors = read_ply(tmp_path / "c.ply")
    assert len(back) == 6 * 9 - 5
    ref = backproject(
        torch.from_numpy(np.where(np.isfinite(depth), depth, 0))[None, None].double(), torch.from_numpy(K)[None]
    )[0].T.numpy()
    valid = (np.isfinite(depth) & (depth > 0)).ravel()
    np.testing.assert_allclose(back, ref[valid], rtol=1e-5)
    np.testing.assert_array_equal(back_colors, image.reshape(-1, 3)[valid])


def test_predict_pointcloud_every_kth_frame(ckpt, synth, frames_dir, tmp_path, capsys):
    out = tmp_path / "out"
    calib = _drive(synth, 1).parent / "calib_cam_to_cam.txt"  # P_rect_02 in pixels of these frames
    assert (
        main(
            [
                "predict",
                "--checkpoint",
                str(ckpt),
                "--input",
                str(frames_dir),
                "--out",
                str(out),
                "--quiet",
                "--pointcloud",
                "--every",
                "2",
                "--no-trajectory",
                "--calib",
                str(calib),
            ]
        )
        == 0
    )
    assert "warning" not in capsys.readouterr().err  # the camera's own K
    plys = sorted((out / "pointcloud").iterdir())
    assert [p.stem for p in plys] == ["0000000000", "0000000002", "0000000004"]
    points, colors = read_ply(plys[1])
    assert len(points) == H * W
    depth = np.load(out / "depth" / "0000000002.npy")
    K = read_calib_intrinsics(calib)
    np.testing.assert_allclose(points[:, 2], depth.ravel(), rtol=1e-6)
    np.testing.assert_allclose(
        points[:, 0], (np.arange(H * W) % W - K[0, 2]) / K[0, 0] * depth.ravel(), rtol=1e-4, atol=1e-6
    )
    np.testing.assert_array_equal(colors, _frames(synth, 1)[2].reshape(-1, 3))


def test_point_clouds_on_a_guessed_camera_are_warned_about(ckpt, frames_dir, tmp_path, capsys):
    """Without --intrinsics or --calib the point clouds use KITTI's K: stderr says so."""
    out = ["--out", str(tmp_path / "out"), "--quiet", "--pointcloud", "--every", "3", "--no-trajectory"]
    assert main(["predict", "--checkpoint", str(ckpt), "--input", str(frames_dir), *out]) == 0
    assert "--pointcloud used KITTI's intrinsics" in capsys.readouterr().err


# ----------------------------------------------------------------------------- export


def test_export_matches_pytorch_and_predict_runs_from_onnx(ckpt, frames_dir, base_run, tmp_path):
    info = export_model(ckpt, tmp_path / "export")
    assert max(info["max_abs_diff"]["depth"].values()) < 1e-4
    assert max(info["max_abs_diff"]["pose"].values()) < 1e-4
    assert {p.name for p in (tmp_path / "export").iterdir()} == {
        "depth.onnx",
        "pose.onnx",
        "weights.safetensors",
        "export.json",
        MANIFEST,
    }
    model, _ = load_model(tmp_path / "export" / "weights.safetensors")
    reference, _ = load_model(ckpt)
    for a, b in zip(model.state_dict().values(), reference.state_dict().values()):
        assert torch.equal(a, b)
    out = tmp_path / "out"
    assert (
        main(
            [
                "predict",
                "--checkpoint",
                str(tmp_path / "export" / "depth.onnx"),
                "--input",
                str(frames_dir),
                "--out",
                str(out),
                "--quiet",
                "--batch-size",
                "3",
            ]
        )
        == 0
    )  # another batch size: dynamic axis
    for i in range(FRAMES):
        np.testing.assert_allclose(
            np.load(out / "depth" / f"{i:010d}.npy"), np.load(base_run / "depth" / f"{i:010d}.npy"), rtol=1e-4
        )
    np.testing.assert_allclose(
        read_kitti_poses(out / "trajectory_kitti.txt"), read_kitti_poses(base_run / "trajectory_kitti.txt"), atol=1e-5
    )
    with pytest.raises(Exception, match="differs from PyTorch"):  # a tolerance nothing meets fails the export
        export_model(ckpt, tmp_path / "strict", tolerance=-1.0)
    assert _leftovers(tmp_path / "strict") == []


def test_a_known_motion_model_predicts_metres_and_no_motion(ckpt, frames_dir, tmp_path):
    """Its pose net was never trained: predict says the depth is metric (scale 1), writes no
    trajectory; export leaves the pose graph out and says metres, and predict from that export says
    metric too. A known_rotation model's depth has the usual free
    scale, and its pose net no trained rotation: no trajectory, no pose graph."""
    state = load_checkpoint(ckpt)
    state["config"]["model"]["known_motion"] = True
    metric = tmp_path / "metric.pt"
    save_checkpoint(metric, state)
    info = export_model(metric, tmp_path / "export")
    assert set(info["files"]) == {"depth", "weights"} and "metres" in info["outputs"]["depth"]
    assert not (tmp_path / "export" / "pose.onnx").exists()
    for model in (metric, tmp_path / "export" / "depth.onnx"):
        out = tmp_path / f"out_{model.stem}"
        assert (
            main(["predict", "--checkpoint", str(model), "--input", str(frames_dir), "--out", str(out), "--quiet"]) == 0
        )
        assert json.loads((out / "scale.json").read_text())["method"] == "metric"
        assert not (out / "trajectory_kitti.txt").exists()
    state["config"]["model"].update(known_motion=False, known_rotation=True)  # its rotation untrained
    save_checkpoint(gyro := tmp_path / "gyro.pt", state)
    assert (
        main(
            ["predict", "--checkpoint", str(gyro), "--input", str(frames_dir), "--out", str(tmp_path / "g"), "--quiet"]
        )
        == 0
    )
    assert json.loads((tmp_path / "g" / "scale.json").read_text())["method"] == "none"
    assert not (tmp_path / "g" / "trajectory_kitti.txt").exists()
    assert set(export_model(gyro, tmp_path / "gyro_export")["files"]) == {"depth", "weights"}


def test_export_of_a_mirrored_pose_net_matches_pytorch_at_batch_1_and_2(tmp_path):
    """Every synth preset averages each pair's pose with its mirror image's (pose_mirror), splitting
    the batch by its size: ONNX Runtime must agree with PyTorch at batch 1 (traced) and 2.

    Mutations caught: the batch size frozen into the trace (``n = int(image_a.shape[0])``); a pose graph
    without the mirror average (2 % off, inside export_model's absolute tolerance)."""
    cfg = load_config(PRESETS / "synth" / "demo.yaml")
    assert cfg.model.pose_mirror
    torch.manual_seed(0)
    model = PoseConsModel(cfg).eval()
    save_checkpoint(tmp_path / "mirror.pt", {"config": cfg.to_dict(), "model": model.state_dict()})
    export_model(tmp_path / "mirror.pt", tmp_path / "export")
    session = ort.InferenceSession(str(tmp_path / "export" / "pose.onnx"), providers=["CPUExecutionProvider"])
    for batch in (1, 2):
        a, b = torch.rand(2, batch, 3, cfg.model.height, cfg.model.width)
        pose, matrix = session.run(["pose", "matrix"], {"image_a": a.numpy(), "image_b": b.numpy()})
        with torch.no_grad():
            rot, t = model.pose_net(a, b)
        # Relative: an untrained pose net's outputs (~1e-4) are below export_model's absolute tolerance.
        np.testing.assert_allclose(pose, torch.cat([rot, t], -1)[:, 0].numpy(), rtol=1e-4, atol=1e-9)
        np.testing.assert_allclose(matrix, pose_vec_to_mat(rot, t).numpy(), rtol=1e-4, atol=1e-9)


# ----------------------------------------------------------------------------- bad input


class Payload:
    """A pickle that would create a folder when unpickled."""

    def __init__(self, target: Path):
        self.target = target

    def __reduce__(self):
        return os.makedirs, (str(self.target),)


def _fails(args: list[str], out: Path, capsys, *fragments: str) -> None:
    assert main(args + ["--out", str(out)] + (["--quiet"] if args[0] == "predict" else [])) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    for fragment in fragments:
        assert fragment in err
    assert not [n for n in _leftovers(out) if n != ".keep"]  # nothing presented as output


def test_bad_inputs_give_one_clear_message_and_no_outputs(ckpt, frames_dir, tmp_path, capsys):
    predict_args = ["predict", "--checkpoint", str(ckpt), "--input"]
    empty = tmp_path / "empty.mp4"
    empty.write_bytes(b"")
    _fails(predict_args + [str(empty)], tmp_path / "o1", capsys, str(empty), "empty")
    garbage = tmp_path / "garbage.mp4"
    garbage.write_bytes(np.random.default_rng(0).bytes(4096))
    _fails(predict_args + [str(garbage)], tmp_path / "o2", capsys, str(garbage), "video")
    text = tmp_path / "notes.txt"
    text.write_text("hello")
    _fails(predict_args + [str(text)], tmp_path / "o3", capsys, str(text), "unsupported")
    no_images = tmp_path / "no_images"
    no_images.mkdir()
    _fails(predict_args + [str(no_images)], tmp_path / "o4", capsys, str(no_images), "no images")

    cfg = load_config(overrides=SMALL[:-1] + ["model.num_layers=18"]).to_dict()
    wrong = tmp_path / "wrong.pt"
    save_checkpoint(wrong, {"config": cfg, "model": torch.load(ckpt, weights_only=True)["model"]})
    _fails(
        ["predict", "--checkpoint", str(wrong), "--input", str(frames_dir)],
        tmp_path / "o5",
        capsys,
        str(wrong),
        "architecture",
    )

    evil = tmp_path / "evil.pt"
    torch.save({"config": {}, "model": Payload(tmp_path / "pwned")}, evil)
    _fails(
        ["predict", "--checkpoint", str(evil), "--input", str(frames_dir)],
        tmp_path / "o6",
        capsys,
        str(evil),
        "refused",
    )
    assert not (tmp_path / "pwned").exists()
    _fails(["export", "--checkpoint", str(evil)], tmp_path / "o7", capsys, str(evil))


def test_truncated_video_fails_without_partial_outputs(ckpt, video, tmp_path, capsys):
    """A video whose data breaks off mid-way: an error, and OUT keeps no half-written results."""
    broken = tmp_path / "broken.mp4"
    broken.write_bytes(video.read_bytes()[: video.stat().st_size // 3])
    out = tmp_path / "out"
    code = main(["predict", "--checkpoint", str(ckpt), "--input", str(broken), "--out", str(out), "--quiet"])
    err = capsys.readouterr().err
    if code == 0:  # the decoder may recover the frames before the cut; then all must be complete
        assert len(list((out / "depth").iterdir())) == json.loads((out / "predict.json").read_text())["frames"]
    else:
        assert code == 2 and str(broken) in err and _leftovers(out) == []
