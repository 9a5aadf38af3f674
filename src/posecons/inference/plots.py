"""Pictures of a prediction run: colour-mapped disparity, scale drift over time, trajectory top view."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only; never needs a display
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ..fileio import atomic_write  # noqa: E402

COLORMAP = "magma"


def colorize(disparity: np.ndarray, cmap: str = COLORMAP) -> np.ndarray:
    """(H, W) disparity → (H, W, 3) uint8, normalised per frame to [min, 95th percentile] so a few
    very near pixels do not wash out the rest."""
    lo, hi = float(disparity.min()), float(np.percentile(disparity, 95))
    norm = np.clip((disparity - lo) / max(hi - lo, 1e-12), 0, 1)
    return (matplotlib.colormaps[cmap](norm)[..., :3] * 255).astype(np.uint8)


def plot_scale_drift(indices: np.ndarray, scales: np.ndarray, scale: float, calibration: np.ndarray,
                     path: Path) -> None:
    """Per-frame GT scale against frame index, the sequence scale as a line, calibration frames marked."""
    fig, ax = plt.subplots(figsize=(7, 3.5))
    ax.plot(indices, scales, ".-", label="per-frame median(gt)/median(pred)")
    used = np.isin(indices, calibration)
    ax.plot(indices[used], scales[used], "o", mfc="none", label="calibration frames")
    ax.axhline(scale, color="k", linestyle="--", label=f"sequence scale {scale:.4g}")
    ax.set_xlabel("frame")
    ax.set_ylabel("scale")
    ax.legend(fontsize=8)
    fig.tight_layout()
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=110))
    plt.close(fig)


def plot_topview(poses: np.ndarray, path: Path) -> None:
    """Top view (x right, z forward) of (N, 4, 4) camera → world poses."""
    fig, ax = plt.subplots(figsize=(5, 5))
    ax.plot(poses[:, 0, 3], poses[:, 2, 3], "-", label="camera")
    ax.plot(poses[:1, 0, 3], poses[:1, 2, 3], "ko", label="start")
    ax.set_xlabel("x")
    ax.set_ylabel("z")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend()
    fig.tight_layout()
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=110))
    plt.close(fig)
