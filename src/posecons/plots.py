"""Every figure of the package (PNG files, matplotlib Agg): evaluation (frame scales per sequence,
scale over time for the least consistent sequences as in the paper's Figure 1, the per-frame abs rel
histogram), training (validation curves), prediction (colour-mapped disparity, scale drift) and the
top view of a trajectory. Nothing else in the package imports matplotlib."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only; never needs a display
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .fileio import atomic_write  # noqa: E402

COLORMAP = "magma"


def _save(fig: plt.Figure, path: str | Path) -> Path:
    path = Path(path)
    fig.tight_layout()
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=120))
    plt.close(fig)
    return path


def _short(name: str) -> str:
    """'2011_09_26/2011_09_26_drive_0002_sync' → '09_26_0002' for axis labels."""
    base = name.rstrip("/").split("/")[-1]
    parts = base.split("_")
    return f"{parts[1]}_{parts[2]}_{parts[4]}" if len(parts) >= 5 and parts[3] == "drive" else base


def _by_sequence(scales: Sequence[float], sequences: Sequence[str]) -> dict[str, np.ndarray]:
    """Indices of the frames with a finite scale, per sequence, in first-seen order."""
    scales = np.asarray(scales, dtype=np.float64)
    names = np.asarray(sequences)
    groups = {name: np.flatnonzero((names == name) & np.isfinite(scales)) for name in dict.fromkeys(sequences)}
    return {name: idx for name, idx in groups.items() if idx.size}


def plot_scale_boxplot(scales: Sequence[float], sequences: Sequence[str], path: str | Path) -> Path:
    """Box plot of the per-frame median scales (N,) of each sequence."""
    scales = np.asarray(scales, dtype=np.float64)
    groups = _by_sequence(scales, sequences)
    fig, ax = plt.subplots(figsize=(max(6.0, 0.35 * len(groups) + 2), 4))
    ax.boxplot([scales[idx] for idx in groups.values()])
    ax.set_xticks(range(1, len(groups) + 1), [_short(n) for n in groups], rotation=90, fontsize=7)
    ax.set_ylabel("median scale  median(gt) / median(pred)")
    ax.set_title("Per-frame scale by sequence")
    return _save(fig, path)


def plot_scale_over_time(
    scales: Sequence[float], sequences: Sequence[str], frames: Sequence[int], path: str | Path, count: int = 5
) -> Path:
    """Scale against frame number for the ``count`` sequences with the largest σ/μ."""
    scales = np.asarray(scales, dtype=np.float64)
    frames = np.asarray(frames)
    groups = _by_sequence(scales, sequences)
    cv = {name: scales[idx].std() / scales[idx].mean() for name, idx in groups.items()}
    fig, ax = plt.subplots(figsize=(7, 4))
    for name in sorted(cv, key=cv.get, reverse=True)[:count]:
        idx = groups[name][np.argsort(frames[groups[name]], kind="stable")]
        ax.plot(frames[idx], scales[idx], marker=".", label=f"{_short(name)}  σ/μ={cv[name]:.3f}")
    ax.set_xlabel("frame")
    ax.set_ylabel("median scale")
    ax.set_title(f"Scale over time, the {min(count, len(cv))} least consistent sequences")
    ax.legend(fontsize=7)
    return _save(fig, path)


def plot_error_histogram(abs_rel: Sequence[float], path: str | Path, bins: int = 40) -> Path:
    """Histogram of per-frame abs rel (NaN entries, i.e. skipped frames, are left out)."""
    values = np.asarray(abs_rel, dtype=np.float64)
    values = values[np.isfinite(values)]
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.hist(values, bins=bins)
    ax.axvline(values.mean(), color="k", linestyle="--", label=f"mean {values.mean():.3f}")
    ax.set_xlabel("abs rel (per frame)")
    ax.set_ylabel("frames")
    ax.legend()
    return _save(fig, path)


def plot_trajectory_topview(
    poses: np.ndarray, path: str | Path, gt: np.ndarray | None = None, label: str = "camera"
) -> Path:
    """Top view (x right, z forward) of (N, 4, 4) camera → world poses, over (N, 4, 4) ground truth
    (then in metres) when given."""
    fig, ax = plt.subplots(figsize=(6, 6))
    if gt is not None:
        ax.plot(gt[:, 0, 3], gt[:, 2, 3], "k-", label="ground truth")
    ax.plot(poses[:, 0, 3], poses[:, 2, 3], "-", label=label)
    start = poses[0] if gt is None else gt[0]
    ax.plot(start[0, 3], start[2, 3], "ko", label="start")
    unit = "" if gt is None else " [m]"
    ax.set_xlabel(f"x{unit}")
    ax.set_ylabel(f"z{unit}")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend()
    return _save(fig, path)


def plot_validation(rows: Sequence[dict], path: str | Path) -> Path:
    """Validation photometric loss (and abs rel, where the records have it) against the training step;
    ``rows`` are the records of ``RUN/metrics.jsonl``."""
    steps = [r["step"] for r in rows]
    fig, ax = plt.subplots(figsize=(6, 3.5))
    ax.plot(steps, [r["val_photometric"] for r in rows], "o-", label="val photometric loss")
    ax.set_xlabel("step")
    ax.set_ylabel("photometric loss")
    handles = list(ax.get_lines())
    if "abs_rel" in rows[0]:
        ax2 = ax.twinx()
        handles += ax2.plot(steps, [r["abs_rel"] for r in rows], "s-", color="tab:red", label="val abs rel")
        ax2.set_ylabel("abs rel (median-scaled)", color="tab:red")
    ax.legend(handles=handles, loc="upper right")
    ax.set_title("validation during training")
    return _save(fig, path)


def colorize(disparity: np.ndarray, cmap: str = COLORMAP) -> np.ndarray:
    """(H, W) disparity → (H, W, 3) uint8, normalised per frame to [min, 95th percentile] so a few
    very near pixels do not wash out the rest."""
    lo, hi = float(disparity.min()), float(np.percentile(disparity, 95))
    norm = np.clip((disparity - lo) / max(hi - lo, 1e-12), 0, 1)
    return (matplotlib.colormaps[cmap](norm)[..., :3] * 255).astype(np.uint8)


def plot_scale_drift(
    indices: np.ndarray, scales: np.ndarray, scale: float, calibration: np.ndarray, path: str | Path
) -> Path:
    """Per-frame GT scale (N,) against frame index (N,), the sequence scale as a line, calibration
    frames marked."""
    fig, ax = plt.subplots(figsize=(7, 3.5))
    ax.plot(indices, scales, ".-", label="per-frame median(gt)/median(pred)")
    used = np.isin(indices, calibration)
    ax.plot(indices[used], scales[used], "o", mfc="none", label="calibration frames")
    ax.axhline(scale, color="k", linestyle="--", label=f"sequence scale {scale:.4g}")
    ax.set_xlabel("frame")
    ax.set_ylabel("scale")
    ax.legend(fontsize=8)
    return _save(fig, path)
