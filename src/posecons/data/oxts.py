"""OXTS packets (30 values a line) ↔ IMU poses, with the KITTI devkit's Mercator convention.

A pose here maps IMU coordinates (x forward, y left, z up) into a local metric world frame
(x east, y north, z up): R = Rz(yaw) · Ry(pitch) · Rx(roll), translation from the Mercator
projection of (lat, lon) scaled by cos(lat of the first packet), and the altitude.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import PoseconsError
from ..fileio import require_file

EARTH_RADIUS = 6378137.0  # metres, as in the KITTI devkit
GRAVITY = 9.81
OXTS_FIELDS = (
    "lat", "lon", "alt", "roll", "pitch", "yaw", "vn", "ve", "vf", "vl", "vu",
    "ax", "ay", "az", "af", "al", "au", "wx", "wy", "wz", "wf", "wl", "wu",
    "pos_accuracy", "vel_accuracy", "navstat", "numsats", "posmode", "velmode", "orimode",
)  # fmt: skip
N_INT_FIELDS = 5  # the last five fields are integer status codes
DATAFORMAT = """lat:   latitude of the oxts-unit (deg)
lon:   longitude of the oxts-unit (deg)
alt:   altitude of the oxts-unit (m)
roll:  roll angle (rad),    0 = level, positive = left side up,      range: -pi   .. +pi
pitch: pitch angle (rad),   0 = level, positive = front down,        range: -pi/2 .. +pi/2
yaw:   heading (rad),       0 = east,  positive = counter clockwise, range: -pi   .. +pi
vn:    velocity towards north (m/s)
ve:    velocity towards east (m/s)
vf:    forward velocity, i.e. parallel to earth-surface (m/s)
vl:    leftward velocity, i.e. parallel to earth-surface (m/s)
vu:    upward velocity, i.e. perpendicular to earth-surface (m/s)
ax:    acceleration in x, i.e. in direction of vehicle front (m/s^2)
ay:    acceleration in y, i.e. in direction of vehicle left (m/s^2)
az:    acceleration in z, i.e. in direction of vehicle top (m/s^2)
af:    forward acceleration (m/s^2)
al:    leftward acceleration (m/s^2)
au:    upward acceleration (m/s^2)
wx:    angular rate around x (rad/s)
wy:    angular rate around y (rad/s)
wz:    angular rate around z (rad/s)
wf:    angular rate around forward axis (rad/s)
wl:    angular rate around leftward axis (rad/s)
wu:    angular rate around upward axis (rad/s)
pos_accuracy:  position accuracy (north/east in m)
vel_accuracy:  velocity accuracy (north/east in m/s)
navstat:       navigation status
numsats:       number of satellites tracked by primary GPS receiver
posmode:       position mode of primary GPS receiver
velmode:       velocity mode of primary GPS receiver
orimode:       orientation mode of primary GPS receiver
"""


def rotation_rpy(roll: np.ndarray, pitch: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """(N, 3, 3) R = Rz(yaw) · Ry(pitch) · Rx(roll) for (N,) angles."""
    cr, sr, cp, sp, cy, sy = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
    return np.stack(
        [
            np.stack([cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr], -1),
            np.stack([sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr], -1),
            np.stack([-sp, cp * sr, cp * cr], -1),
        ],
        -2,
    )


def read_oxts(paths: list[Path]) -> np.ndarray:
    """Read OXTS packet files → (N, 30) float64."""
    rows = []
    for path in paths:
        text = require_file(Path(path), "OXTS packet").read_text().split()
        try:
            values = [float(v) for v in text]
        except ValueError:
            values = []
        if len(values) != len(OXTS_FIELDS):
            raise PoseconsError(f"{path}:1: expected {len(OXTS_FIELDS)} numbers in an OXTS packet")
        if not np.isfinite(values).all():
            raise PoseconsError(f"{path}:1: NaN or infinite number in an OXTS packet")
        rows.append(values)
    return np.asarray(rows, dtype=np.float64).reshape(-1, len(OXTS_FIELDS))


def format_oxts(packet: np.ndarray) -> str:
    """One packet (30,) as a KITTI line (14 significant digits; integer status codes)."""
    floats = " ".join(f"{v:.14g}" for v in packet[:-N_INT_FIELDS])
    ints = " ".join(str(int(round(v))) for v in packet[-N_INT_FIELDS:])
    return f"{floats} {ints}\n"


def oxts_to_poses(packets: np.ndarray) -> np.ndarray:
    """(N, 30) packets → (N, 4, 4) IMU → world poses, world origin at the first packet's position."""
    lat, lon, alt = packets[:, 0], packets[:, 1], packets[:, 2]
    scale = np.cos(np.deg2rad(lat[0]))
    tx = scale * EARTH_RADIUS * np.deg2rad(lon)
    ty = scale * EARTH_RADIUS * np.log(np.tan(np.deg2rad(90.0 + lat) / 2.0))
    poses = np.tile(np.eye(4), (len(packets), 1, 1))
    poses[:, :3, :3] = rotation_rpy(packets[:, 3], packets[:, 4], packets[:, 5])
    poses[:, :3, 3] = np.stack([tx - tx[0], ty - ty[0], alt - alt[0]], axis=-1)
    return poses


def poses_to_oxts(poses: np.ndarray, rpy: np.ndarray, origin: tuple[float, float, float], fps: float) -> np.ndarray:
    """Synthesise packets for IMU poses (N, 4, 4) in a world frame whose origin is at
    ``origin`` = (lat, lon, alt) and which the first pose starts from; ``rpy`` (N, 3) are the
    angles that built the rotations. Rates come from finite differences. Returns (N, 30)."""
    lat0, lon0, alt0 = origin
    scale = np.cos(np.deg2rad(lat0))
    pos = poses[:, :3, 3] - poses[0, :3, 3]
    mx = scale * EARTH_RADIUS * np.deg2rad(lon0) + pos[:, 0]
    my = scale * EARTH_RADIUS * np.log(np.tan(np.deg2rad(90.0 + lat0) / 2.0)) + pos[:, 1]
    lon = np.rad2deg(mx / (scale * EARTH_RADIUS))
    lat = np.rad2deg(2.0 * np.arctan(np.exp(my / (scale * EARTH_RADIUS)))) - 90.0
    rot = poses[:, :3, :3]
    heading = rotation_rpy(0 * rpy[:, 2], 0 * rpy[:, 2], rpy[:, 2])  # the level, yaw-only frame
    vel = _derivative(pos, fps)
    force = _derivative(vel, fps) + np.array([0.0, 0.0, GRAVITY])  # what an accelerometer measures
    rel = np.einsum("nji,njk->nik", rot[:-1], rot[1:])  # R_i^T R_{i+1}
    omega = (
        np.stack([rel[:, 2, 1] - rel[:, 1, 2], rel[:, 0, 2] - rel[:, 2, 0], rel[:, 1, 0] - rel[:, 0, 1]], -1) * fps / 2
    )
    omega = np.concatenate([omega, omega[-1:]]) if len(omega) else np.zeros((len(poses), 3))
    to_heading = np.einsum("nji,njk->nik", heading, rot)  # body → level frame
    out = np.zeros((len(poses), len(OXTS_FIELDS)))
    out[:, 0:3] = np.stack([lat, lon, alt0 + pos[:, 2]], -1)
    out[:, 3:6] = rpy
    out[:, 6:8] = vel[:, [1, 0]]  # north, east
    out[:, 8:11] = np.einsum("nji,nj->ni", heading, vel)
    out[:, 11:14] = np.einsum("nji,nj->ni", rot, force)
    out[:, 14:17] = np.einsum("nji,nj->ni", heading, force)
    out[:, 17:20] = omega
    out[:, 20:23] = np.einsum("nij,nj->ni", to_heading, omega)
    out[:, 23:] = (0.05, 0.02, 4, 10, 6, 6, 6)
    return out


def _derivative(x: np.ndarray, fps: float) -> np.ndarray:
    """Per-second finite differences along axis 0 (zeros for a single sample)."""
    return np.gradient(x, axis=0) * fps if len(x) > 1 else np.zeros_like(x)
