"""Vectorised numpy ray casting of a primitive scene: camera images with exact depth, LiDAR scans.

Speed comes from culling: each bounded primitive is tested only against the rays inside the
image rectangle (camera) or azimuth interval (LiDAR) that its bounding box covers.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from .primitives import INF, Primitive
from .scene import FACADE, MATERIALS, SIDEWALK, TEXEL

SUN = (np.array([0.45, -0.35, 0.82]) / np.linalg.norm([0.45, -0.35, 0.82])).astype(np.float32)
SKY_HORIZON = np.array([0.80, 0.86, 0.93], dtype=np.float32)
SKY_ZENITH = np.array([0.40, 0.58, 0.85], dtype=np.float32)
CONTRAST = np.array([m.contrast for m in MATERIALS], dtype=np.float32)
NEAR = 0.05  # metres; the camera clipping plane used for culling
BOX_EDGES = [(a, b) for a in range(8) for b in range(a + 1, 8) if bin(a ^ b).count("1") == 1]


@dataclass
class Shading:
    textures: list[np.ndarray]  # mip pyramid from make_textures
    tints: np.ndarray  # (P, 3) per-primitive colour
    materials: np.ndarray  # (P,) material index per primitive
    uv_offsets: np.ndarray  # (P, 2)


def shading_tables(prims: list[Primitive], textures: list[np.ndarray]) -> Shading:
    """Per-primitive lookup tables for the shader."""
    tints = np.array([np.asarray(MATERIALS[p.material].color) * p.tint for p in prims], dtype=np.float32)
    return Shading(
        textures,
        tints,
        np.array([p.material for p in prims]),
        np.array([p.uv_offset for p in prims], dtype=np.float32),
    )


def cast(
    prims: list[Primitive], origin: np.ndarray, dirs: np.ndarray, rects: list[list[tuple]]
) -> tuple[np.ndarray, np.ndarray]:
    """First hits of rays (3, R, C) from ``origin``: (t (R, C) float32, inf on a miss; primitive
    index (R, C), −1 on a miss). ``rects[i]`` lists (r0, r1, c0, c1) windows primitive i may hit."""
    t_best = np.full(dirs.shape[1:], INF, dtype=np.float32)
    winner = np.full(dirs.shape[1:], -1, dtype=np.int32)
    for index, (prim, windows) in enumerate(zip(prims, rects)):
        for r0, r1, c0, c1 in windows:
            t = prim.intersect(origin, dirs[:, r0:r1, c0:c1])
            closer = t < t_best[r0:r1, c0:c1]
            np.copyto(t_best[r0:r1, c0:c1], t, where=closer)
            np.copyto(winner[r0:r1, c0:c1], index, where=closer)
    return t_best, winner


def surfaces(prims, origin, dirs, t, winner):
    """Hit points, normals and texture coordinates of every hit ray, grouped per primitive.

    Returns (flat ray indices (n,), points (3, n), normals (3, n), uv (2, n), primitive (n,)).
    """
    flat = np.flatnonzero(winner >= 0)
    prim = winner.reshape(-1)[flat]
    order = np.argsort(prim, kind="stable")  # one sort instead of a scan of each primitive's window
    flat, prim = flat[order], prim[order]
    p = origin.astype(np.float32)[:, None] + dirs.reshape(3, -1)[:, flat] * t.reshape(-1)[flat]
    normal, uv = np.empty_like(p), np.empty((2, flat.size), dtype=np.float32)
    bounds = np.append(np.flatnonzero(np.diff(prim, prepend=-1)), flat.size)
    for a, b in zip(bounds[:-1], bounds[1:]):
        normal[:, a:b], uv[:, a:b] = prims[prim[a]].surface(p[:, a:b])
    return flat, p, normal, uv, prim


def sample_texture(shading: Shading, uv: np.ndarray, prim: np.ndarray, footprint: np.ndarray) -> np.ndarray:
    """Mip-mapped bilinear texture values (n,) at surface coordinates uv (2, n) in metres;
    ``footprint`` (n,) is the surface size of one pixel, which picks the mip level."""
    material = shading.materials[prim]
    scale = np.array([m.uv_scale for m in MATERIALS], dtype=np.float32)[material]
    tex_id = np.array([m.texture for m in MATERIALS])[material]
    coords = (uv + shading.uv_offsets[prim].T) * scale / TEXEL
    level = np.clip(np.round(np.log2(np.maximum(footprint * scale / TEXEL, 1e-6))), 0, len(shading.textures) - 1)
    level = level.astype(np.int64)
    out = np.empty(uv.shape[1], dtype=np.float32)
    for lv in np.nonzero(np.bincount(level))[0]:
        sel = np.nonzero(level == lv)[0]
        tex = shading.textures[lv]
        size = tex.shape[-1]
        flat_tex = tex.reshape(-1)
        x, y = coords[0, sel] * np.float32(0.5**lv) - 0.5, coords[1, sel] * np.float32(0.5**lv) - 0.5
        x0, y0 = np.floor(x), np.floor(y)
        wx, wy = x - x0, y - y0
        mask = size - 1  # sizes are powers of two: wrap-around by bit masking
        x0, y0 = x0.astype(np.int64) & mask, y0.astype(np.int64) & mask
        x1, y1 = (x0 + 1) & mask, (y0 + 1) & mask
        base = tex_id[sel] * size * size
        row0, row1 = base + y0 * size, base + y1 * size
        top = flat_tex[row0 + x0] * (1 - wx) + flat_tex[row0 + x1] * wx
        bottom = flat_tex[row1 + x0] * (1 - wx) + flat_tex[row1 + x1] * wx
        out[sel] = top * (1 - wy) + bottom * wy
    return out


def _pattern(material: np.ndarray, uv: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Multiplicative detail: façade windows (walls only) and sidewalk tile joints. (n,)"""
    out = np.ones(uv.shape[1], dtype=np.float32)
    walls = np.nonzero((material == FACADE) & (np.abs(normal[2]) < 0.5) & (uv[1] > 1.5))[0]
    fu, fv = np.mod(uv[0, walls] / 3.2, 1.0), np.mod((uv[1, walls] - 0.9) / 3.0, 1.0)
    out[walls[(fu > 0.25) & (fu < 0.75) & (fv > 0.3) & (fv < 0.8)]] = 0.3
    tiles = np.nonzero(material == SIDEWALK)[0]
    out[tiles[(np.mod(uv[0, tiles], 0.6) < 0.04) | (np.mod(uv[1, tiles], 0.6) < 0.04)]] = 0.7
    return out


def shade(shading: Shading, dirs: np.ndarray, t: np.ndarray, hits, focal: float) -> np.ndarray:
    """RGB (R, C, 3) float32 in [0, 1]: textured Lambertian surfaces under a fixed sun, sky elsewhere.

    Colours depend only on the surface point (and the fixed sun), so every view of a point agrees.
    """
    flat, _, normal, uv, prim = hits
    d = dirs.reshape(3, -1)
    rgb = np.empty((d.shape[1], 3), dtype=np.float32)
    sky = np.isinf(t.reshape(-1))
    d_sky = d[:, sky]
    elevation = np.clip(d_sky[2] / np.linalg.norm(d_sky, axis=0), 0.0, 1.0)[:, None]
    rgb[sky] = SKY_HORIZON * (1 - elevation) ** 2 + SKY_ZENITH * (1 - (1 - elevation) ** 2)
    if flat.size:
        dir_hit = d[:, flat]
        norm = np.linalg.norm(dir_hit, axis=0)
        cos_view = np.maximum(np.abs(np.einsum("in,in->n", normal, dir_hit)) / norm, 0.2)
        footprint = t.reshape(-1)[flat] * norm / np.float32(focal) / cos_view
        noise = sample_texture(shading, uv, prim, footprint)
        material = shading.materials[prim]
        contrast = CONTRAST[material]
        light = 0.55 + 0.45 * np.maximum(np.einsum("i,in->n", SUN, normal), 0.0)
        gain = (1 - contrast / 2 + contrast * noise) * light * _pattern(material, uv, normal)
        rgb[flat] = shading.tints[prim] * gain[:, None]
    return np.clip(rgb, 0.0, 1.0).reshape(*dirs.shape[1:], 3)


def camera_rects(
    prims: list[Primitive], m_cam_world: np.ndarray, k: np.ndarray, width: int, height: int, far: float = 250.0
):
    """Image windows each primitive may cover, from its bounding box clipped to z ≥ NEAR."""
    rects = []
    for prim in prims:
        corners = prim.corners()
        if corners is None:
            rects.append([(0, height, 0, width)])
            continue
        cam = corners @ m_cam_world[:3, :3].T + m_cam_world[:3, 3]
        z = cam[:, 2]
        if z.max() < NEAR or z.min() > far:
            rects.append([])
            continue
        pts = [cam[z >= NEAR]]
        for a, b in BOX_EDGES:  # where the box crosses the near plane
            if (z[a] - NEAR) * (z[b] - NEAR) < 0:
                w = (NEAR - z[a]) / (z[b] - z[a])
                pts.append((cam[a] + w * (cam[b] - cam[a]))[None])
        pts = np.concatenate(pts)
        uv = pts[:, :2] / pts[:, 2:] * np.diag(k)[:2] + k[:2, 2]
        c0, r0 = np.floor(uv.min(axis=0)).astype(int) - 1
        c1, r1 = np.ceil(uv.max(axis=0)).astype(int) + 2
        c0, c1, r0, r1 = max(c0, 0), min(c1, width), max(r0, 0), min(r1, height)
        rects.append([(r0, r1, c0, c1)] if c0 < c1 and r0 < r1 else [])
    return rects


@functools.lru_cache(maxsize=8)
def _pixel_rays(k_key: tuple[float, ...], width: int, height: int) -> np.ndarray:
    k = np.reshape(k_key, (3, 3))
    u, v = np.meshgrid(np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64))
    rays = np.stack([(u - k[0, 2]) / k[0, 0], (v - k[1, 2]) / k[1, 1], np.ones_like(u)]).astype(np.float32)
    rays.flags.writeable = False
    return rays


def camera_rays(k: np.ndarray, width: int, height: int, uv: np.ndarray | None = None) -> np.ndarray:
    """Camera-frame rays with unit z through pixel centres (u = column, v = row): (3, H, W)
    float32; or through given points uv (N, 2): (3, 1, N) float64."""
    if uv is None:
        return _pixel_rays(tuple(np.asarray(k, dtype=np.float64).ravel()), width, height)
    u, v = uv[None, :, 0].astype(np.float64), uv[None, :, 1].astype(np.float64)
    return np.stack([(u - k[0, 2]) / k[0, 0], (v - k[1, 2]) / k[1, 1], np.ones_like(u)])


def _rotate(rotation: np.ndarray, rays: np.ndarray) -> np.ndarray:
    """Rotate ray directions (3, ...) by a (3, 3) matrix, in float32.

    einsum rather than ``@``: OpenBLAS would spin a second thread per render worker for no gain
    (twice the CPU time at the same wall time).
    """
    return np.einsum("ij,jn->in", rotation.astype(np.float32), rays.reshape(3, -1).astype(np.float32)).reshape(
        rays.shape
    )


def render_camera(
    prims, shading: Shading, t_world_cam: np.ndarray, k: np.ndarray, width: int, height: int
) -> tuple[np.ndarray, np.ndarray]:
    """Render one pinhole view: (RGB uint8 (H, W, 3), camera depth z float32 (H, W), 0 on sky).

    t_world_cam: (4, 4) camera → world pose (camera x right, y down, z forward); k: (3, 3) pixels.
    """
    dirs = _rotate(t_world_cam[:3, :3], camera_rays(k, width, height))
    origin = t_world_cam[:3, 3]
    rects = camera_rects(prims, np.linalg.inv(t_world_cam), k, width, height)
    t, winner = cast(prims, origin, dirs, rects)
    rgb = shade(shading, dirs, t, surfaces(prims, origin, dirs, t, winner), float(k[0, 0]))
    depth = np.where(np.isfinite(t), t, 0.0).astype(np.float32)
    return (rgb * 255.0 + 0.5).astype(np.uint8), depth


def camera_depth_at(prims, t_world_cam: np.ndarray, k: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Exact camera depth z (N,) along the rays through sub-pixel points uv (N, 2); 0 on a miss."""
    dirs = _rotate(t_world_cam[:3, :3], camera_rays(k, 0, 0, uv))
    t, _ = cast(prims, t_world_cam[:3, 3], dirs, [[(0, 1, 0, len(uv))]] * len(prims))
    return np.where(np.isfinite(t), t, 0.0)[0]


@dataclass(frozen=True)
class Lidar:
    """A 64-beam spinning LiDAR (HDL-64E-like: elevations +2° … −24.8°), one instantaneous sweep."""

    azimuth_step_deg: float = 0.2
    max_range: float = 120.0
    beams: int = 64

    def rays(self) -> np.ndarray:
        """Unit directions in the sensor frame (x forward, y left, z up): (3, beams, n_azimuth)."""
        elevation = np.deg2rad(np.linspace(2.0, -24.8, self.beams))[:, None]
        n_az = int(round(360.0 / self.azimuth_step_deg))
        azimuth = -np.pi + (np.arange(n_az) + 0.5) * (2 * np.pi / n_az)
        return np.stack(
            np.broadcast_arrays(
                np.cos(elevation) * np.cos(azimuth),
                np.cos(elevation) * np.sin(azimuth),
                np.sin(elevation) + 0 * azimuth,
            )
        )

    def windows(self, prims: list[Primitive], m_velo_world: np.ndarray, n_az: int) -> list[list[tuple]]:
        """Azimuth column windows each primitive may cover (all beams; two windows across ±180°)."""
        out = []
        step = 2 * np.pi / n_az
        sensor_xy = np.linalg.inv(m_velo_world)[:2, 3]
        for prim in prims:
            corners = prim.corners()
            if corners is None:
                out.append([(0, self.beams, 0, n_az)])
                continue
            local = corners @ m_velo_world[:3, :3].T + m_velo_world[:3, 3]
            lo, hi = local.min(axis=0), local.max(axis=0)
            if np.linalg.norm(local, axis=1).min() > self.max_range + np.linalg.norm(hi - lo):
                out.append([])
                continue
            if _inside_footprint(corners, sensor_xy):
                out.append([(0, self.beams, 0, n_az)])
                continue
            angles = np.arctan2(local[:, 1], local[:, 0])
            mid = np.arctan2(local[:, 1].mean(), local[:, 0].mean())
            rel = np.angle(np.exp(1j * (angles - mid)))  # wrapped to (−π, π] around the centre
            c0 = int(np.floor((mid + rel.min() + np.pi) / step)) - 1
            c1 = int(np.ceil((mid + rel.max() + np.pi) / step)) + 1
            if c1 - c0 >= n_az:
                spans = [(0, n_az)]
            elif c0 < 0:
                spans = [(c0 + n_az, n_az), (0, c1)]
            elif c1 > n_az:
                spans = [(c0, n_az), (0, c1 - n_az)]
            else:
                spans = [(c0, c1)]
            out.append([(0, self.beams, a, b) for a, b in spans if a < b])
        return out

    def scan(self, prims, shading: Shading, t_world_velo: np.ndarray) -> np.ndarray:
        """Points (N, 4) float32 in the sensor frame: x, y, z, reflectance; misses (sky) and
        returns beyond ``max_range`` are dropped."""
        local = self.rays().astype(np.float32)
        dirs = _rotate(t_world_velo[:3, :3], local)
        origin = t_world_velo[:3, 3]
        rects = self.windows(prims, np.linalg.inv(t_world_velo), local.shape[2])
        t, winner = cast(prims, origin, dirs, rects)
        flat, _, _, uv, prim = surfaces(prims, origin, dirs, t, winner)
        order = np.argsort(flat)  # keep the sensor's beam-major firing order
        flat, uv, prim = flat[order], uv[:, order], prim[order]
        rng_t = t.reshape(-1)[flat]
        keep = rng_t <= self.max_range
        noise = sample_texture(shading, uv[:, keep], prim[keep], np.full(keep.sum(), 0.4, np.float32))
        base = np.array([m.reflectance for m in MATERIALS], dtype=np.float32)[shading.materials[prim[keep]]]
        xyz = local.reshape(3, -1)[:, flat[keep]] * rng_t[keep]
        return np.concatenate([xyz.T, np.clip(base * (0.6 + 0.8 * noise), 0, 1)[:, None]], axis=1).astype(np.float32)


def _inside_footprint(corners: np.ndarray, sensor_xy: np.ndarray) -> bool:
    """Whether the sensor stands over a bounding box (8, 3) (then every azimuth may hit it)."""
    lo, hi = corners[:, :2].min(axis=0) - 0.5, corners[:, :2].max(axis=0) + 0.5
    return bool(np.all(sensor_xy >= lo) and np.all(sensor_xy <= hi))
