"""The first training steps of a recipe, step by step: the batch's mean translation of T_{f←0} for
each source, the disparity's mean and its shares saturated at the far and at the near end, and the
share of pixels where a warped source beats the unwarped one (the auto-mask). A run from scratch
settles its direction of motion in these steps; for forward driving the translation's z of T_{−n←0}
must be positive (camera −n is behind), and a run that points it backwards or pins the disparity at
either end collapses (experiments/investigation.md §3, §11, §27). The steps run over as many epochs
as they need, as in training; the first step and every ``--every``-th are printed.

    python experiments/tools/early_steps.py --config synth/study --data-path DATA --steps 200 --every 10 --set train.seed=1

``--late N KEY=VALUE`` switches a loss setting on at step N of the same run, e.g. to ask whether a run
already pinned at one end of the disparity comes back (lab log §28).
"""

from __future__ import annotations

import argparse
import itertools
import tempfile
from pathlib import Path

from posecons.cli.arguments import add_overrides
from posecons.config import load_config, resolve_preset
from posecons.errors import PoseconsError
from posecons.training.collapse import collapse_signs
from posecons.training.trainer import Trainer


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--config", required=True, help="preset name or YAML file")
    p.add_argument("--data-path", required=True)
    p.add_argument("--steps", type=int, default=60, help="training steps, over as many epochs as they need")
    p.add_argument("--every", type=int, default=1, help="print every N-th step (and the first)")
    add_overrides(p, "a config override such as train.warmup_steps=0")
    p.add_argument(
        "--late",
        nargs=2,
        action="append",
        default=[],
        metavar=("STEP", "KEY=VALUE"),
        help="a loss override that takes effect from STEP on (repeatable, one STEP for all)",
    )
    args = p.parse_args()
    for name in ("steps", "every"):
        if getattr(args, name) < 1:
            p.exit(2, f"error: --{name}: must be at least 1, got {getattr(args, name)}\n")
    steps = {step for step, _ in args.late}
    step = steps.pop() if len(steps) == 1 else ""
    if args.late and not (step.isdigit() and int(step) >= 1 and all(kv.startswith("loss.") for _, kv in args.late)):
        p.exit(2, "error: --late: one STEP ≥ 1 for every override, and loss settings only\n")
    try:
        config = load_config(resolve_preset(args.config), args.overrides)
        late_overrides = args.overrides + [kv for _, kv in args.late]
        late = (int(step), load_config(resolve_preset(args.config), late_overrides)) if args.late else None
    except PoseconsError as exc:
        p.exit(2, f"error: {exc}\n")
    sources = config.model.frame_ids[1:]
    print("| step | photometric | " + " | ".join(f"t of T_{{{f}←0}} (x, y, z)" for f in sources), end="")
    print(" | disparity mean | far share | near share | warped share |\n|" + "---|" * (len(sources) + 6))
    for step, losses, outputs in first_steps(config, args.data_path, args.steps, late):
        if step == 1 or step % args.every == 0:
            print_row(step, losses, outputs, sources)


def first_steps(config, data_path: str, steps: int, late=None):
    """(step, losses, outputs) of the first ``steps`` training steps, as ``posecons train`` takes them;
    ``late`` = (N, config): the model's losses follow that config from step N on."""
    with tempfile.TemporaryDirectory() as out:
        trainer = Trainer(config, data_path, Path(out) / "run", quiet=True)
        for epoch in itertools.count():
            for batch in trainer._loader(epoch, 0):
                if late and trainer.step + 1 == late[0]:
                    trainer.model.config = late[1]
                losses, outputs = trainer._micro_step(batch, last=True)
                trainer.step += 1
                yield trainer.step, losses, outputs
                if trainer.step >= steps:
                    return
            trainer.scheduler.step()  # the epoch's lr decay, where the recipe has one, as in training


def print_row(step: int, losses: dict, outputs: dict, sources: list[int]) -> None:
    t = [outputs["poses"][f][:, :3, 3].mean(0).tolist() for f in sources]
    signs = collapse_signs(outputs)
    print(
        f"| {step} | {losses['photometric']:.4f} | "
        + " | ".join(", ".join(f"{v:+.2e}" for v in xyz) for xyz in t)
        + f" | {outputs['disp'][0].mean():.3f} | {signs['far_fraction']:.2f} | {signs['near_fraction']:.2f}"
        + f" | {signs['warped_fraction']:.2f} |",
        flush=True,
    )


if __name__ == "__main__":
    main()
