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


def _frame_folder(folder: Path, count: int, width: int = 120, height: int = 60) -> Path:
    """``count`` frames of a texture that pans 6 px a frame (every one differs from the last)."""
    from PIL import Image

    texture = (np.random.default_rng(1).random((height, width + 6 * count, 3)) * 255).astype(np.uint8)
    folder.mkdir()
    for i in range(count):
        Image.fromarray(np.ascontiguousarray(texture[:, 6 * i : 6 * i + width])).save(folder / f"{i:03d}.png")
    return folder


def test_prepare_with_a_field_of_view_and_every_third_frame(tmp_path: Path, capsys) -> None:
    """--fov 90 on 120 px: fx = fy = 60 / tan(45°) = 60 px, centre (60, 30); --every 3 keeps frames
    0, 3, 6, 9 of 11 (each the source frame of that index). Caught: fov as the full-width focal length
    (fx = 120/tan 45°), radians, the vertical fov, keeping frames 1, 4, 7, 10."""
    src = _frame_folder(tmp_path / "frames", 11)
    out = tmp_path / "data"
    assert main(["prepare", "--input", str(src), "--out", str(out), "--fov", "90", "--every", "3"]) == 0
    assert "warning" not in capsys.readouterr().err
    np.testing.assert_allclose(
        raw_intrinsics(out / "custom"), [[60 / 120, 0, 0.5], [0, 60 / 60, 0.5], [0, 0, 1]], rtol=1e-6
    )
    kept = sorted((out / "custom" / "custom_drive_0000_sync" / "image_02" / "data").glob("*.png"))
    from PIL import Image

    sources = sorted(src.glob("*.png"))
    assert [np.asarray(Image.open(p)).tolist() for p in kept] == [
        np.asarray(Image.open(sources[i])).tolist() for i in (0, 3, 6, 9)
    ]


def test_prepare_without_intrinsics_assumes_60_degrees_and_says_so(tmp_path: Path, capsys) -> None:
    src = _frame_folder(tmp_path / "frames", 5)
    out = tmp_path / "data"
    assert main(["prepare", "--input", str(src), "--out", str(out)]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    f = 60 / np.tan(np.radians(30))  # 103.9 px
    assert len(err) == 1 and err[0].startswith("posecons prepare: warning: no intrinsics given, so a 60° ")
    assert f"fx = fy = {f:.1f} px" in err[0] and "--fov" in err[0]
    assert raw_intrinsics(out / "custom")[0, 0] == pytest.approx(f / 120)


@pytest.mark.parametrize(
    "args,message",
    [
        (["--fov", "60", "--fx", "100", "--fy", "100", "--cx", "1", "--cy", "1"], "not --fx --fy --cx --cy and --fov"),
        (["--fx", "100"], "--fx --fy --cx --cy: give all four"),
        (["--fov", "180"], "--fov"),
        (["--every", "0"], "--every"),
    ],
)
def test_prepare_intrinsics_options_refuse_bad_combinations(tmp_path: Path, capsys, args, message) -> None:
    src = _frame_folder(tmp_path / "frames", 4)
    try:
        code = main(["prepare", "--input", str(src), "--out", str(tmp_path / "data"), *args])
    except SystemExit as exc:  # argparse's usage error
        code = exc.code
    assert code == 2 and message in capsys.readouterr().err and not (tmp_path / "data").exists()


def test_static_threshold_default_is_one_number():
    """The command's default is the library's (two copies of 0.01 once dropped half of a highway clip)."""
    import inspect

    from posecons.cli import build_parser
    from posecons.data.prepare import prepare

    args = build_parser().parse_args(["prepare", "--input", "x.mp4", "--out", "o"])
    assert args.static_threshold == inspect.signature(prepare).parameters["static_threshold"].default
