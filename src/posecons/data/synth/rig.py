"""The synthetic car's sensor rig, modelled on KITTI's 2011_09_26 calibration.

Its numbers are that date's published calibration values, kept in KITTI's own calibration files
(``calib_2011_09_26/``) and read as a drive's are (:mod:`posecons.data.calib`). Rectified cameras 2 (left
colour) and 3 (right colour) are ideal pinholes with ``P_rect_02/03`` scaled to the rendered
size (row 0 by W/1242, row 1 by H/375, so the normalised K does not depend on the size).
Transforms are named ``M_b_a``: 4×4 matrices mapping points of frame a into frame b.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from ..calib import calib_matrix, read_calib_file, rectified_offset, rigid

KITTI_SIZE = (1242, 375)
CALIB = Path(__file__).resolve().parent / "calib_2011_09_26"  # the values, in KITTI's calibration files
CAM_TO_CAM = read_calib_file(CALIB / "calib_cam_to_cam.txt")
VELO_TO_CAM = read_calib_file(CALIB / "calib_velo_to_cam.txt")
IMU_TO_VELO = read_calib_file(CALIB / "calib_imu_to_velo.txt")
IMU_HEIGHT = 0.93  # metres above the road; puts the Velodyne at 1.73 m and the cameras at ~1.65 m


@dataclass(frozen=True)
class Rig:
    """The rig at one rendered image size (width, height), its cameras' focal length ``focal`` × KITTI's."""

    width: int = KITTI_SIZE[0]
    height: int = KITTI_SIZE[1]
    focal: float = 1.0

    def p_rect(self, cam: int) -> np.ndarray:
        """(3, 4) ``P_rect_0<cam>`` scaled to the rendered size, = K [I | t] with K's focal lengths × ``focal``."""
        p = calib_matrix(CAM_TO_CAM, f"P_rect_0{cam}", (3, 4), CALIB / "calib_cam_to_cam.txt").astype(np.float64)
        p[0] *= self.width / KITTI_SIZE[0]
        p[1] *= self.height / KITTI_SIZE[1]
        if self.focal != 1.0:  # the same camera offset t under the new K
            offset = rectified_offset(p)[:3, 3]
            p[0, 0] *= self.focal
            p[1, 1] *= self.focal
            p[:, 3] = p[:, :3] @ offset
        return p

    def k(self, cam: int = 2) -> np.ndarray:
        """(3, 3) pixel intrinsics of rectified camera ``cam``."""
        return self.p_rect(cam)[:, :3]

    @cached_property
    def m_velo_imu(self) -> np.ndarray:
        return rigid(IMU_TO_VELO, CALIB / "calib_imu_to_velo.txt")

    @cached_property
    def m_rect0_velo(self) -> np.ndarray:
        """Velodyne → rectified camera 0 (R_rect_00 · [R|T]_velo→cam; odometry's ``Tr``)."""
        r_rect = np.eye(4)
        r_rect[:3, :3] = calib_matrix(CAM_TO_CAM, "R_rect_00", (3, 3), CALIB / "calib_cam_to_cam.txt")
        return r_rect @ rigid(VELO_TO_CAM, CALIB / "calib_velo_to_cam.txt")

    def m_cam_rect0(self, cam: int) -> np.ndarray:
        """Rectified camera 0 → rectified camera ``cam``: the offset t with P_rect = K [I | t]."""
        return rectified_offset(self.p_rect(cam))

    def m_cam_imu(self, cam: int) -> np.ndarray:
        """IMU → rectified camera ``cam`` (cam 0 is the odometry pose frame)."""
        return self.m_cam_rect0(cam) @ self.m_rect0_velo @ self.m_velo_imu

    def cam_to_cam_text(self) -> dict:
        """``calib_cam_to_cam.txt`` entries, with S_rect/P_rect at the rendered size."""
        entries = dict(CAM_TO_CAM)
        for cam in range(4):
            entries[f"S_rect_0{cam}"] = [self.width, self.height]
            entries[f"P_rect_0{cam}"] = self.p_rect(cam).ravel().tolist()
        order = ["corner_dist"] + [
            f"{k}_0{c}" for c in range(4) for k in ("S", "K", "D", "R", "T", "S_rect", "R_rect", "P_rect")
        ]
        return {key: entries[key] for key in order}
