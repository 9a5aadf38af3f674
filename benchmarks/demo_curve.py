"""Test abs rel of the demo recipe against its training minutes: one run of the synth/demo preset,
stopped after each of --steps, evaluated there as the demo evaluates its last step, and resumed.
The lr schedule does not depend on train.max_steps (warm-up, then constant), so the weights after N
steps are those of an N-step demo. For the throughput issue's "faster at equal learning".

    python benchmarks/demo_curve.py --seed 0 --out /tmp/curve0 --data runs/demo/data

Prints one JSON line per stop. The minutes are the time spent in train() (start-ups of the resumed
sessions and the demo's validations included, evaluations left out); time only on an idle machine.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from posecons.cli.demo import SYNTH
from posecons.config import load_config, resolve_preset
from posecons.data.gt import export_gt
from posecons.data.splits import read_split
from posecons.data.synth import generate_synth
from posecons.evaluation import evaluate
from posecons.training.trainer import train


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seed", type=int, default=0, help="train.seed and, for new data, the data's seed")
    p.add_argument("--out", type=Path, required=True, help="a new folder for the run (and the data if none given)")
    p.add_argument("--data", type=Path, help="the demo's data set (default: generate it into OUT/data)")
    p.add_argument("--steps", type=int, nargs="+", default=[300, 400, 450, 500, 600], help="where to stop")
    p.add_argument("--set", action="append", default=[], help="config overrides, e.g. train.batch_size=2")
    args = p.parse_args()
    data = args.data or args.out / "data"
    if not (data / "synth.json").is_file():
        generate_synth(data, seed=args.seed, **SYNTH)
    split = read_split(data / "splits" / "synth" / "test_files.txt")
    gt = args.out / "gt_test.npz"
    export_gt(data, split, gt)
    run, seconds = args.out / "run", 0.0
    for steps in sorted(args.steps):
        overrides = [f"train.seed={args.seed}", *args.set, f"train.max_steps={steps}"]
        config = load_config(resolve_preset("synth/demo"), overrides)
        start = time.monotonic()
        summary = train(config, data, run, resume=(run / "checkpoints" / "last.pt").is_file(), quiet=True)
        seconds += time.monotonic() - start
        depth = evaluate.checkpoint_depth(run / "checkpoints" / "last.pt", data, split, gt)["frame"]
        record = {"seed": args.seed, "steps": steps, "train_minutes": round(seconds / 60, 2)}
        record.update(precision=summary["precision"], abs_rel=depth["abs_rel"], scale_cv=depth["scale_cv"])
        print(json.dumps(record), flush=True)


if __name__ == "__main__":
    main()
