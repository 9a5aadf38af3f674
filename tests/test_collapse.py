"""A collapsed depth is visible without ground truth: the signs on hand-made outputs, the watch's
persistence rule, and a run made to collapse (its disparity pinned at the far end from the start),
which training warns about in its log and train_summary.json and the demo fails on."""

import json
from pathlib import Path

import pytest
import torch

from posecons.checkpoint import save_checkpoint
from posecons.cli.demo import run_demo
from posecons.config import load_config, resolve_preset
from posecons.errors import Collapsed
from posecons.training.collapse import FLAT_SPREAD, CollapseWatch, collapse_signs, problems
from posecons.training.initial_weights import initial_model
from posecons.training.trainer import train
from tiny import TINY_MODEL

HEALTHY = {"warped_fraction": 0.7, "far_fraction": 0.0, "near_fraction": 0.0, "log_disp_spread": 0.4, "warp_gain": 0.2}


def outputs(disp: torch.Tensor, automask: torch.Tensor | None = None, gain: float = 0.1) -> dict:
    automask = torch.ones(disp.shape[0], *disp.shape[2:], dtype=torch.bool) if automask is None else automask
    return {"disp": {0: disp}, "automask": automask, "warp_gain": torch.tensor(gain)}


def test_signs_count_warped_pixels_pinned_ends_and_the_log_disparity_spread():
    disp = torch.full((2, 1, 4, 4), 0.5)
    disp[0, 0, 0] = 0.005  # 4 of 32 pixels pinned at the far end (small sigmoid = small disparity = far)
    disp[1, 0, 1, :2] = 0.995  # 2 of 32 pinned at the near end
    disp[1, 0, 2, :3] = 0.985  # near, but not pinned: neither end counts them
    automask = torch.zeros(2, 4, 4, dtype=torch.bool)
    automask[:, :3] = True  # a warped source won on 24 of 32 pixels
    signs = collapse_signs(outputs(disp, automask, gain=-0.25))
    spread = [torch.log(d.flatten()).std() for d in disp]
    assert signs["log_disp_spread"] == pytest.approx(float(sum(spread) / 2), rel=1e-6)
    assert {k: v for k, v in signs.items() if k != "log_disp_spread"} == {
        "warped_fraction": 0.75,
        "far_fraction": 0.125,
        "near_fraction": 0.0625,
        "warp_gain": -0.25,
    }
    # the spread is of each image's own log disparity: a depth scaled per image does not change it
    scaled = disp * torch.tensor([0.1, 1.0]).view(2, 1, 1, 1)
    assert collapse_signs(outputs(scaled))["log_disp_spread"] == pytest.approx(signs["log_disp_spread"], rel=1e-5)
    # a constant disparity in each image has no spread, however different the images are
    flat = torch.tensor([0.2, 0.6]).view(2, 1, 1, 1).expand(2, 1, 4, 4)
    assert collapse_signs(outputs(flat))["log_disp_spread"] == 0


@pytest.mark.parametrize(
    "change, kind",
    [
        ({"far_fraction": 0.9}, "far end"),
        ({"near_fraction": 0.6}, "near end"),
        ({"log_disp_spread": FLAT_SPREAD / 2}, "nearly constant"),
        ({"warp_gain": -0.01}, "no better than the unwarped"),
        ({"warp_gain": 0.0}, "no better than the unwarped"),
    ],
)
def test_each_sign_of_a_collapse_is_a_problem_and_a_healthy_step_has_none(change, kind):
    assert problems(HEALTHY) == {}
    found = problems({**HEALTHY, **change})
    assert len(found) == 1 and kind in next(iter(found.values()))
    assert problems({**HEALTHY, "warp_gain": float("nan")}) == {}  # no auto-mask: no verdict on the gain


def test_the_watch_warns_once_a_problem_persists_and_judges_the_end_on_the_last_steps():
    pinned = {**HEALTHY, "far_fraction": 1.0}
    watch = CollapseWatch(start=100)
    assert watch.update(50, pinned) == [] and watch.update(60, pinned) == []  # the warm-up: not judged
    assert watch.summary()["problems"] == []
    assert watch.update(100, pinned) == []  # once is not yet a collapse
    said = watch.update(110, pinned)
    assert len(said) == 1 and "far end" in said[0]
    assert watch.update(120, pinned) == []  # said once per streak
    assert watch.summary() == {"step": 120, "signs": pinned, "problems": said}
    assert watch.update(130, HEALTHY) == [] and watch.update(140, pinned) == []  # a new streak starts
    assert watch.update(150, pinned) == said  # and is said again
    # the end judges the mean of the last three logged steps: one healthy batch does not clear a
    # run that stays near no gain, and one bad batch does not condemn a healthy one
    wavering = CollapseWatch(start=0)
    for step, gain in ((400, -0.004), (450, 0.009), (500, -0.103)):
        wavering.update(step, {**HEALTHY, "warp_gain": gain})
    assert ["no better than the unwarped ones (gain -0.033)" in p for p in wavering.summary()["problems"]] == [True]
    for step, gain in ((400, 0.2), (450, 0.25), (500, -0.1)):
        wavering.update(step, {**HEALTHY, "warp_gain": gain})
    assert wavering.summary()["problems"] == []


@pytest.fixture(scope="module")
def data(make_synth) -> Path:
    return make_synth(2, 16, 192, 64, 3)


def pinned_far(config, path: Path) -> Path:
    """A checkpoint of ``config``'s untrained weights whose every disparity logit starts at −30: the
    sigmoid at 1e-13, the far end, where it passes no gradient."""
    model = initial_model(config, config.train.seed)
    for conv in model.depth_net.decoder.disp_convs.values():
        torch.nn.init.zeros_(conv[1].weight)
        torch.nn.init.constant_(conv[1].bias, -30.0)
    save_checkpoint(path, {"config": config.to_dict(), "model": model.state_dict()})
    return path


COLLAPSE_TEST = [*TINY_MODEL, "train.warmup_steps=0", "train.log_every=1", "train.val_every=off"]


def test_a_run_pinned_at_the_far_end_warns_in_its_log_and_its_summary(data, tmp_path, capsys):
    config = load_config(
        resolve_preset("synth/demo"), [*COLLAPSE_TEST, "train.max_steps=3", "model.frame_ids=[0,-1,1]"]
    )
    config.train.init_from = str(pinned_far(config, tmp_path / "pinned.pt"))
    train(config, data, tmp_path / "run", quiet=True)
    err = capsys.readouterr().err
    assert "warning: step 2: the disparity is pinned at the far end of its range on 100% of the pixels" in err
    assert "at the end of training the disparity is pinned at the far end" in err
    collapse = json.loads((tmp_path / "run" / "train_summary.json").read_text())["collapse"]
    assert collapse["step"] == 3 and collapse["signs"]["far_fraction"] == 1.0
    assert any("far end" in p for p in collapse["problems"])
    # the same run from its untrained weights is not pinned
    config.train.init_from = None
    train(config, data, tmp_path / "control", quiet=True)
    collapse = json.loads((tmp_path / "control" / "train_summary.json").read_text())["collapse"]
    assert collapse["signs"]["far_fraction"] == 0 and not any("end" in p for p in collapse["problems"])


@pytest.mark.slow
def test_the_demo_fails_on_a_collapsed_run_after_writing_its_report(tmp_path):
    config = load_config(resolve_preset("synth/demo"), COLLAPSE_TEST)
    init = pinned_far(config, tmp_path / "pinned.pt")
    sets = [*COLLAPSE_TEST[-3:], "train.max_steps=3", "train.batch_size=2", f"train.init_from={init}"]
    with pytest.raises(Collapsed, match="the depth collapsed in training: the disparity is pinned at the far end"):
        run_demo(
            tmp_path / "demo",
            synth={"drives": 2, "frames": 12, "width": 192, "height": 64, "neighbours": 3},
            overrides=sets,
        )
    report = (tmp_path / "demo" / "report.md").read_text()
    assert "**The depth collapsed in training**" in report
    assert json.loads((tmp_path / "demo" / "summary.json").read_text())["collapse"]["problems"]
