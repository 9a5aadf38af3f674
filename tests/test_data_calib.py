"""Intrinsics conventions: normalised K (row 0 / W, row 1 / H), arguments in (height, width) order."""

from pathlib import Path

import numpy as np
import pytest
import torch

from posecons.data.calib import normalised_to_pixel, pixel_to_normalised, read_calib_intrinsics
from posecons.errors import PoseconsError
from posecons.geometry import scale_intrinsics

K_PIXEL = np.array([[721.5, 0.0, 609.6], [0.0, 721.5, 172.9], [0.0, 0.0, 1.0]])


def test_pixel_and_normalised_k_round_trip_with_height_before_width():
    K_norm = pixel_to_normalised(K_PIXEL, 375, 1242)
    assert np.allclose(K_norm[0], K_PIXEL[0] / 1242) and np.allclose(K_norm[1], K_PIXEL[1] / 375)
    assert np.allclose(normalised_to_pixel(K_norm, 375, 1242), K_PIXEL)


def test_projection_matrix_gives_its_left_3x3_block():
    P = np.hstack([K_PIXEL, [[44.9], [0.2], [0.003]]])
    assert np.allclose(pixel_to_normalised(P, 375, 1242), pixel_to_normalised(K_PIXEL, 375, 1242))


def test_numpy_and_torch_scaling_agree():
    K_norm = pixel_to_normalised(K_PIXEL, 375, 1242)
    K_torch = scale_intrinsics(torch.from_numpy(K_norm)[None], 96, 320)[0].numpy()
    assert np.allclose(K_torch[:3, :3], normalised_to_pixel(K_norm, 96, 320))


def test_pixel_k_from_a_plain_k_a_raw_or_an_odometry_calibration_file(tmp_path):
    (tmp_path / "k.txt").write_text("K: 721.5 0 609.6 0 721.5 172.9 0 0 1\n")
    (tmp_path / "odom.txt").write_text(
        "P0: 1 0 0 0 0 1 0 0 0 0 1 0\nP2: 721.5 0 609.6 44.9 0 721.5 172.9 0.2 0 0 1 0\n"
    )
    for name in ("k.txt", "odom.txt"):
        assert np.allclose(read_calib_intrinsics(tmp_path / name), K_PIXEL)
    (tmp_path / "none.txt").write_text("P0: 1 0 0 0 0 1 0 0 0 0 1 0\n")
    with pytest.raises(PoseconsError, match="none.txt: no 'K', 'P_rect_02' or 'P2'"):
        read_calib_intrinsics(tmp_path / "none.txt")


def test_intrinsics_from_a_plain_3x3_matrix_file(tmp_path):
    """7-Scenes' camera-intrinsics.txt (read in place) is fx = fy = 585, cx = 320, cy = 240; a 'K:' file still
    reads; a matrix whose bottom row is not 0 0 1, or a 3 × 4 one, is refused naming the file."""
    from posecons.data.calib import read_intrinsics

    real = Path(__file__).resolve().parents[2] / "shared" / "real" / "7scenes" / "camera-intrinsics.txt"
    assert np.array_equal(read_intrinsics(real), [[585, 0, 320], [0, 585, 240], [0, 0, 1]])
    (tmp_path / "k.txt").write_text("K: 721.5 0 609.6 0 721.5 172.9 0 0 1\n")
    assert np.allclose(read_intrinsics(tmp_path / "k.txt"), K_PIXEL)
    for text in ("585 0 320\n0 585 240\n0 1 1\n", "585 0 320 0\n0 585 240 0\n0 0 1 0\n"):
        (tmp_path / "bad.txt").write_text(text)
        with pytest.raises(PoseconsError, match=r"bad\.txt: expected a 3 × 3 intrinsics matrix"):
            read_intrinsics(tmp_path / "bad.txt")
