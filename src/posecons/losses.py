"""Losses: Monodepth2's photometric and smoothness terms (SPEC §4), the paper's three pose
constraints (SPEC §5) and SC-SfMLearner's depth consistency (an option). Each function is one equation.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from .geometry import check_tensor, invert_pose, make_pose, pose_distance, project_depth, warp

_IMAGE = (None, None, None, None)


def _box3(x: torch.Tensor) -> torch.Tensor:
    """Mean over each 3×3 window (valid region, stride 1) as two separable sums of shifted views: the
    same value as ``F.avg_pool2d(x, 3, 1)`` up to float rounding, and on the CPU (where the pooling
    kernels are the slowest part of a loss) 2–3× faster forward and backward (docs/performance.md)."""
    rows = x[..., :-2, :] + x[..., 1:-1, :] + x[..., 2:, :]
    return (rows[..., :-2] + rows[..., 1:-1] + rows[..., 2:]) / 9


def ssim_dissimilarity(x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    """clamp((1 − SSIM(x, y)) / 2, 0, 1) per pixel and channel, (B, C, H, W).

    Local statistics use a 3×3 box filter on reflection-padded inputs; C1 = 0.01², C2 = 0.03².
    """
    check_tensor("x", x, _IMAGE)
    check_tensor("y", y, tuple(x.shape))
    c1, c2 = 0.01**2, 0.03**2
    x, y = F.pad(x, (1, 1, 1, 1), mode="reflect"), F.pad(y, (1, 1, 1, 1), mode="reflect")
    mu_x, mu_y = _box3(x), _box3(y)
    mu_xx, mu_yy, mu_xy = mu_x * mu_x, mu_y * mu_y, mu_x * mu_y
    var_x, var_y, cov = _box3(x * x) - mu_xx, _box3(y * y) - mu_yy, _box3(x * y) - mu_xy
    ssim = ((2 * mu_xy + c1) * (2 * cov + c2)) / ((mu_xx + mu_yy + c1) * (var_x + var_y + c2))
    return ((1 - ssim) / 2).clamp(0, 1)


def photometric_error(pred: torch.Tensor, target: torch.Tensor, ssim_weight: float = 0.85) -> torch.Tensor:
    """pe = 0.85·mean_c((1 − SSIM)/2) + 0.15·mean_c|pred − target|, (B, 1, H, W)."""
    check_tensor("pred", pred, _IMAGE)
    check_tensor("target", target, tuple(pred.shape))
    l1 = (pred - target).abs().mean(1, keepdim=True)
    return ssim_weight * ssim_dissimilarity(pred, target).mean(1, keepdim=True) + (1 - ssim_weight) * l1


def min_reprojection(
    reprojection: torch.Tensor, identity: torch.Tensor | None = None
) -> tuple[torch.Tensor, torch.Tensor]:
    """Per-pixel minimum over sources, with auto-masking (SPEC §4).

    reprojection: pe(warped_f, I_0) stacked over sources, (B, S, H, W); identity: pe(I_f, I_0)
    for the unwarped sources, (B, S, H, W), or None to disable auto-masking. Identity errors
    get Gaussian noise (std 1e-5) to break ties. Returns the per-pixel minimum (B, H, W) and the
    mask of pixels where a warped source won (B, H, W). Where an identity term wins, the value
    holds no network output, so those pixels drop out of the gradient (as in Monodepth2, the
    constant still counts in the mean's value).
    """
    check_tensor("reprojection", reprojection, _IMAGE)
    if identity is None:
        loss = reprojection.min(1).values
        return loss, torch.ones_like(loss, dtype=torch.bool)
    check_tensor("identity", identity, tuple(reprojection.shape))
    identity = identity + torch.randn_like(identity) * 1e-5
    combined, idx = torch.cat([identity, reprojection], 1).min(1)
    keep = idx >= identity.shape[1]
    return combined, keep


def smoothness_loss(disp: torch.Tensor, img: torch.Tensor) -> torch.Tensor:
    """Edge-aware smoothness of mean-normalised disparity (B, 1, h, w) against img (B, 3, h, w)."""
    check_tensor("disp", disp, (None, 1, None, None))
    check_tensor("img", img, (disp.shape[0], None, disp.shape[2], disp.shape[3]))
    d = disp / (disp.mean((2, 3), keepdim=True) + 1e-7)
    grad_dx = (d[..., :, :-1] - d[..., :, 1:]).abs()
    grad_dy = (d[..., :-1, :] - d[..., 1:, :]).abs()
    grad_ix = (img[..., :, :-1] - img[..., :, 1:]).abs().mean(1, keepdim=True)
    grad_iy = (img[..., :-1, :] - img[..., 1:, :]).abs().mean(1, keepdim=True)
    return (grad_dx * torch.exp(-grad_ix)).mean() + (grad_dy * torch.exp(-grad_iy)).mean()


def depth_consistency_loss(
    target_depth: torch.Tensor, source_depth: torch.Tensor, T: torch.Tensor, K: torch.Tensor
) -> torch.Tensor:
    """Geometry consistency of SC-SfMLearner (Bian et al., NeurIPS 2019): mean of
    D_diff = |D_{0→f} − D_f'| / (D_{0→f} + D_f') over the target pixels that land inside the source image.

    target_depth: D_0 (B, 1, H, W); source_depth: D_f, the source frame's own prediction (B, 1, H, W);
    T: T_{f←0} (B, 4, 4); K: pixel K (B, 3, 3) at this resolution. D_{0→f} is the depth of the
    target's points in camera f, D_f' is D_f sampled bilinearly where they project. Points behind
    camera f count as outside. Several sources go in as one batch (their pixels pooled in the mean).
    """
    diff, inside = depth_difference(target_depth, source_depth, T, K)
    return diff.sum() / inside.sum().clamp(min=1)


def depth_difference(
    target_depth: torch.Tensor, source_depth: torch.Tensor, T: torch.Tensor, K: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """Per target pixel, D_diff of :func:`depth_consistency_loss` (B, 1, H, W), 0 where the pixel lands
    outside source f or behind its camera, and the mask of the pixels that land inside (B, 1, H, W)."""
    check_tensor("source_depth", source_depth, tuple(target_depth.shape))
    projected, grid = project_depth(target_depth, T, K)
    sampled = F.grid_sample(source_depth, grid, mode="bilinear", padding_mode="border", align_corners=True)
    inside = (grid.abs() <= 1).all(-1, keepdim=True).permute(0, 3, 1, 2) & (projected > 0)
    # Outside pixels get D_diff = 0 from finite values, so neither the value nor the gradient sees them.
    projected = torch.where(inside, projected, sampled)
    return (projected - sampled).abs() / (projected + sampled), inside


# ----------------------------------------------------------------------------- pose constraints


def forward_backward_loss(t_fwd: torch.Tensor, t_bwd: torch.Tensor) -> torch.Tensor:
    """mean d(T_{f←0}, inverse(T_{0←f})): the pose of a pair and of the reversed pair must be inverses.

    t_fwd: T_{f←0} (B, 4, 4); t_bwd: T_{0←f} predicted from the reversed pair (B, 4, 4).
    """
    return pose_distance(t_fwd, invert_pose(t_bwd)).mean()


def identity_loss(axisangle: torch.Tensor, translation: torch.Tensor) -> torch.Tensor:
    """mean(‖e‖₁ + ‖t‖₁) of the pose net's raw output for the pair (I_0, I_0)."""
    check_tensor("axisangle", axisangle, (None, 1, 3))
    check_tensor("translation", translation, tuple(axisangle.shape))
    return (axisangle.abs().sum((1, 2)) + translation.abs().sum((1, 2))).mean()


def cycle_loss(t_skip: torch.Tensor, t_second: torch.Tensor, t_first: torch.Tensor) -> torch.Tensor:
    """mean d(T_{+1←−1}, T_{+1←0} · T_{0←−1}): the skip pose must equal the composed pair.

    Arguments in the formula's reading order: t_skip T_{+1←−1}, t_second T_{+1←0}, t_first
    T_{0←−1}; each (B, 4, 4).
    """
    check_tensor("t_second", t_second, (None, 4, 4))
    check_tensor("t_first", t_first, tuple(t_second.shape))
    return pose_distance(t_skip, t_second @ t_first).mean()


# ----------------------------------------------------------------------------- measured speed (not in the paper)


def velocity_loss(translation: torch.Tensor, distance: torch.Tensor) -> torch.Tensor:
    """mean |‖t‖₂ − ŝ·d| / mean ‖t‖₂ over the batch's pairs, ŝ = Σ‖t‖₂ / Σd (both detached): each
    translation's length in proportion to the metres d travelled between its frames. PackNet-SfM's
    velocity supervision asks for ‖t‖ = d; here one scale ŝ a batch is left free, because a pose net
    that outputs 0.01 × its activations cannot reach metres in a short run, and the normalisation keeps
    the term from pulling every translation (and so the depth) smaller. A pair that stands still
    (d = 0) is asked for no translation.

    translation: the pose net's raw t (N, 1, 3) of N pairs; distance: (N,) metres.
    """
    check_tensor("translation", translation, (None, 1, 3))
    check_tensor("distance", distance, (translation.shape[0],))
    length = translation.norm(dim=-1).squeeze(1)
    scale = (length.sum() / distance.sum().clamp(min=1e-12)).detach()
    return (length - scale * distance).abs().mean() / length.mean().detach().clamp(min=1e-12)


# ----------------------------------------------------------------------------- far pixels' rotation (not in the paper)


def far_rotation_loss(
    target: torch.Tensor,
    sources: torch.Tensor,
    rotations: torch.Tensor,
    K: torch.Tensor,
    depth: torch.Tensor,
    fraction: float,
    ssim_weight: float = 0.85,
) -> torch.Tensor:
    """Mean photometric error of each source warped by its rotation alone, over the target's farthest
    ``fraction`` of pixels by ``depth``: a point at infinity moves by the homography K R K⁻¹ whatever
    the translation, so these pixels teach the pose net's rotation without going through a depth that
    may be compressed there. Only the ranking of ``depth`` is used (detached: the loss trains R alone);
    pixels tied with the cut-off count as far.

    target (B, 3, H, W); sources (B, S, 3, H, W); rotations (B, S, 3, 3), R of T_{f←0}; K: pixel K
    (B, 3, 3) at this size; depth (B, 1, H, W); fraction in (0, 1].
    """
    b, s = sources.shape[:2]
    check_tensor("sources", sources, (target.shape[0], None, *target.shape[1:]))
    check_tensor("rotations", rotations, (b, s, 3, 3))
    check_tensor("depth", depth, (b, 1, *target.shape[-2:]))
    depth = depth.detach()
    far = depth >= depth.flatten(1).quantile(1 - fraction, dim=1).view(b, 1, 1, 1)
    T = make_pose(rotations.flatten(0, 1), rotations.new_zeros(b * s, 3))  # (B·S), sample-major
    warped = warp(sources.flatten(0, 1), depth.repeat_interleave(s, 0), T, K.repeat_interleave(s, 0))
    error = photometric_error(warped, target.repeat_interleave(s, 0), ssim_weight).view(b, s, *depth.shape[-2:])
    return (error * far).sum() / (far.sum() * s)


def saturation_loss(logits: list[torch.Tensor], bound: float) -> torch.Tensor:
    """Mean squared excess of the disparity logits beyond ±``bound``, averaged over the scales (not in
    the paper). Zero while every sigmoid lies in (σ(−bound), σ(bound)); beyond, a gradient back toward
    the range where the sigmoid's own has vanished. A run whose disparity reaches either end of the
    sigmoid stays pinned there (experiments/investigation.md §26, §27); this keeps it movable.

    logits: one (B, 1, H, W) tensor per scale; bound > 0."""
    return torch.stack([F.relu(x.abs() - bound).square().mean() for x in logits]).mean()
