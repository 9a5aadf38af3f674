"""The lab's tools in experiments/tools: at_steps.py keeps a study run's weights at the asked steps only,
once per checkpoint write; adopt.py, automask_depth.py, camera_height.py, continue_runs.py,
early_steps.py, ema_decays.py, monodepth2_fp32.py, residual_regions.py, scale_components.py,
test_time_scale.py and weight_average.py as their tests say; a folder that is no
study is one line and exit status 2."""

from __future__ import annotations

import functools
import importlib.util
import json
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from posecons.checkpoint import load_checkpoint

TOOLS = Path(__file__).resolve().parents[1] / "experiments" / "tools"


def load_tool(name: str):
    """experiments/tools/<name>.py as a module (the tools are scripts, not a package: as when one runs,
    its folder is on sys.path for the siblings it imports)."""
    if str(TOOLS) not in sys.path:
        sys.path.insert(0, str(TOOLS))
    load = importlib.util.spec_from_file_location(name, TOOLS / f"{name}.py")
    tool = importlib.util.module_from_spec(load)
    load.loader.exec_module(tool)
    return tool


at_steps = load_tool("at_steps")


def write_last(run: Path, step: int, mtime: float) -> Path:
    last = run / "checkpoints" / "last.pt"
    last.parent.mkdir(parents=True, exist_ok=True)
    weights = {"w": torch.full((2,), float(step))}
    state = {"config": {"k": 1}, "model": weights, "raw_model": weights, "step": step, "optimizer": {"lr": 1.0}}
    torch.save(state, last)
    os.utime(last, (mtime, mtime))
    return last


def test_keep_copies_the_weights_at_the_asked_steps_once(tmp_path):
    study, weights, seen = tmp_path / "study", tmp_path / "kept", {}
    cyc = study / "runs" / "cyc" / "seed2"
    write_last(cyc, 300, 1.0)
    write_last(study / "runs" / "baseline" / "seed0", 400, 1.0)
    assert at_steps.keep_new(study, weights, {400, 500}, seen) == ["baseline_seed0_step400.pt"]
    kept = load_checkpoint(weights / "baseline_seed0_step400.pt")
    assert set(kept) == {"config", "model", "raw_model", "step"} and kept["model"]["w"].tolist() == [400.0, 400.0]
    assert at_steps.keep_new(study, weights, {400, 500}, seen) == []  # no new checkpoint, no new copy
    write_last(cyc, 500, 2.0)  # the next checkpoint of cyc
    assert at_steps.keep_new(study, weights, {400, 500}, seen) == ["cyc_seed2_step500.pt"]
    assert sorted(p.name for p in weights.iterdir()) == ["baseline_seed0_step400.pt", "cyc_seed2_step500.pt"]


def test_a_folder_without_runs_is_one_line_and_exit_2(tmp_path):
    for argv in (
        ["at_steps.py", "keep", str(tmp_path), str(tmp_path / "w"), "--steps", "5"],
        ["step_times.py", str(tmp_path)],
        ["ema_decays.py", "study/synth_fast", str(tmp_path), str(tmp_path / "o"), "--seed", "0", "--decays", "0.9"],
    ):
        done = subprocess.run([sys.executable, str(TOOLS / argv[0]), *argv[1:]], capture_output=True, text=True)
        assert done.returncode == 2 and done.stderr.strip() == f"error: {tmp_path}: not a study folder (no runs/ in it)"


def test_automask_depth_names_a_missing_checkpoint_in_one_line_before_any_output(tmp_path):
    """A bad checkpoint is one error line and exit 2, and no table header is printed before it."""
    missing = tmp_path / "last.pt"
    tool = [sys.executable, str(TOOLS / "automask_depth.py")]
    done = subprocess.run([*tool, str(missing), str(tmp_path)], capture_output=True, text=True)
    assert (done.returncode, done.stdout, done.stderr) == (2, "", f"error: checkpoint {missing} does not exist\n")
    done = subprocess.run([*tool, str(missing), str(tmp_path), "--lines", "0"], capture_output=True, text=True)
    assert (done.returncode, done.stdout, done.stderr) == (2, "", "error: --lines: must be at least 1, got 0\n")


def test_adopt_takes_old_results_only_after_a_rerun_reproduced_one_exactly(tmp_path):
    """experiments/tools/adopt.py: a rerun equal to the old result in every number lets the sources in
    with the rerun's threads, CPU kind and processor, the spec's config and an adopted record; a rerun one digit off
    adopts nothing (caught: numbers compared loosely, or the texts compared, which differ by path)."""
    import json

    adopt = load_tool("adopt")
    depth = {"frame": {"scale_cv": 0.07, "abs_rel": 0.23, "predictions": "old/last.pt"}}
    old, rerun, source = tmp_path / "old.json", tmp_path / "rerun.json", tmp_path / "cyc_seed3.json"
    old.write_text(json.dumps({"depth": depth, "pose": {"06": {"ate_full_rmse": 2.5}}}))
    environment = {"threads": 1, "cpu": "AVX512, bf16 native", "processor": "AMD EPYC", "commit": "abc"}
    new_depth = {"frame": {**depth["frame"], "predictions": "new/last.pt", "depth_range": None}}
    rerun.write_text(
        json.dumps({"depth": new_depth, "pose": {"06": {"ate_full_rmse": 2.5}}, "environment": environment})
    )
    source.write_text(json.dumps({"variant": "cyc", "seed": 3, "depth": depth, "environment": {"machine": "m"}}))
    out = tmp_path / "study"
    assert adopt.adopt("study/synth_fast", out, [(rerun, old)], [source]) == [out / "results" / "cyc_seed3.json"]
    taken = json.loads((out / "results" / "cyc_seed3.json").read_text())
    assert taken["environment"] == {"machine": "m", "threads": 1, "cpu": "AVX512, bf16 native", "processor": "AMD EPYC"}
    assert taken["config"]["loss"]["constraints"] == ["cyc"] and taken["overrides"][-1] == "train.seed=3"
    assert taken["adopted"] == {"from": str(source), "reproduced": [f"{rerun} = {old}"]}
    off = json.loads(rerun.read_text())
    off["pose"]["06"]["ate_full_rmse"] = 2.5000001
    rerun.write_text(json.dumps(off))
    (out / "results" / "cyc_seed3.json").unlink()
    result = subprocess.run(
        [
            sys.executable,
            str(TOOLS / "adopt.py"),
            "study/synth_fast",
            str(out),
            str(source),
            "--check",
            f"{rerun}={old}",
        ],
        capture_output=True,
        text=True,
    )
    assert result.returncode == 2 and "does not reproduce" in result.stderr and "ate_full_rmse" in result.stderr
    assert not (out / "results" / "cyc_seed3.json").exists()


def test_camera_height_scales_each_drive_or_frame_by_its_road_plane(tmp_path):
    """Two drives whose predictions are the true road-plane depth times a known factor per frame, at a
    quarter of the ground truth's size: one factor per drive is the median inverse over its first two
    frames, a window of 1 each frame's own inverse, a window of 3 the inverse of the centred median
    (shortened at a drive's ends). Caught: the ratio inverted, the ground truth's K used for the smaller
    prediction, one factor for all drives, the window not centred, a window running into the next drive."""
    from posecons.data.calib import format_calib, normalised_to_pixel, raw_intrinsics
    from posecons.data.splits import SplitLine
    from posecons.data.synth.rig import Rig

    tool = load_tool("camera_height")
    (tmp_path / "2011_09_26").mkdir()
    (tmp_path / "2011_09_26" / "calib_cam_to_cam.txt").write_text(format_calib(Rig(384, 128).cam_to_cam_text()))
    k = raw_intrinsics(tmp_path / "2011_09_26", 2)

    def road(height: int, width: int) -> np.ndarray:
        fy, cy = normalised_to_pixel(k, height, width)[1, 1:]
        rows = np.arange(height)[:, None]
        depth = np.where(rows > cy + 1, 1.65 * fy / np.maximum(rows - cy, 1e-9), 80.0)
        return np.broadcast_to(depth, (height, width)).astype(np.float32)

    lines = [SplitLine(f"2011_09_26/d{d}", f, "l") for d in (0, 1) for f in range(3)]
    gts = [road(128, 384)] * 6
    scale = [2.0, 4.0, 2.0, 0.5, 0.5, 1.0]
    disps = np.stack([1 / (road(32, 96) * s) for s in scale])
    heights = tool.frame_heights(disps, gts, lines, tmp_path)
    np.testing.assert_allclose(heights[0], 1.65, rtol=2e-3)
    np.testing.assert_allclose(heights[1], 1.65 * np.array(scale), rtol=2e-3)
    expected = {None: [0.375] * 3 + [2.0] * 3, 1: [1 / s for s in scale], 3: [1 / 3, 0.5, 1 / 3, 2.0, 2.0, 4 / 3]}
    for window, want in expected.items():
        np.testing.assert_allclose(tool.drive_scales(*heights, lines, 2, window), want, rtol=2e-3, err_msg=f"{window}")


def test_extra_emas_follow_their_formula_and_leave_the_trajectory_alone(make_synth, tmp_path, monkeypatch):
    """experiments/tools/ema_decays.py: an EMA of the run's own decay equals the run's EMA, one of another
    decay is d·w₁ + (1 − d)·w₂ of the two steps' raw weights, and the raw weights are those of the same
    run without the extra EMAs, to the bit. Caught: an extra EMA never updated, the decays swapped, an
    extra update that draws random numbers."""
    import posecons.training.trainer as trainer_module
    from posecons.config import load_config
    from tiny import TINY_MODEL

    tool = load_tool("ema_decays")
    data = make_synth(2, 16, 192, 64, 3)
    own, other = 0.9, 0.5
    overrides = [*TINY_MODEL, f"train.ema_decay={own}", "train.max_steps=2", "train.val_every=off", "train.lr=1e-3"]
    trainer_module.train(load_config(overrides=overrides), data, tmp_path / "plain", quiet=True)
    monkeypatch.setattr(trainer_module.Trainer, "__init__", trainer_module.Trainer.__init__)  # restored after
    extra = tool.track_extra_emas([own, other])
    trainer_module.train(load_config(overrides=overrides), data, tmp_path / "tracked", quiet=True)

    plain, tracked = (load_checkpoint(tmp_path / r / "checkpoints" / "last.pt") for r in ("plain", "tracked"))
    for k, w2 in tracked["raw_model"].items():
        assert torch.equal(w2, plain["raw_model"][k]), k
    same, mixed = extra[own].module.state_dict(), extra[other].module.state_dict()
    for k, ema in tracked["model"].items():
        assert torch.equal(same[k], ema), k
        if ema.is_floating_point():  # parameters and BatchNorm statistics: w₁ from the run's own EMA
            w2 = tracked["raw_model"][k]
            w1 = (ema - (1 - own) * w2) / own
            assert torch.allclose(mixed[k], other * w1 + (1 - other) * w2, rtol=1e-4, atol=1e-6), k


def test_ema_decays_refuses_bad_decays_and_an_existing_run_in_one_line(tmp_path):
    """A decay outside (0, 1) and a run folder that exists (a resume would lack the extra EMAs; an
    earlier run is not deleted) are each one line and exit status 2, and the folder is left as it was."""
    (tmp_path / "study" / "runs").mkdir(parents=True)
    kept = tmp_path / "out" / "runs" / "baseline" / "seed0" / "checkpoints" / "last.pt"
    kept.parent.mkdir(parents=True)
    kept.write_bytes(b"weights")
    base = [
        sys.executable,
        str(TOOLS / "ema_decays.py"),
        "study/synth_fast",
        str(tmp_path / "study"),
        str(tmp_path / "out"),
    ]
    for extra, message in (
        (["--decays", "1.5"], "error: --decays: each must be between 0 and 1, got [1.5]"),
        (["--decays", "0.9"], f"error: {kept.parents[1]} exists: remove it to train this run again"),
    ):
        done = subprocess.run([*base, "--seed", "0", *extra], capture_output=True, text=True)
        assert done.returncode == 2 and done.stderr.strip() == message
    assert kept.read_bytes() == b"weights"


def test_median_held_replaces_each_frames_median_by_its_drives_centred_average():
    """experiments/tools/test_time_scale.py: frames whose depth is a fixed map times a known factor get
    each frame's log-median replaced by the mean over the centred window within its drive, so the
    factors come back as the geometric moving average; the shape of each map is untouched. Caught: the
    window not centred, running into the next drive, depth and disparity confused, a per-pixel change."""
    tool = load_tool("test_time_scale")
    shape = np.linspace(1.0, 30.0, 16 * 48, dtype=np.float32).reshape(16, 48)
    scale = np.array([1.0, 4.0, 2.0, 0.5, 8.0])
    drives = ["a", "a", "a", "b", "b"]
    held = tool.median_held(np.stack([1 / (shape * s) for s in scale]), drives, 3)
    geo = lambda *x: float(np.exp(np.mean(np.log(x))))  # noqa: E731
    want = [geo(1, 4), geo(1, 4, 2), geo(4, 2), geo(0.5, 8), geo(0.5, 8)]
    for i, w in enumerate(want):
        np.testing.assert_allclose(1 / held[i], shape * w, rtol=1e-5, err_msg=f"frame {i}")
    steady = tool.median_held(np.stack([1 / shape] * 4), ["a"] * 4, 3)
    np.testing.assert_allclose(steady, np.stack([1 / shape] * 4), rtol=1e-6)


def test_early_steps_takes_the_steps_of_training_across_epochs_and_lr_decay(make_synth, tmp_path):
    """experiments/tools/early_steps.py: its photometric loss at every step equals the one `posecons
    train` logs at that step, through an epoch boundary and the lr decay after it. Caught: one epoch
    only (the tool stopped at its end), the next epoch's data order not drawn, the decay not applied;
    --every 0 is one line and exit 2."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    from posecons.config import load_config
    from posecons.training.trainer import Trainer, train
    from tiny import TINY_MODEL

    tool = load_tool("early_steps")
    data = make_synth(2, 16, 192, 64, 3)
    base = [*TINY_MODEL, "train.val_every=off", "train.log_every=1", "train.image_every=0", "train.lr=1e-3"]
    per_epoch = Trainer(load_config(overrides=base), data, tmp_path / "count", quiet=True).steps_per_epoch
    steps = 2 * per_epoch + 2
    config = load_config(
        overrides=[*base, f"train.max_steps={steps}", "train.lr_decay_epochs=[2]", "train.lr_decay=0.01"]
    )
    train(config, data, tmp_path / "run", quiet=True)
    log = EventAccumulator(str(tmp_path / "run" / "tb"))
    log.Reload()
    logged = {e.step: e.value for e in log.Scalars("loss/photometric")}
    probed = {step: losses["photometric"] for step, losses, _ in tool.first_steps(config, data, steps)}
    assert sorted(probed) == list(range(1, steps + 1)) == sorted(logged)
    for step, value in probed.items():
        assert abs(value - logged[step]) <= 1e-6 * abs(value), step
    tool_cmd = [sys.executable, str(TOOLS / "early_steps.py"), "--config", "synth/study", "--data-path", str(data)]
    done = subprocess.run([*tool_cmd, "--every", "0"], capture_output=True, text=True)
    assert (done.returncode, done.stdout, done.stderr) == (2, "", "error: --every: must be at least 1, got 0\n")


def test_early_steps_late_switches_a_loss_setting_on_at_its_step_of_the_same_run(make_synth):
    """early_steps.py --late N KEY=VALUE: the steps before N equal the run without it and lack the
    term; from step N on the term is in the loss. Caught: switched one step early or late, the switch
    rebuilding the run. A step below 1 or not a number, a setting outside loss.*, an unknown key: one
    line, exit 2."""
    from posecons.config import load_config
    from tiny import TINY_MODEL

    tool = load_tool("early_steps")
    data = make_synth(2, 12, 192, 64, 3)
    base = [*TINY_MODEL, "train.val_every=off", "train.image_every=0", "train.lr=1e-3"]
    plain = [(step, losses) for step, losses, _ in tool.first_steps(load_config(overrides=base), data, 3)]
    late = (2, load_config(overrides=[*base, "loss.far_rotation_weight=1"]))
    switched = [(step, losses) for step, losses, _ in tool.first_steps(load_config(overrides=base), data, 3, late)]
    assert switched[0][1]["total"] == plain[0][1]["total"] and "far_rotation" not in switched[0][1]
    assert [("far_rotation" in losses) for _, losses in switched[1:]] == [True, True]
    assert switched[1][1]["photometric"] == plain[1][1]["photometric"]  # the same weights until then
    assert switched[1][1]["total"] > plain[1][1]["total"]
    tool_cmd = [sys.executable, str(TOOLS / "early_steps.py"), "--config", "synth/study", "--data-path", str(data)]
    for bad in (["0", "loss.saturation_weight=1"], ["x", "loss.saturation_weight=1"], ["5", "train.lr=1"]):
        done = subprocess.run([*tool_cmd, "--late", *bad], capture_output=True, text=True)
        assert (done.returncode, done.stdout) == (2, "")
        assert done.stderr == "error: --late: one STEP ≥ 1 for every override, and loss settings only\n"
    done = subprocess.run([*tool_cmd, "--late", "5", "loss.nope=1"], capture_output=True, text=True)
    assert (done.returncode, done.stdout) == (2, "") and done.stderr.startswith("error: unknown config key 'loss.nope'")
    assert len(done.stderr.splitlines()) == 1


def test_depth_floor_counts_the_pixels_at_the_floor_and_the_lidar_points_below_it(tmp_path):
    """experiments/tools/depth_floor.py on a hand-made frame: LiDAR at 4, 8 and 16 m on thirds of the
    image, the prediction the truth ÷ 1000 but clipped at a floor of 0.006 (6 m at that scale): the
    4 m third sits at the floor and is the LiDAR's share below it. Caught: the floor's 1.2× ignored,
    the frame's scale inverted, a span of the LiDAR's zeros. A folder that is no study, a missing checkpoint:
    one line each, exit 2, before any output."""
    tool = load_tool("depth_floor")
    gt = np.zeros((6, 30), np.float32)
    gt[::2, :10], gt[::2, 10:20], gt[::2, 20:] = 4.0, 8.0, 16.0  # every other row has LiDAR
    depth = np.maximum(np.repeat(gt[:1], 6, 0) / 1000, 0.006)[None]
    stats = tool.floor_stats(depth, [gt], 0.006)
    assert stats["near_floor"] == pytest.approx(1 / 3) and stats["lidar_below_floor"] == pytest.approx(1 / 3)
    assert stats["lidar_span"] == pytest.approx(4.0) and stats["pred_span"] == pytest.approx(16 / 6)
    tool_cmd = [sys.executable, str(TOOLS / "depth_floor.py"), str(tmp_path), str(tmp_path / "last.pt")]
    done = subprocess.run(tool_cmd, capture_output=True, text=True)
    not_study = f"error: {tmp_path}: not a study folder with synthetic data (no gt/test_depth.npz)\n"
    assert (done.returncode, done.stdout, done.stderr) == (2, "", not_study)
    (tmp_path / "gt").mkdir()
    (tmp_path / "gt" / "test_depth.npz").write_bytes(b"")
    done = subprocess.run(tool_cmd, capture_output=True, text=True)
    missing = f"error: checkpoint {tmp_path / 'last.pt'} does not exist\n"
    assert (done.returncode, done.stdout, done.stderr) == (2, "", missing)


def test_residual_regions_finds_the_region_a_frame_misjudges(tmp_path):
    """experiments/tools/residual_regions.py on three hand-made frames whose prediction is the LiDAR's
    depth ÷ 2 (the split's scale) except, in frame 1, the far half (20 m, the crop's upper rows) and, in
    frame 2, the crop's left fifth, both ÷ 4: those regions' r is +log 2 in their frame's block and
    every other region's 0, each with its share of the crop's points. Caught: log(pred/gt), the split's
    median not subtracted, rows and columns swapped, the crop ignored in the fractions. A --block below
    1: one line, exit 2, before any output."""
    tool = load_tool("residual_regions")
    gt = np.zeros((20, 40), np.float32)
    gt[8:13:2], gt[14:19:2] = 20.0, 5.0  # LiDAR on every other row of the crop (rows 8–18, columns 1–37)
    disps = np.repeat(2 / np.maximum(gt, 1e-6)[None], 3, 0)
    disps[1][gt == 20.0] *= 2
    disps[2][:, :9] *= 2  # columns 1–8: (c − 1) / 37 < 0.2
    frames = [tool.point_residuals(d, gt) for d in disps]
    edges = {"column": [0, 0.2, 0.4, 0.6, 0.8, 1.01], "row": [0, 0.25, 0.5, 0.75, 1.01], "depth": [0, 8, 16, np.inf]}
    table = tool.region_table(frames, 1, edges)
    r, share = {k: v[..., 0] for k, v in table.items()}, {k: v[..., 1] for k, v in table.items()}
    np.testing.assert_allclose(np.concatenate([r["column"][0], r["row"][0]]), 0, atol=1e-6)
    np.testing.assert_allclose(r["depth"][0], [0, np.nan, 0], atol=1e-6)  # no LiDAR point at 8–16 m
    np.testing.assert_allclose(r["depth"][1], [0, np.nan, math.log(2)], atol=1e-6)
    np.testing.assert_allclose(r["row"][1][[0, 3]], [math.log(2), 0], atol=1e-6)
    np.testing.assert_allclose(r["column"][2], [math.log(2), 0, 0, 0, 0], atol=1e-6)
    np.testing.assert_allclose(r["row"][2], 0, atol=1e-6)
    assert share["column"][0, 0] == pytest.approx(8 / 37) and share["depth"][0, 2] == pytest.approx(0.5)
    cmd = [sys.executable, str(TOOLS / "residual_regions.py"), str(tmp_path), str(tmp_path / "last.pt"), "--block", "0"]
    done = subprocess.run(cmd, capture_output=True, text=True)
    assert (done.returncode, done.stdout, done.stderr) == (2, "", "error: --block 0: must be at least 1\n")


def test_scale_components_reads_the_raw_weights_when_asked(tmp_path):
    """experiments/tools/scale_components.py on one run whose EMA scales are constant and whose raw
    scales grow as the scene's depth^0.5: ``v`` gives slope 0 and ``v@raw`` slope 0.5, and the paired
    row is their difference; a misspelt variant is one line and exit 2. Caught: ``@raw`` ignored (both
    slopes 0), or the raw weights read for both."""
    from posecons.data.gt import write_gt
    from posecons.data.splits import SplitLine

    scene = np.array([4.0, 8.0, 16.0, 32.0])
    write_gt(
        tmp_path / "gt.npz",
        [np.full((2, 3), d, np.float32) for d in scene],
        [SplitLine("d/s", i, "l") for i in range(4)],
    )

    def frame(scales):
        return {"depth": {"frame": {"scales": list(scales), "scale_cv": float(np.std(scales) / np.mean(scales))}}}

    run = {"variant": "v", "seed": 0, **frame(np.ones(4)), "raw_weights": frame(np.sqrt(scene))}
    (tmp_path / "v_seed0.json").write_text(json.dumps(run))
    cmd = [
        sys.executable,
        str(TOOLS / "scale_components.py"),
        "--results",
        str(tmp_path),
        "--gt",
        str(tmp_path / "gt.npz"),
    ]
    out = subprocess.run([*cmd, "v", "v@raw"], capture_output=True, text=True, check=True).stdout.splitlines()
    slope = {line.split()[0]: float(line.split()[5]) for line in out[1:3]}
    assert slope == pytest.approx({"v": 0.0, "v@raw": 0.5})
    assert out[3].startswith("v@raw − v") and float(out[3].split()[7]) == pytest.approx(0.5)
    done = subprocess.run([*cmd, "v@rwa"], capture_output=True, text=True)
    assert (done.returncode, done.stdout, done.stderr) == (2, "", f"error: {tmp_path}: no v@rwa_seed*.json\n")


def test_continue_runs_makes_the_longer_run_of_the_same_seed(make_synth, tmp_path, capsys):
    """experiments/tools/continue_runs.py: a 2-step run copied and resumed to 4 steps equals the 4-step
    run of its seed, raw weights and EMA to the bit, and its folder holds the config the study checks.
    Caught: the copy leaving out the checkpoints (a fresh start, its step not 2), the source's own
    config written (the study refuses it; a resume would stop at step 2), a spec whose longer variant
    differs in more than its length, a finished target overwritten."""
    import yaml

    from posecons.study.runner import config_changes
    from posecons.study.spec import load_spec
    from posecons.training.trainer import train
    from tiny import TINY_MODEL

    tool = load_tool("continue_runs")
    data = make_synth(2, 16, 192, 64)
    synth = {"drives": 2, "frames": 16, "width": 192, "height": 64, "neighbours": 1, "seed": 0}
    common = [*TINY_MODEL, "model.frame_ids=[0,-1,1]", "train.val_every=off", "train.ema_decay=0.5", "train.lr=1e-3"]
    variants = {
        "short": ["train.max_steps=2"],
        "long": ["train.max_steps=4"],
        "other": ["train.max_steps=4", "train.lr=1e-4"],
    }
    spec = tmp_path / "spec.yaml"
    spec.write_text(
        yaml.safe_dump(
            {"preset": "synth/demo", "overrides": common, "data": {"synth": synth}, "seeds": [0], "variants": variants}
        )
    )
    study = tmp_path / "study"
    config = functools.partial(load_spec(str(spec)).config, seed=0)
    train(config("short"), data, study / "runs" / "short" / "seed0", quiet=True)
    train(config("long"), data, tmp_path / "fresh", quiet=True)

    run = tool.continue_run(str(spec), study, "short", "long", 0)
    assert run == study / "runs" / "long" / "seed0" and load_checkpoint(run / "checkpoints" / "last.pt")["step"] == 2
    assert config_changes(yaml.safe_load((run / "config.yaml").read_text()), config("long")) == []
    train(config("long"), data, run, resume=True, quiet=True)
    continued, fresh = (load_checkpoint(r / "checkpoints" / "last.pt") for r in (run, tmp_path / "fresh"))
    assert continued["step"] == fresh["step"] == 4
    for part in ("raw_model", "model"):
        for k, w in fresh[part].items():
            assert torch.equal(continued[part][k], w), (part, k)

    for target, why in (("other", "more than train.max_steps"), ("long", "exists already")):
        with pytest.raises(SystemExit) as stop:
            sys.argv = ["continue_runs.py", str(spec), str(study), "short", target, "--seeds", "0"]
            tool.main()
        assert stop.value.code == 2 and why in capsys.readouterr().err


def test_weight_average_folds_each_new_step_after_the_start_once(tmp_path):
    """experiments/tools/weight_average.py: the average of the raw weights of the checkpoints after
    ``after``, each step once, BatchNorm's integer count the newest, and a restart keeps the average.
    Caught: the EMA averaged instead of the raw weights, a step folded twice, the start step counted,
    a running mean that weights the newest step 1/2."""
    tool = load_tool("weight_average")
    run, out, seen = tmp_path / "study" / "runs" / "long" / "seed3", tmp_path / "average", {}
    out.mkdir()

    def checkpoint(step: int, mtime: float) -> None:
        last = run / "checkpoints" / "last.pt"
        last.parent.mkdir(parents=True, exist_ok=True)
        raw = {"w": torch.full((2,), float(step)), "bn.num_batches_tracked": torch.tensor(step)}
        ema = {"w": torch.zeros(2), "bn.num_batches_tracked": torch.tensor(0)}
        torch.save({"config": {"k": 1}, "model": ema, "raw_model": raw, "step": step}, last)
        os.utime(last, (mtime, mtime))

    for step, mtime in ((100, 1.0), (200, 2.0), (300, 3.0), (300, 4.0), (600, 5.0)):
        checkpoint(step, mtime)
        tool.keep_new(tmp_path / "study", out, "long", 100, seen if step < 600 else {})  # the last: a restart
    average = load_checkpoint(out / "long_seed3.pt")
    assert average["averaged_steps"] == [200, 300, 600]
    assert average["model"]["w"].tolist() == pytest.approx([1100 / 3] * 2, rel=1e-6)
    assert average["model"]["bn.num_batches_tracked"].item() == 600


def test_the_docs_state_the_fp32_differences_from_monodepth2_that_monodepth2_fp32_measures():
    """monodepth2_fp32.py's SSIM and CPU-disparity differences from a reference typed from Monodepth2's
    definitions against the figures of docs/training.md ("Precision"): each measured within a factor 1.5
    of its figure (two digits, from the development CPU), none 0, so no page may call --precision 32 bit
    for bit. Caught: the old "bit-for-bit reproduction" and "identical disparities" claims, a change of
    the SSIM's or the ELU's arithmetic that the figures no longer describe."""
    tool = load_tool("monodepth2_fp32")
    root = TOOLS.parents[1]
    pages = ("README.md", "docs/training.md", "docs/inference.md", "src/posecons/configs/kitti/baseline.yaml")
    text = {page: " ".join((root / page).read_text().split()) for page in pages}
    for page in pages:
        assert not re.search(r"bit-for-bit|identical disparit", text[page]), page
    number = r"([0-9.]+e-[0-9]+)"
    figures = re.search(
        rf"SSIM terms differ from Monodepth2's by up to {number} on two consecutive real KITTI frames at "
        rf"640×192 .*? and {number} on random images; their image means agree to {number}, and in float64 the "
        rf"terms agree to {number}\. .*? float32 rounding, {number} on a random-weight ResNet-18",
        text["docs/training.md"],
    )
    assert figures, "docs/training.md no longer states the differences in the words this test reads"
    kitti, random, means, float64, disparity = (float(f) for f in figures.groups())

    pairs = tool.image_pairs()
    (kitti_measured, _), *random_measured = fp32 = tool.ssim_differences(torch.float32, pairs)
    measured = {
        kitti: kitti_measured,
        random: max(r[0] for r in random_measured),
        means: max(d[1] for d in fp32),
        disparity: tool.disparity_difference(torch.cat([pairs[0][0], pairs[1][0]])),
    }
    for figure, value in measured.items():
        assert figure / 1.5 <= value <= figure * 1.5, (figure, value)
    assert max(max(d) for d in tool.ssim_differences(torch.float64, pairs)) <= float64 * 1.5
