"""The demo pipeline end to end at toy size: every stage runs through the library functions the
commands call, and the report, plots and summary come out (learning itself is asserted in test_training's overfit)."""

import json

import pytest
import torch

from posecons.cli.demo import recipe, run_demo
from posecons.config import load_config, resolve_preset
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
    for key in ("abs_rel", "abs_rel_untrained", "scale_cv", "ate_mean", "minutes"):
        assert key in saved and saved[key] == summary[key] and saved[key] >= 0
    report = (out / "report.md").read_text()
    # The preset's precision "auto", resolved for this CPU, is recorded and reported.
    assert saved["precision"] == resolve_precision("auto", torch.device("cpu"))[0]
    assert f"with precision {saved['precision']}" in report
    assert "| untrained |" in report and f"| trained ({recipe(saved['config'])[0]}) |" in report
    assert "constant velocity" in report
    assert "stabilis" not in report and not (out / "eval" / "depth_stabilised.json").exists()  # removed
    # The demo evaluates the last step, chosen without ground truth, and the report says so.
    assert saved["checkpoint"]["selected_by"] == "none: the weights at that step"
    assert "last.pt, step 3; selected by: none: the weights at that step" in report
    for plot in (
        "validation.png",
        "scale_boxplot.png",
        "scale_over_time.png",
        "abs_rel_histogram.png",
        "trajectory.png",
    ):
        assert (out / "plots" / plot).stat().st_size > 1000
        assert f"plots/{plot}" in report


@pytest.mark.parametrize(
    "sets,label,words",
    [
        (["loss.constraints=[cyc]", "train.ema_decay=0"], "cyc", "the cycle constraint"),
        (
            ["loss.constraints=[]", "loss.far_rotation_weight=0", "loss.saturation_weight=0", "train.ema_decay=0"],
            "baseline",
            "no pose constraint",
        ),
        (
            [
                "loss.constraints=[fb,id]",
                "loss.far_rotation_weight=1",
                "loss.saturation_weight=1",
                "train.ema_decay=0.99",
            ],
            "fb, id, far rotation, wall, EMA",
            "the forward-backward constraint, the identity constraint, the far pixels' rotation (rotation factor 0.01), "
            "the wall on the disparity logits, a weight EMA of decay 0.99",
        ),
    ],
)
def test_the_report_names_what_the_run_trained_with(sets, label, words):
    """The report's row and sentence come from the run's config, so a changed preset or --set cannot
    leave them naming another recipe."""
    config = load_config(resolve_preset("synth/demo"), sets).to_dict()
    assert recipe(config)[0] == label and recipe(config)[1].startswith(words)
