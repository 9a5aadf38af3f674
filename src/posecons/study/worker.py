"""One run of a study in a process of its own, started by ``posecons study --jobs N``
(:func:`.runner._run_side_by_side`): train or resume it, evaluate its last weights, write its JSON.
The study folder's data, ground truth and untrained rows are already there."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..errors import PoseconsError
from .runner import environment, prepare_data, train_and_evaluate
from .spec import load_spec


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m posecons.study.worker", description=__doc__.split("\n")[0])
    p.add_argument("spec", type=Path)
    p.add_argument("out", type=Path)
    p.add_argument("variant")
    p.add_argument("seed", type=int)
    p.add_argument("--accelerator", default="auto")
    p.add_argument("--data-path", type=Path)
    p.add_argument("--odometry-path", type=Path)
    args = p.parse_args(argv)
    try:
        spec = load_spec(args.spec, args.data_path, args.odometry_path)
        data = prepare_data(spec, args.out)
        train_and_evaluate(
            spec, data, args.out, args.variant, args.seed, args.accelerator, True, environment(args.accelerator)
        )
    except PoseconsError as exc:
        print(f"posecons study ({args.variant} seed {args.seed}): error: {exc}", file=sys.stderr)
        return getattr(exc, "exit_code", 2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
