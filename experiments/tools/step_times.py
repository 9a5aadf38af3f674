"""Seconds per step of each run of a study folder, read from its TensorBoard wall times: the median of
the intervals between logged steps (train.log_every apart), which leaves out the start-up and any
pause (a study stopped with SIGSTOP while something else was timed). docs/performance.md, sizing.

    python experiments/tools/step_times.py runs/study_bf16 [more study folders]
"""

from __future__ import annotations

import argparse
import statistics
from pathlib import Path

from tensorboard.backend.event_processing.event_accumulator import EventAccumulator


def step_seconds(tb: Path) -> list[float]:
    """Seconds per step over each interval between two logged steps of one run's ``tb/``."""
    events = EventAccumulator(str(tb))
    events.Reload()
    logged = sorted({e.step: e.wall_time for e in events.Scalars("lr")}.items())
    return [(t2 - t1) / (s2 - s1) for (s1, t1), (s2, t2) in zip(logged, logged[1:])]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("studies", type=Path, nargs="+", help="study --out folders")
    studies = p.parse_args().studies
    for study in studies:
        if not (study / "runs").is_dir():
            p.exit(2, f"error: {study}: not a study folder (no runs/ in it)\n")
    for study in studies:
        for tb in sorted(study.glob("runs/*/seed*/tb")):
            seconds = step_seconds(tb)
            if seconds:
                run = tb.parent.relative_to(study / "runs")
                print(
                    f"{study}: {run}  {statistics.median(seconds):.3f} s per step (median of {len(seconds)} intervals)"
                )


if __name__ == "__main__":
    main()
