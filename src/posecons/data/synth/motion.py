"""Car trajectories: varying speed (0.5–1.5 m per frame at 10 Hz in the default profile), turns,
small pitch and roll, and a stop with exactly static frames."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..oxts import rotation_rpy
from .profile import PROFILES, Profile
from .rig import IMU_HEIGHT

MAX_ACCEL = 0.1  # metres per frame per frame (10 m/s² at 10 Hz)


@dataclass
class Trajectory:
    """Per-frame IMU poses (N, 4, 4) (IMU → world; world x east, y north, z up at road level),
    the roll/pitch/yaw (N, 3) that built them, and the speed (N,) in metres per frame."""

    imu_poses: np.ndarray
    rpy: np.ndarray
    speed: np.ndarray


def _piecewise(rng: np.random.Generator, frames: int, draw, lengths=(15, 40)) -> np.ndarray:
    """Piecewise-constant series: segments of random length, each value from ``draw()``."""
    out = np.empty(frames)
    i = 0
    while i < frames:
        n = int(rng.integers(*lengths))
        out[i : i + n] = draw()
        i += n
    return out


def _follow(target: np.ndarray, start: float, max_step: float) -> np.ndarray:
    """Rate-limited tracking of a target series (reaches targets exactly, e.g. a speed of 0)."""
    out = np.empty_like(target)
    value = start
    for i, goal in enumerate(target):
        value += np.clip(goal - value, -max_step, max_step)
        out[i] = value
    return out


def make_trajectory(rng: np.random.Generator, frames: int, profile: Profile = PROFILES["street"]) -> Trajectory:
    """A drive of ``frames`` frames starting at the world origin, heading drawn at random."""
    target_speed = _piecewise(rng, frames, lambda: rng.uniform(*profile.speed))
    speed = _follow(target_speed, target_speed[0], MAX_ACCEL)
    if frames >= 40:  # one stop: braking, 3–6 exactly static frames, pulling away
        start = int(rng.integers(5, frames - 30))
        braking = int(np.ceil(speed[start] / MAX_ACCEL))
        target_speed[start : start + braking + int(rng.integers(3, 7))] = 0.0
        speed = _follow(target_speed, target_speed[0], MAX_ACCEL)
    turn = profile.max_curvature
    curvature = _piecewise(rng, frames, lambda: rng.choice([0.0, rng.uniform(-turn, turn)]))
    curvature = _follow(curvature, 0.0, 0.004)
    step = np.concatenate([[0.0], speed[:-1]])  # distance covered arriving at each frame
    yaw = rng.uniform(-np.pi, np.pi) + np.cumsum(curvature * step)
    mid_yaw = np.concatenate([[yaw[0]], (yaw[1:] + yaw[:-1]) / 2])
    xy = np.cumsum(step[:, None] * np.stack([np.cos(mid_yaw), np.sin(mid_yaw)], -1), axis=0)
    s = np.cumsum(step)  # body motion follows distance, so a stopped car is exactly still
    phase = rng.uniform(0, 2 * np.pi, 3)
    pitch = 0.010 * np.sin(2 * np.pi * s / 17.0 + phase[0]) + 0.004 * np.sin(2 * np.pi * s / 6.3 + phase[1])
    roll = 0.008 * np.sin(2 * np.pi * s / 23.0 + phase[2])
    rpy = np.stack([roll, pitch, yaw], -1)
    poses = np.tile(np.eye(4), (frames, 1, 1))
    poses[:, :3, :3] = rotation_rpy(roll, pitch, yaw)
    poses[:, :3, 3] = np.concatenate([xy, np.full((frames, 1), IMU_HEIGHT)], axis=1)
    return Trajectory(poses, rpy, speed)


def extended_path(traj: Trajectory, before: float = 40.0, after: float = 130.0) -> tuple[np.ndarray, np.ndarray]:
    """The car's ground track (M, 2) and heading (M,), extended straight by ``before`` metres
    behind the start and ``after`` metres past the end (1 m steps), for laying out the scene."""
    xy, yaw = traj.imu_poses[:, :2, 3], traj.rpy[:, 2]
    back = np.arange(before, 0, -1.0)[:, None]
    ahead = np.arange(1.0, after + 1)[:, None]
    head0 = np.array([np.cos(yaw[0]), np.sin(yaw[0])])
    head1 = np.array([np.cos(yaw[-1]), np.sin(yaw[-1])])
    points = np.concatenate([xy[0] - back * head0, xy, xy[-1] + ahead * head1])
    headings = np.concatenate([np.full(len(back), yaw[0]), yaw, np.full(len(ahead), yaw[-1])])
    return points, headings
