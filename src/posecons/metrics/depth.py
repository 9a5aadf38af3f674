"""Depth metrics, scale statistics and the standard KITTI depth protocol (SPEC §9).

Plain numpy functions, cheap enough for training-time validation. The protocol:
resize the predicted (scaled) disparity bilinearly to the GT size (``align_corners=False``),
depth = 1 / disparity, mask the valid GT pixels, scale (per frame, per sequence or not at all),
clamp the prediction to [1e-3, 80] m (or to a depth range of the user's, as dense indoor GT needs),
then average the per-frame metrics over frames.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..errors import PoseconsError

MIN_DEPTH = 1e-3
MAX_DEPTH = 80.0
# Garg et al.'s crop as fractions of (H, W): rows [top, bottom), cols [left, right).
GARG_CROP = (0.40810811, 0.99189189, 0.03594771, 0.96405229)
METRIC_NAMES = ("abs_rel", "sq_rel", "rmse", "rmse_log", "a1", "a2", "a3")
SCALINGS = ("frame", "sequence", "none")
CROPS = ("garg", "none")
# Which mask each kind of ground truth is evaluated with (dense: depth images of an RGB-D camera).
CROP_FOR_GT_KIND = {"lidar": "garg", "improved": "none", "dense": "none"}


def garg_crop_bounds(height: int, width: int) -> tuple[int, int, int, int]:
    """(top, bottom, left, right) pixel bounds of the Garg crop; int() of each fractional bound."""
    top, bottom, left, right = GARG_CROP
    return int(top * height), int(bottom * height), int(left * width), int(right * width)


def valid_mask(gt: np.ndarray, crop: str = "garg", depth_range: tuple[float, float] | None = None) -> np.ndarray:
    """Boolean (H, W) mask of the GT pixels that are evaluated.

    ``garg``: min < gt < max inside the Garg crop, (min, max) = ``depth_range`` or (1e-3, 80) m
    (Eigen split, LiDAR GT); ``none``: finite gt > 0 everywhere (KITTI improved GT, eigen_benchmark),
    or min < gt < max everywhere when ``depth_range`` is given (dense GT of an RGB-D camera).
    """
    if crop not in CROPS:
        raise PoseconsError(f"unknown crop {crop!r}; expected one of {CROPS}")
    if crop == "none" and depth_range is None:
        return np.isfinite(gt) & (gt > 0)
    low, high = depth_range or (MIN_DEPTH, MAX_DEPTH)
    mask = (gt > low) & (gt < high)  # NaN compares false: never valid
    if crop == "garg":
        top, bottom, left, right = garg_crop_bounds(*gt.shape)
        in_crop = np.zeros(gt.shape, dtype=bool)
        in_crop[top:bottom, left:right] = True
        mask &= in_crop
    return mask


def resize_disparity(disp: np.ndarray, height: int, width: int) -> np.ndarray:
    """Bilinearly resize a (h, w) disparity to (height, width), half-pixel centres (align_corners=False)."""
    if disp.shape == (height, width):
        return np.asarray(disp, dtype=np.float32)
    import torch  # here, not at the top: the CLI reads this module's constants without torch
    import torch.nn.functional as F

    t = torch.as_tensor(np.asarray(disp, dtype=np.float32))[None, None]
    return F.interpolate(t, size=(height, width), mode="bilinear", align_corners=False)[0, 0].numpy()


def compute_depth_metrics(gt: np.ndarray, pred: np.ndarray) -> dict[str, float]:
    """The seven standard metrics for one frame; gt and pred are matching 1-D arrays of valid depths (m)."""
    gt = np.asarray(gt, dtype=np.float64)
    pred = np.asarray(pred, dtype=np.float64)
    ratio = np.maximum(gt / pred, pred / gt)
    diff = gt - pred
    return {
        "abs_rel": float(np.mean(np.abs(diff) / gt)),
        "sq_rel": float(np.mean(diff**2 / gt)),
        "rmse": float(np.sqrt(np.mean(diff**2))),
        "rmse_log": float(np.sqrt(np.mean((np.log(gt) - np.log(pred)) ** 2))),
        "a1": float(np.mean(ratio < 1.25)),
        "a2": float(np.mean(ratio < 1.25**2)),
        "a3": float(np.mean(ratio < 1.25**3)),
    }


def frame_scale(gt: np.ndarray, pred: np.ndarray, mask: np.ndarray) -> float:
    """The frame's median scale median(gt) / median(pred) over the pixels of ``mask``; gt and pred are
    depths (H, W) at the GT size (pred resized as disparity, then inverted). NaN when ``mask`` is empty.

    The caller chooses the mask. :func:`depth_metrics` passes :func:`valid_mask` of its crop (the Garg
    crop and the 80 m cap for LiDAR GT): the published protocol, comparable with the literature.
    ``predict``'s calibration and drift pass ``valid_mask(gt, "none")`` (every finite gt > 0): its GT
    comes with any camera, not only the KITTI LiDAR the crop was cut for, and the scale it finds
    multiplies every pixel of the saved depth, far ones included.
    """
    if not mask.any():
        return float("nan")
    return float(np.median(gt[mask]) / np.median(pred[mask]))


def drift_stats(scales: np.ndarray, scale: float) -> dict:
    """σ/μ (population σ) of per-frame scales and their largest relative deviation from ``scale``."""
    scales = np.asarray(scales, dtype=np.float64)
    scales = scales[np.isfinite(scales)]
    if scales.size == 0:
        return {}
    return {
        "frames": int(scales.size),
        "cv": float(scales.std() / scales.mean()),
        "max_rel_deviation": float(np.abs(scales / scale - 1).max()),
        "mean": float(scales.mean()),
        "min": float(scales.min()),
        "max": float(scales.max()),
    }


def check_disparities(disps: np.ndarray, name: str = "predictions") -> np.ndarray:
    """Validate (N, h, w) disparities (a singleton channel (N, 1, h, w) is squeezed); returns float32."""
    disps = np.asarray(disps)
    if disps.ndim == 4 and disps.shape[1] == 1:
        disps = disps[:, 0]
    if disps.ndim != 3:
        raise PoseconsError(f"{name}: expected disparities of shape (N, h, w), got {disps.shape}")
    disps = disps.astype(np.float32, copy=False)
    bad = ~np.isfinite(disps) | (disps <= 0)
    if bad.any():
        frames = np.flatnonzero(bad.any(axis=(1, 2)))
        raise PoseconsError(
            f"{name}: {int(bad.sum())} NaN/inf or non-positive disparities in {frames.size} frame(s), "
            f"first at frame {int(frames[0])}; disparities must be finite and > 0"
        )
    return disps


def scale_consistency(scales: Sequence[float], sequences: Sequence[str]) -> dict:
    """Scale consistency of per-frame median scales (N,) grouped by sequence name (N,).

    NaN scales (skipped frames) are ignored. σ is numpy's population std (ddof=0).
    Returns ``scale_cv`` (mean over sequences of σ/μ), ``scale_cv_pooled`` (σ/μ over all frames),
    ``scale_std_over_median`` (std(s / median(s)) over all frames, as Monodepth2 printed),
    ``scale_median`` and ``per_sequence`` {name: {n, scale_mean, scale_cv}} in first-seen order.
    """
    scales = np.asarray(scales, dtype=np.float64)
    if len(scales) != len(sequences):
        raise PoseconsError(f"{len(scales)} scales but {len(sequences)} sequence names")
    ok = np.isfinite(scales)
    if not ok.any():
        raise PoseconsError("no frame has a valid scale")
    per_sequence = {}
    for name in dict.fromkeys(sequences):
        s = scales[ok & (np.asarray(sequences) == name)]
        if s.size:
            per_sequence[name] = {
                "n": int(s.size),
                "scale_mean": float(s.mean()),
                "scale_cv": float(s.std() / s.mean()),
            }
    pooled = scales[ok]
    return {
        "scale_cv": float(np.mean([v["scale_cv"] for v in per_sequence.values()])),
        "scale_cv_pooled": float(pooled.std() / pooled.mean()),
        "scale_std_over_median": float(np.std(pooled / np.median(pooled))),
        "scale_median": float(np.median(pooled)),
        "per_sequence": per_sequence,
    }


def scale_vs_scene_depth(scales: Sequence[float], scene_depths: Sequence[float], sequences: Sequence[str]) -> dict:
    """How much of the per-frame scale variation follows the scene: per sequence, the least-squares
    slope of log scale on log scene depth (the frame's median ground-truth depth) and their
    correlation, σ/μ of the scale with that dependence divided out, and the frame-to-frame jitter
    rms(log s_{i+1} − log s_i)/√2 (σ for independent noise of σ in log s); each the mean over
    sequences, as ``scale_cv``. Slope 0: the scale ignores the scene. A depth net whose prediction
    grows like gt^(1−b) (compressed depth) has slope b: its scale varies with how far the scene is,
    however consistent it is over time."""
    scales, depths = np.log(np.asarray(scales, dtype=np.float64)), np.log(np.asarray(scene_depths, dtype=np.float64))
    if not len(scales) == len(depths) == len(sequences):
        raise PoseconsError(f"{len(scales)} scales, {len(depths)} scene depths, {len(sequences)} sequence names")
    rows = []
    for name in dict.fromkeys(sequences):
        m = (np.asarray(sequences) == name) & np.isfinite(scales) & np.isfinite(depths)
        s, d = scales[m], depths[m] - depths[m].mean()
        slope = float(d @ (s - s.mean()) / (d @ d)) if d.any() else 0.0
        corr = float(np.corrcoef(s, d)[0, 1]) if d.any() and s.std() > 0 else 0.0
        rest = np.exp(s - slope * d)
        rows.append((slope, corr, rest.std() / rest.mean(), np.sqrt(np.mean(np.diff(s) ** 2) / 2)))
    slope, corr, rest_cv, jitter = np.mean(rows, axis=0)
    return {"slope": float(slope), "corr": float(corr), "scale_cv_rest": float(rest_cv), "jitter": float(jitter)}


def scale_factors(scales: np.ndarray, sequences: Sequence[str], scaling: str, fixed: float = 1.0) -> np.ndarray:
    """(N,) factors that multiply each frame's predicted depth, from the (N,) frame scales (NaN = skipped);
    ``none`` gives ``fixed`` for every frame."""
    if scaling == "frame":
        return np.asarray(scales, dtype=np.float64)
    factors = np.full(len(scales), fixed)
    if scaling == "sequence":
        names = np.asarray(sequences)
        for name in dict.fromkeys(sequences):
            members = names == name
            if np.isfinite(scales[members]).any():  # a fully skipped sequence keeps 1 (never used)
                factors[members] = np.nanmedian(scales[members])
    return factors


def depth_metrics(
    pred_disps: np.ndarray | Sequence[np.ndarray],
    gt_depths: Sequence[np.ndarray],
    sequences: Sequence[str],
    scaling: str = "frame",
    crop: str = "garg",
    pred_name: str = "predictions",
    gt_name: str = "ground truth",
    scale_factor: float = 1.0,
    depth_range: tuple[float, float] | None = None,
) -> dict:
    """Evaluate N predicted disparities against N GT depth maps (split order).

    pred_disps: (N, h, w) scaled disparities; gt_depths: N arrays (H_i, W_i) in metres (0 = none);
    sequences: N sequence names (the split line's folder). ``scaling`` is ``frame``, ``sequence``
    (one factor per sequence: the median of its frame scales) or ``none``, which multiplies every
    depth by ``scale_factor`` instead (Monodepth2's 5.4 for stereo-trained models); ``crop`` is ``garg`` or
    ``none`` (see :func:`valid_mask`). ``depth_range`` (min, max) in metres: only GT strictly inside it
    is evaluated and the scaled prediction is clamped to it (None: the crop's protocol, clamp to
    [1e-3, 80]). Frames without valid GT pixels are skipped and listed.
    ``pred_name``/``gt_name`` name the inputs in error messages (e.g. file paths).

    Returns the metric means over evaluated frames plus ``scales`` (per-frame median ratios, NaN
    for skipped frames), the :func:`scale_consistency` keys, ``per_frame_abs_rel``,
    ``per_sequence`` ({name: {n, scale_mean, scale_cv, abs_rel}}), ``n_frames``, ``skipped``.
    """
    if scaling not in SCALINGS:
        raise PoseconsError(f"unknown scaling {scaling!r}; expected one of {SCALINGS}")
    if crop not in CROPS:
        raise PoseconsError(f"unknown crop {crop!r}; expected one of {CROPS}")
    if not (np.isfinite(scale_factor) and scale_factor > 0) or (scale_factor != 1.0 and scaling != "none"):
        raise PoseconsError(f"scale factor {scale_factor} needs scaling 'none' (not {scaling!r}) and must be > 0")
    if depth_range is not None and not (np.isfinite(depth_range).all() and 0 < depth_range[0] < depth_range[1]):
        raise PoseconsError(f"depth range {depth_range} must be two finite depths with 0 < min < max (metres)")
    disps = check_disparities(pred_disps, pred_name)
    if not (len(disps) == len(gt_depths) == len(sequences)):
        raise PoseconsError(
            f"{pred_name} has {len(disps)} frames but {gt_name} has {len(gt_depths)} "
            f"(and {len(sequences)} split lines); they must match one to one"
        )

    # Pass 1: valid pixels and the per-frame median scale of every frame.
    valid_pairs: list[tuple[np.ndarray, np.ndarray]] = []
    scales = np.full(len(disps), np.nan)
    for i, (disp, gt) in enumerate(zip(disps, gt_depths)):
        gt = np.asarray(gt, dtype=np.float32)
        if gt.ndim != 2:
            raise PoseconsError(f"{gt_name}: frame {i} has shape {gt.shape}, expected (H, W)")
        mask = valid_mask(gt, crop, depth_range)
        pred = 1.0 / resize_disparity(disp, *gt.shape)
        valid_pairs.append((gt[mask], pred[mask]))
        scales[i] = frame_scale(gt, pred, mask)  # NaN: no valid pixel, the frame is skipped
    evaluated = np.flatnonzero(np.isfinite(scales))
    if evaluated.size == 0:
        raise PoseconsError(f"{gt_name}: no frame has valid ground-truth pixels")

    # Pass 2: apply the chosen scaling, clamp, and compute the per-frame metrics.
    sequences = list(sequences)
    factors = scale_factors(scales, sequences, scaling, scale_factor)
    per_frame = {}
    for i in evaluated:
        gt, pred = valid_pairs[i]
        pred = np.clip(pred * factors[i], *(depth_range or (MIN_DEPTH, MAX_DEPTH)))
        per_frame[int(i)] = compute_depth_metrics(gt, pred)

    result: dict = {k: float(np.mean([m[k] for m in per_frame.values()])) for k in METRIC_NAMES}
    result.update(scaling=scaling, scale_factor=scale_factor, crop=crop, n_frames=int(evaluated.size))
    result.update(depth_range=None if depth_range is None else list(depth_range))
    result.update(scale_consistency(scales, sequences))
    for name, stats in result["per_sequence"].items():
        stats["abs_rel"] = float(np.mean([m["abs_rel"] for i, m in per_frame.items() if sequences[i] == name]))
    skipped = [i for i in range(len(disps)) if i not in per_frame]
    result.update(
        scales=[float(s) for s in scales],  # NaN for skipped frames; written as null in JSON
        per_frame_abs_rel=[per_frame[i]["abs_rel"] if i in per_frame else float("nan") for i in range(len(disps))],
        n_skipped=len(skipped),
        skipped=skipped,
    )
    return result
