"""Two test-time options that need no ground truth and no pose net, tried on a study's finished runs
for scale consistency (the consistency issue), each written as result JSONs of the same variant and
seed so that experiments/tools/paired.py pairs it with the plain evaluation on one network:

- ``flip``: Monodepth2's flip post-processing (``evaluate-depth --post-process``), which averages
  out part of a single prediction's error.
- ``medianW``: each frame's depth × exp(mean of log m over the W frames centred on it − log m), m the
  frame's median predicted depth over the Garg crop: the drive's median depth held to a W-frame
  moving average. It removes scale jitter only where the network's median varies faster than the
  scene's.

Both the EMA and the raw weights of each run are evaluated (``VARIANT@raw`` in paired.py).

    python experiments/tools/test_time_scale.py study/synth_fast runs/study_fast runs/test_time --window 5
    python experiments/tools/paired.py runs/study_fast/results/baseline@raw runs/test_time/median5/baseline@raw
"""

from __future__ import annotations

import argparse
import itertools
import sys
from pathlib import Path

import numpy as np

from posecons.data.gt import load_gt
from posecons.errors import PoseconsError
from posecons.evaluation import evaluate
from posecons.fileio import write_json
from posecons.inference.backend import load_predictor
from posecons.metrics.depth import garg_crop_bounds
from posecons.study.report import load_results
from posecons.study.runner import SCALINGS, prepare_data, result_name
from posecons.study.spec import load_spec


def median_held(disps: np.ndarray, drives: list[str], window: int) -> np.ndarray:
    """(N, h, w) disparities of consecutive frames, ``drives`` naming each frame's drive → the same with
    each frame's median depth over the Garg crop replaced by its centred ``window``-frame moving
    average in log (shorter at a drive's ends)."""
    top, bottom, left, right = garg_crop_bounds(*disps.shape[1:])
    log_m = np.log(np.median(1.0 / disps[:, top:bottom, left:right].astype(np.float64), axis=(1, 2)))
    held, half, start = np.empty_like(log_m), window // 2, 0
    for _, group in itertools.groupby(drives):
        n = len(list(group))
        x = log_m[start : start + n]
        held[start : start + n] = [x[max(0, t - half) : t + half + 1].mean() for t in range(n)]
        start += n
    factors = np.exp(held - log_m)  # depth × factor
    return (disps / factors[:, None, None]).astype(disps.dtype)


def evaluate_options(spec_name: str, study: Path, out: Path, window: int, variants: list[str] | None) -> None:
    """OUT/flip/ and OUT/median<window>/ result JSONs for every run of ``study`` (of ``variants``) with its last.pt."""
    data = prepare_data(load_spec(spec_name), study)
    gts, _ = load_gt(data.gt)
    drives = [line.folder for line in data.split]
    options = {
        "flip": lambda p, d: evaluate.model_disparities(p, data.train_path, data.split, post_process=True),
        f"median{window}": lambda p, d: median_held(d, drives, window),
    }
    for result in load_results(study / "results"):
        variant, seed = result["variant"], result["seed"]
        checkpoint = study / "runs" / variant / f"seed{seed}" / "checkpoints" / "last.pt"
        if "raw_weights" not in result or not checkpoint.is_file() or variants and variant not in variants:
            continue
        todo = [name for name in options if not (out / name / result_name(variant, seed)).is_file()]
        depths: dict[str, dict[str, dict]] = {name: {} for name in todo}
        for entry in ("model", "raw_model") if todo else ():
            predictor = load_predictor(checkpoint, "cpu", entry=entry)
            plain = evaluate.model_disparities(predictor, data.train_path, data.split)
            for name in todo:
                disps = options[name](predictor, plain)
                depths[name][entry] = {
                    s: evaluate.evaluate_depth(disps, gts, data.split, data.gt_kind, scaling=s) for s in SCALINGS
                }
        for name in todo:
            write_json(
                out / name / result_name(variant, seed),
                {
                    **{k: result[k] for k in ("variant", "seed", "steps", "environment")},
                    "depth": depths[name]["model"],
                    "pose": result["pose"],
                    "raw_weights": {"depth": depths[name]["raw_model"], "pose": result["raw_weights"]["pose"]},
                },
            )
            cv = depths[name]["raw_model"]["frame"]["scale_cv"]
            print(
                f"{name} {variant} seed {seed}: raw σ/μ {result['raw_weights']['depth']['frame']['scale_cv']:.4f} → {cv:.4f}",
                flush=True,
            )


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("spec", help="the study's spec, e.g. study/synth_fast")
    p.add_argument("study", type=Path, help="the study folder (its results/ and runs/)")
    p.add_argument("out", type=Path, help="folder for the result JSONs, one subfolder per option")
    p.add_argument("--window", type=int, default=5, help="frames of the median's moving average (default 5)")
    p.add_argument("--variants", nargs="+", help="only these variants (default: every one with checkpoints)")
    args = p.parse_args()
    if not (args.study / "results").is_dir():
        p.exit(2, f"error: {args.study}: not a study folder (no results/ in it)\n")
    if args.window < 2:
        p.exit(2, f"error: --window: must be at least 2 frames, got {args.window}\n")
    try:
        evaluate_options(args.spec, args.study, args.out, args.window, args.variants)
    except PoseconsError as exc:
        print(f"error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None


if __name__ == "__main__":
    main()
