import math

import pytest
import torch
import torch.nn.functional as F

from posecons.geometry import invert_pose, make_pose, pose_vec_to_mat
from posecons.losses import (
    cycle_loss,
    depth_consistency_loss,
    far_rotation_loss,
    forward_backward_loss,
    identity_loss,
    min_reprojection,
    photometric_error,
    saturation_loss,
    smoothness_loss,
    ssim_dissimilarity,
    velocity_loss,
)
from sky import sky_view


def poses(b=4):
    return pose_vec_to_mat(torch.randn(b, 1, 3, dtype=torch.float64) * 0.1, torch.randn(b, 1, 3, dtype=torch.float64))


def test_ssim_of_image_with_itself_is_zero():
    x = torch.rand(2, 3, 10, 12)
    assert torch.allclose(ssim_dissimilarity(x, x), torch.zeros_like(x), atol=1e-5)
    assert ssim_dissimilarity(x, torch.rand(2, 3, 10, 12)).mean() > 0.1


def test_ssim_hand_computed_constant_images():
    # Constant images a, b: μ = a, b, σ = 0, so SSIM = (2ab + C1) / (a² + b² + C1).
    a, b, c1 = 0.2, 0.6, 0.01**2
    ssim = (2 * a * b + c1) / (a * a + b * b + c1)
    out = ssim_dissimilarity(
        torch.full((1, 1, 4, 4), a, dtype=torch.float64), torch.full((1, 1, 4, 4), b, dtype=torch.float64)
    )
    assert torch.allclose(out, torch.full_like(out, (1 - ssim) / 2), atol=1e-6)


def test_photometric_error_hand_checked():
    pred = torch.zeros(1, 3, 4, 4)
    target = torch.zeros(1, 3, 4, 4)
    target[:, 0] = 0.3  # one channel differs by 0.3 everywhere: mean_c L1 = 0.1
    a, b, c1 = 0.0, 0.3, 0.01**2
    dssim_c0 = (1 - (2 * a * b + c1) / (a * a + b * b + c1)) / 2
    expected = 0.85 * dssim_c0 / 3 + 0.15 * 0.1
    pe = photometric_error(pred, target)
    assert pe.shape == (1, 1, 4, 4)
    assert torch.allclose(pe, torch.full_like(pe, expected), atol=1e-6)


def test_automask_keeps_identity_pixels_when_source_equals_target():
    reproj = torch.full((2, 2, 5, 5), 0.5)  # warping made things worse
    identity = torch.zeros(2, 2, 5, 5)  # the unwarped source equals the target
    loss, keep = min_reprojection(reproj, identity)
    assert not keep.any()
    assert loss.abs().max() < 1e-4  # the identity term wins: no reprojection loss there
    loss, keep = min_reprojection(torch.zeros(2, 2, 5, 5), torch.full((2, 2, 5, 5), 0.5))
    assert keep.all()


def test_min_reprojection_takes_per_pixel_minimum():
    reproj = torch.tensor([[[[1.0, 0.2]], [[0.3, 0.9]]]])  # (B=1, S=2, H=1, W=2)
    loss, _ = min_reprojection(reproj)
    assert torch.allclose(loss, torch.tensor([[[0.3, 0.2]]]))


def test_smoothness_zero_for_constant_disparity_and_edge_aware():
    """Mutations caught: no mean normalisation; the channel sum in place of mean_c; the y term left out."""
    img = torch.rand(1, 3, 8, 8)
    assert smoothness_loss(torch.full((1, 1, 8, 8), 0.3), img).item() == pytest.approx(0.0, abs=1e-7)
    # A vertical step 1 → 3 between columns 3 and 4: mean 2, so the normalised step is 1, in one of
    # the 7 horizontal differences of each row; no vertical differences.
    disp = torch.ones(1, 1, 8, 8)
    disp[..., 4:] = 3.0
    flat, edge = torch.zeros(1, 3, 8, 8), torch.zeros(1, 3, 8, 8)
    edge[..., 4:] = torch.tensor([0.3, 0.6, 0.9])[:, None, None]  # an image edge there: mean_c |∂x I| = 0.6
    assert smoothness_loss(disp, flat).item() == pytest.approx(1 / 7)
    assert smoothness_loss(disp, edge).item() == pytest.approx(math.exp(-0.6) / 7)
    assert smoothness_loss(disp.mT, edge.mT).item() == pytest.approx(math.exp(-0.6) / 7)  # the same in y
    # scale invariance: the disparity is mean-normalised inside
    assert smoothness_loss(disp * 7, edge).item() == pytest.approx(math.exp(-0.6) / 7)


def test_forward_backward_zero_for_exact_inverse():
    T = poses()
    assert forward_backward_loss(T, invert_pose(T)).item() == pytest.approx(0, abs=1e-9)
    assert forward_backward_loss(T, poses()).item() > 1e-3


def test_cycle_zero_for_exact_composition():
    first, second = poses(), poses()
    assert cycle_loss(second @ first, second, first).item() == pytest.approx(0, abs=1e-9)
    assert cycle_loss(first @ second, second, first).item() > 1e-3  # wrong order composes wrong poses


def test_identity_loss():
    """Mutation caught: ‖·‖₂ instead of ‖·‖₁ (the vectors here have several non-zero entries)."""
    aa, t = torch.zeros(3, 1, 3), torch.zeros(3, 1, 3)
    assert identity_loss(aa, t).item() == 0
    aa[0, 0] = torch.tensor([0.3, -0.4, 0.0])  # ‖·‖₁ = 0.7, ‖·‖₂ = 0.5
    t[0, 0] = torch.tensor([0.1, 0.2, -0.2])  # ‖·‖₁ = 0.5, ‖·‖₂ = 0.3
    t[1, 0, 2] = -0.6
    assert identity_loss(aa, t).item() == pytest.approx((0.7 + 0.5 + 0.6 + 0) / 3)  # the mean over the batch


def test_velocity_loss_asks_for_lengths_in_proportion_to_the_distances():
    """Mutations caught: ‖·‖₁ instead of ‖·‖₂ (0.7 against 0.5 below), a squared error, no
    normalisation, a gradient through ŝ or the mean length."""
    t = torch.tensor([[[0.3, 0.4, 0.0]], [[0.0, -0.6, 0.8]]], requires_grad=True)  # lengths 0.5 and 1.0
    for d in ([0.5, 1.0], [5.0, 10.0]):  # any common scale is free
        assert velocity_loss(t, torch.tensor(d)).item() == pytest.approx(0, abs=1e-7)
    # d = (1, 1): ŝ = 1.5 / 2 = 0.75, |0.5 − 0.75| + |1.0 − 0.75| = 0.5, / 2 pairs / mean length 0.75
    loss = velocity_loss(t, torch.tensor([1.0, 1.0]))
    assert loss.item() == pytest.approx(0.5 / 2 / 0.75)
    assert velocity_loss(3 * t, torch.tensor([1.0, 1.0])).item() == pytest.approx(loss.item())  # no pull to shrink
    loss.backward()
    # descending the gradient lengthens the shorter translation and shortens the longer one, by the same amount
    assert (t.grad[0] * t[0]).sum() < 0 and (t.grad[1] * t[1]).sum() > 0
    assert t.grad[0].norm().item() == pytest.approx(t.grad[1].norm().item()) == pytest.approx(1 / 2 / 0.75)
    assert velocity_loss(t, torch.tensor([0.0, 0.0])).item() == pytest.approx(1.0)  # standing still: no translation
    # lengths 1, 1, 4 against equal distances: ŝ = 2, and with ŝ and the mean length detached each
    # gradient is sign(‖t‖ − ŝd) along t / (3 pairs · mean length 2)
    u = torch.tensor([[[1.0, 0, 0]], [[0, 1.0, 0]], [[0, 0, 4.0]]], requires_grad=True)
    velocity_loss(u, torch.ones(3)).backward()
    expected = torch.tensor([[[-1.0, 0, 0]], [[0, -1.0, 0]], [[0, 0, 1.0]]]) / 6
    assert torch.allclose(u.grad, expected)
    with pytest.raises(ValueError, match="distance"):
        velocity_loss(t, torch.ones(3))


def test_bad_inputs_raise_value_error():
    with pytest.raises(ValueError, match="target"):
        photometric_error(torch.rand(1, 3, 4, 4), torch.rand(1, 3, 4, 5))
    with pytest.raises(ValueError, match="x: expected a floating-point"):
        ssim_dissimilarity(torch.zeros(1, 3, 4, 4, dtype=torch.uint8), torch.rand(1, 3, 4, 4))
    with pytest.raises(ValueError, match="axisangle"):
        identity_loss(torch.zeros(3, 3), torch.zeros(3, 1, 3))


def test_ssim_matches_window_by_window_formula():
    # SSIM from its definition, one 3×3 reflection-padded window at a time, in float64.
    import numpy as np

    rng = np.random.default_rng(0)
    x, y = rng.random((2, 6, 7)), rng.random((2, 6, 7))
    c1, c2 = 0.01**2, 0.03**2
    px, py = np.pad(x, ((0, 0), (1, 1), (1, 1)), mode="reflect"), np.pad(y, ((0, 0), (1, 1), (1, 1)), mode="reflect")
    expected = np.zeros_like(x)
    for c, i, j in np.ndindex(*x.shape):
        a, b = px[c, i : i + 3, j : j + 3], py[c, i : i + 3, j : j + 3]
        cov = (a * b).mean() - a.mean() * b.mean()
        ssim = ((2 * a.mean() * b.mean() + c1) * (2 * cov + c2)) / (
            (a.mean() ** 2 + b.mean() ** 2 + c1) * (a.var() + b.var() + c2)
        )
        expected[c, i, j] = np.clip((1 - ssim) / 2, 0, 1)
    out = ssim_dissimilarity(torch.from_numpy(x)[None], torch.from_numpy(y)[None])[0].numpy()
    assert np.allclose(out, expected, atol=1e-12)


@pytest.mark.parametrize("dtype, atol", [(torch.float32, 1e-4), (torch.float64, 1e-12)])
def test_photometric_error_with_separable_box_filter_equals_the_pooled_form(dtype, atol):
    # The 3×3 means are two separable sums of shifted views for speed; the reference below is the
    # pooling form (Monodepth2's). The loss value equals it to 1e-6 in float32, its gradient to float rounding.
    def pooled_ssim(x, y):
        c1, c2 = 0.01**2, 0.03**2
        x, y = F.pad(x, (1, 1, 1, 1), mode="reflect"), F.pad(y, (1, 1, 1, 1), mode="reflect")
        mu_x, mu_y = F.avg_pool2d(x, 3, 1), F.avg_pool2d(y, 3, 1)
        var_x, var_y = F.avg_pool2d(x * x, 3, 1) - mu_x**2, F.avg_pool2d(y * y, 3, 1) - mu_y**2
        cov = F.avg_pool2d(x * y, 3, 1) - mu_x * mu_y
        ssim = ((2 * mu_x * mu_y + c1) * (2 * cov + c2)) / ((mu_x**2 + mu_y**2 + c1) * (var_x + var_y + c2))
        return ((1 - ssim) / 2).clamp(0, 1)

    g = torch.Generator().manual_seed(0)
    target = F.avg_pool2d(torch.rand(2, 3, 34, 50, generator=g, dtype=dtype), 3, 1)  # smooth, image-like
    pred = (target + 0.05 * torch.randn(target.shape, generator=g, dtype=dtype)).clamp(0, 1).requires_grad_()
    expected = 0.85 * pooled_ssim(pred, target).mean(1, keepdim=True) + 0.15 * (pred - target).abs().mean(
        1, keepdim=True
    )
    (grad_expected,) = torch.autograd.grad(expected.mean(), pred)
    out = photometric_error(pred, target)
    (grad,) = torch.autograd.grad(out.mean(), pred)
    assert torch.allclose(out, expected, rtol=0, atol=atol)
    assert abs(out.mean().item() - expected.mean().item()) <= (1e-6 if dtype == torch.float32 else 1e-14)
    relative = (grad - grad_expected).norm() / grad_expected.norm()
    assert relative <= (1e-4 if dtype == torch.float32 else 1e-12), relative


def plane_seen_after(t, dtype=torch.float64, b=2, h=16, w=24, z=10.0, f=20.0):
    """A fronto-parallel plane at depth z seen by the target, the motion T_{f←0} = [I | t] and pixel K.
    After any such translation the plane is still fronto-parallel, at depth z + t_z in camera f."""
    K = torch.tensor([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1]], dtype=dtype).expand(b, 3, 3)
    T = make_pose(torch.eye(3, dtype=dtype).expand(b, 3, 3), torch.tensor(t, dtype=dtype).expand(b, 3))
    return torch.full((b, 1, h, w), z, dtype=dtype), T, K


@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
@pytest.mark.parametrize("t", [(0.0, 0.0, 0.5), (0.0, 0.0, -0.8), (0.3, -0.2, 0.5)])
def test_depth_consistency_is_zero_for_consistent_depth_and_pose(dtype, t):
    depth, T, K = plane_seen_after(t, dtype)
    source = torch.full_like(depth, 10.0 + t[2])  # D_f: the plane's depth in camera f, everywhere
    assert depth_consistency_loss(depth, source, T, K).item() == pytest.approx(0, abs=1e-6)
    assert depth_consistency_loss(depth, source * 1.01, T, K).item() > 1e-3


def test_depth_consistency_grows_with_inconsistency_as_the_closed_form():
    depth, T, K = plane_seen_after((0.1, 0.0, 0.5))
    values = []
    for s in (1.1, 1.3, 2.0):  # D_f = s·D_{0→f} at every pixel: D_diff = |s − 1| / (s + 1)
        values.append(depth_consistency_loss(depth, torch.full_like(depth, s * 10.5), T, K).item())
        assert values[-1] == pytest.approx(abs(s - 1) / (s + 1), rel=1e-9)
    assert values[0] < values[1] < values[2]
    under = depth_consistency_loss(depth, torch.full_like(depth, 10.5 / 1.3), T, K).item()
    assert under == pytest.approx(values[1], rel=1e-9)  # a source that is 1.3× too near costs the same


def test_depth_consistency_counts_only_pixels_that_land_inside_the_source():
    h, w, z, f = 16, 24, 10.0, 20.0
    depth, T, K = plane_seen_after((3.5 * z / f, 0.0, 0.0), h=h, w=w, z=z, f=f)  # target u lands at u + 3.5
    source = torch.full_like(depth, z)
    source[..., -1] = 5 * z  # wrong in the last column only
    # Of each row, u = 0 … W−5 land inside; only u = W−5 reaches the last column, at W−1.5, where the
    # bilinear sample is 3z: D_diff = 2z / 4z. The 4 pixels beyond the edge (border value 5z) do not count.
    loss = depth_consistency_loss(depth, source, T, K)
    assert loss.item() == pytest.approx(0.5 / (w - 4), rel=1e-6)  # project() adds eps to z
    # Points behind camera f land nowhere: nothing counts, and the gradient is zero, not NaN.
    depth.requires_grad_()
    _, behind, _ = plane_seen_after((0.0, 0.0, -2 * z), h=h, w=w, z=z, f=f)
    loss = depth_consistency_loss(depth, source, behind, K)
    loss.backward()
    assert loss.item() == 0 and torch.equal(depth.grad, torch.zeros_like(depth))


def _random_consistency_case(dtype):
    g = torch.Generator().manual_seed(1)
    depth = (torch.rand(2, 1, 12, 20, generator=g, dtype=torch.float64) * 5 + 2).to(dtype).requires_grad_()
    source = (torch.rand(2, 1, 12, 20, generator=g, dtype=torch.float64) * 5 + 2).to(dtype).requires_grad_()
    T = pose_vec_to_mat(
        (torch.randn(2, 1, 3, generator=g, dtype=torch.float64) * 0.02).to(dtype),
        (torch.randn(2, 1, 3, generator=g, dtype=torch.float64) * 0.3).to(dtype),
    )
    K = torch.tensor([[18.0, 0, 9.5], [0, 18.0, 5.5], [0, 0, 1]], dtype=dtype).expand(2, 3, 3)
    loss = depth_consistency_loss(depth, source, T, K)
    loss.backward()
    return loss.detach(), depth.grad, source.grad


def test_depth_consistency_gradients_reach_both_depths_and_float32_agrees_with_float64():
    ref, ref_target_grad, ref_source_grad = _random_consistency_case(torch.float64)
    val, target_grad, source_grad = _random_consistency_case(torch.float32)
    assert 0.05 < ref.item() < 1  # a real inconsistency, not the zero of an empty mask
    for grad in (ref_target_grad, ref_source_grad):
        assert torch.isfinite(grad).all() and grad.abs().sum() > 0
    assert val.item() == pytest.approx(ref.item(), rel=1e-5)
    assert torch.allclose(target_grad.double(), ref_target_grad, rtol=1e-3, atol=1e-7)
    assert torch.allclose(source_grad.double(), ref_source_grad, rtol=1e-3, atol=1e-7)


SKY_H, SKY_W = 64, 96
SKY_K = torch.tensor([[0.58 * SKY_W, 0, 0.5 * SKY_W], [0, 1.92 * SKY_H, 0.5 * SKY_H], [0, 0, 1]], dtype=torch.float64)


def rotation(axisangle) -> torch.Tensor:
    e = torch.as_tensor(axisangle, dtype=torch.float64).view(1, 1, 3)
    return pose_vec_to_mat(e, torch.zeros_like(e))[0, :3, :3]


def far_rotation(target, sources, rotations, depth, fraction=1.0):
    """far_rotation_loss of (B, 3, H, W) targets, (B, S, 3, H, W) sources, (B, S, 3, 3) float64 R."""
    K = SKY_K.float().expand(len(target), 3, 3)
    return far_rotation_loss(target, sources, rotations.float(), K, depth, fraction)


def test_far_rotation_loss_is_least_at_the_true_rotation_and_its_gradient_turns_toward_it():
    """A sky at infinity before and after a turn of 2.4° (mostly yaw): the source warped by the true
    rotation reproduces the target up to interpolation; no turn, the opposite turn (Rᵀ: the
    convention swapped) and the same angle about the pitch axis do not. From no turn, the gradient's
    descent turns toward the true rotation, about the yaw axis most. Caught: R transposed, a translation or the depth let in."""
    true = torch.tensor([0.005, 0.04, 0.008])
    target = sky_view(torch.eye(3, dtype=torch.float64), SKY_K, SKY_H, SKY_W)[None]
    source = sky_view(rotation(true), SKY_K, SKY_H, SKY_W)[None, None]
    depth = torch.ones(1, 1, SKY_H, SKY_W, requires_grad=True)

    def loss(R):
        return far_rotation(target, source, R[None, None], depth)

    at_truth = loss(rotation(true))
    assert at_truth < 0.002
    assert loss(torch.eye(3, dtype=torch.float64)) > 10 * at_truth
    assert loss(rotation(true).T) > 2 * loss(torch.eye(3, dtype=torch.float64))
    assert loss(rotation([true.norm(), 0, 0])) > 10 * at_truth
    w = torch.zeros(3, dtype=torch.float64, requires_grad=True)
    loss(rotation(w)).backward()
    descent = -w.grad
    assert descent @ true.double() > 0 and descent.abs().argmax() == 1  # toward the turn, mostly its yaw
    assert depth.grad is None  # the ranking only: no gradient to the depth


def test_far_rotation_loss_pairs_each_sample_and_source_with_its_own_rotation():
    """Two samples, two sources each, four different turns: each (sample, source) pair warped by its
    own rotation explains the sky; the (B, S) rotations read in (S, B) order do not."""
    turns = torch.tensor([[[0, 0.03, 0], [0, -0.02, 0.01]], [[0.01, 0.05, 0], [0, -0.04, 0]]], dtype=torch.float64)
    R = torch.stack([torch.stack([rotation(t) for t in sample]) for sample in turns])
    target = sky_view(torch.eye(3, dtype=torch.float64), SKY_K, SKY_H, SKY_W).expand(2, 3, SKY_H, SKY_W)
    sources = torch.stack([torch.stack([sky_view(r, SKY_K, SKY_H, SKY_W) for r in sample]) for sample in R])
    depth = torch.ones(2, 1, SKY_H, SKY_W)
    right = far_rotation(target, sources, R, depth)
    assert right < 0.002
    assert far_rotation(target, sources, R.transpose(0, 1).reshape(R.shape), depth) > 10 * right


def test_far_rotation_loss_counts_only_the_farthest_fraction_by_depth():
    """The source's rows below the top 40 % replaced by noise (what the translation moves in a real
    scene), the depth falling from the top row down: the far third's loss at the true rotation is the
    clean sky's; with the depth's order reversed (the far third in the noise), or every pixel counted,
    it is not. Caught: the quantile taken from the near end, disparity ranked as depth."""
    R = rotation([0.0, 0.03, 0.0])
    target = sky_view(torch.eye(3, dtype=torch.float64), SKY_K, SKY_H, SKY_W)[None]
    clean = sky_view(R, SKY_K, SKY_H, SKY_W)[None, None]
    noisy = clean.clone()
    noisy[..., int(0.4 * SKY_H) :, :] = torch.rand_like(noisy[..., int(0.4 * SKY_H) :, :])
    falling = (100.0 / (1 + torch.arange(SKY_H, dtype=torch.float32))).view(1, 1, SKY_H, 1).expand(1, 1, SKY_H, SKY_W)
    far_third = far_rotation(target, noisy, R[None, None], falling, 1 / 3)
    assert far_third.item() == pytest.approx(
        far_rotation(target, clean, R[None, None], falling, 1 / 3).item(), abs=1e-6
    )
    assert far_third < 0.002
    assert far_rotation(target, noisy, R[None, None], falling.flip(2), 1 / 3) > 0.05
    assert far_rotation(target, noisy, R[None, None], falling, 1.0) > 10 * far_third


def test_saturation_loss_is_zero_inside_the_bound_and_the_squared_excess_beyond_it_averaged_over_scales():
    inside = [torch.tensor([[-4.5, 0.0], [3.0, 4.5]]).view(1, 1, 2, 2), torch.full((1, 1, 1, 2), -4.0)]
    assert saturation_loss(inside, 4.6).item() == 0.0
    fine = torch.tensor([7.6, -6.6, 0.0, 4.6]).view(1, 1, 2, 2).requires_grad_()  # excess 3, 2, 0, 0
    coarse = torch.tensor([5.6, 1.0]).view(1, 1, 1, 2).requires_grad_()  # excess 1, 0
    loss = saturation_loss([fine, coarse], 4.6)
    assert loss.item() == pytest.approx(((9 + 4) / 4 + 1 / 2) / 2, rel=1e-6)
    loss.backward()
    # Descent moves each logit beyond the bound back toward it (2·excess / pixels / scales) and no other.
    torch.testing.assert_close(fine.grad.flatten(), torch.tensor([3.0, -2.0, 0.0, 0.0]) * 2 / 4 / 2)
    torch.testing.assert_close(coarse.grad.flatten(), torch.tensor([1.0, 0.0]) * 2 / 2 / 2)
