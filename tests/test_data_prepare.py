"""``prepare``: videos and frame folders become a KITTI-raw-layout dataset that KittiRawDataset reads."""

from __future__ import annotations

from pathlib import Path

import av
import numpy as np
import pytest

from posecons.cli import main
from posecons.data.calib import raw_intrinsics
from posecons.data.kitti_raw import KittiRawDataset
from posecons.data.splits import read_split


def _write_video(path: Path, frames: int = 16, still: int = 4) -> None:
    """A panning texture (then ``still`` repeated frames, which prepare must drop) as H.264 MP4."""
    rng = np.random.default_rng(0)
    texture = (rng.random((48, 400, 3)) * 255).astype(np.uint8).repeat(2, axis=0)
    with av.open(str(path), "w") as container:
        stream = container.add_stream("libx264", rate=10)
        stream.width, stream.height, stream.pix_fmt = 128, 96, "yuv420p"
        for i in range(frames):
            x = 8 * min(i, frames - still)
            frame = av.VideoFrame.from_ndarray(np.ascontiguousarray(texture[:, x : x + 128]), format="rgb24")
            container.mux(stream.encode(frame))
        container.mux(stream.encode())


@pytest.mark.slow
def test_prepare_video_is_readable(tmp_path: Path) -> None:
    video = tmp_path / "clip.mp4"
    _write_video(video)
    out = tmp_path / "custom"
    assert (
        main(
            [
                "prepare",
                "--input",
                str(video),
                "--out",
                str(out),
                "--fx",
                "100",
                "--fy",
                "100",
                "--cx",
                "64",
                "--cy",
                "48",
                "--width",
                "64",
                "--height",
                "48",
            ]
        )
        == 0
    )
    frames = sorted((out / "custom" / "custom_drive_0000_sync" / "image_02" / "data").glob("*.png"))
    assert 11 <= len(frames) <= 13  # the still tail is dropped
    k = raw_intrinsics(out / "custom")
    np.testing.assert_allclose(k, [[100 / 128, 0, 0.5], [0, 100 / 96, 0.5], [0, 0, 1]], rtol=1e-6)
    lines = read_split(out / "splits" / "custom" / "train_files.txt") + read_split(
        out / "splits" / "custom" / "val_files.txt"
    )
    assert len(lines) == len(frames) - 2
    ds = KittiRawDataset(out, out / "splits" / "custom" / "train_files.txt", 32, 64, train=False)
    sample = ds[0]
    assert sample["frames"].shape == (3, 3, 32, 64)
    np.testing.assert_allclose(sample["intrinsics"].numpy(), k, rtol=1e-6)


def test_prepare_frame_folder_with_calib_file(tmp_path: Path) -> None:
    from PIL import Image

    src = tmp_path / "frames"
    src.mkdir()
    rng = np.random.default_rng(1)
    texture = (rng.random((40, 200, 3)) * 255).astype(np.uint8)
    for i in range(6):
        Image.fromarray(texture[:, 10 * i : 10 * i + 80]).save(src / f"f{i:03d}.png")
    calib = tmp_path / "calib.txt"
    calib.write_text("K: 50 0 40 0 50 20 0 0 1\n")
    out = tmp_path / "out"
    assert main(["prepare", "--input", str(src), "--out", str(out), "--calib", str(calib)]) == 0
    ds = KittiRawDataset(out, out / "splits" / "custom" / "train_files.txt", 40, 80, train=False)
    assert len(ds) + len(read_split(out / "splits" / "custom" / "val_files.txt")) == 4
    np.testing.assert_allclose(ds[0]["intrinsics"].numpy()[0], [50 / 80, 0, 0.5], rtol=1e-6)
