"""Coloured point clouds from a depth map and pixel intrinsics, written as PLY."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def backproject_pixels(u: np.ndarray, v: np.ndarray, z: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Pixel columns u (N,), rows v (N,) and depths z (N,) with pixel K (3, 3) → (N, 3) float64 camera
    points X = z·K⁻¹[u, v, 1]ᵀ (the numpy twin of :func:`posecons.geometry.backproject`)."""
    rays = np.linalg.inv(K) @ np.stack([u, v, np.ones_like(u)]).astype(np.float64)
    return (rays * z).T


def depth_to_points(depth: np.ndarray, image: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(H, W) depth, (H, W, 3) uint8 colours, pixel K (3, 3) → camera points (N, 3) float32 and
    colours (N, 3) uint8, one per valid pixel (finite depth > 0)."""
    h, w = depth.shape
    v, u = np.mgrid[0:h, 0:w]
    valid = np.isfinite(depth) & (depth > 0)
    points = backproject_pixels(u[valid], v[valid], depth[valid], K)
    return points.astype(np.float32), image[valid].astype(np.uint8)


def write_ply(path: str | Path, points: np.ndarray, colors: np.ndarray, binary: bool = True) -> None:
    """Write (N, 3) float32 points with (N, 3) uint8 colours as a PLY (binary little-endian or ASCII)."""
    header = (
        "ply\n"
        f"format {'binary_little_endian' if binary else 'ascii'} 1.0\n"
        f"element vertex {len(points)}\n"
        "property float x\nproperty float y\nproperty float z\n"
        "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n"
    )
    with open(path, "wb") as f:
        f.write(header.encode("ascii"))
        if binary:
            rows = np.empty(len(points), dtype=[("xyz", "<f4", 3), ("rgb", "u1", 3)])
            rows["xyz"], rows["rgb"] = points, colors
            f.write(rows.tobytes())
        else:
            for p, c in zip(points, colors):
                f.write(f"{p[0]:.6g} {p[1]:.6g} {p[2]:.6g} {c[0]} {c[1]} {c[2]}\n".encode("ascii"))


def read_ply(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Read back a PLY written by :func:`write_ply` → (points (N, 3), colours (N, 3))."""
    data = Path(path).read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode("ascii").splitlines()
    count = int(next(line.split()[2] for line in header if line.startswith("element vertex")))
    if "format ascii 1.0" in header:
        rows = np.loadtxt(data[end:].decode("ascii").splitlines(), ndmin=2).reshape(count, 6)
        return rows[:, :3].astype(np.float32), rows[:, 3:].astype(np.uint8)
    rows = np.frombuffer(data[end:], dtype=[("xyz", "<f4", 3), ("rgb", "u1", 3)], count=count)
    return rows["xyz"].copy(), rows["rgb"].copy()
