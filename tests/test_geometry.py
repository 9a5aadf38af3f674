import math

import pytest
import torch

from posecons.geometry import (
    axis_angle_to_matrix,
    backproject,
    disp_to_depth,
    flip_intrinsics,
    invert_pose,
    make_pose,
    pixels_to_grid,
    pose_distance,
    pose_distance_terms,
    pose_vec_to_mat,
    project,
    project_depth,
    scale_intrinsics,
    transform_points,
    warp,
)

DTYPES = [torch.float64, torch.float32]
TOL = {torch.float64: 1e-12, torch.float32: 2e-6}


def random_pose(b: int, dtype=torch.float64) -> torch.Tensor:
    return pose_vec_to_mat(torch.randn(b, 1, 3, dtype=dtype), torch.randn(b, 1, 3, dtype=dtype))


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("b", [1, 3, 12])
def test_inverse_times_pose_is_identity(b, dtype):
    T = random_pose(b, dtype)
    eye = torch.eye(4, dtype=T.dtype).expand(b, 4, 4)
    assert torch.allclose(invert_pose(T) @ T, eye, atol=5 * TOL[dtype])
    assert torch.allclose(T @ invert_pose(T), eye, atol=5 * TOL[dtype])


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("b", [1, 3, 12])
def test_batched_transposes_are_per_sample(b, dtype):
    aa, t = torch.randn(b, 1, 3, dtype=dtype), torch.randn(b, 1, 3, dtype=dtype)
    inv = pose_vec_to_mat(aa, t, invert=True)
    assert torch.allclose(inv, invert_pose(pose_vec_to_mat(aa, t)), atol=TOL[dtype])
    for i in range(b):  # each sample against its own single-sample computation
        single = pose_vec_to_mat(aa[i : i + 1], t[i : i + 1])
        R = single[0, :3, :3]
        assert torch.allclose(inv[i, :3, :3], R.T, atol=TOL[dtype])
        assert torch.allclose(inv[i, :3, 3], -R.T @ single[0, :3, 3], atol=5 * TOL[dtype])


@pytest.mark.parametrize("dtype", DTYPES)
def test_rodrigues_matches_known_rotation_and_is_orthonormal(dtype):
    R = axis_angle_to_matrix(torch.tensor([[0.0, 0.0, math.pi / 2]], dtype=dtype))[0]
    assert torch.allclose(
        R @ torch.tensor([1.0, 0, 0], dtype=dtype), torch.tensor([0.0, 1, 0], dtype=dtype), atol=TOL[dtype]
    )
    Rs = axis_angle_to_matrix(torch.randn(5, 3, dtype=dtype))
    assert torch.allclose(Rs @ Rs.mT, torch.eye(3, dtype=dtype).expand(5, 3, 3), atol=2 * TOL[dtype])
    assert torch.allclose(torch.linalg.det(Rs), torch.ones(5, dtype=dtype), atol=2 * TOL[dtype])


@pytest.mark.parametrize("dtype", DTYPES)
def test_pose_distance_properties(dtype):
    T, P = random_pose(6, dtype), random_pose(6, dtype)
    assert torch.equal(pose_distance(T, T), torch.zeros(6, dtype=dtype))
    assert torch.allclose(pose_distance(T, P), pose_distance(P, T), atol=TOL[dtype])
    assert (pose_distance(T, P) > 0).all()


@pytest.mark.parametrize("dtype", DTYPES)
def test_pose_distance_formula(dtype):
    angle = 0.3
    R = axis_angle_to_matrix(torch.tensor([[0.0, angle, 0.0]], dtype=dtype))
    T = make_pose(R, torch.tensor([[1.0, 2.0, 3.0]], dtype=dtype))
    P = make_pose(torch.eye(3, dtype=dtype)[None], torch.tensor([[0.5, 2.0, 4.0]], dtype=dtype))
    expected = abs(1 - ((1 + 2 * math.cos(angle)) - 1) / 2) + 0.5 + 0.0 + 1.0
    assert pose_distance(T, P).item() == pytest.approx(expected, abs=5 * TOL[dtype])
    rotation, translation = pose_distance_terms(T, P)  # the two terms apart: 1 − cos θ and the L1 of Δt
    assert rotation.item() == pytest.approx(1 - math.cos(angle), abs=5 * TOL[dtype])
    assert translation.item() == pytest.approx(1.5, abs=5 * TOL[dtype])


def _rotation_pairs(n: int, dtheta: float, dtype: torch.dtype):
    """Rotations of 0.01 rad (the pose decoder's scale) and partners that differ by ``dtheta`` rad."""
    g = torch.Generator().manual_seed(0)
    unit = lambda v: v / v.norm(dim=-1, keepdim=True)  # noqa: E731
    base = 0.01 * unit(torch.randn(n, 1, 3, generator=g, dtype=torch.float64))
    other = base + dtheta * unit(torch.randn(n, 1, 3, generator=g, dtype=torch.float64))
    aa = base.to(dtype).requires_grad_()
    zero = torch.zeros(n, 1, 3, dtype=dtype)
    d = pose_distance(pose_vec_to_mat(aa, zero), pose_vec_to_mat(other.to(dtype), zero))
    d.sum().backward()
    return d.detach().double(), aa.grad.double()[:, 0]


@pytest.mark.parametrize("dtheta", [1e-4, 1e-3])
def test_pose_distance_is_accurate_in_float32_near_agreement(dtheta):
    # The trace form 1 − (tr − 1)/2 returns exact zeros for half of these pairs at 1e-4 rad and
    # gradients of the wrong sign for a fifth of them.
    ref, ref_grad = _rotation_pairs(1000, dtheta, torch.float64)
    val, grad = _rotation_pairs(1000, dtheta, torch.float32)
    assert ref.min() > 0
    assert ((val - ref).abs() / ref < 0.01).float().mean() == 1.0
    assert (torch.nn.functional.cosine_similarity(grad, ref_grad, dim=-1) > 0.99).float().mean() >= 0.99


def test_gradients_finite_at_zero_rotation():
    aa = torch.zeros(2, 1, 3, dtype=torch.float64, requires_grad=True)
    t = torch.zeros(2, 1, 3, dtype=torch.float64, requires_grad=True)
    T = pose_vec_to_mat(aa, t)
    W = torch.randn(4, 4, dtype=torch.float64)
    ((T * W).sum() + pose_distance(T, torch.eye(4, dtype=T.dtype).expand(2, 4, 4)).sum()).backward()
    assert torch.isfinite(aa.grad).all() and torch.isfinite(t.grad).all()
    # At e = 0, dR/de is the skew matrix: d/de_x Σ W∘R = W[2,1] − W[1,2], and so on.
    expected = torch.stack([W[2, 1] - W[1, 2], W[0, 2] - W[2, 0], W[1, 0] - W[0, 1]])
    assert torch.allclose(aa.grad[:, 0], expected.expand(2, 3), atol=1e-9)


def test_disp_to_depth_range():
    scaled, depth = disp_to_depth(torch.tensor([0.0, 1.0]), 0.1, 100.0)
    assert torch.allclose(depth, torch.tensor([100.0, 0.1]))
    assert torch.allclose(scaled * depth, torch.ones(2))


def test_scale_intrinsics_per_level():
    K = torch.tensor([[[0.58, 0, 0.5], [0, 1.92, 0.5], [0, 0, 1]]])
    for s in range(4):
        Ks = scale_intrinsics(K, 192 // 2**s, 640 // 2**s)
        assert Ks[0, 0, 0].item() == pytest.approx(0.58 * 640 / 2**s)
        assert Ks[0, 1, 2].item() == pytest.approx(0.5 * 192 / 2**s)


def test_backproject_project_round_trip():
    K = torch.tensor([[[50.0, 0, 15.5], [0, 50.0, 7.5], [0, 0, 1]]]).repeat(2, 1, 1)
    depth = torch.rand(2, 1, 16, 32) * 10 + 1
    pix = project(backproject(depth, K), K)
    v, u = torch.meshgrid(torch.arange(16.0), torch.arange(32.0), indexing="ij")
    assert torch.allclose(pix[:, 0], u.flatten().expand(2, -1), atol=1e-3)
    assert torch.allclose(pix[:, 1], v.flatten().expand(2, -1), atol=1e-3)


def test_identity_pose_reproduces_image_for_any_depth():
    img = torch.rand(3, 3, 24, 40)
    depth = torch.rand(3, 1, 24, 40) * 50 + 0.5
    K = torch.tensor([[30.0, 0, 20], [0, 30.0, 12], [0, 0, 1]]).expand(3, 3, 3)
    warped = warp(img, depth, torch.eye(4).expand(3, 4, 4), K)
    assert torch.allclose(warped, img, atol=1e-4)


def test_x_translation_shifts_pixels_by_fx_t_over_z():
    h, w, fx, z, tx = 8, 64, 40.0, 10.0, 1.0  # shift = fx·t/Z = 4 pixels
    ramp = torch.arange(w, dtype=torch.float32).expand(1, 1, h, w).clone()
    K = torch.tensor([[[fx, 0, w / 2], [0, fx, h / 2], [0, 0, 1]]])
    T = make_pose(torch.eye(3)[None], torch.tensor([[tx, 0.0, 0.0]]))
    warped = warp(ramp, torch.full((1, 1, h, w), z), T, K)
    shift = fx * tx / z
    # target pixel u samples the source at u + shift (the source camera sees the point moved by +t)
    assert torch.allclose(warped[..., : w - 5], ramp[..., : w - 5] + shift, atol=1e-3)


def test_bad_shapes_and_dtypes_name_the_argument():
    with pytest.raises(ValueError, match=r"axisangle.*\(\*, 1, 3\).*\(2, 3\)"):
        pose_vec_to_mat(torch.zeros(2, 3), torch.zeros(2, 1, 3))
    with pytest.raises(ValueError, match="translation"):
        pose_vec_to_mat(torch.zeros(2, 1, 3), torch.zeros(3, 1, 3))
    with pytest.raises(ValueError, match="T: expected a floating-point tensor"):
        invert_pose(torch.zeros(2, 4, 4, dtype=torch.long))
    with pytest.raises(ValueError, match="depth"):
        backproject(torch.zeros(2, 16, 32), torch.eye(3).expand(2, 3, 3))


@pytest.mark.parametrize("dtype", DTYPES)
def test_warping_a_flipped_frame_with_the_flipped_k_is_the_flipped_warp(dtype):
    # A mirror image is the view of the mirrored world: x ↦ −x turns T into S·T·S, S = diag(−1, 1, 1, 1).
    h, w = 24, 40
    K_norm = torch.tensor([[[0.7, 0, 0.43], [0, 1.9, 0.55], [0, 0, 1]]], dtype=dtype)  # off-centre cx
    src = torch.rand(1, 3, h, w, dtype=dtype)
    depth = torch.rand(1, 1, h, w, dtype=dtype) * 10 + 5
    T = pose_vec_to_mat(
        torch.tensor([[[0.02, -0.05, 0.01]]], dtype=dtype), torch.tensor([[[0.3, 0.1, -0.4]]], dtype=dtype)
    )
    S = torch.diag(torch.tensor([-1.0, 1, 1, 1], dtype=dtype))
    warped = warp(src, depth, T, scale_intrinsics(K_norm, h, w))
    flipped = warp(src.flip(-1), depth.flip(-1), S @ T @ S, scale_intrinsics(flip_intrinsics(K_norm, w), h, w))
    assert torch.allclose(
        flipped, warped.flip(-1), atol=1e-4 if dtype == torch.float32 else 1e-6
    )  # project() adds eps to z
    # cx ↦ 1 − cx, the first-order rule, is a pixel off
    naive = K_norm.clone()
    naive[0, 0, 2] = 1 - naive[0, 0, 2]
    off = warp(src.flip(-1), depth.flip(-1), S @ T @ S, scale_intrinsics(naive, h, w))
    assert (off - warped.flip(-1)).abs().max() > 0.05


@pytest.mark.parametrize("dtype", DTYPES)
def test_project_depth_gives_the_points_depth_in_the_source_camera_and_warps_grid(dtype):
    b, h, w = 2, 12, 20
    depth = torch.rand(b, 1, h, w, dtype=dtype) * 10 + 1
    T, K = random_pose(b, dtype), torch.tensor([[25.0, 0, 9.5], [0, 25.0, 5.5], [0, 0, 1]], dtype=dtype).expand(b, 3, 3)
    projected, grid = project_depth(depth, T, K)
    points = transform_points(T, backproject(depth, K))
    assert projected.shape == (b, 1, h, w) and grid.shape == (b, h, w, 2)
    assert torch.equal(projected.flatten(1), points[:, 2])
    # warp samples at exactly this grid: the same maths in the same order, so bit-identical
    assert torch.equal(grid, pixels_to_grid(project(points, K), h, w))
    src = torch.rand(b, 3, h, w, dtype=dtype)
    expected = torch.nn.functional.grid_sample(src, grid, padding_mode="border", align_corners=True)
    assert torch.equal(warp(src, depth, T, K), expected)
    # a pure translation along z: every point's depth grows by t_z
    Tz = make_pose(torch.eye(3, dtype=dtype).expand(b, 3, 3), torch.tensor([0.0, 0.0, 0.7], dtype=dtype).expand(b, 3))
    assert torch.allclose(project_depth(depth, Tz, K)[0], depth + 0.7, atol=TOL[dtype] * 10)
