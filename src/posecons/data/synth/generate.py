"""``posecons synth``: write a synthetic KITTI raw + odometry dataset with splits (see docs/data.md).

Layout under the output directory::

    <date>/calib_{cam_to_cam,velo_to_cam,imu_to_velo}.txt
    <date>/<date>_drive_NNNN_sync/{image_02,image_03}/data/<frame:010d>.<ext>, timestamps.txt
    <date>/<date>_drive_NNNN_sync/velodyne_points/data/<frame:010d>.bin, timestamps.txt
    <date>/<date>_drive_NNNN_sync/oxts/data/<frame:010d>.txt, dataformat.txt, timestamps.txt
    odometry/sequences/NN/{image_2,image_3}/<frame:06d>.png, calib.txt, times.txt
    odometry/poses/NN.txt
    splits/synth/{train,val,test}_files.txt, splits/synth_odom/test_files_NN.txt
    synth.json
"""

from __future__ import annotations

import io
import json
import os
import shutil
from dataclasses import dataclass
from datetime import datetime, timedelta
from pathlib import Path

import numpy as np
from PIL import Image

from ...errors import PoseconsError
from ...fileio import output_dir
from ..calib import format_calib
from ..oxts import DATAFORMAT, format_oxts, poses_to_oxts
from ..parallel import fork_map
from ..splits import SplitLine, write_split
from ..trajectory_io import write_kitti_poses
from .motion import Trajectory, extended_path, make_trajectory
from .primitives import Primitive
from .profile import PROFILES
from .render import Lidar, Shading, render_camera, shading_tables
from .rig import IMU_TO_VELO, KITTI_SIZE, VELO_TO_CAM, Rig
from .scene import build_scene, make_textures

DATE = "2020_01_01"
FPS = 10.0
ORIGIN = (49.0, 8.4, 115.0)  # lat, lon, alt of the world origin (Karlsruhe-like)
STATIC_SPAN = 0.3  # metres: a frame whose neighbours −1/+1 are closer than this is static


def drive_folder(index: int) -> str:
    """Split-file folder of synthetic drive ``index`` (``<date>/<date>_drive_NNNN_sync``)."""
    return f"{DATE}/{DATE}_drive_{index:04d}_sync"


@dataclass
class Drive:
    """Everything that defines one synthetic drive; rebuilt identically from (seed, index, frames)."""

    trajectory: Trajectory
    prims: list[Primitive]

    def camera_pose(self, rig: Rig, frame: int, cam: int) -> np.ndarray:
        """(4, 4) rectified camera ``cam`` → world pose (cam 0: the odometry pose frame)."""
        return self.trajectory.imu_poses[frame] @ np.linalg.inv(rig.m_cam_imu(cam))

    def velo_pose(self, rig: Rig, frame: int) -> np.ndarray:
        """(4, 4) Velodyne → world pose."""
        return self.trajectory.imu_poses[frame] @ np.linalg.inv(rig.m_velo_imu)


def make_drive(seed: int, index: int, frames: int, profile: str = "street") -> Drive:
    """The trajectory and street of drive ``index`` of a dataset generated with ``seed`` and ``profile``."""
    rng = np.random.default_rng([seed, index])
    trajectory = make_trajectory(rng, frames, PROFILES[profile])
    return Drive(trajectory, build_scene(rng, *extended_path(trajectory), PROFILES[profile]))


def lidar_for_width(width: int) -> Lidar:
    """A LiDAR whose horizontal density follows the image width (0.2° at KITTI's 1242 px)."""
    return Lidar(azimuth_step_deg=0.2 * max(1.0, KITTI_SIZE[0] / width))


def _encode(rgb: np.ndarray, ext: str) -> bytes:
    buf = io.BytesIO()
    if ext == "png":
        Image.fromarray(rgb).save(buf, format="PNG", compress_level=1)
    else:
        Image.fromarray(rgb).save(buf, format="JPEG", quality=95)
    return buf.getvalue()


@dataclass
class _Job:
    """What the frame workers need (inherited by forked processes, never pickled)."""

    drive: Drive
    shading: Shading
    rig: Rig
    lidar: Lidar
    ext: str
    drive_dir: Path
    sequence_dir: Path


_JOB: _Job | None = None


def _render_frame(frame: int) -> None:
    job = _JOB
    for cam, raw_name, odo_name in ((2, "image_02", "image_2"), (3, "image_03", "image_3")):
        rgb, _ = render_camera(
            job.drive.prims,
            job.shading,
            job.drive.camera_pose(job.rig, frame, cam),
            job.rig.k(cam),
            job.rig.width,
            job.rig.height,
        )
        raw_path = job.drive_dir / raw_name / "data" / f"{frame:010d}.{job.ext}"
        raw_path.write_bytes(_encode(rgb, job.ext))
        odo_path = job.sequence_dir / odo_name / f"{frame:06d}.png"
        if job.ext == "png":
            _link_or_copy(raw_path, odo_path)
        else:
            odo_path.write_bytes(_encode(rgb, "png"))
    scan = job.lidar.scan(job.drive.prims, job.shading, job.drive.velo_pose(job.rig, frame))
    scan.astype("<f4").tofile(job.drive_dir / "velodyne_points" / "data" / f"{frame:010d}.bin")


def _link_or_copy(src: Path, dst: Path) -> None:
    try:
        os.link(src, dst)
    except OSError:
        shutil.copyfile(src, dst)


def _timestamps(start: datetime, frames: int) -> str:
    return "".join(
        f"{(start + timedelta(seconds=i / FPS)).strftime('%Y-%m-%d %H:%M:%S.%f')}000\n" for i in range(frames)
    )


def _write_drive_metadata(drive: Drive, rig: Rig, drive_dir: Path, sequence: str, odometry: Path, index: int) -> None:
    frames = len(drive.trajectory.speed)
    stamps = _timestamps(datetime(2020, 1, 1, 12, 0, 0) + timedelta(minutes=10 * index), frames)
    for sensor in ("image_02", "image_03", "velodyne_points", "oxts"):
        (drive_dir / sensor / "timestamps.txt").write_text(stamps)
    packets = poses_to_oxts(drive.trajectory.imu_poses, drive.trajectory.rpy, ORIGIN, FPS)
    for frame, packet in enumerate(packets):
        (drive_dir / "oxts" / "data" / f"{frame:010d}.txt").write_text(format_oxts(packet))
    (drive_dir / "oxts" / "dataformat.txt").write_text(DATAFORMAT)
    seq_dir = odometry / "sequences" / sequence
    calib = {f"P{cam}": rig.p_rect(cam).ravel() for cam in range(4)}
    calib["Tr"] = rig.m_rect0_velo[:3].ravel()
    (seq_dir / "calib.txt").write_text(format_calib(calib, calib_time=None))
    (seq_dir / "times.txt").write_text("".join(f"{i / FPS:e}\n" for i in range(frames)))
    cam0 = np.stack([drive.camera_pose(rig, i, 0) for i in range(frames)])
    write_kitti_poses(odometry / "poses" / f"{sequence}.txt", np.linalg.inv(cam0[0]) @ cam0)


def moving_frames(drive: Drive, rig: Rig, neighbours: int = 1) -> list[int]:
    """Frames n … N−1−n whose neighbours −n/+n exist and are at least STATIC_SPAN apart (non-static)."""
    centres = np.stack([drive.camera_pose(rig, i, 2)[:3, 3] for i in range(len(drive.trajectory.speed))])
    span = np.linalg.norm(centres[2 * neighbours :] - centres[: -2 * neighbours], axis=1)
    return [i + neighbours for i in np.nonzero(span >= STATIC_SPAN)[0]]


def check_synth_args(
    drives: int, frames: int, ext: str, width: int, height: int, neighbours: int, profile: str = "street"
) -> None:
    """Refuse a data set :func:`generate_synth` cannot make, before any work."""
    if profile not in PROFILES:
        raise PoseconsError(f"synth: unknown --profile {profile!r}; known: {', '.join(PROFILES)}")
    if drives < 2 or frames < 2 * neighbours + 1 or neighbours < 1:
        raise PoseconsError(
            f"synth needs at least 2 drives (one held out for testing) and {2 * neighbours + 1} "
            f"frames for ±{neighbours} neighbours, got {drives} × {frames}"
        )
    if ext not in ("png", "jpg") or width < 16 or height < 16:
        raise PoseconsError(f"synth: unsupported --ext {ext!r} or size {width}x{height}")


def generate_synth(
    out: Path,
    drives: int = 4,
    frames: int = 100,
    seed: int = 0,
    ext: str = "png",
    width: int = KITTI_SIZE[0],
    height: int = KITTI_SIZE[1],
    workers: int | None = None,
    neighbours: int = 1,
    profile: str = "street",
) -> dict:
    """Write the dataset (all or nothing) and return its description (also in ``synth.json``).

    Training lines are the moving frames whose neighbours ±``neighbours`` exist, for training
    with ``model.frame_ids: [0, -n, n]``. ``profile``: the scene statistics (:mod:`.profile`).
    """
    check_synth_args(drives, frames, ext, width, height, neighbours, profile)
    workers = workers or min(2, os.cpu_count() or 1)
    rig, lidar = Rig(width, height, PROFILES[profile].focal), lidar_for_width(width)
    textures = make_textures(np.random.default_rng([seed, 1_000_003]), detail=PROFILES[profile].detail)
    n_test = max(1, drives // 4)
    test_ids = list(range(drives - n_test, drives))
    rng = np.random.default_rng([seed, 2_000_003])
    train_lines, test_lines, static = [], [], {}
    with output_dir(out) as tmp:
        date_dir, odometry = tmp / DATE, tmp / "odometry"
        date_dir.mkdir()
        (date_dir / "calib_cam_to_cam.txt").write_text(format_calib(rig.cam_to_cam_text()))
        (date_dir / "calib_velo_to_cam.txt").write_text(format_calib(VELO_TO_CAM))
        (date_dir / "calib_imu_to_velo.txt").write_text(format_calib(IMU_TO_VELO))
        (odometry / "poses").mkdir(parents=True)
        for index in range(drives):
            drive = make_drive(seed, index, frames, profile)
            folder, sequence = drive_folder(index), f"{index:02d}"
            drive_dir, seq_dir = tmp / folder, odometry / "sequences" / sequence
            for sub in ("image_02/data", "image_03/data", "velodyne_points/data", "oxts/data"):
                (drive_dir / sub).mkdir(parents=True)
            for sub in ("image_2", "image_3"):
                (seq_dir / sub).mkdir(parents=True)
            _render_drive(
                _Job(drive, shading_tables(drive.prims, textures), rig, lidar, ext, drive_dir, seq_dir), frames, workers
            )
            _write_drive_metadata(drive, rig, drive_dir, sequence, odometry, index)
            static[folder] = [int(i) for i in np.nonzero(drive.trajectory.speed == 0)[0]]
            if index in test_ids:
                test_lines += [SplitLine(folder, f, "l") for f in range(frames)]
                odom = [SplitLine(str(index), f, "l") for f in range(frames - 1)]
                write_split(tmp / "splits" / "synth_odom" / f"test_files_{sequence}.txt", odom)
            else:
                train_lines += [
                    SplitLine(folder, f, "lr"[rng.integers(2)]) for f in moving_frames(drive, rig, neighbours)
                ]
        rng.shuffle(train_lines)
        n_val = max(1, len(train_lines) // 10) if len(train_lines) > 1 else 0
        write_split(tmp / "splits" / "synth" / "train_files.txt", train_lines[n_val:])
        write_split(tmp / "splits" / "synth" / "val_files.txt", train_lines[:n_val])
        write_split(tmp / "splits" / "synth" / "test_files.txt", test_lines, frame_digits=10)
        k = rig.k(2)
        info = {
            "generator": "posecons synth",
            "seed": seed,
            "profile": profile,
            "width": width,
            "height": height,
            "frames": frames,
            "fps": FPS,
            "ext": ext,
            "date": DATE,
            "drives": [drive_folder(i) for i in range(drives)],
            "train_drives": [drive_folder(i) for i in range(drives) if i not in test_ids],
            "test_drives": [drive_folder(i) for i in test_ids],
            "odometry_sequences": {drive_folder(i): f"{i:02d}" for i in range(drives)},
            "test_sequences": [f"{i:02d}" for i in test_ids],
            "splits": {"depth": "splits/synth", "odometry": "splits/synth_odom"},
            "neighbours": neighbours,
            "intrinsics_px": {"fx": k[0, 0], "fy": k[1, 1], "cx": k[0, 2], "cy": k[1, 2]},
            "stereo_baseline_m": float(np.linalg.norm(rig.m_cam_rect0(2)[:3, 3] - rig.m_cam_rect0(3)[:3, 3])),
            "lidar_azimuth_step_deg": lidar.azimuth_step_deg,
            "static_frames": static,
        }
        (tmp / "synth.json").write_text(json.dumps(info, indent=2) + "\n")
    return info


def _render_drive(job: _Job, frames: int, workers: int) -> None:
    """Render every frame, in forked worker processes where the platform allows it."""
    global _JOB
    _JOB = job
    try:
        fork_map(_render_frame, range(frames), workers)
    finally:
        _JOB = None
