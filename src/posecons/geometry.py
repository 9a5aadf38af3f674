"""SE(3) poses, the camera model and view synthesis (SPEC §1, §3 and the paper's eq. 2).

Conventions, pinned by tests:
- A pose ``T_{b←a}`` is a (B, 4, 4) matrix mapping 3-D points in camera a into camera b.
- The pose net's 6-vector is (axis-angle e, translation t); M = [R(e) | t], R by Rodrigues.
- Intrinsics are (B, 3, 3) or (B, 4, 4); "normalised" K has row 0 divided by W and row 1 by H.
- Pixel centres are at integer coordinates and sampling uses ``align_corners=True``, so pixel
  u maps to grid coordinate 2u/(W-1) - 1 exactly: identity motion reproduces the image.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F


def check_tensor(name: str, x: object, shape: tuple) -> torch.Tensor:
    """Raise ValueError unless ``x`` is a floating tensor matching ``shape``.

    ``shape`` holds ints for fixed sizes, None for any size and a leading ``...`` for any
    number of leading dimensions.
    """
    want = "(" + ", ".join("…" if s is ... else "*" if s is None else str(s) for s in shape) + ")"
    if not isinstance(x, torch.Tensor) or not x.is_floating_point():
        got = f"a {x.dtype} tensor" if isinstance(x, torch.Tensor) else type(x).__name__
        raise ValueError(f"{name}: expected a floating-point tensor of shape {want}, got {got}")
    fixed = shape[1:] if shape and shape[0] is ... else shape
    ok = x.dim() >= len(fixed) if shape and shape[0] is ... else x.dim() == len(fixed)
    if ok:
        tail = x.shape[x.dim() - len(fixed) :]
        ok = all(s is None or s == t for s, t in zip(fixed, tail))
    if not ok:
        raise ValueError(f"{name}: expected shape {want}, got {tuple(x.shape)}")
    return x


# ----------------------------------------------------------------------------- SE(3)


def axis_angle_to_matrix(axisangle: torch.Tensor) -> torch.Tensor:
    """Rodrigues' formula: (..., 3) axis-angle → (..., 3, 3) rotation.

    Uses sin(θ)/θ and (1-cos θ)/θ² with a Taylor series near θ = 0, so the value and its
    gradient stay finite at zero rotation (the identity constraint lives there).
    """
    theta2 = (axisangle * axisangle).sum(-1, keepdim=True).unsqueeze(-1)  # (..., 1, 1)
    small = theta2 < 1e-8
    safe2 = torch.where(small, torch.ones_like(theta2), theta2)
    theta = safe2.sqrt()
    a = torch.where(small, 1 - theta2 / 6, torch.sin(theta) / theta)
    b = torch.where(small, 0.5 - theta2 / 24, (1 - torch.cos(theta)) / safe2)
    x, y, z = axisangle.unbind(-1)
    zero = torch.zeros_like(x)
    skew = torch.stack([zero, -z, y, z, zero, -x, -y, x, zero], -1).view(*axisangle.shape[:-1], 3, 3)
    eye = torch.eye(3, dtype=axisangle.dtype, device=axisangle.device)
    return eye + a * skew + b * (skew @ skew)


def make_pose(rotation: torch.Tensor, translation: torch.Tensor) -> torch.Tensor:
    """(..., 3, 3) R and (..., 3) t → (..., 4, 4) [R | t; 0 0 0 1]."""
    top = torch.cat([rotation, translation.unsqueeze(-1)], -1)
    bottom = torch.zeros_like(top[..., :1, :])
    bottom[..., 0, 3] = 1
    return torch.cat([top, bottom], -2)


def invert_pose(T: torch.Tensor) -> torch.Tensor:
    """(..., 4, 4) rigid transform → its inverse [Rᵀ | −Rᵀt] (never [Rᵀ | −t])."""
    check_tensor("T", T, (..., 4, 4))
    rot_t = T[..., :3, :3].mT
    return make_pose(rot_t, -(rot_t @ T[..., :3, 3:]).squeeze(-1))


def pose_vec_to_mat(axisangle: torch.Tensor, translation: torch.Tensor, invert: bool = False) -> torch.Tensor:
    """Pose-net output (B, 1, 3), (B, 1, 3) → (B, 4, 4) [R | t], or [Rᵀ | −Rᵀt] if ``invert``."""
    check_tensor("axisangle", axisangle, (None, 1, 3))
    check_tensor("translation", translation, (axisangle.shape[0], 1, 3))
    rot = axis_angle_to_matrix(axisangle[:, 0])
    t = translation[:, 0]
    if invert:
        rot = rot.mT
        t = -(rot @ t.unsqueeze(-1)).squeeze(-1)
    return make_pose(rot, t)


def pose_distance(T: torch.Tensor, P: torch.Tensor) -> torch.Tensor:
    """The paper's eq. 2, d(T, P), shape (B,): the sum of :func:`pose_distance_terms`."""
    rot_term, trans_term = pose_distance_terms(T, P)
    return rot_term + trans_term


def pose_distance_terms(T: torch.Tensor, P: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The two terms of the paper's eq. 2, d(T, P) = |1 − (tr(R_T R_Pᵀ) − 1)/2| + ‖t_T − t_P‖₁: the
    rotation term and the translation term, each (B,).

    The rotation term is 1 − cos(angle between R_T and R_P), smooth at zero (no acos). It is
    computed as ¼‖R_T − R_P‖²_F, which equals (3 − tr(R_T R_Pᵀ))/2 exactly for rotations and is
    never negative (so no abs): the trace form cancels catastrophically in float32 near
    agreement — where the constraints act — and there returns 0 or gradients of the wrong sign.
    """
    check_tensor("T", T, (None, 4, 4))
    check_tensor("P", P, (T.shape[0], 4, 4))
    rot_term = 0.25 * (T[:, :3, :3] - P[:, :3, :3]).square().sum((-1, -2))
    trans_term = (T[:, :3, 3] - P[:, :3, 3]).abs().sum(-1)
    return rot_term, trans_term


# ----------------------------------------------------------------------------- camera


def disp_to_depth(disp: torch.Tensor, min_depth: float, max_depth: float) -> tuple[torch.Tensor, torch.Tensor]:
    """Sigmoid output → (scaled disparity in [1/max, 1/min], depth = 1/scaled)."""
    check_tensor("disp", disp, (...,))
    min_disp, max_disp = 1 / max_depth, 1 / min_depth
    scaled = min_disp + (max_disp - min_disp) * disp
    return scaled, 1 / scaled


def scale_intrinsics(K_norm: torch.Tensor, height: int, width: int) -> torch.Tensor:
    """Normalised (B, 3, 3) K → pixel K for an image of ``height`` × ``width``.

    Pyramid level s uses ``scale_intrinsics(K, H // 2**s, W // 2**s)``.
    """
    check_tensor("K_norm", K_norm, (None, 3, 3))
    scale = K_norm.new_tensor([width, height, 1.0]).view(1, 3, 1)
    return K_norm * scale


def flip_intrinsics(K_norm: torch.Tensor, width: int) -> torch.Tensor:
    """Normalised K (..., 3, 3) of the horizontally mirrored image, ``width`` pixels wide.

    With integer pixel centres a flip maps u ↦ W − 1 − u, so cx ↦ W − 1 − cx in pixels and
    cx/W ↦ 1 − cx/W − 1/W normalised (1 − cx to first order). Exact at the resolution ``width``;
    at pyramid level s the normalised-K convention rescales it to cx_s' = W_s − cx_s − 2⁻ˢ.
    """
    flipped = K_norm.clone()
    flipped[..., 0, 2] = (width - 1) / width - K_norm[..., 0, 2]
    return flipped


def mirror_pose(T: torch.Tensor) -> torch.Tensor:
    """T (..., 4, 4) seen in the horizontally mirrored image (x ↦ −x): M·T·M with M = diag(−1, 1, 1, 1),
    which negates the entries of row 0 and of column 0 except the one they share."""
    m = T.new_tensor([-1.0, 1.0, 1.0, 1.0])
    return T * m[:, None] * m


def pixel_grid(height: int, width: int, like: torch.Tensor) -> torch.Tensor:
    """Homogeneous pixel coordinates (3, H·W): rows u, v, 1 (u along the width)."""
    v, u = torch.meshgrid(
        torch.arange(height, dtype=like.dtype, device=like.device),
        torch.arange(width, dtype=like.dtype, device=like.device),
        indexing="ij",
    )
    return torch.stack([u, v, torch.ones_like(u)]).view(3, -1)


def backproject(depth: torch.Tensor, K: torch.Tensor) -> torch.Tensor:
    """Depth (B, 1, H, W) and pixel K (B, 3, 3) → camera points X = D·K⁻¹[u, v, 1]ᵀ, (B, 3, H·W)."""
    check_tensor("depth", depth, (None, 1, None, None))
    check_tensor("K", K, (depth.shape[0], 3, 3))
    _, _, h, w = depth.shape
    # inv_ex: the same inverse as linalg.inv without its error check, which on CUDA waits for the device.
    rays = torch.linalg.inv_ex(K).inverse @ pixel_grid(h, w, depth)
    return rays * depth.view(depth.shape[0], 1, -1)


def project(points: torch.Tensor, K: torch.Tensor, eps: float = 1e-7) -> torch.Tensor:
    """Camera points (B, 3, N) → pixel coordinates (B, 2, N) through pixel K (B, 3, 3)."""
    check_tensor("points", points, (None, 3, None))
    check_tensor("K", K, (points.shape[0], 3, 3))
    p = K @ points
    return p[:, :2] / (p[:, 2:3] + eps)


def transform_points(T: torch.Tensor, points: torch.Tensor) -> torch.Tensor:
    """Apply (B, 4, 4) T to (B, 3, N) points."""
    return T[:, :3, :3] @ points + T[:, :3, 3:]


def pixels_to_grid(pixels: torch.Tensor, height: int, width: int) -> torch.Tensor:
    """Pixel coordinates (B, 2, H·W) → grid_sample grid (B, H, W, 2) for ``align_corners=True``."""
    size = pixels.new_tensor([width - 1, height - 1]).view(1, 2, 1).clamp(min=1)
    grid = pixels / size * 2 - 1
    return grid.view(pixels.shape[0], 2, height, width).permute(0, 2, 3, 1)


def project_depth(depth: torch.Tensor, T: torch.Tensor, K: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The target's pixels seen from the source camera: back-project ``depth`` (B, 1, H, W) through
    pixel K (B, 3, 3), move the points by T_{source←target} (B, 4, 4) and project them.

    Returns their depth in the source camera, D_{target→source} (B, 1, H, W), and where they land
    in the source image as a grid_sample grid (B, H, W, 2) for ``align_corners=True``; pixels
    landing inside the image have both grid coordinates in [−1, 1].
    """
    check_tensor("T", T, (depth.shape[0], 4, 4))
    b, _, h, w = depth.shape
    points = transform_points(T, backproject(depth, K))
    grid = pixels_to_grid(project(points, K), h, w)
    return points[:, 2:3].reshape(b, 1, h, w), grid


def warp(source: torch.Tensor, depth: torch.Tensor, T: torch.Tensor, K: torch.Tensor) -> torch.Tensor:
    """Synthesise the target view from ``source`` (B, C, H, W) (SPEC §3).

    depth: target depth (B, 1, H, W); T: T_{source←target} (B, 4, 4); K: pixel K (B, 3, 3)
    at this resolution. Bilinear sampling with border padding.
    """
    check_tensor("source", source, (None, None, None, None))
    check_tensor("T", T, (source.shape[0], 4, 4))
    _, _, h, w = depth.shape
    if source.shape[-2:] != (h, w):
        raise ValueError(f"source: expected spatial size {(h, w)} like depth, got {tuple(source.shape[-2:])}")
    _, grid = project_depth(depth, T, K)
    return F.grid_sample(source, grid, mode="bilinear", padding_mode="border", align_corners=True)


def resize_image(image: torch.Tensor, height: int, width: int) -> torch.Tensor:
    """Antialiased bilinear resize of (B, C, H, W) images on their device (no-op at the same size): the
    frames at each scale of the view synthesis."""
    if image.shape[-2:] == (height, width):
        return image
    return F.interpolate(image, size=(height, width), mode="bilinear", align_corners=False, antialias=True)


__all__ = [
    "axis_angle_to_matrix",
    "backproject",
    "check_tensor",
    "disp_to_depth",
    "flip_intrinsics",
    "invert_pose",
    "make_pose",
    "mirror_pose",
    "pixel_grid",
    "pixels_to_grid",
    "pose_distance",
    "pose_vec_to_mat",
    "project",
    "project_depth",
    "resize_image",
    "scale_intrinsics",
    "transform_points",
    "warp",
]
