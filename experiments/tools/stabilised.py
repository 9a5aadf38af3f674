"""A study's runs with the test-time stabiliser (``predict --stabilise``, SPEC §12) applied to their
test depths: each finished run's last weights are evaluated as the study evaluates them, with every
test drive's disparities divided by the stabiliser's factors, and written as a result JSON of the same
variant and seed, so that experiments/tools/paired.py pairs stabilised against plain seed by seed on one network.

    python experiments/tools/stabilised.py study/synth_fast runs/study_fast runs/study_fast_stabilised
    python experiments/tools/paired.py runs/study_fast/results/baseline runs/study_fast_stabilised/baseline
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from posecons.errors import PoseconsError
from posecons.evaluation import evaluate
from posecons.fileio import write_json
from posecons.study.report import load_results
from posecons.study.runner import SCALINGS, prepare_data, result_name
from posecons.study.spec import load_spec


def stabilise_study(spec_name: str, study: Path, out: Path) -> list[Path]:
    """OUT/<variant>_seed<k>.json for each run of ``study`` with a result and its last.pt, once each;
    → the files written. Pose results are copied (the stabiliser changes depth only)."""
    data = prepare_data(load_spec(spec_name), study)
    written = []
    for result in load_results(study / "results"):
        variant, seed = result["variant"], result["seed"]
        checkpoint = study / "runs" / variant / f"seed{seed}" / "checkpoints" / "last.pt"
        target = out / result_name(variant, seed)
        if target.is_file() or not checkpoint.is_file():  # done before, or a reference row (no training)
            continue
        depth = evaluate.checkpoint_depth(checkpoint, data.train_path, data.split, data.gt, SCALINGS, stabilised=True)
        stable = {s: depth[f"{s}_stabilised"] for s in SCALINGS}
        # the same run's network, so the same kind of run (report.run_kind pairs only runs of one kind)
        kept = {k: result[k] for k in ("variant", "seed", "steps", "environment") if k in result}
        write_json(target, {**kept, "depth": stable, "pose": result["pose"]})
        print(
            f"{target}: σ/μ {result['depth']['frame']['scale_cv']:.4f} → {stable['frame']['scale_cv']:.4f}", flush=True
        )
        written.append(target)
    return written


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("spec", help="the study's spec, e.g. study/synth_fast")
    p.add_argument("study", type=Path, help="the study folder (its results/ and runs/)")
    p.add_argument("out", type=Path, help="folder for the stabilised result JSONs")
    args = p.parse_args()
    if not (args.study / "results").is_dir():
        p.exit(2, f"error: {args.study}: not a study folder (no results/ in it)\n")
    try:
        stabilise_study(args.spec, args.study, args.out)
    except PoseconsError as exc:
        print(f"error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None


if __name__ == "__main__":
    main()
