"""Scene statistics of a synthetic benchmark. ``street`` is the default (every study so far);
``open`` is a second benchmark that differs where a conclusion about scale consistency could depend
on the data: speed varies more (0.3–2.0 m a frame at 10 Hz), turns are sharper (radius down to 17 m),
the façades stand 6–30 m from the road instead of 7.5–10.5 m, so the scene's depth differs more from
drive to drive, and half the façade slots are open lots (hedge and tree with the far scene behind),
so it changes more along a drive; fewer cars are parked. ``sparse`` differs in kind, not only in the
scene's layout: another camera (0.75 × KITTI's focal length, a 98° field of view instead of 81°), surfaces
with little fine texture (the noise octaves under half a metre at 0.15 of their amplitude, so most of the
photometric gradient comes from edges), and faster driving (0.8–2.2 m a frame)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Profile:
    speed: tuple[float, float] = (0.5, 1.5)  # range of the target speeds, metres per frame
    max_curvature: float = 0.035  # 1/m: turn radius ≥ ~29 m keeps the street layout clear of the path
    setback: tuple[float, float] = (7.5, 10.5)  # road centre → façade line on each side, metres
    open_lot: float = 0.2  # chance that a façade slot is an open lot with a hedge and a tree
    parked_car: float = 0.55  # chance of a parked car in each 5.5–9 m slot along the kerb
    focal: float = 1.0  # the camera's focal length, × KITTI's (same principal point)
    detail: float = 1.0  # amplitude of the texture's octaves finer than half a metre, × the default's


PROFILES = {
    "street": Profile(),
    "open": Profile(speed=(0.3, 2.0), max_curvature=0.06, setback=(6.0, 30.0), open_lot=0.5, parked_car=0.3),
    "sparse": Profile(
        speed=(0.8, 2.2),
        max_curvature=0.045,
        setback=(5.0, 14.0),
        open_lot=0.3,
        parked_car=0.2,
        focal=0.75,
        detail=0.15,
    ),
}
