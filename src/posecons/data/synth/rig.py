"""The synthetic car's sensor rig, modelled on KITTI's 2011_09_26 calibration.

The numbers below are that date's published calibration values. Rectified cameras 2 (left
colour) and 3 (right colour) are ideal pinholes with ``P_rect_02/03`` scaled to the rendered
size (row 0 by W/1242, row 1 by H/375, so the normalised K does not depend on the size).
Transforms are named ``M_b_a``: 4×4 matrices mapping points of frame a into frame b.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

KITTI_SIZE = (1242, 375)
CAM_TO_CAM = {
    "corner_dist": [9.950000e-02],
    "S_00": [1.392000e03, 5.120000e02],
    "K_00": [9.842439e02, 0, 6.900000e02, 0, 9.808141e02, 2.331966e02, 0, 0, 1],
    "D_00": [-3.728755e-01, 2.037299e-01, 2.219027e-03, 1.383707e-03, -7.233722e-02],
    "R_00": [1, 0, 0, 0, 1, 0, 0, 0, 1],
    "T_00": [2.573699e-16, -1.059758e-16, 1.614870e-16],
    "R_rect_00": [9.999239e-01, 9.837760e-03, -7.445048e-03, -9.869795e-03, 9.999421e-01, -4.278459e-03,
                  7.402527e-03, 4.351614e-03, 9.999631e-01],
    "P_rect_00": [7.215377e02, 0, 6.095593e02, 0, 0, 7.215377e02, 1.728540e02, 0, 0, 0, 1, 0],
    "S_01": [1.392000e03, 5.120000e02],
    "K_01": [9.895267e02, 0, 7.020000e02, 0, 9.878386e02, 2.455590e02, 0, 0, 1],
    "D_01": [-3.644661e-01, 1.790019e-01, 1.148107e-03, -6.298563e-04, -5.314062e-02],
    "R_01": [9.993513e-01, 1.860866e-02, -3.083487e-02, -1.887662e-02, 9.997863e-01, -8.421873e-03,
             3.067156e-02, 8.998467e-03, 9.994890e-01],
    "T_01": [-5.370000e-01, 4.822061e-03, -1.252488e-02],
    "R_rect_01": [9.996878e-01, -8.976826e-03, 2.331651e-02, 8.876121e-03, 9.999508e-01, 4.418952e-03,
                  -2.335503e-02, -4.210612e-03, 9.997184e-01],
    "P_rect_01": [7.215377e02, 0, 6.095593e02, -3.875744e02, 0, 7.215377e02, 1.728540e02, 0, 0, 0, 1, 0],
    "S_02": [1.392000e03, 5.120000e02],
    "K_02": [9.597910e02, 0, 6.960217e02, 0, 9.569251e02, 2.241806e02, 0, 0, 1],
    "D_02": [-3.691481e-01, 1.968681e-01, 1.353473e-03, 5.677587e-04, -6.770705e-02],
    "R_02": [9.999758e-01, -5.267463e-03, -4.552439e-03, 5.251945e-03, 9.999804e-01, -3.413835e-03,
             4.570332e-03, 3.389843e-03, 9.999838e-01],
    "T_02": [5.956621e-02, 2.900141e-04, 2.577209e-03],
    "R_rect_02": [9.998817e-01, 1.511453e-02, -2.841595e-03, -1.511724e-02, 9.998853e-01, -9.338510e-04,
                  2.827154e-03, 9.766976e-04, 9.999955e-01],
    "P_rect_02": [7.215377e02, 0, 6.095593e02, 4.485728e01, 0, 7.215377e02, 1.728540e02, 2.163791e-01,
                  0, 0, 1, 2.745884e-03],
    "S_03": [1.392000e03, 5.120000e02],
    "K_03": [9.037596e02, 0, 6.957519e02, 0, 9.019653e02, 2.242509e02, 0, 0, 1],
    "D_03": [-3.639558e-01, 1.788651e-01, 6.029694e-04, -3.922424e-04, -5.382460e-02],
    "R_03": [9.995599e-01, 1.699522e-02, -2.431313e-02, -1.704422e-02, 9.998531e-01, -1.809756e-03,
             2.427880e-02, 2.223358e-03, 9.997028e-01],
    "T_03": [-4.731050e-01, 5.551470e-03, -5.250882e-03],
    "R_rect_03": [9.998321e-01, -7.193136e-03, 1.685599e-02, 7.232804e-03, 9.999712e-01, -2.293585e-03,
                  -1.683901e-02, 2.415116e-03, 9.998553e-01],
    "P_rect_03": [7.215377e02, 0, 6.095593e02, -3.395242e02, 0, 7.215377e02, 1.728540e02, 2.199936e00,
                  0, 0, 1, 2.729905e-03],
}  # fmt: skip
VELO_TO_CAM = {
    "R": [7.533745e-03, -9.999714e-01, -6.166020e-04, 1.480249e-02, 7.280733e-04, -9.998902e-01,
          9.998621e-01, 7.523790e-03, 1.480755e-02],
    "T": [-4.069766e-03, -7.631618e-02, -2.717806e-01],
    "delta_f": [0, 0],
    "delta_c": [0, 0],
}  # fmt: skip
IMU_TO_VELO = {
    "R": [9.999976e-01, 7.553071e-04, -2.035826e-03, -7.854027e-04, 9.998898e-01, -1.482298e-02,
          2.024406e-03, 1.482454e-02, 9.998881e-01],
    "T": [-8.086759e-01, 3.195559e-01, -7.997231e-01],
}  # fmt: skip
IMU_HEIGHT = 0.93  # metres above the road; puts the Velodyne at 1.73 m and the cameras at ~1.65 m


def _rigid(entry: dict) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = np.reshape(entry["R"], (3, 3))
    out[:3, 3] = entry["T"]
    return out


@dataclass(frozen=True)
class Rig:
    """The rig at one rendered image size (width, height)."""

    width: int = KITTI_SIZE[0]
    height: int = KITTI_SIZE[1]

    def p_rect(self, cam: int) -> np.ndarray:
        """(3, 4) ``P_rect_0<cam>`` scaled to the rendered size."""
        p = np.reshape(CAM_TO_CAM[f"P_rect_0{cam}"], (3, 4)).astype(np.float64)
        p[0] *= self.width / KITTI_SIZE[0]
        p[1] *= self.height / KITTI_SIZE[1]
        return p

    def k(self, cam: int = 2) -> np.ndarray:
        """(3, 3) pixel intrinsics of rectified camera ``cam``."""
        return self.p_rect(cam)[:, :3]

    @cached_property
    def m_velo_imu(self) -> np.ndarray:
        return _rigid(IMU_TO_VELO)

    @cached_property
    def m_rect0_velo(self) -> np.ndarray:
        """Velodyne → rectified camera 0 (R_rect_00 · [R|T]_velo→cam; odometry's ``Tr``)."""
        r_rect = np.eye(4)
        r_rect[:3, :3] = np.reshape(CAM_TO_CAM["R_rect_00"], (3, 3))
        return r_rect @ _rigid(VELO_TO_CAM)

    def m_cam_rect0(self, cam: int) -> np.ndarray:
        """Rectified camera 0 → rectified camera ``cam``: the offset t with P_rect = K [I | t]."""
        p = self.p_rect(cam)
        out = np.eye(4)
        out[:3, 3] = np.linalg.solve(p[:, :3], p[:, 3])
        return out

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
