"""The model: depth + pose networks, view synthesis and every loss, behind one call.

Training, validation, evaluation and tests all go through :meth:`PoseConsModel.forward`,
which takes a batch dict and returns predictions and a dict of named losses.

Batch keys (see ``posecons.data``):
    frames      (B, F, 3, H, W) un-augmented RGB in [0, 1], in the order of ``model.frame_ids``
    intrinsics  (B, 3, 3) normalised K (row 0 / W, row 1 / H)
    color_aug   (B, 4) optional colour-jitter factors; the networks see jittered frames,
                the losses the un-augmented ones (SPEC §6)
"""

from __future__ import annotations

import torch
import torch.nn as nn
import torch.nn.functional as F

from .config import Config
from .geometry import check_tensor, disp_to_depth, pose_vec_to_mat, scale_intrinsics, warp
from .losses import (cycle_loss, forward_backward_loss, identity_loss, min_reprojection,
                     photometric_error, smoothness_loss)
from .networks import DepthNet, PoseNet, imagenet_weights_name, load_imagenet_state


class PoseConsModel(nn.Module):
    def __init__(self, config: Config):
        super().__init__()
        self.config = config
        m = config.model
        imagenet = load_imagenet_state(m.num_layers, m.pretrained)  # fetched once for both encoders
        self.depth_net = DepthNet(m.num_layers, imagenet, tuple(m.scales))
        self.pose_net = PoseNet(m.num_layers, imagenet)
        # How the encoders were initialised, for the run's config, checkpoints and reports.
        self.initialisation = (f"ImageNet ({imagenet_weights_name(m.num_layers)})" if imagenet is not None
                               else "random (trained from scratch)")

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

    def pose_pairs(self, constraints: list[str]) -> list[tuple[str, int, int]]:
        """(role, a, b) frame-id pairs the pose net must see this step; a pair gives T_{b←a}.

        Sources are fed in temporal order (SPEC §1); fb adds each reversed pair, id (0, 0),
        cyc (−n, +n).
        """
        sources = self.config.model.frame_ids[1:]
        pairs = [("pose", min(f, 0), max(f, 0)) for f in sources]
        if "fb" in constraints:
            pairs += [("reverse", max(f, 0), min(f, 0)) for f in sources]
        if "id" in constraints:
            pairs.append(("id", 0, 0))
        if "cyc" in constraints:
            pairs.append(("cyc", *self.cycle_ids()))
        return pairs

    def cycle_ids(self) -> tuple[int, int]:
        """(−n, +n): the nearest source on each side of the target (n = 1 for frames 0, −1, +1)."""
        sources = self.config.model.frame_ids[1:]
        return max(f for f in sources if f < 0), min(f for f in sources if f > 0)

    def forward(self, batch: dict, step: int = 0) -> tuple[dict, dict[str, torch.Tensor]]:
        m, lo = self.config.model, self.config.loss
        frames = check_tensor("batch['frames']", batch["frames"], (None, len(m.frame_ids), 3, m.height, m.width))
        K = check_tensor("batch['intrinsics']", batch["intrinsics"], (frames.shape[0], 3, 3)).float()
        net_frames = frames
        if "color_aug" in batch:
            from .data.augment import color_jitter
            net_frames = color_jitter(frames, batch["color_aug"])
        index = {f: i for i, f in enumerate(m.frame_ids)}

        disps = self.depth_net(net_frames[:, 0])

        # Every pose-net input of this step in one batched pass, normalised per pair group; the
        # temporal pairs (listed first) alone update the running statistics.
        constraints = self.active_constraints(step)
        pairs = self.pose_pairs(constraints)
        a = torch.cat([net_frames[:, index[p[1]]] for p in pairs])
        b = torch.cat([net_frames[:, index[p[2]]] for p in pairs])
        aa_all, t_all = self.pose_net(a, b, groups=len(pairs), tracked=len(m.frame_ids) - 1)
        with torch.autocast(frames.device.type, enabled=False):
            raw = {p: (aa, t) for p, aa, t in zip(pairs, aa_all.float().chunk(len(pairs)),
                                                  t_all.float().chunk(len(pairs)))}

            def mat(role: str, a: int, b: int, invert: bool = False) -> torch.Tensor:
                return pose_vec_to_mat(*raw[(role, a, b)], invert=invert)

            sources = m.frame_ids[1:]
            # T_{f←0} for warping: the temporal pair gives T_{0←f} when f < 0, so invert it.
            poses = {f: mat("pose", min(f, 0), max(f, 0), invert=f < 0) for f in sources}
            losses = self._view_synthesis_losses(frames.float(), K, disps, poses)
            weights = {"fb": lo.fb_weight, "id": lo.id_weight, "cyc": lo.cyc_weight}
            for name in constraints:
                if name == "fb":  # T_{0←f} from each reversed pair against T_{f←0}
                    t_bwd = torch.cat([mat("reverse", max(f, 0), min(f, 0), invert=f < 0) for f in sources])
                    losses["fb"] = forward_backward_loss(torch.cat([poses[f] for f in sources]), t_bwd,
                                                         lo.translation_norm)
                elif name == "id":
                    losses["id"] = identity_loss(*raw[("id", 0, 0)])
                else:  # T_{+n←−n} against T_{+n←0} · T_{0←−n}
                    prev, nxt = self.cycle_ids()
                    losses["cyc"] = cycle_loss(mat("cyc", prev, nxt), mat("pose", prev, 0), mat("pose", 0, nxt),
                                               lo.translation_norm)
                losses["total"] = losses["total"] + weights[name] * losses[name]

        outputs = {"disp": disps, "poses": poses, "depth": disp_to_depth(disps[0], m.min_depth, m.max_depth)[1],
                   "automask": losses.pop("_automask")}
        return outputs, losses

    def _view_synthesis_losses(self, frames: torch.Tensor, K_norm: torch.Tensor, disps: dict,
                               poses: dict[int, torch.Tensor]) -> dict[str, torch.Tensor]:
        """Min-reprojection with auto-masking plus smoothness, averaged over scales (SPEC §3–4)."""
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
            reproj = torch.cat([photometric_error(warp(src, depth, poses[f], K), tgt, lo.ssim_weight)
                                for f, src in zip(m.frame_ids[1:], srcs)], 1)
            if lo.automask and (identity is None or lo.v1_multiscale):
                identity = torch.cat([photometric_error(src, tgt, lo.ssim_weight) for src in srcs], 1)
            per_pixel, keep = min_reprojection(reproj, identity if lo.automask else None)
            automask = keep if automask is None else automask
            photo.append(per_pixel.mean())
            smooth.append(lo.smoothness_weight / 2 ** s * smoothness_loss(disps[s].float(), _resize(target, hs, ws)))
        photometric = torch.stack(photo).mean()
        smoothness = torch.stack(smooth).mean()
        return {"photometric": photometric, "smoothness": smoothness, "total": photometric + smoothness,
                "_automask": automask}


def _resize(image: torch.Tensor, height: int, width: int) -> torch.Tensor:
    """Antialiased bilinear resize on the device (no-op at the same size)."""
    if image.shape[-2:] == (height, width):
        return image
    return F.interpolate(image, size=(height, width), mode="bilinear", align_corners=False, antialias=True)
