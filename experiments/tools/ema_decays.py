"""Several weight-EMA decays from one training run: the EMA never feeds back into training, so a run
that also keeps EMAs of other decays follows the same trajectory as the study's run of that seed, and
its raw weights and its ``train.ema_decay`` EMA must reproduce the study's result (a check printed per
run). Each decay's weights are evaluated as the study evaluates a run, into
OUT/ema<decay>/results/<variant>_seed<k>.json (with the raw weights beside them), which
experiments/tools/paired.py and ``posecons study --report-only`` read (the consistency issue: does a
slower EMA lower σ/μ further?).

    python experiments/tools/ema_decays.py study/synth_fast runs/study_fast runs/ema --seed 0 --decays 0.995 0.998

Run it with the pinned code that trained the study, at the study's thread count (OMP_NUM_THREADS). An
interrupted run is not resumed (the extra EMAs are not in ``last.pt``): remove its folder and start again.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import torch
from torch.optim.swa_utils import AveragedModel, get_ema_multi_avg_fn

import posecons.training.trainer as trainer_module
from posecons.errors import PoseconsError
from posecons.fileio import atomic_write, write_json
from posecons.study.runner import environment, evaluate_weights, prepare_data, raw_weights_result, result_name
from posecons.study.spec import load_spec


def track_extra_emas(decays: list[float]) -> dict[float, AveragedModel]:
    """Make every Trainer built from now on update one more EMA per decay after each optimiser step,
    exactly when it updates its own; returns the (filled once a Trainer exists) EMAs by decay."""
    extra: dict[float, AveragedModel] = {}
    build = trainer_module.Trainer.__init__

    def init(self, *args, **kwargs):
        build(self, *args, **kwargs)
        if self.ema is None:
            raise PoseconsError("the run keeps no weight EMA (train.ema_decay=0) to check the extra ones against")
        for d in decays:
            extra[d] = AveragedModel(self.model, multi_avg_fn=get_ema_multi_avg_fn(d), use_buffers=True)
        own = self.ema.update_parameters

        def update(model):
            own(model)
            for average in extra.values():
                average.update_parameters(model)

        self.ema.update_parameters = update

    trainer_module.Trainer.__init__ = init
    return extra


def run(spec_name: str, study: Path, out: Path, variant: str, seed: int, decays: list[float]) -> None:
    run_dir = out / "runs" / variant / f"seed{seed}"
    if run_dir.exists():  # a resumed trajectory would lack the extra EMAs, and an earlier run is kept
        raise PoseconsError(f"{run_dir} exists: remove it to train this run again")
    spec = load_spec(spec_name)
    data = prepare_data(spec, study)
    config = spec.config(variant, seed)
    extra = track_extra_emas(decays)
    trainer_module.train(config, data.train_path, run_dir, quiet=True)
    last = run_dir / "checkpoints" / "last.pt"
    state = torch.load(last, map_location="cpu", weights_only=False)
    weights = {config.train.ema_decay: last}
    for d, average in extra.items():
        weights[d] = out / "weights" / f"{variant}_seed{seed}_ema{d:g}.pt"
        copy = {**state, "model": average.module.state_dict()}
        atomic_write(weights[d], lambda tmp, copy=copy: torch.save(copy, tmp))
    for d, file in sorted(weights.items()):
        result = {"variant": variant, "seed": seed, "ema_decay": d, "steps": state["step"], "weights": str(file)}
        result.update(evaluate_weights(file, data), **raw_weights_result(last, data), environment=environment("auto"))
        write_json(out / f"ema{d:g}" / "results" / result_name(variant, seed), result)
        print(
            f"{variant} seed {seed}, EMA {d:g}: σ/μ {result['depth']['frame']['scale_cv']:.4f}, "
            f"abs rel {result['depth']['frame']['abs_rel']:.4f}; raw σ/μ "
            f"{result['raw_weights']['depth']['frame']['scale_cv']:.4f}",
            flush=True,
        )
    reference = study / "results" / result_name(variant, seed)
    if reference.is_file():  # the same trajectory: the raw weights and the own EMA give the study's numbers
        ref = json.loads(reference.read_text())
        own = json.loads((out / f"ema{config.train.ema_decay:g}" / "results" / result_name(variant, seed)).read_text())
        same = all(
            r["depth"]["frame"][m] == o["depth"]["frame"][m]
            for r, o in ((ref, own), (ref["raw_weights"], own["raw_weights"]))
            for m in ("scale_cv", "abs_rel")
        )
        print(f"{'reproduces' if same else 'DOES NOT reproduce'} {reference}", flush=True)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("spec")
    p.add_argument("study", type=Path, help="the study folder: its data, and its results to check against")
    p.add_argument("out", type=Path)
    p.add_argument("--variant", default="baseline")
    p.add_argument("--seed", type=int, required=True)
    p.add_argument("--decays", type=float, nargs="+", required=True)
    args = p.parse_args()
    if not (args.study / "runs").is_dir():
        p.exit(2, f"error: {args.study}: not a study folder (no runs/ in it)\n")
    if any(not 0 < d < 1 for d in args.decays):
        p.exit(2, f"error: --decays: each must be between 0 and 1, got {args.decays}\n")
    try:
        run(args.spec, args.study, args.out, args.variant, args.seed, args.decays)
    except PoseconsError as exc:
        print(f"error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None


if __name__ == "__main__":
    main()
