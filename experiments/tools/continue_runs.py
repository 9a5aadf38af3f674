"""A study's finished runs continued to more steps as the runs of a longer variant, without training
their first part again. The study recipes' lr schedule does not depend on train.max_steps (warm-up,
then constant or stepped by epoch) and a resume is exact, so the run (FROM, seed k) resumed up to N
steps is the N-step run of seed k. This copies FROM's checkpoints to runs/TO/seed<k>/ and writes the
config the spec gives TO; ``posecons study`` then resumes each of them as an interrupted run.

    python experiments/tools/continue_runs.py experiments/specs/synth_fast_farrot4000.yaml runs/study_fast farrot_rs2000 farrot_rs4000 --seeds 0 1 2 3 4 5
    posecons study --spec experiments/specs/synth_fast_farrot4000.yaml --out runs/study_fast --variants farrot_rs4000 --seeds 0 1 2 3 4 5 --jobs 2
"""

from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

import yaml

from posecons.errors import PoseconsError
from posecons.fileio import write_text
from posecons.study.report import read_json
from posecons.study.runner import config_changes
from posecons.study.spec import load_spec

ONLY_CHANGE = "train.max_steps"


def continue_run(spec_name: str, study: Path, source: str, target: str, seed: int) -> Path:
    """runs/TARGET/seed<k> of ``study`` made from the finished run runs/SOURCE/seed<k>; → its folder."""
    spec = load_spec(spec_name)
    if target not in spec.variants:
        raise PoseconsError(f"{spec_name}: no variant {target!r}")
    src, dst = (study / "runs" / v / f"seed{seed}" for v in (source, target))
    if not (src / "train_summary.json").is_file():
        raise PoseconsError(f"{src}: not a finished run (no train_summary.json)")
    if dst.exists():
        raise PoseconsError(f"{dst}: exists already; the study resumes it as it is")
    wanted = spec.config(target, seed)
    changes = config_changes(yaml.safe_load((src / "config.yaml").read_text()), wanted)
    others = [c for c in changes if c.split(":")[0] != ONLY_CHANGE]
    if others:
        raise PoseconsError(f"{src}: its config differs from {target}'s in more than {ONLY_CHANGE}: {others}")
    done = read_json(src / "train_summary.json")["steps"]  # a finished run's last step, without loading last.pt
    if done >= wanted.train.max_steps:
        raise PoseconsError(f"{src}: already at step {done}, not below {target}'s {wanted.train.max_steps}")
    # a temporary name first, so that an interrupted copy is never taken for a run to resume
    partial = dst.with_name(dst.name + ".partial")
    shutil.rmtree(partial, ignore_errors=True)
    shutil.copytree(src / "checkpoints", partial / "checkpoints")
    write_text(partial / "config.yaml", yaml.safe_dump(wanted.to_dict(), sort_keys=False))
    partial.rename(dst)
    return dst


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("spec", help="the spec that declares TO")
    p.add_argument("study", type=Path, help="the study folder holding runs/FROM")
    p.add_argument("source", metavar="FROM", help="the finished shorter variant")
    p.add_argument("target", metavar="TO", help="the longer variant of the spec")
    p.add_argument("--seeds", type=int, nargs="+", required=True)
    args = p.parse_args()
    try:
        for seed in args.seeds:
            print(continue_run(args.spec, args.study, args.source, args.target, seed), flush=True)
    except PoseconsError as exc:
        print(f"error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None


if __name__ == "__main__":
    main()
