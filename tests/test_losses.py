import pytest
import torch

from posecons.geometry import invert_pose, pose_vec_to_mat
from posecons.losses import (
    cycle_loss,
    forward_backward_loss,
    identity_loss,
    min_reprojection,
    photometric_error,
    smoothness_loss,
    ssim_dissimilarity,
)


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
    img = torch.rand(1, 3, 8, 8)
    assert smoothness_loss(torch.full((1, 1, 8, 8), 0.3), img).item() == pytest.approx(0.0, abs=1e-7)
    disp = torch.zeros(1, 1, 8, 8)
    disp[..., 4:] = 1.0  # a disparity edge between columns 3 and 4
    flat, edge = torch.zeros(1, 3, 8, 8), torch.zeros(1, 3, 8, 8)
    edge[..., 4:] = 1.0  # an image edge at the same place makes the step cheaper
    assert smoothness_loss(disp, edge) < smoothness_loss(disp, flat)
    # scale invariance: the disparity is mean-normalised inside
    assert torch.allclose(smoothness_loss(disp * 7, flat), smoothness_loss(disp, flat))


def test_forward_backward_zero_for_exact_inverse():
    T = poses()
    assert forward_backward_loss(T, invert_pose(T)).item() == pytest.approx(0, abs=1e-9)
    assert forward_backward_loss(T, poses()).item() > 1e-3


def test_cycle_zero_for_exact_composition():
    first, second = poses(), poses()
    assert cycle_loss(second @ first, second, first).item() == pytest.approx(0, abs=1e-9)
    assert cycle_loss(first @ second, second, first).item() > 1e-3  # wrong order composes wrong poses


def test_identity_loss():
    aa, t = torch.zeros(3, 1, 3), torch.zeros(3, 1, 3)
    assert identity_loss(aa, t).item() == 0
    aa[0, 0, 0], t[1, 0, 2] = 0.3, -0.6
    assert identity_loss(aa, t).item() == pytest.approx(0.3)


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
