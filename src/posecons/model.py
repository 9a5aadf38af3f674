"""The model: depth + pose networks, view synthesis and every loss, behind one call.

Training, validation, evaluation and tests all go through :meth:`PoseConsModel.forward`,
which takes a batch dict and returns predictions and a dict of named losses.

Batch keys (see ``posecons.data``):
    frames      (B, F, 3, H, W) un-augmented RGB in [0, 1], in the order of ``model.frame_ids``
    intrinsics  (B, 3, 3) normalised K (row 0 / W, row 1 / H)
    net_frames  (B, F, 3, H, W) optional: what the networks see, e.g. colour-jittered by
                :func:`posecons.data.augment.jitter_batch`; the losses always use ``frames`` (SPEC §6)
    motions     (B, F − 1, 4, 4) the camera's true motion T_{f←0} to each source, in metres: needed by
                model.known_motion (which warps with it), model.known_rotation (its rotations) and
                loss.velocity_weight (its lengths)
"""

from __future__ import annotations

import logging
import math
from typing import Callable

import torch
import torch.nn as nn
import torch.nn.functional as F

from .config import Config
from .geometry import check_tensor, disp_to_depth, invert_pose, make_pose, pose_vec_to_mat, scale_intrinsics, warp
from .losses import (
    cycle_loss,
    depth_consistency_loss,
    depth_difference,
    far_rotation_loss,
    forward_backward_loss,
    identity_loss,
    min_reprojection,
    photometric_error,
    saturation_loss,
    smoothness_loss,
    velocity_loss,
)
from .networks import DepthNet, PoseNet, imagenet_weights_name, load_imagenet_state


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


class _CompiledOrEager:
    """``torch.compile(fn)``, and ``fn`` itself from the first call on that fails to compile."""

    def __init__(self, fn: Callable):
        self.eager, self.fn = fn, torch.compile(fn, dynamic=False)

    def __call__(self, *args):
        try:
            return self.fn(*args)
        except torch._dynamo.exc.BackendCompilerFailed as exc:  # e.g. no C++ compiler
            logging.getLogger(__name__).warning(
                "train.compile_losses: torch.compile failed (%s); the losses run eagerly", str(exc).splitlines()[0]
            )
            self.fn = self.eager
            return self.fn(*args)


class PoseConsModel(nn.Module):
    def __init__(self, config: Config):
        super().__init__()
        self.config = config
        m = config.model
        imagenet = load_imagenet_state(m.num_layers, m.pretrained)  # fetched once for both encoders
        self.depth_net = DepthNet(m.num_layers, imagenet, tuple(m.scales))
        self.pose_net = PoseNet(m.num_layers, imagenet, mirror=m.pose_mirror, rotation_scale=m.pose_rotation_scale)
        self.photometric_error = (
            _CompiledOrEager(photometric_error) if config.train.compile_losses else photometric_error
        )
        # How the encoders were initialised, for the run's config, checkpoints and reports.
        self.initialisation = (
            f"ImageNet ({imagenet_weights_name(m.num_layers)})"
            if imagenet is not None
            else "random (trained from scratch)"
        )

    # ------------------------------------------------------------------ inference API
    def predict_depth(self, images: torch.Tensor, scale: int = 0) -> tuple[torch.Tensor, torch.Tensor]:
        """images (B, 3, H, W) in [0, 1] → (scaled disparity, depth), each (B, 1, H/2^s, W/2^s)."""
        m = self.config.model
        return disp_to_depth(self.depth_net(images)[scale], m.min_depth, m.max_depth)

    def predict_pose(self, image_a: torch.Tensor, image_b: torch.Tensor) -> torch.Tensor:
        """Ordered pair (B, 3, H, W) ×2 → T_{b←a} (B, 4, 4)."""
        return pose_vec_to_mat(*self.pose_net(image_a, image_b))

    # ------------------------------------------------------------------ training
    def active_constraints(self, step: int) -> list[str]:
        lo = self.config.loss
        if step < lo.constraint_start_step:
            return []
        active = [c for c in lo.constraints if c != "id"]
        # The identity constraint sees a random fraction of batches (SPEC §5).
        if "id" in lo.constraints and (lo.identity_fraction >= 1 or torch.rand(()) < lo.identity_fraction):
            active.append("id")
        return active

    def pose_pairs(self, constraints: list[str]) -> list[tuple[int, int]]:
        """The frame pairs (a, b) the pose net sees this step, temporal pairs first (they alone
        update BatchNorm's running statistics): fb adds each reversed pair, id (0, 0), cyc and the
        skip pair's view synthesis (−n, +n)."""
        sources = self.config.model.frame_ids[1:]
        pairs = [temporal(f) for f in sources]
        if "fb" in constraints:
            pairs += [temporal(f)[::-1] for f in sources]
        if "id" in constraints:
            pairs.append((0, 0))
        if "cyc" in constraints or self.config.loss.skip_weight > 0:
            pairs.append(self.cycle_ids())
        return pairs

    def cycle_ids(self) -> tuple[int, int]:
        """(−n, +n): the nearest source on each side of the target (n = 1 for frames 0, −1, +1)."""
        sources = self.config.model.frame_ids[1:]
        return max(f for f in sources if f < 0), min(f for f in sources if f > 0)

    def forward(
        self, batch: dict, step: int = 0, with_constraints: bool = True
    ) -> tuple[dict, dict[str, torch.Tensor]]:
        """Outputs and losses of a training step; ``with_constraints=False`` (validation) computes
        no constraint loss and draws nothing from the RNG for them."""
        m, lo = self.config.model, self.config.loss
        shape = (None, len(m.frame_ids), 3, m.height, m.width)
        frames = check_tensor("batch['frames']", batch["frames"], shape)
        net_frames = check_tensor("batch['net_frames']", batch.get("net_frames", frames), tuple(frames.shape))
        K = check_tensor("batch['intrinsics']", batch["intrinsics"], (frames.shape[0], 3, 3)).float()
        index = {f: i for i, f in enumerate(m.frame_ids)}

        if (
            lo.depth_consistency_weight > 0 or lo.skip_weight > 0
        ):  # target and sources in one pass: their depth is needed too
            b = frames.shape[0]
            all_logits = self.depth_net(torch.cat([net_frames[:, i] for i in range(len(m.frame_ids))]), logits=True)
            logits = {s: x[:b] for s, x in all_logits.items()}
            source_disp = torch.sigmoid(all_logits[0][b:])  # (S·B, 1, H, W), the sources in frame_ids order
        else:
            logits = self.depth_net(net_frames[:, 0], logits=True)
        disps = {s: torch.sigmoid(x) for s, x in logits.items()}

        sources = m.frame_ids[1:]
        motions = None
        if m.known_motion or m.known_rotation or lo.velocity_weight > 0:
            if "motions" not in batch:
                raise ValueError(
                    "model.known_motion, known_rotation and loss.velocity_weight need batch['motions'] (T_{f←0})"
                )
            motions = check_tensor("batch['motions']", batch["motions"], (frames.shape[0], len(sources), 4, 4))
            motions = motions.float()
        # Every pose-net input of this step in one batched pass, BatchNorm statistics per pair group.
        constraints = self.active_constraints(step) if with_constraints else []
        if not m.known_motion:
            pairs = self.pose_pairs(constraints)
            a = torch.cat([net_frames[:, index[i]] for i, _ in pairs])
            b = torch.cat([net_frames[:, index[j]] for _, j in pairs])
            sizes = [frames.shape[0]] * len(pairs)
            P = PairPoses(pairs, sizes, *self.pose_net(a, b, groups=sizes, tracked=len(m.frame_ids) - 1))

        with torch.autocast(frames.device.type, enabled=False):
            if m.known_motion:
                poses = {f: motions[:, i] for i, f in enumerate(sources)}
            else:
                poses = {f: P.T(f, 0, input=temporal(f)) for f in sources}  # T_{f←0}, for warping
            if m.known_rotation:  # the data's rotation, the pose net's translation
                poses = {f: make_pose(motions[:, i, :3, :3], poses[f][:, :3, 3]) for i, f in enumerate(sources)}
            dc, masks = None, None
            if lo.depth_consistency_weight > 0:
                dc, masks = self._depth_consistency(disps[0], source_disp, K, poses)
            losses, automask, warp_gain = self._view_synthesis_losses(frames.float(), K, disps, poses, masks)
            # The paper's constraints (SPEC §5), each in the reading order of its equation.
            if "fb" in constraints:  # d(T_{f←0}, inverse(T_{0←f} from the reversed pair)) for each source
                losses["fb"] = forward_backward_loss(
                    torch.cat([P.T(f, 0, input=temporal(f)) for f in sources]),
                    torch.cat([P.T(0, f, input=temporal(f)[::-1]) for f in sources]),
                )
            if "id" in constraints:  # ‖e‖₁ + ‖t‖₁ of pose(I_0, I_0)
                losses["id"] = identity_loss(*P.vector(0, 0))
            if "cyc" in constraints:  # d(T_{+n←−n}, T_{+n←0} · T_{0←−n})
                prev, nxt = self.cycle_ids()
                losses["cyc"] = cycle_loss(
                    P.T(nxt, prev, input=(prev, nxt)),
                    P.T(nxt, 0, input=temporal(nxt)),
                    P.T(0, prev, input=temporal(prev)),
                )
            terms = list(constraints)
            if dc is not None:
                losses["dc"] = dc
                terms.append("dc")
            if lo.skip_weight > 0:  # frame +n seen from frame −n through T_{+n←−n}
                prev, nxt = self.cycle_ids()
                losses["skip"] = self._skip_synthesis(frames.float(), K, source_disp, P.T(nxt, prev, input=(prev, nxt)))
                terms.append("skip")
            if lo.velocity_weight > 0:  # each source pair's translation against the measured distance
                d = motions[..., :3, 3].norm(dim=-1)  # (B, S) metres to each source
                losses["velocity"] = velocity_loss(
                    torch.cat([P.vector(*temporal(f))[1] for f in sources]), d.t().reshape(-1)
                )
                terms.append("velocity")
            if lo.far_rotation_weight > 0 and step >= lo.far_rotation_start_step:
                losses["far_rotation"] = self._far_rotation(frames.float(), K, disps, poses)
                terms.append("far_rotation")
            if lo.saturation_weight > 0:
                losses["saturation"] = saturation_loss(list(logits.values()), lo.saturation_bound)
                terms.append("saturation")
            weights = {"fb": lo.fb_weight, "id": lo.id_weight, "cyc": lo.cyc_weight}
            weights.update(dc=lo.depth_consistency_weight, skip=lo.skip_weight, velocity=lo.velocity_weight)
            weights.update(far_rotation=lo.far_rotation_weight, saturation=lo.saturation_weight)
            losses["total"] = losses["total"] + sum(weights[c] * losses[c] for c in terms)

        outputs = {
            "disp": disps,
            "poses": poses,
            "depth": disp_to_depth(disps[0], m.min_depth, m.max_depth)[1],
            "automask": automask,
            "warp_gain": warp_gain,
        }
        return outputs, losses

    def _depth_consistency(
        self, disp: torch.Tensor, source_disp: torch.Tensor, K_norm: torch.Tensor, poses: dict[int, torch.Tensor]
    ) -> tuple[torch.Tensor, torch.Tensor | None]:
        """SC-SfMLearner's depth consistency of the target disparity (B, 1, H, W) with the sources'
        (S·B, 1, H, W), warped by T_{f←0}; → (loss, None) in the one_way form. In the sc_depth form
        (SC-Depth as published) the loss is the mean of that direction and the reverse one (each
        source's depth moved into the target by T_{0←f}), and the second value is the self-discovered
        mask 1 − D_diff of each source (B, S, H, W), detached, for the photometric error. Scale 0
        only: the full-resolution depth is the one evaluated, and the coarser scales, upsampled to
        that size, would repeat the same constraint at less detail for one more projection each."""
        m = self.config.model
        sources = m.frame_ids[1:]
        depth, source_depth = (disp_to_depth(d.float(), m.min_depth, m.max_depth)[1] for d in (disp, source_disp))
        depth = depth.repeat(len(sources), 1, 1, 1)
        T = torch.cat([poses[f] for f in sources])
        K = scale_intrinsics(K_norm, m.height, m.width).repeat(len(sources), 1, 1)
        diff, inside = depth_difference(depth, source_depth, T, K)
        loss = diff.sum() / inside.sum().clamp(min=1)
        if self.config.loss.depth_consistency_form == "one_way":
            return loss, None
        reverse = depth_consistency_loss(source_depth, depth, invert_pose(T), K)
        mask = (1 - diff.detach()).view(len(sources), -1, *diff.shape[-2:]).transpose(0, 1)
        return (loss + reverse) / 2, mask

    def _skip_synthesis(
        self, frames: torch.Tensor, K_norm: torch.Tensor, source_disp: torch.Tensor, T_skip: torch.Tensor
    ) -> torch.Tensor:
        """Mean auto-masked photometric error of frame +n warped into frame −n with −n's own depth
        (from the sources' disparities (S·B, 1, H, W), frame_ids order) and T_skip = T_{+n←−n}: the
        skip pair's pose learns the motion over 2n frames from the images, as each step's does. Scale
        0 only, as the depth consistency."""
        m, lo = self.config.model, self.config.loss
        prev, nxt = self.cycle_ids()
        b, index = frames.shape[0], m.frame_ids[1:].index(prev)
        depth = disp_to_depth(source_disp[index * b : (index + 1) * b].float(), m.min_depth, m.max_depth)[1]
        target, source = frames[:, m.frame_ids.index(prev)], frames[:, m.frame_ids.index(nxt)]
        K = scale_intrinsics(K_norm, m.height, m.width)
        reprojection = self.photometric_error(warp(source, depth, T_skip, K), target, lo.ssim_weight)
        identity = self.photometric_error(source, target, lo.ssim_weight) if lo.automask else None
        return min_reprojection(reprojection, identity)[0].mean()

    def _far_rotation(
        self, frames: torch.Tensor, K_norm: torch.Tensor, disps: dict, poses: dict[int, torch.Tensor]
    ) -> torch.Tensor:
        """losses.far_rotation_loss of the sources warped by the rotation of T_{f←0}, averaged over the
        scales, each at its native size: a turn of 0.1–0.25 rad between frames ±3 moves the far pixels
        by 10–30 px at 192×64, which the coarsest scale sees as 1–4 px."""
        m, lo = self.config.model, self.config.loss
        rotations = torch.stack([poses[f][:, :3, :3] for f in m.frame_ids[1:]], 1)
        terms = []
        for s in m.scales:
            hs, ws = disps[s].shape[-2:]
            images = _resize(frames.flatten(0, 1), hs, ws).view(*frames.shape[:3], hs, ws)
            depth = disp_to_depth(disps[s].float(), m.min_depth, m.max_depth)[1]
            K = scale_intrinsics(K_norm, hs, ws)
            terms.append(
                far_rotation_loss(
                    images[:, 0], images[:, 1:], rotations, K, depth, lo.far_rotation_fraction, lo.ssim_weight
                )
            )
        return torch.stack(terms).mean()

    def _view_synthesis_losses(
        self,
        frames: torch.Tensor,
        K_norm: torch.Tensor,
        disps: dict,
        poses: dict[int, torch.Tensor],
        masks: torch.Tensor | None = None,
    ) -> tuple[dict[str, torch.Tensor], torch.Tensor, torch.Tensor]:
        """Min-reprojection with auto-masking plus smoothness, averaged over scales (SPEC §3–4);
        also the full-scale auto-mask (B, H, W), True where a warped source won, and the warp's gain
        at that scale: 1 − (mean best warped error) / (mean best unwarped error), > 0 where depth and
        pose explain the target better than no motion (NaN without the auto-mask, which alone
        computes the unwarped error). ``masks`` (B, S, H, W): weights of each source's reprojection
        error before the minimum (SC-Depth's self-discovered mask, resized to each scale)."""
        m, lo = self.config.model, self.config.loss
        h, w = m.height, m.width
        target, sources = frames[:, 0], [frames[:, i] for i in range(1, frames.shape[1])]
        identity = None
        photo, smooth, automask = [], [], None
        for s in m.scales:
            disp = disps[s].float()
            hs, ws = disp.shape[-2:]
            if lo.v1_multiscale:  # warp at the scale's native size
                size, tgt, srcs = (hs, ws), _resize(target, hs, ws), [_resize(x, hs, ws) for x in sources]
            else:  # upsample the disparity and compute the loss at full resolution
                size, tgt, srcs = (h, w), target, sources
                disp = F.interpolate(disp, size=size, mode="bilinear", align_corners=False)
            depth = disp_to_depth(disp, m.min_depth, m.max_depth)[1]
            K = scale_intrinsics(K_norm, *size)
            reproj = torch.cat(
                [
                    self.photometric_error(warp(src, depth, poses[f], K), tgt, lo.ssim_weight)
                    for f, src in zip(m.frame_ids[1:], srcs)
                ],
                1,
            )
            if masks is not None:
                reproj = reproj * (masks if masks.shape[-2:] == size else F.interpolate(masks, size=size, mode="area"))
            if lo.automask and (identity is None or lo.v1_multiscale):
                identity = torch.cat([self.photometric_error(src, tgt, lo.ssim_weight) for src in srcs], 1)
            per_pixel, keep = min_reprojection(reproj, identity if lo.automask else None)
            if automask is None:
                automask, warp_gain = keep, torch.tensor(math.nan)
                if lo.automask:
                    warp_gain = 1 - reproj.detach().min(1).values.mean() / identity.min(1).values.mean()
            photo.append(per_pixel.mean())
            smooth.append(lo.smoothness_weight / 2**s * smoothness_loss(disps[s].float(), _resize(target, hs, ws)))
        photometric = torch.stack(photo).mean()
        smoothness = torch.stack(smooth).mean()
        losses = {"photometric": photometric, "smoothness": smoothness, "total": photometric + smoothness}
        return losses, automask, warp_gain


def _resize(image: torch.Tensor, height: int, width: int) -> torch.Tensor:
    """Antialiased bilinear resize on the device (no-op at the same size)."""
    if image.shape[-2:] == (height, width):
        return image
    return F.interpolate(image, size=(height, width), mode="bilinear", align_corners=False, antialias=True)
