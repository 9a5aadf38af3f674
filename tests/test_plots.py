"""Every figure of posecons.plots is written as a PNG from small inputs; colorize maps to uint8 RGB."""

import matplotlib
import numpy as np
import pytest

from posecons import plots


def test_every_figure_is_written(tmp_path):
    scales = [1.0, 1.1, np.nan, 0.9, 1.2, 1.05]
    seqs = ["2011_09_26/2011_09_26_drive_0002_sync"] * 3 + ["b"] * 3
    poses = np.tile(np.eye(4), (5, 1, 1))
    poses[:, 2, 3] = np.arange(5)
    rows = [{"step": s, "val_photometric": 0.2 - 0.01 * s, "abs_rel": 0.4 - 0.02 * s} for s in (1, 2, 3)]
    written = [
        plots.plot_scale_boxplot(scales, seqs, tmp_path / "a" / "box.png"),  # creates the folder
        plots.plot_scale_over_time(scales, seqs, [0, 1, 2, 0, 1, 2], tmp_path / "time.png"),
        plots.plot_error_histogram([0.1, 0.2, np.nan, 0.15], tmp_path / "hist.png"),
        plots.plot_trajectory_topview(poses, tmp_path / "traj.png"),
        plots.plot_trajectory_topview(poses, tmp_path / "traj_gt.png", gt=poses, label="aligned"),
        plots.plot_validation(rows, tmp_path / "val.png"),
        plots.plot_scale_drift(np.arange(4), np.array([1.0, 1.1, 0.9, 1.0]), 1.0, np.arange(2), tmp_path / "drift.png"),
        plots.plot_scale_boxplots({"a": scales, "b": scales[::-1]}, seqs, tmp_path / "boxes.png", normalise=True),
        plots.plot_scales_over_time({"a": scales, "b": scales}, seqs, [0, 1, 2, 0, 1, 2], tmp_path / "t2.png", 1, True),
        plots.plot_paired_differences(
            [
                {"metric": m, "variant": v, "mean": 0.1, "low": -0.1, "high": 0.3}
                for m in ("abs rel", "σ/μ", "ATE", "δ")
                for v in ("a", "b")
            ],
            tmp_path / "paired.png",
        ),
    ]
    assert all(path.stat().st_size > 1000 for path in written)


def test_colorize_gives_rgb_bytes_of_the_same_size():
    color = plots.colorize(np.linspace(0.01, 1.0, 12).reshape(3, 4))
    assert color.shape == (3, 4, 3) and color.dtype == np.uint8
    assert not np.array_equal(color[0, 0], color[-1, -1])  # near and far get different colours


@pytest.mark.parametrize("cmap", ["magma", "viridis"])
def test_colorize_gives_the_colormaps_own_bytes(cmap):
    """The colour table gives what the colormap itself gives through (colours × 255) as uint8, at the
    ends of the range, on and beside each bin's edge, outside the range (clipped) and for NaN (black).
    Caught: rounding the bin (× (N − 1)), the top value past the table, NaN left to the table."""
    colours = matplotlib.colormaps[cmap]
    edges = np.arange(colours.N + 1) / colours.N
    values = np.concatenate(
        [edges, edges - 1e-9, edges + 1e-9, [-0.5, 1.5, np.nan], np.random.default_rng(0).random(500)]
    )
    got = plots.colorize(values[None], cmap=cmap, limits=(0.0, 1.0))
    want = (colours(np.clip(values, 0, 1))[..., :3] * 255).astype(np.uint8)
    want[np.isnan(values)] = 0
    np.testing.assert_array_equal(got[0], want)
