"""A driving-like scene laid out along a trajectory: road, sidewalks, façades, parked cars,
poles, trees, hedges and lane dashes, with world-anchored procedural textures."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .primitives import Box, Cylinder, Ground, Primitive, Sphere
from .profile import PROFILES, Profile

TEXEL = 0.03  # metres per texel at mip level 0
TEXTURE_SIZE = 1024  # texels (a power of two); textures tile every 30.72 m


@dataclass(frozen=True)
class Material:
    color: tuple[float, float, float]
    texture: int  # which noise texture
    contrast: float  # colour = tint · colour · (1 − contrast/2 + contrast · noise)
    uv_scale: float  # texture frequency multiplier
    reflectance: float = 0.3  # LiDAR intensity base


MATERIALS = (
    Material((0.36, 0.36, 0.37), 0, 0.7, 1.0, reflectance=0.15),  # 0 asphalt
    Material((0.66, 0.64, 0.60), 1, 0.5, 1.0, 0.3),  # 1 sidewalk (tile joints)
    Material((0.72, 0.62, 0.52), 2, 0.6, 0.5, 0.4),  # 2 façade (windows)
    Material((0.80, 0.80, 0.80), 1, 0.3, 1.0, reflectance=0.6),  # 3 car body
    Material((0.16, 0.19, 0.23), 2, 0.5, 2.0, reflectance=0.1),  # 4 glass
    Material((0.50, 0.50, 0.52), 1, 0.4, 2.0, reflectance=0.5),  # 5 pole
    Material((0.33, 0.24, 0.16), 2, 0.8, 3.0, reflectance=0.3),  # 6 trunk
    Material((0.25, 0.42, 0.17), 3, 1.0, 2.5, reflectance=0.25),  # 7 foliage
    Material((0.92, 0.92, 0.90), 1, 0.15, 1.0, reflectance=0.9),  # 8 road paint
)
ASPHALT, SIDEWALK, FACADE, CAR, GLASS, POLE, TRUNK, FOLIAGE, PAINT = range(len(MATERIALS))
FACADE_TINTS = ((1.0, 1.0, 1.0), (1.15, 0.8, 0.65), (0.9, 0.95, 1.05), (1.2, 1.1, 0.8), (0.75, 0.75, 0.78))
CAR_TINTS = (
    (0.9, 0.1, 0.1),
    (0.15, 0.25, 0.7),
    (0.95, 0.95, 0.95),
    (0.2, 0.2, 0.22),
    (0.6, 0.6, 0.62),
    (0.2, 0.5, 0.3),
)


def make_textures(rng: np.random.Generator, count: int = 4, detail: float = 1.0) -> list[np.ndarray]:
    """``count`` tileable multi-octave value-noise textures as a mip pyramid:
    a list of (count, S/2^l, S/2^l) float32 arrays in [0, 1], level 0 first. ``detail`` scales the
    octaves finer than half a metre (periods of 16 texels and under)."""
    size = TEXTURE_SIZE
    base = np.zeros((count, size, size), dtype=np.float32)
    # a fairly flat spectrum from 3.8 m down to 6 cm: gradients at every image resolution
    for period, amplitude in ((128, 1.0), (64, 0.9), (32, 0.8), (16, 0.75), (8, 0.7), (4, 0.6), (2, 0.45)):
        grid = rng.standard_normal((count, size // period, size // period)).astype(np.float32)
        base += amplitude * (detail if period <= 16 else 1.0) * _upsample_periodic(grid, period)
    base -= base.mean(axis=(1, 2), keepdims=True)
    base = np.clip(0.5 + base / (6 * base.std(axis=(1, 2), keepdims=True)), 0.0, 1.0)
    levels = [base]
    while levels[-1].shape[-1] > 1:
        x = levels[-1]
        levels.append(0.25 * (x[:, 0::2, 0::2] + x[:, 1::2, 0::2] + x[:, 0::2, 1::2] + x[:, 1::2, 1::2]))
    return levels


def _upsample_periodic(grid: np.ndarray, factor: int) -> np.ndarray:
    """Bilinear upsampling of (C, n, n) by ``factor`` with wrap-around (keeps tiling seamless)."""
    n = grid.shape[-1]
    pos = (np.arange(n * factor) + 0.5) / factor - 0.5
    i0 = np.floor(pos).astype(int)
    w = (pos - i0).astype(np.float32)
    i0, i1 = i0 % n, (i0 + 1) % n
    rows = grid[:, i0] * (1 - w)[None, :, None] + grid[:, i1] * w[None, :, None]
    return rows[:, :, i0] * (1 - w) + rows[:, :, i1] * w


class PathFrame:
    """Arc-length parameterisation of a 2-D path: position and heading at any distance s."""

    def __init__(self, xy: np.ndarray, heading: np.ndarray) -> None:
        step = np.linalg.norm(np.diff(xy, axis=0), axis=1)
        keep = np.concatenate([[True], step > 1e-6])  # stops repeat a point: drop the repeats
        self.xy, self.heading = xy[keep], np.unwrap(heading[keep])
        self.s = np.concatenate([[0.0], np.cumsum(step[step > 1e-6])])

    def at(self, s: float, lateral: float) -> tuple[np.ndarray, float]:
        """Point ``lateral`` metres to the left of the path at distance ``s``, and the heading."""
        x, y = np.interp(s, self.s, self.xy[:, 0]), np.interp(s, self.s, self.xy[:, 1])
        psi = float(np.interp(s, self.s, self.heading))
        return np.array([x - lateral * np.sin(psi), y + lateral * np.cos(psi)]), psi


def build_scene(
    rng: np.random.Generator, path_xy: np.ndarray, path_heading: np.ndarray, profile: Profile = PROFILES["street"]
) -> list[Primitive]:
    """Lay out a street of the ``profile`` along a path (N, 2) with headings (N,) (the car's track,
    extended before and after so the scene covers what the sensors see). Nothing is placed within
    1.3 m of the path. Returns the primitives, ground first."""
    path = PathFrame(path_xy, path_heading)
    length = path.s[-1]
    prims: list[Primitive] = [Ground(ASPHALT, np.ones(3), rng.uniform(0, 25, 2))]

    def box(material, s, lateral, size, z0=0.0, tint=(1, 1, 1)):
        xy, psi = path.at(s, lateral)
        half = np.asarray(size, dtype=np.float64) / 2
        prims.append(
            Box(material, np.asarray(tint, float), rng.uniform(0, 25, 2), np.array([*xy, z0 + half[2]]), half, psi)
        )

    for s in np.arange(rng.uniform(0, 9), length, 9.0):  # dashed centre line, 1.75 m left of the car
        box(PAINT, s, 1.75, (3.0, 0.15, 0.01))
    for side in (1.0, -1.0):
        setback = rng.uniform(*profile.setback)
        for s in np.arange(0.0, length, 10.0):  # sidewalk slabs between road and façades
            box(SIDEWALK, s + 5, side * (4.6 + setback) / 2, (10.05, setback - 4.6, 0.15))
        s = rng.uniform(-5, 5)
        while s < length:  # façades, with open lots holding hedges and trees
            if rng.random() < profile.open_lot:
                lot = rng.uniform(8, 15)
                box(FOLIAGE, s + lot / 2, side * (setback + 0.6), (lot, 1.2, rng.uniform(1.0, 2.0)))
                _tree(prims, rng, *path.at(s + lot / 2, side * (setback + 3.0)))
                s += lot
                continue
            length_b, depth, height = rng.uniform(10, 25), rng.uniform(6, 10), rng.uniform(6, 16)
            tint = FACADE_TINTS[rng.integers(len(FACADE_TINTS))]
            box(FACADE, s + length_b / 2, side * (setback + depth / 2), (length_b, depth, height), tint=tint)
            s += length_b + rng.choice([0.0, rng.uniform(1, 4)])
        s = rng.uniform(0, 8)
        while s < length:  # parked cars: body and cabin
            if rng.random() < profile.parked_car:
                tint = CAR_TINTS[rng.integers(len(CAR_TINTS))]
                box(CAR, s, side * 3.4, (4.2, 1.8, 0.9), z0=0.25, tint=tint)
                box(GLASS, s - 0.2, side * 3.4, (2.2, 1.6, 0.6), z0=1.15)
            s += rng.uniform(5.5, 9.0)
        for s in np.arange(rng.uniform(0, 20), length, rng.uniform(18, 30)):  # poles
            xy, _ = path.at(s, side * 4.9)
            prims.append(Cylinder(POLE, np.ones(3), rng.uniform(0, 25, 2), xy, 0.12, 0.0, rng.uniform(5.5, 8.0)))
        for s in np.arange(rng.uniform(0, 15), length, rng.uniform(12, 25)):  # street trees
            if rng.random() < 0.6:
                _tree(prims, rng, *path.at(s, side * 5.8))
    return [p for p in prims if isinstance(p, Ground) or _clearance(p, path.xy) > 1.3]


def _tree(prims: list[Primitive], rng: np.random.Generator, xy: np.ndarray, _heading: float) -> None:
    radius = rng.uniform(1.3, 2.2)
    prims.append(Cylinder(TRUNK, np.ones(3), rng.uniform(0, 25, 2), xy, 0.18, 0.0, 2.8))
    tint = np.array([rng.uniform(0.8, 1.2), rng.uniform(0.85, 1.15), 1.0])
    prims.append(Sphere(FOLIAGE, tint, rng.uniform(0, 25, 2), np.array([*xy, 2.6 + 0.8 * radius]), radius))


def _clearance(prim: Primitive, path_xy: np.ndarray) -> float:
    """Smallest horizontal distance from the path points to the primitive's footprint."""
    corners = prim.corners()[:, :2]
    if isinstance(prim, Box):  # exact for the rotated rectangle
        c, s = np.cos(prim.yaw), np.sin(prim.yaw)
        rel = path_xy - prim.center[:2]
        local = np.stack([c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1]], -1)
        return float(np.linalg.norm(np.maximum(np.abs(local) - prim.half[:2], 0), axis=1).min())
    centre, radius = corners.mean(axis=0), (corners.max(axis=0) - corners.min(axis=0)).max() / 2
    return float(np.linalg.norm(path_xy - centre, axis=1).min() - radius)
