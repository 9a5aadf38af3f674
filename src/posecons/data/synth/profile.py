"""Scene statistics of a synthetic benchmark. ``street`` is the default (every study so far);
``open`` is a second benchmark that differs where a conclusion about scale consistency could depend
on the data: speed varies more (0.3–2.0 m a frame at 10 Hz), turns are sharper (radius down to 17 m),
the façades stand 6–30 m from the road instead of 7.5–10.5 m, so the scene's depth differs more from
drive to drive, and half the façade slots are open lots (hedge and tree with the far scene behind),
so it changes more along a drive; fewer cars are parked."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Profile:
    speed: tuple[float, float] = (0.5, 1.5)  # range of the target speeds, metres per frame
    max_curvature: float = 0.035  # 1/m: turn radius ≥ ~29 m keeps the street layout clear of the path
    setback: tuple[float, float] = (7.5, 10.5)  # road centre → façade line on each side, metres
    open_lot: float = 0.2  # chance that a façade slot is an open lot with a hedge and a tree
    parked_car: float = 0.55  # chance of a parked car in each 5.5–9 m slot along the kerb


PROFILES = {
    "street": Profile(),
    "open": Profile(speed=(0.3, 2.0), max_curvature=0.06, setback=(6.0, 30.0), open_lot=0.5, parked_car=0.3),
}
