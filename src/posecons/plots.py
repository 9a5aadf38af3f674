"""Every figure of the package (PNG files, matplotlib Agg): evaluation (frame scales per sequence,
scale over time for the least consistent sequences as in the paper's Figure 1, for one run or
several side by side, the per-frame abs rel histogram), studies (paired differences), training (validation curves), prediction (colour-mapped disparity, scale drift) and the
top view of a trajectory, examples of depth beside its ground truth. Nothing else in the package imports matplotlib."""

from __future__ import annotations

from collections.abc import Sequence
from functools import cache
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


def short_name(name: str) -> str:
    """'2011_09_26/2011_09_26_drive_0002_sync' → '09_26_0002' for axis labels and table columns."""
    base = name.rstrip("/").split("/")[-1]
    parts = base.split("_")
    return f"{parts[1]}_{parts[2]}_{parts[4]}" if len(parts) >= 5 and parts[3] == "drive" else base


def _by_sequence(scales: Sequence[float], sequences: Sequence[str]) -> dict[str, np.ndarray]:
    """Indices of the frames with a finite scale, per sequence, in first-seen order."""
    scales = np.asarray(scales, dtype=np.float64)
    names = np.asarray(sequences)
    groups = {name: np.flatnonzero((names == name) & np.isfinite(scales)) for name in dict.fromkeys(sequences)}
    return {name: idx for name, idx in groups.items() if idx.size}


def _runs(runs: dict[str, Sequence[float]], normalise: bool) -> dict[str, np.ndarray]:
    """Each run's (N,) scales, divided by their median over all frames with ``normalise``: runs of a
    monocular network have arbitrary scales of their own, and only the spread is comparable."""
    arrays = {label: np.asarray(scales, dtype=np.float64) for label, scales in runs.items()}
    return {label: a / np.nanmedian(a) for label, a in arrays.items()} if normalise else arrays


def plot_scale_boxplot(scales: Sequence[float], sequences: Sequence[str], path: str | Path) -> Path:
    """Box plot of the per-frame median scales (N,) of each sequence."""
    return plot_scale_boxplots({"": scales}, sequences, path)


def plot_scale_boxplots(
    runs: dict[str, Sequence[float]], sequences: Sequence[str], path: str | Path, normalise: bool = False
) -> Path:
    """Per-frame median scales of each sequence, one box per run (label → (N,) scales of the same N
    frames, NaN = skipped) side by side; ``normalise`` divides each run's scales by their median."""
    arrays = _runs(runs, normalise)
    scored = np.isfinite(np.stack(list(arrays.values()))).any(axis=0)  # frames with a scale in some run
    groups = _by_sequence(np.where(scored, 1.0, np.nan), sequences)
    width = 0.8 / len(arrays)
    fig, ax = plt.subplots(figsize=(max(6.0, 0.35 * len(groups) * len(arrays) + 2), 4))
    for k, (label, scales) in enumerate(arrays.items()):
        data = [scales[idx][np.isfinite(scales[idx])] for idx in groups.values()]
        positions = np.arange(1, len(groups) + 1) + (k - (len(arrays) - 1) / 2) * width
        boxes = ax.boxplot(data, positions=positions, widths=0.9 * width, patch_artist=bool(label))
        if label:
            for box in boxes["boxes"]:
                box.set_facecolor(f"C{k}")
            boxes["boxes"][0].set_label(label)
    ax.set_xticks(range(1, len(groups) + 1), [short_name(n) for n in groups], rotation=90, fontsize=7)
    ax.set_ylabel("scale / median scale of the run" if normalise else "median scale  median(gt) / median(pred)")
    ax.set_title("Per-frame scale by sequence")
    if any(runs):
        ax.legend(fontsize=8)
    return _save(fig, path)


def plot_scale_over_time(
    scales: Sequence[float], sequences: Sequence[str], frames: Sequence[int], path: str | Path, count: int = 5
) -> Path:
    """Scale against frame number for the ``count`` sequences with the largest σ/μ."""
    return plot_scales_over_time({"": scales}, sequences, frames, path, count)


def plot_scales_over_time(
    runs: dict[str, Sequence[float]],
    sequences: Sequence[str],
    frames: Sequence[int],
    path: str | Path,
    count: int = 5,
    normalise: bool = False,
) -> Path:
    """Scale against frame number for the ``count`` sequences with the largest σ/μ in the first run,
    one colour per sequence and one line style per run (label → (N,) scales of the same N frames)."""
    arrays = _runs(runs, normalise)
    frames = np.asarray(frames)
    first = next(iter(arrays.values()))
    groups = _by_sequence(first, sequences)
    cv = {name: first[idx].std() / first[idx].mean() for name, idx in groups.items()}
    fig, ax = plt.subplots(figsize=(7, 4))
    for c, name in enumerate(sorted(cv, key=cv.get, reverse=True)[:count]):
        idx = groups[name][np.argsort(frames[groups[name]], kind="stable")]
        for k, (label, scales) in enumerate(arrays.items()):
            own = scales[idx].std() / scales[idx].mean()
            ax.plot(
                frames[idx],
                scales[idx],
                marker=".",
                color=f"C{c}",
                linestyle=("-", "--", ":", "-.")[k % 4],
                label=f"{label + '  ' if label else ''}{short_name(name)}  σ/μ={own:.3f}",
            )
    ax.set_xlabel("frame")
    ax.set_ylabel("scale / median scale of the run" if normalise else "median scale")
    order = "" if len(arrays) == 1 else f" (of {next(iter(runs))})"
    ax.set_title(f"Scale over time, the {min(count, len(cv))} least consistent sequences{order}")
    ax.legend(fontsize=7)
    return _save(fig, path)


def plot_paired_differences(rows: Sequence[dict], path: str | Path) -> Path:
    """One panel per metric: each variant's mean paired difference from the reference with its interval.
    ``rows``: dicts with ``metric``, ``variant``, ``mean``, ``low``, ``high`` (metrics in first-seen order)."""
    metrics = list(dict.fromkeys(r["metric"] for r in rows))
    cols = min(3, len(metrics))
    grid = (-(-len(metrics) // cols), cols)
    height = 0.35 * len(rows) / len(metrics) + 1.6
    fig, axes = plt.subplots(*grid, figsize=(3.6 * cols, height * grid[0]), squeeze=False)
    for ax in axes.flat[len(metrics) :]:
        ax.set_visible(False)
    for ax, metric in zip(axes.flat, metrics):
        mine = [r for r in rows if r["metric"] == metric]
        y = np.arange(len(mine))
        mean = np.array([r["mean"] for r in mine])
        err = np.abs(np.array([[r["low"] for r in mine], [r["high"] for r in mine]]) - mean)
        ax.errorbar(mean, y, xerr=err, fmt="o", capsize=3)
        ax.axvline(0, color="k", linewidth=0.8)
        ax.set_yticks(y, [r["variant"] for r in mine])
        ax.invert_yaxis()
        ax.set_title(metric, fontsize=9)
        ax.tick_params(axis="x", labelsize=7)
        ax.locator_params(axis="x", nbins=4)
    fig.suptitle("difference from the reference, mean over seeds with its 95 % t-interval", fontsize=9)
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
    poses: np.ndarray, path: str | Path, gt: np.ndarray | None = None, label: str = "camera", metres: bool = False
) -> Path:
    """Top view (x right, z forward) of (N, 4, 4) camera → world poses, over (N, 4, 4) ground truth
    (then in metres) when given; ``metres``: the poses are in metres without it."""
    fig, ax = plt.subplots(figsize=(6, 6))
    if gt is not None:
        ax.plot(gt[:, 0, 3], gt[:, 2, 3], "k-", label="ground truth")
    ax.plot(poses[:, 0, 3], poses[:, 2, 3], "-", label=label)
    start = poses[0] if gt is None else gt[0]
    ax.plot(start[0, 3], start[2, 3], "ko", label="start")
    unit = " [m]" if metres or gt is not None else " [model units]"
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


def colour_range(disparity: np.ndarray) -> tuple[float, float]:
    """[min, 95th percentile] of a disparity map (or a stack of them): a few very near pixels do not
    wash out the rest."""
    return float(disparity.min()), float(np.percentile(disparity, 95))


@cache
def _colour_table(cmap: str) -> np.ndarray:
    """(N, 3) uint8: the colormap's N colours as ``colorize`` writes them."""
    colours = matplotlib.colormaps[cmap]
    return (colours(np.arange(colours.N))[:, :3] * 255).astype(np.uint8)


def colorize(disparity: np.ndarray, cmap: str = COLORMAP, limits: tuple[float, float] | None = None) -> np.ndarray:
    """(H, W) disparity → (H, W, 3) uint8 over ``limits`` (default: :func:`colour_range` of this
    frame), NaN black. A sequence passes one range for all frames, so that colours do not flicker
    between frames and a change of scale shows as one. The colormap's own lookup (value × N, the top
    value in the last bin) through a table of its colours: the same bytes, twice as fast."""
    lo, hi = limits or colour_range(disparity)
    norm = np.clip((disparity - lo) / max(hi - lo, 1e-12), 0, 1)
    table = _colour_table(cmap)
    nan = np.isnan(norm)
    rgb = table[np.minimum(np.where(nan, 0, norm * len(table)).astype(np.intp), len(table) - 1)]
    rgb[nan] = 0
    return rgb


def plot_depth_examples(rows: Sequence[dict], path: str | Path) -> Path:
    """One row per frame: its image, the ground-truth depth and the scaled prediction, both drawn as
    inverse depth over the ground truth's colour range, so that a colour means one depth in both
    (black: no ground truth). ``rows``: dicts with ``title``, ``image`` ((H, W, 3) uint8), ``gt``
    ((H, W) metres, 0 where there is none) and ``pred`` ((H, W) metres)."""
    height, width = rows[0]["gt"].shape
    fig, axes = plt.subplots(len(rows), 3, figsize=(10, 10 / 3 * height / width * len(rows) + 0.4), squeeze=False)
    for ax_row, row in zip(axes, rows):
        valid = row["gt"] > 0
        limits = colour_range(1.0 / row["gt"][valid])
        gt = np.where(valid[..., None], colorize(1.0 / np.where(valid, row["gt"], 1.0), limits=limits), 0)
        panels = (row["image"], gt, colorize(1.0 / row["pred"], limits=limits))
        for ax, image, name in zip(ax_row, panels, (row["title"], "ground truth", "prediction (scaled)")):
            ax.imshow(image)
            ax.set_title(name, fontsize=8)
            ax.set_axis_off()
    return _save(fig, path)


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
