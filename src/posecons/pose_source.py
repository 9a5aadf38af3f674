"""Where a training step's poses come from: the pose net's outputs by input pair (:class:`PairPoses`)
and the pose source that turns them, or the data's true motion, into the warping poses T_{f←0}.

The source is chosen once from the config (:func:`pose_source`): the pose net (Monodepth2),
``model.known_rotation`` (the data's rotation, the pose net's translation) or ``model.known_motion``
(the data's motion; the pose net does not run).
"""

from __future__ import annotations

import torch
import torch.nn as nn

from .config import ModelConfig
from .geometry import make_pose, pose_vec_to_mat


class PairPoses:
    """The pose net's outputs of one step, by input pair: the frame pair (a, b) gave T_{b←a};
    ``sizes``: how many samples each pair had (its group in the batched pass).

    ``vector(a, b)``: the raw 6-vector, axis-angle and translation, each (B, 1, 3).
    ``T(dst, src, input)``: T_{dst←src} (B, 4, 4) from the output for the input pair ``input`` —
    that output when ``input == (src, dst)``, its inverse [Rᵀ | −Rᵀt] when ``input == (dst, src)``.
    """

    def __init__(
        self, pairs: list[tuple[int, int]], sizes: list[int], axisangle: torch.Tensor, translation: torch.Tensor
    ):
        chunks = zip(axisangle.float().split(sizes), translation.float().split(sizes))
        self.vectors = dict(zip(pairs, chunks))

    def vector(self, a: int, b: int) -> tuple[torch.Tensor, torch.Tensor]:
        return self.vectors[(a, b)]

    def T(self, dst: int, src: int, input: tuple[int, int]) -> torch.Tensor:
        if tuple(input) not in ((src, dst), (dst, src)):
            raise ValueError(f"the input pair {input} does not relate frames {src} and {dst}")
        return pose_vec_to_mat(*self.vectors[tuple(input)], invert=tuple(input) == (dst, src))


def temporal(f: int) -> tuple[int, int]:
    """The pose-net input pair for source f in temporal order (SPEC §1): (f, 0) if f < 0, else (0, f)."""
    return (min(f, 0), max(f, 0))


def cycle_ids(frame_ids: list[int]) -> tuple[int, int]:
    """(−n, +n): the nearest source on each side of the target (n = 1 for frames 0, −1, +1)."""
    sources = frame_ids[1:]
    return max(f for f in sources if f < 0), min(f for f in sources if f > 0)


class NetworkPoses:
    """The pose net's T_{f←0} from its temporal pair: every pair of the step in one batched pass,
    BatchNorm statistics per pair group, only the temporal pairs (first) tracked."""

    option = None  # the config key that chose this source
    needs_motions = False

    def __init__(self, frame_ids: list[int]):
        self.frame_ids = frame_ids

    def __call__(
        self, pose_net: nn.Module, net_frames: torch.Tensor, pairs: list[tuple[int, int]], motions: torch.Tensor | None
    ) -> tuple[PairPoses, dict[int, torch.Tensor]]:
        """net_frames (B, F, 3, H, W), ``pairs`` temporal first, motions (B, S, 4, 4) or None → (the
        outputs by pair, T_{f←0} (B, 4, 4) by source, in fp32 whatever the autocast)."""
        index = {f: i for i, f in enumerate(self.frame_ids)}
        a = torch.cat([net_frames[:, index[i]] for i, _ in pairs])
        b = torch.cat([net_frames[:, index[j]] for _, j in pairs])
        sizes = [net_frames.shape[0]] * len(pairs)
        P = PairPoses(pairs, sizes, *pose_net(a, b, groups=sizes, tracked=len(self.frame_ids) - 1))
        with torch.autocast(net_frames.device.type, enabled=False):
            return P, self.warping_poses(P, motions)

    def warping_poses(self, P: PairPoses, motions: torch.Tensor | None) -> dict[int, torch.Tensor]:
        return {f: P.T(f, 0, input=temporal(f)) for f in self.frame_ids[1:]}


class KnownRotation(NetworkPoses):
    """The pose net's translation with the data's rotation (what a rig's gyro measures)."""

    option = "model.known_rotation"
    needs_motions = True

    def warping_poses(self, P: PairPoses, motions: torch.Tensor) -> dict[int, torch.Tensor]:
        poses = super().warping_poses(P, motions)
        return {f: make_pose(motions[:, i, :3, :3], poses[f][:, :3, 3]) for i, f in enumerate(self.frame_ids[1:])}


class KnownMotion:
    """The data's true T_{f←0}; the pose net does not run (no pose term may be on: Config.validate)."""

    option = "model.known_motion"
    needs_motions = True

    def __init__(self, frame_ids: list[int]):
        self.frame_ids = frame_ids

    def __call__(
        self, pose_net: nn.Module, net_frames: torch.Tensor, pairs: list[tuple[int, int]], motions: torch.Tensor
    ) -> tuple[None, dict[int, torch.Tensor]]:
        return None, {f: motions[:, i] for i, f in enumerate(self.frame_ids[1:])}


def pose_source(m: ModelConfig) -> NetworkPoses | KnownMotion:
    """The pose source that ``model.known_motion`` and ``model.known_rotation`` choose."""
    if m.known_motion:
        return KnownMotion(m.frame_ids)
    return (KnownRotation if m.known_rotation else NetworkPoses)(m.frame_ids)
