"""`make demo`: synthetic KITTI-format data → CPU training (the synth/demo preset) → evaluation
→ ``report.md`` (with plots) and ``summary.json``.

A short script over the library functions the commands also call: ``generate_synth``, ``export_gt``,
``train`` and the evaluation runs of :mod:`posecons.evaluation.evaluate`.
"""

from __future__ import annotations

import json
import shutil
import time
from pathlib import Path

from ..checkpoint import describe_checkpoint
from ..config import load_config, resolve_preset
from ..data.gt import export_gt
from ..data.splits import read_split
from ..data.synth import generate_synth
from ..errors import Collapsed
from ..evaluation import evaluate
from ..evaluation.compare import checkpoint_note, result_cells, table1
from ..fileio import write_json, write_text
from ..plots import plot_validation
from ..training.initial_weights import save_initial_weights
from ..training.trainer import train

# The demo's synthetic data set: small frames keep decoding cheap on a 2-core CPU.
SYNTH = {"drives": 6, "frames": 120, "width": 384, "height": 128, "neighbours": 3}


_CONSTRAINTS = {"id": "identity", "fb": "forward-backward", "cyc": "cycle"}


def recipe(config: dict) -> tuple[str, str]:
    """What a run's ``config`` (``Config.to_dict()``) trains with beyond Monodepth2's losses: a short
    label for the report's table and the same in words."""
    loss, train = config["loss"], config["train"]
    parts = [(c, f"the {_CONSTRAINTS[c]} constraint") for c in loss["constraints"]]
    if loss["far_rotation_weight"] > 0:
        parts.append(
            ("far rotation", f"the far pixels' rotation (rotation factor {config['model']['pose_rotation_scale']})")
        )
    if loss["saturation_weight"] > 0:
        parts.append(("wall", "the wall on the disparity logits"))
    if train["ema_decay"] > 0:
        parts.append(("EMA", f"a weight EMA of decay {train['ema_decay']}"))
    if not parts:
        return "baseline", "no pose constraint (Monodepth2's losses only)"
    return ", ".join(label for label, _ in parts), ", ".join(words for _, words in parts)


def _read_jsonl(path: Path) -> list[dict]:
    """The records of a JSON-lines file (none if it does not exist)."""
    lines = path.read_text().splitlines() if path.is_file() else []
    return [json.loads(line) for line in lines if line.strip()]


def run_demo(out: Path, seed: int = 0, synth: dict = SYNTH, overrides: list[str] = ()) -> dict:
    """Run the whole demo into ``out``; ``synth`` (``generate_synth`` arguments) and ``overrides`` shrink
    it for tests."""
    start = time.time()
    out.mkdir(parents=True, exist_ok=True)
    data, run, ev, plots = out / "data", out / "run", out / "eval", out / "plots"
    meta_file = data / "synth.json"
    if not meta_file.is_file():
        print("[1/5] generating the synthetic KITTI-format data set", flush=True)
        generate_synth(data, seed=seed, **synth)
    meta = json.loads(meta_file.read_text())
    test_split = read_split(data / "splits" / "synth" / "test_files.txt")
    odom_seq = f"{int(meta['test_sequences'][0]):02d}"

    config = load_config(resolve_preset("synth/demo"), [f"train.seed={seed}", *overrides])
    untrained = out / "untrained.pt"
    save_initial_weights(untrained, config)

    print("[2/5] exporting test ground truth and evaluating the untrained network", flush=True)
    gt = ev / "gt_test.npz"
    export_gt(data, test_split, gt)
    before = evaluate.checkpoint_depth(untrained, data, test_split, gt)["frame"]
    write_json(ev / "depth_untrained.json", before)

    print(f"[3/5] training (synth/demo preset: {recipe(config.to_dict())[1]}) on the CPU", flush=True)
    shutil.rmtree(run, ignore_errors=True)
    train_start = time.time()
    trained = train(config, data, run, accelerator="cpu")
    train_minutes = (time.time() - train_start) / 60
    # The last step: chosen without ground truth, as the paper's protocol does.
    ckpt = run / "checkpoints" / "last.pt"
    weights = describe_checkpoint(ckpt)

    print("[4/5] evaluating depth (Eigen metrics, σ/μ) and pose (ATE) on the held-out drives", flush=True)
    depth = {**evaluate.checkpoint_depth(ckpt, data, test_split, gt)["frame"], "checkpoint": weights}
    evaluate.write_depth_plots(depth, test_split, plots)
    write_json(ev / "depth.json", depth)
    pose = {**evaluate.checkpoint_pose(ckpt, data / "odometry", odom_seq, plots), "checkpoint": weights}
    write_json(ev / "pose.json", pose)
    validations = _read_jsonl(run / "metrics.jsonl")
    if validations:
        plot_validation(validations, plots / "validation.png")

    print("[5/5] writing the report", flush=True)
    summary = {
        "abs_rel": depth["abs_rel"],
        "abs_rel_untrained": before["abs_rel"],
        "abs_rel_improvement": 1 - depth["abs_rel"] / before["abs_rel"],
        "sq_rel": depth["sq_rel"],
        "rmse": depth["rmse"],
        "a1": depth["a1"],
        "scale_cv": depth["scale_cv"],
        "scale_cv_untrained": before["scale_cv"],
        "ate_mean": pose["ate_mean"],
        "ate_std": pose["ate_std"],
        "ate_full_rmse": pose["ate_full_rmse"],
        "ate_mean_const_velocity": pose["const_velocity"]["ate_mean"],
        "ate_full_rmse_const_velocity": pose["const_velocity"]["ate_full_rmse"],
        "t_err": pose["t_err"],
        "r_err": pose["r_err"],
        "checkpoint": weights,
        "train_minutes": train_minutes,
        "precision": trained["precision"],
        "minutes": (time.time() - start) / 60,
        "collapse": trained["collapse"],
        "config": config.to_dict(),
    }
    write_json(out / "summary.json", summary)
    write_text(out / "report.md", _report(summary, depth, before, pose, odom_seq, meta))
    if trained["collapse"]["problems"]:
        raise Collapsed(
            f"the depth collapsed in training: {'; '.join(trained['collapse']['problems'])} "
            f"(TensorBoard: {run / 'tb'}, mask/*); the report {out / 'report.md'} is not a result"
        )
    return summary


def _report(s: dict, depth: dict, before: dict, pose: dict, seq: str, meta: dict) -> str:
    cv = pose["const_velocity"]
    m, t = s["config"]["model"], s["config"]["train"]
    label, words = recipe(s["config"])
    rows = [
        [name, *result_cells(r, scale_format=".4f")]
        for name, r in (("untrained", before), (f"trained ({label})", depth))
    ]
    collapse = "".join(
        f"**The depth collapsed in training**: {p}. The numbers below are not a result.\n\n"
        for p in s["collapse"]["problems"]
    )
    return f"""# posecons demo report

{collapse}Synthetic KITTI-format data (seed {meta.get("seed")}, {len(meta.get("drives", []))} drives), ResNet-{m["num_layers"]}
at {m["width"]}×{m["height"]}, batch {t["batch_size"]}, lr {t["lr"]}, {t["max_steps"]} steps with {words},
trained on the CPU in {s["train_minutes"]:.1f} min with precision {s["precision"]} (whole demo {s["minutes"]:.1f} min).
Evaluated: {checkpoint_note(s["checkpoint"])}.
Test: the held-out drives' `test_files.txt`, LiDAR ground truth, Garg crop, per-frame median scaling.

## Depth (paper Table 1 layout)

{table1(rows, ["model"])}
abs rel falls by **{100 * s["abs_rel_improvement"]:.0f} %** from the untrained network.

![validation](plots/validation.png)

### Scale consistency

Per-frame scales median(gt)/median(pred): σ/μ per sequence averaged = {depth["scale_cv"]:.4f}
(pooled {depth["scale_cv_pooled"]:.4f}; std/median {depth["scale_std_over_median"]:.4f}).

![scales](plots/scale_boxplot.png) ![scale over time](plots/scale_over_time.png)

![abs rel histogram](plots/abs_rel_histogram.png)

## Ego-motion (odometry sequence {seq})

| | 5-frame snippet ATE | full ATE (Sim(3)) | t_err % | r_err °/100 m |
|---|---|---|---|---|
| pose net | {pose["ate_mean"]:.4f} ± {pose["ate_std"]:.4f} | {pose["ate_full_rmse"]:.3f} | {pose["t_err"]:.2f} | {pose["r_err"]:.2f} |
| constant velocity (no images) | {cv["ate_mean"]:.4f} ± {cv["ate_std"]:.4f} | {cv["ate_full_rmse"]:.3f} | {cv["t_err"]:.2f} | {cv["r_err"]:.2f} |

The snippet ATE is nearly blind on smooth driving: compare it with the constant-velocity row.
t_err / r_err: the KITTI odometry devkit's errors, {evaluate.segments_note(pose)}.

![trajectory](plots/trajectory.png)

Files: `eval/depth.json`, `eval/pose.json`, `run/` (config, checkpoints, TensorBoard logs, metrics),
`summary.json`.
"""
