"""The model: depth + pose networks and the training loss, behind one call.

Training, validation, evaluation and tests all go through :meth:`PoseConsModel.forward`,
which takes a batch dict and returns predictions and a dict of named losses: the view synthesis
(photometric + smoothness) computed here, and each other term by its unit in :mod:`posecons.terms`.

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

from . import terms
from .config import Config
from .geometry import check_tensor, disp_to_depth, pose_vec_to_mat, resize_image, scale_intrinsics, warp
from .losses import min_reprojection, photometric_error, smoothness_loss
from .networks import DepthNet, PoseNet, imagenet_weights_name, load_imagenet_state
from .pose_source import pose_source, temporal
from .terms import StepContext, Term


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
    """The depth and pose networks and the training loss of ``config``: view synthesis, and the loss
    terms (:mod:`posecons.terms`) and pose source (:mod:`posecons.pose_source`) that it chooses."""

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

    @property
    def config(self) -> Config:
        return self._config

    @config.setter
    def config(self, config: Config) -> None:
        """A new config chooses the loss terms and the pose source again (the networks stay)."""
        self._config = config
        self.terms = [term(config) for term in terms.TERMS if term.enabled(config)]
        self.pose_source = pose_source(config.model)

    # ------------------------------------------------------------------ training
    def active_terms(self, step: int, with_constraints: bool = True) -> list[Term]:
        """The terms that count at ``step``; the identity constraint's draw is made here (SPEC §5)."""
        return [t for t in self.terms if (with_constraints or not t.constraint) and t.active(step)]

    def pose_pairs(self, active: list[Term]) -> list[tuple[int, int]]:
        """The frame pairs (a, b) the pose net sees this step: the temporal pairs first (they alone
        update BatchNorm's running statistics), then each pair the ``active`` terms add, once."""
        pairs = [temporal(f) for f in self.config.model.frame_ids[1:]]
        return list(dict.fromkeys(pairs + [pair for t in active for pair in t.pose_pairs()]))

    def forward(
        self, batch: dict, step: int = 0, with_constraints: bool = True
    ) -> tuple[dict, dict[str, torch.Tensor]]:
        """Outputs and losses of a training step; ``with_constraints=False`` (validation) computes
        none of the paper's constraints and draws nothing from the RNG for them."""
        m = self.config.model
        shape = (None, len(m.frame_ids), 3, m.height, m.width)
        frames = check_tensor("batch['frames']", batch["frames"], shape)
        net_frames = check_tensor("batch['net_frames']", batch.get("net_frames", frames), tuple(frames.shape))
        K = check_tensor("batch['intrinsics']", batch["intrinsics"], (frames.shape[0], 3, 3)).float()
        active = self.active_terms(step, with_constraints)
        logits, source_disp = self._disparities(net_frames, any(t.needs_source_depth for t in active))
        disps = {s: torch.sigmoid(x) for s, x in logits.items()}
        motions = self._motions(batch, frames.shape[0], active)
        P, poses = self.pose_source(self.pose_net, net_frames, self.pose_pairs(active), motions)

        with torch.autocast(frames.device.type, enabled=False):
            ctx = StepContext(frames.float(), K, logits, disps, poses, P, source_disp, motions, self.photometric_error)
            values = {t.name: t(ctx) for t in active if t.before_view_synthesis}
            losses, automask, warp_gain = self._view_synthesis_losses(
                ctx.frames, K, disps, poses, ctx.photometric_mask, masked=self._masks_static(step)
            )
            values.update({t.name: t(ctx) for t in active if not t.before_view_synthesis})
            losses.update({t.name: values[t.name] for t in active})
            losses["total"] = losses["total"] + sum(t.weight * values[t.name] for t in active)

        outputs = {
            "disp": disps,
            "poses": poses,
            "depth": disp_to_depth(disps[0], m.min_depth, m.max_depth)[1],
            "automask": automask,
            "warp_gain": warp_gain,
        }
        return outputs, losses

    def _disparities(
        self, net_frames: torch.Tensor, with_sources: bool
    ) -> tuple[dict[int, torch.Tensor], torch.Tensor | None]:
        """The target's disparity logits by scale and, ``with_sources``, the sources' scale-0
        disparities (S·B, 1, H, W) in frame_ids order, from one depth-net pass over every frame."""
        if not with_sources:
            return self.depth_net(net_frames[:, 0], logits=True), None
        b = net_frames.shape[0]
        all_logits = self.depth_net(torch.cat([net_frames[:, i] for i in range(net_frames.shape[1])]), logits=True)
        return {s: x[:b] for s, x in all_logits.items()}, torch.sigmoid(all_logits[0][b:])

    def _motions(self, batch: dict, b: int, active: list[Term]) -> torch.Tensor | None:
        """batch['motions'] (B, S, 4, 4) in fp32 where the pose source or an active term needs it, else None."""
        needed_by = [self.pose_source.option] if self.pose_source.needs_motions else []
        needed_by += [f"loss.{t.weight_key}" for t in active if t.needs_motions]
        if not needed_by:
            return None
        if "motions" not in batch:
            raise ValueError(f"{' and '.join(needed_by)} need batch['motions'] (T_{{f←0}})")
        sources = len(self.config.model.frame_ids) - 1
        return check_tensor("batch['motions']", batch["motions"], (b, sources, 4, 4)).float()

    def _masks_static(self, step: int) -> bool:
        """Whether the auto-mask is on at ``step``: from ``loss.automask_start_step`` on. Before it every
        pixel counts, so a warp worse than no motion is seen wherever it is worse: a run whose first
        steps point backwards is corrected instead of learning from the few pixels that a wrong warp
        wins by chance (experiments/investigation.md §30)."""
        lo = self.config.loss
        return lo.automask and step >= lo.automask_start_step

    def _view_synthesis_losses(
        self,
        frames: torch.Tensor,
        K_norm: torch.Tensor,
        disps: dict,
        poses: dict[int, torch.Tensor],
        masks: torch.Tensor | None = None,
        masked: bool = True,
    ) -> tuple[dict[str, torch.Tensor], torch.Tensor, torch.Tensor]:
        """Min-reprojection with auto-masking plus smoothness, averaged over scales (SPEC §3–4);
        also the full-scale auto-mask (B, H, W), True where a warped source won, and the warp's gain
        at that scale: 1 − (mean best warped error) / (mean best unwarped error), > 0 where depth and
        pose explain the target better than no motion (NaN without the auto-mask, which alone
        computes the unwarped error). ``masks`` (B, S, H, W): weights of each source's reprojection
        error before the minimum (SC-Depth's self-discovered mask, resized to each scale); ``masked``:
        whether the minimum includes the unwarped sources (the auto-mask) at this step."""
        m, lo = self.config.model, self.config.loss
        h, w = m.height, m.width
        target, sources = frames[:, 0], [frames[:, i] for i in range(1, frames.shape[1])]
        identity = None
        photo, smooth, automask = [], [], None
        for s in m.scales:
            disp = disps[s].float()
            hs, ws = disp.shape[-2:]
            if lo.v1_multiscale:  # warp at the scale's native size
                size, tgt, srcs = (hs, ws), resize_image(target, hs, ws), [resize_image(x, hs, ws) for x in sources]
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
            per_pixel, keep = min_reprojection(reproj, identity if lo.automask and masked else None)
            if automask is None:
                automask, warp_gain = keep, torch.tensor(math.nan)
                if lo.automask:
                    warp_gain = 1 - reproj.detach().min(1).values.mean() / identity.min(1).values.mean()
            photo.append(per_pixel.mean())
            smooth.append(lo.smoothness_weight / 2**s * smoothness_loss(disps[s].float(), resize_image(target, hs, ws)))
        photometric = torch.stack(photo).mean()
        smoothness = torch.stack(smooth).mean()
        losses = {"photometric": photometric, "smoothness": smoothness, "total": photometric + smoothness}
        return losses, automask, warp_gain
