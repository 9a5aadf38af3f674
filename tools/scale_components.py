"""What a study's σ/μ is made of: for each variant (mean ± std over its seeds), the mean σ/μ of the
frame scales, how strongly the scale follows the scene's depth (log-log slope and correlation with
the frame's median LiDAR depth), the σ/μ left once that dependence is divided out, and the
frame-to-frame jitter (:func:`posecons.metrics.depth.scale_vs_scene_depth`; docs/results.md §4).

    python tools/scale_components.py --results OUT/results --gt OUT/gt/test_depth.npz baseline cyc [...]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from posecons.data.gt import load_gt
from posecons.metrics.depth import scale_vs_scene_depth

KEYS = ("slope", "corr", "scale_cv_rest", "jitter")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--results", type=Path, required=True, help="a study's results folder (VARIANT_seedK.json)")
    p.add_argument("--gt", type=Path, required=True, help="the study's exported test ground truth")
    p.add_argument("variants", nargs="+")
    args = p.parse_args()
    maps, lines = load_gt(args.gt)
    scene = np.array([np.median(m[m > 0]) for m in maps])
    sequences = [line.split()[0] for line in lines]
    print(f"{'variant':14s} seeds  σ/μ              " + "  ".join(f"{k:15s}" for k in KEYS))
    for variant in args.variants:
        rows = []
        for path in sorted(args.results.glob(f"{variant}_seed*.json")):
            depth = json.loads(path.read_text())["depth"]["frame"]
            parts = scale_vs_scene_depth(depth["scales"], scene, sequences)
            rows.append([depth["scale_cv"], *(parts[k] for k in KEYS)])
        if not rows:
            print(f"{variant:14s} no results")
            continue
        a = np.array(rows)
        cells = "  ".join(f"{m:+.4f} ± {s:.4f}" for m, s in zip(a.mean(0), a.std(0)))
        print(f"{variant:14s} {len(rows):5d}  {cells}")


if __name__ == "__main__":
    main()
