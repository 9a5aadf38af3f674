"""One run of a study in a process of its own, started by ``posecons study --jobs N``
(:func:`.runner._run_side_by_side`) as ``python -m posecons.study.worker JOB``, JOB the JSON of
:func:`run`'s arguments: train or resume it, evaluate its last weights, write its JSON.
The study folder's data, ground truth and untrained rows are already there."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from ..errors import PoseconsError
from .runner import environment, prepare_data, train_and_evaluate
from .spec import load_spec


def run(
    spec: str, out: str, variant: str, seed: int, accelerator: str, data_path: str | None, odometry_path: str | None
) -> int:
    """Run ``variant`` × ``seed`` of the study ``spec`` in ``out``, with the spec's data roots as the study
    resolved them; the exit status (an error is one line, as the CLI's)."""
    try:
        study = load_spec(spec, *(Path(p) if p else None for p in (data_path, odometry_path)))
        data = prepare_data(study, Path(out))
        train_and_evaluate(study, data, Path(out), variant, seed, accelerator, True, environment(accelerator))
    except PoseconsError as exc:
        print(f"posecons study ({variant} seed {seed}): error: {exc}", file=sys.stderr)
        return getattr(exc, "exit_code", 2)
    return 0


if __name__ == "__main__":
    sys.exit(run(**json.loads(sys.argv[1])))
