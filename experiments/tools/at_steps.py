"""A study's runs evaluated as the runs of a shorter recipe, without training those: the lr schedule
of the study recipes does not depend on train.max_steps (warm-up, then constant), so a run's weights
after N steps are those of an N-step run. While a study trains, ``keep`` copies the weights from each
run's ``last.pt`` (written every train.checkpoint_every steps) when it reaches one of the steps; then
``evaluate`` runs the study's own evaluation on every copy and writes one result JSON per run and step,
which experiments/tools/paired.py and ``posecons study --report-only`` read (experiments/investigation.md §10).

    python experiments/tools/at_steps.py keep runs/study_bf16 runs/study_bf16_at/weights --steps 400 500 &
    python experiments/tools/at_steps.py evaluate experiments/specs/synth_bf16.yaml runs/study_bf16 runs/study_bf16_at/weights runs/study_bf16_at
    python experiments/tools/paired.py runs/study_bf16_at/step400/results/baseline runs/study_bf16_at/step400/results/cyc
"""

from __future__ import annotations

import argparse
import re
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import torch

from posecons.checkpoint import load_checkpoint
from posecons.errors import PoseconsError
from posecons.fileio import atomic_write, write_json
from posecons.study.runner import evaluate_weights, prepare_data, raw_weights_result, result_name
from posecons.study.spec import load_spec

NAME = re.compile(r"(?P<variant>.+)_seed(?P<seed>\d+)_step(?P<step>\d+)\.pt")


def poll(fold_new, interval: float = 15.0) -> None:
    """Until stopped: every ``interval`` seconds, call ``fold_new()`` and print what it names."""
    while True:
        for line in fold_new():
            print(f"{time.strftime('%H:%M:%S')} {line}", flush=True)
        time.sleep(interval)


def new_checkpoints(study: Path, seen: dict[Path, float], variant: str = "*") -> Iterator[tuple[Path, dict]]:
    """(path, state) of each run's ``last.pt`` (of ``variant``) not ``seen`` at its current mtime."""
    for last in sorted(study.glob(f"runs/{variant}/seed*/checkpoints/last.pt")):
        try:
            mtime = last.stat().st_mtime
            if seen.get(last) == mtime:
                continue
            state = load_checkpoint(last)
        except (OSError, PoseconsError):  # replaced while being read: the next round reads the new one
            continue
        seen[last] = mtime
        yield last, state


def keep_new(study: Path, weights: Path, steps: set[int], seen: dict[Path, float]) -> list[str]:
    """Copy the weights of each run's ``last.pt`` not ``seen`` at its mtime to
    WEIGHTS/<variant>_seed<k>_step<N>.pt where N is one of ``steps``; the names of the copies."""
    kept = []
    for last, state in new_checkpoints(study, seen):
        run = last.parent.parent
        target = weights / f"{run.parent.name}_{run.name}_step{state['step']}.pt"
        if state["step"] in steps and not target.exists():
            copy = {k: state[k] for k in ("config", "model", "raw_model", "step") if k in state}
            atomic_write(target, lambda tmp, copy=copy: torch.save(copy, tmp))
            kept.append(target.name)
    return kept


def evaluate(spec_name: str, study: Path, weights: Path, out: Path) -> None:
    """Each kept copy → OUT/step<N>/results/<variant>_seed<k>.json, as the study evaluates a run."""
    spec = load_spec(spec_name)
    data = prepare_data(spec, study)
    for file in sorted(weights.glob("*_step*.pt")):
        match = NAME.fullmatch(file.name)
        if not match:
            continue
        variant, seed, step = match["variant"], int(match["seed"]), int(match["step"])
        target = out / f"step{step}" / "results" / result_name(variant, seed)
        if target.is_file():
            continue
        result = {"variant": variant, "seed": seed, "steps": step, "weights": str(file)}
        result.update(evaluate_weights(file, data), **raw_weights_result(file, data))
        write_json(target, result)
        print(f"{target}: σ/μ {result['depth']['frame']['scale_cv']:.4f}", flush=True)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="command", required=True)
    k = sub.add_parser("keep", help="copy the runs' weights at the given steps while the study trains")
    k.add_argument("study", type=Path)
    k.add_argument("weights", type=Path)
    k.add_argument("--steps", type=int, nargs="+", required=True)
    e = sub.add_parser("evaluate", help="evaluate every kept copy as the study evaluates a run")
    e.add_argument("spec")
    e.add_argument("study", type=Path)
    e.add_argument("weights", type=Path)
    e.add_argument("out", type=Path)
    args = p.parse_args()
    if not (args.study / "runs").is_dir():
        p.exit(2, f"error: {args.study}: not a study folder (no runs/ in it)\n")
    try:
        if args.command == "keep":
            seen: dict[Path, float] = {}
            poll(lambda: keep_new(args.study, args.weights, set(args.steps), seen))
        else:
            evaluate(args.spec, args.study, args.weights, args.out)
    except PoseconsError as exc:
        print(f"error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None


if __name__ == "__main__":
    main()
