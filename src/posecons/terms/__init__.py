"""The loss terms beyond view synthesis, each a :class:`Term` in its own module, and their registry.

:class:`~posecons.model.PoseConsModel` makes one instance of each registered term that a run's config
enables, asks the ones active at a step what they need (pose-net pairs, the sources' depth, the
data's motion), calls them on the step's :class:`StepContext` and adds weight × value to the total.
A new term is one module here and one entry in :data:`TERMS` (CONTRIBUTING.md).
"""

from __future__ import annotations

from .base import StepContext, Term
from .constraints import Cycle, ForwardBackward, Identity
from .depth_consistency import DepthConsistency
from .far_rotation import FarRotation
from .saturation import Saturation
from .skip_synthesis import SkipSynthesis
from .velocity import Velocity

# The registry, in the order of the losses dict, of the pose net's extra pairs and of the sum.
TERMS: list[type[Term]] = [
    ForwardBackward,
    Identity,
    Cycle,
    DepthConsistency,
    SkipSynthesis,
    Velocity,
    FarRotation,
    Saturation,
]

__all__ = ["TERMS", "StepContext", "Term"]
