"""What a study's σ/μ is made of: for each variant (mean ± std over its seeds), the mean σ/μ of the
frame scales, how strongly the scale follows the scene's depth (log-log slope and correlation with
the frame's median LiDAR depth), the σ/μ left once that dependence is divided out, and the
frame-to-frame jitter (:func:`posecons.metrics.depth.scale_vs_scene_depth`; experiments/investigation.md §4);
then, seed by seed, each variant's difference from the first one named. ``VARIANT@raw`` reads the
runs' raw weights instead of their EMA weights, through experiments/tools/paired.py's reader.

    python experiments/tools/scale_components.py --results OUT/results --gt OUT/gt/test_depth.npz baseline@raw cyc [...]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from paired import side  # the sibling tool's reader of RESULTS/VARIANT[@raw]

from posecons.data.gt import load_gt
from posecons.errors import PoseconsError
from posecons.metrics.depth import scale_vs_scene_depth

KEYS = ("slope", "corr", "scale_cv_rest", "jitter")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--results", type=Path, required=True, help="a study's results folder (VARIANT_seedK.json)")
    p.add_argument("--gt", type=Path, required=True, help="the study's exported test ground truth")
    p.add_argument("variants", nargs="+")
    args = p.parse_args()
    try:
        maps, lines = load_gt(args.gt)
        runs = {variant: side(str(args.results / variant)) for variant in args.variants}
    except PoseconsError as exc:
        print(f"error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None
    scene = np.array([np.median(m[m > 0]) for m in maps])
    sequences = [line.split()[0] for line in lines]
    print(f"{'variant':14s} seeds  {'σ/μ':15s}  " + "  ".join(f"{k:15s}" for k in KEYS))
    table = {}
    for variant, variant_runs in runs.items():
        for run in variant_runs:
            depth = run["depth"]["frame"]
            parts = scale_vs_scene_depth(depth["scales"], scene, sequences)
            table.setdefault(variant, {})[run["seed"]] = [
                depth["scale_cv"],
                *(parts[k] for k in KEYS),
            ]
    for variant, by_seed in table.items():
        a = np.array(list(by_seed.values()))
        print(f"{variant:14s} {len(a):5d}  " + "  ".join(f"{m:+.4f} ± {s:.4f}" for m, s in zip(a.mean(0), a.std(0))))
    reference = args.variants[0]
    for variant in [v for v in table if v != reference and reference in table]:  # paired by seed
        seeds = [k for k in table[variant] if k in table[reference]]
        d = np.array([np.subtract(table[variant][k], table[reference][k]) for k in seeds])
        if len(d):
            cells = "  ".join(f"{m:+.4f} ({(c > 0).sum()}/{len(c)} +)" for m, c in zip(d.mean(0), d.T))
            print(f"{variant} − {reference}".ljust(14) + f" {len(d):5d}  {cells}")


if __name__ == "__main__":
    main()
