"""Time ``posecons synth`` on the reference workload: 4 drives × 100 frames at 1242×375.

Usage: python benchmarks/synth_speed.py [--drives 4] [--frames 100] [--width 1242] [--height 375] [--workers N]
The dataset is written to a temporary directory and deleted afterwards. Prints the wall time and
the CPU time of this process and its render workers (user + system), which does not depend on
what else the machine is running: on an idle machine, wall ≈ CPU / workers.
"""

from __future__ import annotations

import argparse
import os
import resource
import tempfile
import time
from pathlib import Path

from posecons.data.synth import generate_synth


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--drives", type=int, default=4)
    parser.add_argument("--frames", type=int, default=100)
    parser.add_argument("--width", type=int, default=1242)
    parser.add_argument("--height", type=int, default=375)
    parser.add_argument("--workers", type=int, default=None)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "synth"
        start, cpu0 = time.perf_counter(), _cpu_seconds()
        generate_synth(
            out, args.drives, args.frames, seed=0, width=args.width, height=args.height, workers=args.workers
        )
        seconds, cpu = time.perf_counter() - start, _cpu_seconds() - cpu0
        size = sum(p.stat().st_size for p in out.rglob("*") if p.is_file() and "odometry" not in p.parts)
    frames = args.drives * args.frames
    print(
        f"synth {args.drives} drives x {args.frames} frames at {args.width}x{args.height}: "
        f"wall {seconds:.1f} s, CPU {cpu:.1f} s ({cpu / frames * 1000:.0f} ms/frame; {os.cpu_count()} CPUs, "
        f"load average {os.getloadavg()[0]:.1f}), {size / 1e6:.0f} MB"
    )


def _cpu_seconds() -> float:
    """User + system time of this process and its waited-for children."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


if __name__ == "__main__":
    main()
