"""What the test-time stabiliser (SPEC §12) sees, against what σ/μ measures: per test drive, the
stabiliser's frame-to-frame ratios r_t (its factors follow ℓ_t = α (ℓ_{t−1} + log r_t), so log r_t =
ℓ_t / α − ℓ_{t−1}) beside the changes of the per-frame scales median(gt) / median(pred) that σ/μ is
made of. If the network's scale jittered as a whole from frame to frame, log r_t would track
Δ log s_t (correlation near 1, equal spread), and the chain without its mean bias would lower σ/μ.

    python experiments/tools/stabilised.py SPEC runs/study runs/study_stabilised
    python experiments/tools/stabiliser_ratios.py runs/study/results runs/study_stabilised baseline_seed0 cyc_seed0
"""

from __future__ import annotations

import argparse
import math
import sys
from itertools import groupby
from pathlib import Path

import numpy as np

from posecons.errors import PoseconsError
from posecons.inference.stabilise import DEFAULT_TIME_CONSTANT
from posecons.study.report import read_json


def drive_rows(plain: dict, stable: dict, time_constant: float = DEFAULT_TIME_CONSTANT) -> list[dict]:
    """One row per test drive of a result JSON and its stabilised twin (experiments/tools/stabilised.py):
    the ratios' mean ("bias", per frame) and SD, the SD of Δ log s, their correlation, σ/μ of the
    plain frames and σ/μ after chaining the ratios less their drive's mean (not causal)."""
    alpha = math.exp(-1.0 / time_constant)
    scales = np.asarray(plain["depth"]["frame"]["scales"], dtype=np.float64)
    log_factor = np.log(np.asarray(stable["depth"]["frame"]["stabiliser_factors"], dtype=np.float64))
    drives = [line.split()[0] for line in plain["test_lines"]]
    if not len(drives) == len(scales) == len(log_factor):
        raise PoseconsError("the result and its stabilised twin have different frames")
    rows = []
    for drive, group in groupby(range(len(drives)), key=drives.__getitem__):
        index = list(group)
        log_s, ell = np.log(scales[index]), log_factor[index]
        log_r = ell[1:] / alpha - ell[:-1]
        chained = [0.0]
        for step in log_r - log_r.mean():
            chained.append(alpha * (chained[-1] + step))
        detrended = np.exp(log_s - np.asarray(chained))  # the factor multiplies the depth: the scale ÷ it
        rows.append(
            {
                "drive": drive,
                "bias": float(log_r.mean()),
                "sd_log_r": float(log_r.std()),
                "sd_dlog_s": float(np.diff(log_s).std()),
                "corr": float(np.corrcoef(log_r, np.diff(log_s))[0, 1]),
                "scale_cv": float(scales[index].std() / scales[index].mean()),
                "scale_cv_detrended": float(detrended.std() / detrended.mean()),
            }
        )
    return rows


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("results", type=Path, help="the study's results/ folder")
    p.add_argument("stabilised", type=Path, help="experiments/tools/stabilised.py's folder")
    p.add_argument("names", nargs="+", help="result names, e.g. baseline_seed0")
    args = p.parse_args()
    print("| run | drive | bias of log r | SD log r | SD Δ log s | corr | σ/μ | σ/μ, ratios less their mean |")
    print("| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: |")
    try:
        for name in args.names:
            files = [folder / f"{name}.json" for folder in (args.results, args.stabilised)]
            for file in files:
                if not file.is_file():
                    raise PoseconsError(f"{file}: not found")
            for r in drive_rows(*(read_json(f) for f in files)):
                print(
                    f"| {name} | {r['drive'].rsplit('_', 2)[-2]} | {r['bias']:+.4f} | {r['sd_log_r']:.4f} | "
                    f"{r['sd_dlog_s']:.4f} | {r['corr']:+.2f} | {r['scale_cv']:.4f} | {r['scale_cv_detrended']:.4f} |"
                )
    except PoseconsError as exc:
        print(f"error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None


if __name__ == "__main__":
    main()
