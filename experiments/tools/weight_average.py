"""A uniform average of a run's raw weights over the second part of its training (as stochastic weight
averaging does, Izmailov et al. 2018), made while a study trains and evaluated as the study evaluates
a run. The recipe's 0.99 EMA averages about the last 100 steps; this averages every checkpoint after
step AFTER (each train.checkpoint_every steps and each epoch's end), BatchNorm statistics included, as
the EMA does.

``keep`` polls each runs/VARIANT/seed<k>/checkpoints/last.pt of the study and folds each new step
after AFTER into OUT/VARIANT_seed<k>.pt (the mean so far and the steps in it), so that it can be
stopped and started again; ``evaluate`` writes OUT/results/VARIANT_seed<k>.json, which
experiments/tools/paired.py pairs with the study's own results.

    python experiments/tools/weight_average.py keep runs/study_fast runs/average_fast --variant farrot_rs4000 --after 2000 &
    python experiments/tools/weight_average.py evaluate experiments/specs/synth_fast_farrot4000.yaml runs/study_fast runs/average_fast
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

import torch
from at_steps import new_checkpoints, poll  # the sibling tool's watcher of a study's checkpoints

from posecons.checkpoint import load_checkpoint
from posecons.errors import PoseconsError
from posecons.fileio import atomic_write, write_json
from posecons.study.report import read_json
from posecons.study.runner import evaluate_weights, prepare_data, result_name
from posecons.study.spec import load_spec

NAME = re.compile(r"(?P<variant>.+)_seed(?P<seed>\d+)\.pt")


def fold(average: dict | None, state: dict) -> dict:
    """The running mean of ``average`` (None: none yet) with the raw weights of checkpoint ``state``;
    integer buffers (BatchNorm's batch count) take the newest value."""
    raw = state.get("raw_model", state["model"])
    if average is None:
        return {"config": state["config"], "model": dict(raw), "step": state["step"], "averaged_steps": [state["step"]]}
    n = len(average["averaged_steps"]) + 1
    mean = {k: (m + (raw[k] - m) / n if m.is_floating_point() else raw[k].clone()) for k, m in average["model"].items()}
    return {
        **average,
        "model": mean,
        "step": state["step"],
        "averaged_steps": [*average["averaged_steps"], state["step"]],
    }


def keep_new(study: Path, out: Path, variant: str, after: int, seen: dict[Path, float]) -> list[str]:
    """Fold each run's ``last.pt`` not ``seen`` at its mtime, if its step is past ``after`` and not in
    the average yet; → '<file> step N' for each fold."""
    folded = []
    for last, state in new_checkpoints(study, seen, variant):
        target = out / f"{variant}_{last.parent.parent.name}.pt"
        average = load_checkpoint(target) if target.is_file() else None
        if state["step"] <= after or (average and state["step"] in average["averaged_steps"]):
            continue
        average = fold(average, state)
        atomic_write(target, lambda tmp, average=average: torch.save(average, tmp))
        folded.append(f"{target.name} step {state['step']}")
    return folded


def evaluate(spec_name: str, study: Path, out: Path) -> None:
    """The average of each finished run → OUT/results/<variant>_seed<k>.json, as the study evaluates a
    run; an average that missed the run's last step is an error."""
    data = prepare_data(load_spec(spec_name), study)
    for file in sorted(out.glob("*_seed*.pt")):
        match = NAME.fullmatch(file.name)
        name = result_name(match["variant"], int(match["seed"]))
        target, run = out / "results" / name, study / "results" / name
        if target.is_file() or not run.is_file():  # done before, or the run still trains
            continue
        steps, trained = load_checkpoint(file)["averaged_steps"], read_json(run)
        if steps[-1] != trained["steps"]:
            raise PoseconsError(f"{file}: ends at step {steps[-1]}, its run at {trained['steps']}")
        # the run's environment: the same trajectory, so the same kind of run (report.run_kind pairs by it)
        result = {"variant": match["variant"], "seed": int(match["seed"]), "steps": steps[-1], "averaged_steps": steps}
        result["environment"] = trained["environment"]
        result.update(evaluate_weights(file, data))
        write_json(target, result)
        print(f"{target}: σ/μ {result['depth']['frame']['scale_cv']:.4f} ({len(steps)} steps averaged)", flush=True)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="command", required=True)
    k = sub.add_parser("keep", help="fold new checkpoints into the averages until stopped")
    k.add_argument("study", type=Path)
    k.add_argument("out", type=Path)
    k.add_argument("--variant", required=True)
    k.add_argument("--after", type=int, required=True, help="average the steps after this one")
    k.add_argument("--poll", type=float, default=15.0, help="seconds between looks")
    e = sub.add_parser("evaluate", help="evaluate every average")
    e.add_argument("spec")
    e.add_argument("study", type=Path)
    e.add_argument("out", type=Path)
    args = p.parse_args()
    try:
        if args.command == "evaluate":
            evaluate(args.spec, args.study, args.out)
            return
        if not (args.study / "runs").is_dir():
            raise PoseconsError(f"{args.study}: not a study folder (no runs/ in it)")
        args.out.mkdir(parents=True, exist_ok=True)
        seen: dict[Path, float] = {}
        poll(lambda: keep_new(args.study, args.out, args.variant, args.after, seen), args.poll)
    except PoseconsError as exc:
        print(f"error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None


if __name__ == "__main__":
    main()
