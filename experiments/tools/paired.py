"""Two sets of study runs compared seed by seed: the same variant in two study folders (another
recipe or precision, experiments/investigation.md §9), two variants of one folder, or a run's raw weights against
its EMA (``VARIANT@raw``: an EMA run holds the result of its raw weights of the same step, so the two
are paired on one trajectory, §7). Printed: mean ± std over seeds of the study's paired metrics for
each side (the std is how noisy a single run is), then B − A with the study report's paired statistics
(t-interval, exact sign-flip p, MDE; Holm over the secondary metrics).

    python experiments/tools/paired.py runs/study_w/results/baseline_ema@raw runs/study_w/results/baseline_ema
    python experiments/tools/paired.py runs/study_w/results/cyc runs/study_bf16/results/cyc@raw
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from posecons.errors import PoseconsError
from posecons.study.report import cell, load_results, paired_metrics, paired_rows, paired_table

RAW = "@raw"


def side(arg: str) -> list[dict]:
    """The runs named by ``RESULTS/VARIANT[@raw]``, relabelled with ``arg`` so that both sides pair."""
    raw = arg.endswith(RAW)
    path = Path(arg.removesuffix(RAW))
    runs = [r for r in load_results(path.parent) if r["variant"] == path.name]
    if raw:
        runs = [{**r, **r["raw_weights"]} for r in runs if "raw_weights" in r]
    if not runs:
        why = " with raw_weights (not trained with an EMA?)" if raw else ""
        raise PoseconsError(f"{path.parent}: no {path.name}_seed*.json{why}")
    return [{**r, "variant": arg} for r in runs]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("a", help="RESULTS/VARIANT or RESULTS/VARIANT@raw: the reference")
    p.add_argument("b", help="the same form: what is compared with the reference")
    args = p.parse_args()
    try:
        results = side(args.a) + side(args.b)
    except PoseconsError as exc:
        print(f"error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None
    metrics = paired_metrics(results)
    for name in (args.a, args.b):
        print(f"{name}: seeds {sorted(r['seed'] for r in results if r['variant'] == name)}")
    print(f"\n| runs | {' | '.join(label for label, _, _ in metrics)} |")
    print("|---" * (len(metrics) + 1) + "|")
    for name in (args.a, args.b):
        cells = [cell([get(r) for r in results if r["variant"] == name], fmt) for _, get, fmt in metrics]
        print(f"| {name} | {' | '.join(cells)} |")
    print()
    print(paired_table(paired_rows([args.a, args.b], results), args.a))


if __name__ == "__main__":
    main()
