"""What the weight EMA (train.ema_decay) does to a study's runs: each run with an EMA holds, beside
its EMA result, the result of its raw weights at the same step (``raw_weights``; the study writes
both), so the two are paired on one trajectory. Printed: for the raw and the EMA weights, mean ± std
over seeds of the study's paired metrics (the std is how noisy a single run is), then the EMA − raw
difference with its bootstrap interval and per-seed signs (docs/results.md §7).

    python tools/ema_effect.py --results OUT/results baseline_ema
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from posecons.metrics.stats import mean_std
from posecons.study.report import load_results, paired_metrics, paired_rows, paired_table


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--results", type=Path, required=True, help="a study's results folder (VARIANT_seedK.json)")
    p.add_argument("variant", help="a variant trained with train.ema_decay > 0")
    args = p.parse_args()
    ema = [r for r in load_results(args.results) if r["variant"] == args.variant and "raw_weights" in r]
    if not ema:
        print(
            f"{args.results}: no {args.variant}_seed*.json with raw_weights (not trained with an EMA?)", file=sys.stderr
        )
        raise SystemExit(2)
    raw_name = f"{args.variant} (raw)"
    results = ema + [{**r, **r["raw_weights"], "variant": raw_name} for r in ema]
    metrics = paired_metrics(results)
    print(f"{len(ema)} seeds: {sorted(r['seed'] for r in ema)}\n")
    print(f"| weights | {' | '.join(label for label, _, _ in metrics)} |")
    print("|---" * (len(metrics) + 1) + "|")
    for name in (raw_name, args.variant):
        spread = [mean_std([get(r) for r in results if r["variant"] == name]) for _, get, _ in metrics]
        cells = [f"{m:{fmt}} ± {s:{fmt}}" for (m, s), (_, _, fmt) in zip(spread, metrics)]
        print(f"| {name} | {' | '.join(cells)} |")
    print()
    print(paired_table(paired_rows([raw_name, args.variant], results), raw_name))


if __name__ == "__main__":
    main()
