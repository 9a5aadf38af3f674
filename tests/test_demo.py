"""The demo pipeline end to end at toy size: every stage runs through the library functions the
commands call, and the report, plots and summary come out (learning itself is asserted in test_training's overfit)."""

import json

import pytest
import torch

from posecons.training.demo import run_demo
from posecons.training.precision import resolve_precision

pytestmark = pytest.mark.slow


def test_demo_writes_report_summary_and_plots(tmp_path):
    out = tmp_path / "demo"
    summary = run_demo(
        out,
        synth={"drives": 2, "frames": 14, "width": 192, "height": 64, "neighbours": 3},
        overrides=["train.max_steps=3", "train.val_every=3", "train.batch_size=2", "train.val_samples=4"],
    )
    saved = json.loads((out / "summary.json").read_text())
    for key in ("abs_rel", "abs_rel_untrained", "scale_cv", "scale_cv_stabilised", "ate_mean", "minutes"):
        assert key in saved and saved[key] == summary[key] and saved[key] >= 0
    report = (out / "report.md").read_text()
    # The preset's precision "auto", resolved for this CPU, is recorded and reported.
    assert saved["precision"] == resolve_precision("auto", torch.device("cpu"))[0]
    assert f"with precision {saved['precision']}" in report
    assert "| untrained |" in report and "| trained (cyc) |" in report and "constant velocity" in report
    # The stabilised row is the same predictions × the stabiliser's factors, not a copy of the plain row.
    stable = json.loads((out / "eval" / "depth_stabilised.json").read_text())
    assert stable["scale_cv"] == saved["scale_cv_stabilised"] != saved["scale_cv"]
    assert len(stable["stabiliser_factors"]) == stable["n_frames"] and "| trained + `predict --stabilise` |" in report
    # The demo evaluates the last step, chosen without ground truth, and the report says so.
    assert saved["checkpoint"]["selected_by"] == "none: the weights at that step"
    assert "last.pt, step 3; selected by: none: the weights at that step" in report
    for plot in (
        "validation.png",
        "scale_boxplot.png",
        "scale_over_time.png",
        "scale_over_time_stabilised.png",
        "abs_rel_histogram.png",
        "trajectory.png",
    ):
        assert (out / "plots" / plot).stat().st_size > 1000
        assert f"plots/{plot}" in report
