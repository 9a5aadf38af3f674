"""Bad input gives one clear PoseconsError naming the file (and line), and leaves no partial output."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from posecons.cli import main
from posecons.data.calib import raw_intrinsics, read_calib_file
from posecons.data.gt import export_gt, load_velodyne
from posecons.data.kitti_raw import KittiRawDataset
from posecons.data.prepare import prepare
from posecons.data.splits import read_split
from posecons.errors import PoseconsError

DRIVE = "2011_09_26/2011_09_26_drive_0002_sync"


def _mini_raw(root: Path, kitti_dir: Path, frames: int = 3, scan: bool = True) -> Path:
    """A tiny raw tree: the real 2011_09_26 calibration, frames 0..frames-1, one scan."""
    date = root / "2011_09_26"
    date.mkdir(parents=True)
    for name in ("calib_cam_to_cam.txt", "calib_velo_to_cam.txt", "calib_imu_to_velo.txt"):
        (date / name).write_bytes((kitti_dir / "calib" / "2011_09_26" / name).read_bytes())
    images = root / DRIVE / "image_02" / "data"
    images.mkdir(parents=True)
    from PIL import Image

    for i in range(frames):
        Image.new("RGB", (62, 19), (i * 40, 0, 0)).save(images / f"{i:010d}.png")
    if scan:
        velo = root / DRIVE / "velodyne_points" / "data"
        velo.mkdir(parents=True)
        np.array([[10, 0, 0, 0.5]], dtype=np.float32).tofile(velo / "0000000001.bin")
    return root


def test_split_line_errors_name_file_and_line(tmp_path: Path) -> None:
    split = tmp_path / "split.txt"
    split.write_text(f"{DRIVE} 1 l\n{DRIVE} 1\n")
    with pytest.raises(PoseconsError, match=r"split\.txt:2: .*2 fields"):
        read_split(split)
    split.write_text(f"{DRIVE} one l\n")
    with pytest.raises(PoseconsError, match=r"split\.txt:1: frame 'one'"):
        read_split(split)
    with pytest.raises(PoseconsError, match="missing.txt: split file not found"):
        read_split(tmp_path / "missing.txt")


def test_missing_neighbour_frame_names_split_line(tmp_path: Path, kitti_dir: Path) -> None:
    root = _mini_raw(tmp_path / "raw", kitti_dir)
    split = tmp_path / "train.txt"
    split.write_text(f"{DRIVE} 1 l\n{DRIVE} 2 l\n")
    with pytest.raises(PoseconsError, match=r"train\.txt:2: frame 2\+1 .* missing: .*0000000003\.png"):
        KittiRawDataset(root, split, 16, 32)


def test_calibration_errors(tmp_path: Path, kitti_dir: Path) -> None:
    bad = tmp_path / "calib_cam_to_cam.txt"
    text = (kitti_dir / "calib" / "2011_09_26" / "calib_cam_to_cam.txt").read_text().splitlines()
    text[2] = "S_00 1.392000e+03 5.120000e+02"
    bad.write_text("\n".join(text))
    with pytest.raises(PoseconsError, match=r"calib_cam_to_cam\.txt:3: expected 'key: values'"):
        read_calib_file(bad)
    text[2] = "S_00: 1.392000e+03 5.12x0e+02"
    bad.write_text("\n".join(text))
    with pytest.raises(PoseconsError, match=r"calib_cam_to_cam\.txt:3: bad number in 'S_00'"):
        read_calib_file(bad)
    with pytest.raises(PoseconsError, match=r"nowhere/calib_cam_to_cam\.txt: calibration file not found"):
        raw_intrinsics(tmp_path / "nowhere")


def test_bad_scan_and_missing_scan_leave_no_output(tmp_path: Path, kitti_dir: Path) -> None:
    root = _mini_raw(tmp_path / "raw", kitti_dir)
    scan = root / DRIVE / "velodyne_points" / "data" / "0000000001.bin"
    scan.write_bytes(scan.read_bytes() + b"\0" * 5)
    with pytest.raises(PoseconsError, match=r"0000000001\.bin: size 21 bytes is not a multiple of 16"):
        load_velodyne(scan)
    out = tmp_path / "gt" / "gt.npz"
    out.parent.mkdir()
    with pytest.raises(PoseconsError, match=r"0000000002\.bin: Velodyne scan not found"):
        export_gt(root, [f"{DRIVE} 2 l"], out)
    assert not out.exists() and list(out.parent.iterdir()) == []
    code = main(["export-gt", "--data-path", str(root), "--split-file", str(tmp_path / "none.txt"), "--out", str(out)])
    assert code == 2 and not out.exists()


def test_unreadable_video_leaves_no_output(tmp_path: Path) -> None:
    video = tmp_path / "broken.mp4"
    video.write_bytes(b"this is not a video" * 10)
    out = tmp_path / "custom"
    with pytest.raises(PoseconsError, match=r"broken\.mp4: unreadable video"):
        prepare([video], out, np.eye(3))
    assert not out.exists() and [p.name for p in tmp_path.iterdir()] == ["broken.mp4"]


def test_synth_refuses_non_empty_output(tmp_path: Path) -> None:
    (tmp_path / "keep.txt").write_text("x")
    assert (
        main(["synth", "--out", str(tmp_path), "--drives", "2", "--frames", "3", "--width", "32", "--height", "16"])
        == 2
    )
    assert [p.name for p in tmp_path.iterdir()] == ["keep.txt"]


def test_skip_incomplete_drops_lines_without_neighbours_and_says_how_many(
    tmp_path: Path, kitti_dir: Path, capsys
) -> None:
    root = _mini_raw(tmp_path / "raw", kitti_dir, frames=3)
    split = tmp_path / "train.txt"
    split.write_text(f"{DRIVE} 1 l\n{DRIVE} 2 l\n")
    with pytest.raises(PoseconsError, match="data.skip_incomplete=true drops such lines"):
        KittiRawDataset(root, split, 16, 32)
    dataset = KittiRawDataset(root, split, 16, 32, skip_incomplete=True)
    assert [line.frame for line in dataset.lines] == [1]
    assert "train.txt: dropped 1 of 2 lines whose frames [0, -1, 1] do not all exist" in capsys.readouterr().err


def test_a_frame_of_another_size_is_named(tmp_path: Path, kitti_dir: Path) -> None:
    from PIL import Image

    root = _mini_raw(tmp_path / "raw", kitti_dir, frames=4)
    odd = root / DRIVE / "image_02" / "data" / "0000000003.png"
    Image.new("RGB", (40, 19)).save(odd)
    split = tmp_path / "train.txt"
    split.write_text(f"{DRIVE} 1 l\n{DRIVE} 2 l\n")
    dataset = KittiRawDataset(root, split, 16, 32)
    assert dataset[0]["frames"].shape == (3, 3, 16, 32)
    with pytest.raises(PoseconsError, match=r"0000000003\.png: image is 40×19 pixels but .*0000000001\.png .* 62×19"):
        dataset[1]


def test_bundled_splits_are_found_by_name() -> None:
    assert len(read_split("eigen")) == 697  # eigen/test_files.txt
    assert read_split("odom/test_files_09.txt")[0].folder == "9"
    with pytest.raises(PoseconsError, match="eigen_nope: split file not found .*bundled split: eigen, eigen_benchmark"):
        read_split("eigen_nope")
