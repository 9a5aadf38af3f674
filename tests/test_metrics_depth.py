"""Depth metrics and the standard protocol (SPEC §9) on small hand-computed cases."""

import numpy as np
import pytest

from posecons.errors import PoseconsError
from posecons.metrics.depth import (
    MAX_DEPTH,
    MIN_DEPTH,
    compute_depth_metrics,
    depth_metrics,
    drift_stats,
    frame_scale,
    garg_crop_bounds,
    resize_disparity,
    scale_consistency,
    scale_vs_scene_depth,
    valid_mask,
)


def test_garg_crop_bounds_on_a_kitti_frame():
    # int(0.40810811·375) = 153, int(0.99189189·375) = 371, int(0.03594771·1242) = 44, int(0.96405229·1242) = 1197
    assert garg_crop_bounds(375, 1242) == (153, 371, 44, 1197)
    mask = valid_mask(np.full((375, 1242), 10.0, np.float32), "garg")
    rows, cols = np.nonzero(mask)
    assert (rows.min(), rows.max() + 1, cols.min(), cols.max() + 1) == (153, 371, 44, 1197)
    assert mask.sum() == (371 - 153) * (1197 - 44)


def test_mask_depth_limits():
    gt = np.zeros((375, 1242), np.float32)
    gt[200, 100:105] = [MIN_DEPTH, 0.5, 79.9, MAX_DEPTH, 120.0]
    assert valid_mask(gt, "garg")[200, 100:105].tolist() == [False, True, True, False, False]
    # Improved GT: finite gt > 0 everywhere, no crop and no 80 m cap.
    gt[0, :2] = [5.0, np.inf]
    assert valid_mask(gt, "none").sum() == 6


def test_a_depth_range_masks_dense_gt_everywhere_and_narrows_the_garg_mask():
    """Dense GT (crop none) with a range: min < gt < max strictly, NaN and inf out, no crop; with the Garg
    crop the range replaces 1e-3–80 m. Caught: a range ignored without the crop, or bounds taken as ≤."""
    gt = np.zeros((375, 1242), np.float32)
    gt[200, 100:107] = [0.1, 0.5, 9.9, 10.0, 30.0, np.nan, np.inf]
    gt[0, 0] = 5.0  # outside the Garg crop
    assert valid_mask(gt, "none", (0.1, 10.0))[200, 100:107].tolist() == [False, True, True] + [False] * 4
    assert valid_mask(gt, "none", (0.1, 10.0)).sum() == 3
    assert valid_mask(gt, "garg", (0.1, 10.0)).sum() == 2


def test_metrics_by_hand():
    gt = np.array([2.0, 4.0])
    pred = np.array([1.1, 5.0])
    m = compute_depth_metrics(gt, pred)
    assert m["abs_rel"] == pytest.approx((0.9 / 2 + 1 / 4) / 2)
    assert m["sq_rel"] == pytest.approx((0.81 / 2 + 1 / 4) / 2)
    assert m["rmse"] == pytest.approx(np.sqrt((0.81 + 1) / 2))
    assert m["rmse_log"] == pytest.approx(np.sqrt((np.log(2 / 1.1) ** 2 + np.log(0.8) ** 2) / 2))
    # ratios max(gt/pred, pred/gt) = 1.818 and 1.25; thresholds are strict: 1.25, 1.5625, 1.953
    assert (m["a1"], m["a2"], m["a3"]) == (0.0, 0.5, 1.0)


def test_resize_is_bilinear_half_pixel():
    disp = np.array([[1.0, 3.0]], np.float32)
    # Doubling the width with align_corners=False: centres at 0.25, 0.75, 1.25, 1.75 (edges clamp).
    assert resize_disparity(disp, 1, 4)[0].tolist() == pytest.approx([1.0, 1.5, 2.5, 3.0])


def _frame(gt_depth: float, pred_depth: float, shape=(375, 1242)) -> tuple[np.ndarray, np.ndarray]:
    """Constant GT and a constant predicted disparity at a quarter of the GT size."""
    gt = np.full(shape, gt_depth, np.float32)
    disp = np.full((shape[0] // 4, shape[1] // 4), 1.0 / pred_depth, np.float32)
    return disp, gt


def test_median_scaling_and_clamp():
    """Mutations caught: the median of the ratios gt/pred, or a ratio of means, as the frame scale."""
    # Three pixels, no crop: median(gt)/median(pred) = 4/3, while median(gt/pred) = 2 and
    # mean(gt)/mean(pred) = 9/4 (the ratios are 2, 1, 4).
    gt, pred = np.array([[2.0, 4.0, 12.0]], np.float32), np.array([[1.0, 4.0, 3.0]], np.float32)
    r = depth_metrics((1 / pred)[None], [gt], ["a"], scaling="frame", crop="none")
    assert r["scales"] == pytest.approx([4 / 3])
    # Scaled prediction 4/3, 16/3, 4 against 2, 4, 12: relative errors 1/3, 1/3, 2/3.
    assert r["abs_rel"] == pytest.approx(4 / 9)
    # No scaling: relative errors 1/2, 0, 3/4; a prediction of 500 m is clamped to 80 m.
    unscaled = depth_metrics((1 / pred)[None], [gt], ["a"], scaling="none", crop="none")
    assert unscaled["abs_rel"] == pytest.approx(5 / 12)
    far, gt = _frame(10.0, 500.0)
    assert depth_metrics(far[None], [gt], ["a"], scaling="none")["abs_rel"] == pytest.approx(7.0)
    # The clamp comes after scaling: a 0.5 m prediction scaled ×200 (GT 100 m, improved GT) is cut to 80 m.
    gt100 = np.full((8, 8), 100.0, np.float32)
    r = depth_metrics(np.full((1, 4, 4), 2.0, np.float32), [gt100], ["a"], crop="none")
    assert r["scales"] == pytest.approx([200.0]) and r["abs_rel"] == pytest.approx(0.2)


def test_a_depth_range_clamps_the_prediction_to_it():
    """GT 9 m, prediction 20 m: clamped to 10 m with the range 0.1–10 m (abs rel 1/9), to 80 m without
    (11/9); GT 8 m, prediction 0.01 m: raised to 0.1 m (abs rel 7.9/8)."""

    def abs_rel(gt: float, pred: float, depth_range=None) -> float:
        disp = np.full((1, 2, 2), 1 / pred, np.float32)
        gts = [np.full((2, 2), gt, np.float32)]
        return depth_metrics(disp, gts, ["a"], scaling="none", crop="none", depth_range=depth_range)["abs_rel"]

    assert abs_rel(9.0, 20.0, (0.1, 10.0)) == pytest.approx(1 / 9)
    assert abs_rel(9.0, 20.0) == pytest.approx(11 / 9)
    assert abs_rel(8.0, 0.01, (0.1, 10.0)) == pytest.approx(7.9 / 8)
    with pytest.raises(PoseconsError, match="depth range"):
        abs_rel(8.0, 4.0, (10.0, 0.1))


def test_sequence_scaling_uses_one_factor_per_sequence():
    # Sequence a: frame scales 2, 4, 6 → factor 4; sequence b: one frame with scale 3 → factor 3.
    frames = [_frame(10.0, 10.0 / s) for s in (2.0, 4.0, 6.0, 3.0)]
    disps = np.stack([f[0] for f in frames])
    gts = [f[1] for f in frames]
    r = depth_metrics(disps, gts, ["a", "a", "a", "b"], scaling="sequence")
    assert r["scales"] == pytest.approx([2.0, 4.0, 6.0, 3.0])
    # Scaled predictions in a: 20, 10, 6.67 m against 10 m → abs rel 1, 0, 1/3; b is exact.
    assert r["per_sequence"]["a"]["abs_rel"] == pytest.approx((1 + 0 + 1 / 3) / 3, rel=1e-5)
    assert r["per_sequence"]["b"]["abs_rel"] == pytest.approx(0.0, abs=1e-6)
    assert r["abs_rel"] == pytest.approx((1 + 0 + 1 / 3 + 0) / 4, rel=1e-5)
    assert depth_metrics(disps, gts, ["a", "a", "a", "b"], scaling="frame")["abs_rel"] == pytest.approx(0, abs=1e-6)


def test_scale_consistency_constant_and_linear_drift():
    """Mutations caught: sample σ (ddof=1); the pooled σ/μ as ``scale_cv``; σ of s/mean as σ/median."""
    assert scale_consistency([3.0] * 5, ["s"] * 5)["scale_cv"] == 0.0
    # Sequence d drifts linearly, 1, 2, 3: μ = 2, σ² = 2/3 (population σ); sequence c stays at 4.
    r = scale_consistency([1.0, 2.0, 3.0, 4.0, 4.0], ["d"] * 3 + ["c"] * 2)
    assert r["per_sequence"]["d"] == pytest.approx({"n": 3, "scale_mean": 2.0, "scale_cv": np.sqrt(2 / 3) / 2})
    assert r["per_sequence"]["c"] == {"n": 2, "scale_mean": 4.0, "scale_cv": 0.0}
    assert r["scale_cv"] == pytest.approx(np.sqrt(2 / 3) / 4)  # the mean over the two sequences
    # All five frames: mean 2.8, median 3, σ² = (1.8² + 0.8² + 0.2² + 2·1.2²) / 5 = 1.36.
    assert r["scale_cv_pooled"] == pytest.approx(np.sqrt(1.36) / 2.8)
    assert r["scale_std_over_median"] == pytest.approx(np.sqrt(1.36) / 3)
    assert r["scale_median"] == 3.0


def test_drifting_prediction_through_the_protocol():
    n, a = 6, 0.1
    frames = [_frame(10.0, 10.0 / (1 + a * i), shape=(40, 40)) for i in range(n)]
    r = depth_metrics(np.stack([f[0] for f in frames]), [f[1] for f in frames], ["s"] * n, crop="none")
    assert r["scale_cv"] == pytest.approx(a * np.sqrt((n**2 - 1) / 12) / (1 + a * (n - 1) / 2), rel=1e-5)


def test_frames_without_valid_gt_are_skipped_and_reported():
    disp, gt = _frame(10.0, 5.0)
    empty = np.zeros_like(gt)
    r = depth_metrics(np.stack([disp, disp]), [gt, empty], ["a", "a"])
    assert (r["n_frames"], r["n_skipped"], r["skipped"]) == (1, 1, [1])
    assert np.isnan(r["scales"][1]) and r["scales"][0] == pytest.approx(2.0)


@pytest.mark.parametrize("value", [np.nan, 0.0, -1.0])
def test_bad_disparities_name_the_input(value):
    disp, gt = _frame(10.0, 5.0)
    disp[3, 4] = value
    with pytest.raises(PoseconsError, match="pred.npy.*frame 0"):
        depth_metrics(disp[None], [gt], ["a"], pred_name="pred.npy")


def test_count_mismatch_names_both_inputs():
    disp, gt = _frame(10.0, 5.0)
    with pytest.raises(PoseconsError, match="pred.npy has 2 frames but gt.npz has 1"):
        depth_metrics(np.stack([disp, disp]), [gt], ["a"], pred_name="pred.npy", gt_name="gt.npz")


def test_frame_scale_takes_the_medians_over_the_mask_it_is_given():
    gt, pred = np.array([[2.0, 4.0, 12.0, 90.0]]), np.array([[1.0, 4.0, 3.0, 1.0]])
    assert frame_scale(gt, pred, valid_mask(gt, "none")) == pytest.approx(8 / 2)
    assert frame_scale(gt, pred, gt < MAX_DEPTH) == pytest.approx(4 / 3)  # the 90 m pixel left out
    assert np.isnan(frame_scale(gt, pred, np.zeros_like(gt, bool)))


def test_drift_stats_ignore_nan_and_measure_the_deviation_from_the_chosen_scale():
    stats = drift_stats(np.array([1.0, 2.0, np.nan, 3.0]), 2.0)
    assert stats["frames"] == 3 and stats["max_rel_deviation"] == pytest.approx(0.5)
    assert stats["cv"] == pytest.approx(np.std([1.0, 2.0, 3.0]) / 2.0)
    assert drift_stats(np.array([np.nan]), 1.0) == {}


def test_scale_vs_scene_depth_separates_scene_dependence_from_the_rest():
    depth = np.array([5.0, 8.0, 12.0, 20.0, 9.0, 6.0])
    # Compressed depth, pred ∝ gt^0.6: the scale is 2·gt^0.4, all of it explained by the scene.
    r = scale_vs_scene_depth(2 * depth**0.4, depth, ["a"] * 6)
    assert r["slope"] == pytest.approx(0.4) and r["corr"] == pytest.approx(1.0) and r["scale_cv_rest"] < 1e-12
    # Scales independent of the scene (alternating): slope 0, the whole σ/μ remains, jitter ≈ 0.1.
    alternating = np.array([1.0, 1.2, 1.0, 1.2])
    r = scale_vs_scene_depth(alternating, [7.0] * 4, ["b"] * 4)
    assert r["slope"] == 0.0 and r["scale_cv_rest"] == pytest.approx(alternating.std() / alternating.mean())
    assert r["jitter"] == pytest.approx(np.log(1.2) / np.sqrt(2))
    # Per sequence, then averaged: a scene-dependent and a constant sequence.
    both = scale_vs_scene_depth([*(2 * depth**0.4), 3.0, 3.0, 3.0], [*depth, 4.0, 9.0, 16.0], ["a"] * 6 + ["c"] * 3)
    assert both["slope"] == pytest.approx(0.2) and both["scale_cv_rest"] < 1e-12
