"""Analytic primitives for the ray caster: ground plane, oriented boxes, vertical cylinders, spheres.

All rays of one cast share one origin ``o`` (3,); directions are ``d`` (3, ...) arrays. ``intersect``
returns the ray parameter t of the first hit in front of the origin (inf on a miss); with camera
rays scaled to unit camera z, t is the camera depth. ``surface`` gives world normals and texture
coordinates (metres on the surface) at hit points ``p`` (3, n).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

INF = np.float32(np.inf)
UNIT_CUBE = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=np.float64)


@dataclass
class Primitive:
    material: int
    tint: np.ndarray  # (3,) RGB multiplier of the material colour
    uv_offset: np.ndarray  # (2,) metres, so equal materials do not share a texture phase

    def corners(self) -> np.ndarray | None:
        """(8, 3) corners of a box that bounds the primitive (None: unbounded)."""
        raise NotImplementedError


@dataclass
class Ground(Primitive):
    """The plane z = 0, facing up."""

    max_t: float = 300.0

    def corners(self) -> None:
        return None

    def intersect(self, o: np.ndarray, d: np.ndarray) -> np.ndarray:
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.float32(-o[2]) / d[2]
        return np.where((t > 0) & (t < self.max_t), t, INF)

    def surface(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        normal = np.zeros_like(p)
        normal[2] = 1
        return normal, p[:2]


@dataclass
class Box(Primitive):
    """A box with centre ``center`` (3,), half sizes ``half`` (3,), turned by ``yaw`` about z."""

    center: np.ndarray = None
    half: np.ndarray = None
    yaw: float = 0.0

    def corners(self) -> np.ndarray:
        c, s = np.cos(self.yaw), np.sin(self.yaw)
        rot = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
        return self.center + (UNIT_CUBE * self.half) @ rot.T

    def _to_local(self, v: np.ndarray, point: bool) -> np.ndarray:
        c, s = np.float32(np.cos(self.yaw)), np.float32(np.sin(self.yaw))
        if point:
            v = v - self.center.astype(np.float32).reshape((3,) + (1,) * (v.ndim - 1))
        return np.stack([c * v[0] + s * v[1], -s * v[0] + c * v[1], v[2]])

    def intersect(self, o: np.ndarray, d: np.ndarray) -> np.ndarray:
        ol = self._to_local(o.astype(np.float32), point=True)
        dl = self._to_local(d, point=False)
        tmin = tmax = None
        with np.errstate(divide="ignore", invalid="ignore"):
            for axis in range(3):
                inv = np.float32(1.0) / dl[axis]
                t0 = (np.float32(-self.half[axis]) - ol[axis]) * inv
                t1 = (np.float32(self.half[axis]) - ol[axis]) * inv
                near, far = np.minimum(t0, t1), np.maximum(t0, t1)
                tmin = near if tmin is None else np.maximum(tmin, near)
                tmax = far if tmax is None else np.minimum(tmax, far)
        return np.where((tmax >= tmin) & (tmin > 0), tmin, INF)

    def surface(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        pl = self._to_local(p, point=True)
        half = self.half.astype(np.float32)[:, None]
        face = np.argmax(np.abs(pl) / half, axis=0)
        normal_l = np.zeros_like(pl)
        cols = np.arange(pl.shape[1])
        normal_l[face, cols] = np.sign(pl[face, cols])
        c, s = np.float32(np.cos(self.yaw)), np.float32(np.sin(self.yaw))
        normal = np.stack([c * normal_l[0] - s * normal_l[1], s * normal_l[0] + c * normal_l[1], normal_l[2]])
        height = pl[2] + half[2, 0]  # measured from the bottom, so façade patterns sit on the street
        u = np.where(face == 0, pl[1], pl[0])
        v = np.where(face == 2, pl[1], height)
        return normal, np.stack([u, v])


@dataclass
class Cylinder(Primitive):
    """A vertical cylinder (side only) with axis at ``xy`` (2,), ``radius``, from z0 to z1."""

    xy: np.ndarray = None
    radius: float = 0.1
    z0: float = 0.0
    z1: float = 1.0

    def corners(self) -> np.ndarray:
        r = self.radius
        lo, hi = np.array([*(self.xy - r), self.z0]), np.array([*(self.xy + r), self.z1])
        return (lo + hi) / 2 + UNIT_CUBE * (hi - lo) / 2

    def intersect(self, o: np.ndarray, d: np.ndarray) -> np.ndarray:
        ox, oy = np.float32(o[0] - self.xy[0]), np.float32(o[1] - self.xy[1])
        a = d[0] * d[0] + d[1] * d[1]
        b = ox * d[0] + oy * d[1]
        disc = b * b - a * np.float32(ox * ox + oy * oy - self.radius**2)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (-b - np.sqrt(disc)) / a
        z = np.float32(o[2]) + t * d[2]
        return np.where((disc >= 0) & (t > 0) & (z >= self.z0) & (z <= self.z1), t, INF)

    def surface(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        dx, dy = p[0] - np.float32(self.xy[0]), p[1] - np.float32(self.xy[1])
        normal = np.stack([dx, dy, np.zeros_like(dx)]) / np.float32(self.radius)
        return normal, np.stack([np.arctan2(dy, dx) * np.float32(self.radius), p[2]])


@dataclass
class Sphere(Primitive):
    """A sphere with ``center`` (3,) and ``radius``."""

    center: np.ndarray = None
    radius: float = 1.0

    def corners(self) -> np.ndarray:
        return self.center + UNIT_CUBE * self.radius

    def intersect(self, o: np.ndarray, d: np.ndarray) -> np.ndarray:
        oc = (o - self.center).astype(np.float32)
        a = d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
        b = oc[0] * d[0] + oc[1] * d[1] + oc[2] * d[2]
        disc = b * b - a * np.float32(oc @ oc - self.radius**2)
        with np.errstate(invalid="ignore"):
            t = (-b - np.sqrt(disc)) / a
        return np.where((disc >= 0) & (t > 0), t, INF)

    def surface(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        normal = (p - self.center.astype(np.float32)[:, None]) / np.float32(self.radius)
        return normal, np.stack([np.arctan2(normal[1], normal[0]) * np.float32(self.radius), p[2]])
