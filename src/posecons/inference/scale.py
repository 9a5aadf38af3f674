"""One metric scale per sequence: given, from ground truth (median ratio, :func:`~posecons.metrics.depth.frame_scale`),
or from the camera's height above a fitted ground plane.

Depth maps here are (H, W) float arrays at the original image size, in the model's units.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import PoseconsError
from .pointcloud import backproject_pixels

GROUND_ROWS = (0.6, 1.0)  # image rows (fractions of H) searched for the ground plane
GROUND_COLS = (0.2, 0.8)  # central columns: the road rather than parked cars and walls
MAX_TILT_DEG = 30.0  # accepted angle between the plane normal and the camera's down axis


def fit_ground_plane(points: np.ndarray, iterations: int = 200, seed: int = 0) -> tuple[np.ndarray, float, int]:
    """RANSAC then least squares: (N, 3) camera points (x right, y down, z forward) → (unit normal n,
    offset d, inliers) with n·X = d for points on the plane, n pointing down (n_y > 0), so d is the
    camera's height above it. Only near-horizontal planes below the camera are considered."""
    points = np.asarray(points, dtype=np.float64)
    if len(points) < 3:
        raise PoseconsError("too few ground points to fit a plane")
    rng = np.random.default_rng(seed)
    # Inlier band relative to the region's depth, since the points are in the model's units.
    threshold = 0.01 * np.median(points[:, 2])
    sample = points[rng.integers(0, len(points), (iterations, 3))]  # (I, 3 points, 3)
    normals = np.cross(sample[:, 1] - sample[:, 0], sample[:, 2] - sample[:, 0])
    norm = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = normals / np.where(norm > 0, norm, 1) * np.where(normals[:, 1:2] < 0, -1, 1)
    offsets = (normals * sample[:, 0]).sum(1)
    ok = (norm[:, 0] > 0) & (normals[:, 1] >= np.cos(np.radians(MAX_TILT_DEG))) & (offsets > 0)
    if not ok.any():
        raise PoseconsError("no near-horizontal plane below the camera found in the ground region")
    counts = (np.abs(points @ normals[ok].T - offsets[ok]) < threshold).sum(0)
    best = np.flatnonzero(ok)[counts.argmax()]
    inliers = points[np.abs(points @ normals[best] - offsets[best]) < threshold]
    centroid = inliers.mean(0)
    normal = np.linalg.svd(inliers - centroid, full_matrices=False)[2][-1]  # least-variance direction
    normal = normal if normal[1] > 0 else -normal
    return normal, float(normal @ centroid), len(inliers)


def ground_points(depth: np.ndarray, K: np.ndarray, max_points: int = 20000, seed: int = 0) -> np.ndarray:
    """Back-project the lower central region of an (H, W) depth map with pixel K (3, 3) → (N, 3)."""
    h, w = depth.shape
    r0, r1 = int(GROUND_ROWS[0] * h), int(GROUND_ROWS[1] * h)
    c0, c1 = int(GROUND_COLS[0] * w), int(GROUND_COLS[1] * w)
    v, u = np.mgrid[r0:r1, c0:c1]
    z = depth[r0:r1, c0:c1].astype(np.float64)
    keep = np.isfinite(z) & (z > 0)
    u, v, z = u[keep], v[keep], z[keep]
    if len(z) > max_points:
        pick = np.random.default_rng(seed).choice(len(z), max_points, replace=False)
        u, v, z = u[pick], v[pick], z[pick]
    return backproject_pixels(u, v, z, K)


def camera_height(depth: np.ndarray, K: np.ndarray) -> float:
    """Height of the camera above the ground plane fitted to an (H, W) depth map (its units)."""
    return fit_ground_plane(ground_points(depth, K))[1]


@dataclass
class ScaleResult:
    """The sequence's scale and how it was found (written to scale.json)."""

    method: str  # "none", "metric" (a known_motion model's own metres), "given", "ground_truth" or "camera_height"
    value: float
    frames: list[str] = field(default_factory=list)  # frames used for calibration
    per_frame: list[float] = field(default_factory=list)  # their individual scales

    def to_dict(self) -> dict:
        return {"method": self.method, "value": self.value, "frames_used": self.frames, "frame_scales": self.per_frame}


def combine(method: str, names: list[str], scales: list[float], what: str) -> ScaleResult:
    """Median of per-frame calibration scales; an error when no frame gave one."""
    finite = [s for s in scales if np.isfinite(s)]
    if not finite:
        raise PoseconsError(f"scale calibration: {what}")
    return ScaleResult(method, float(np.median(finite)), names, [float(s) for s in scales])
