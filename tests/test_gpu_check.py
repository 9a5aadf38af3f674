"""benchmarks/gpu_check.sh --dry-run: the GPU script runs every part on the CPU at toy sizes, so that it
has not rotted when a GPU is lent (issue: close to the hardware)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "gpu_check.sh"


@pytest.mark.slow
def test_the_gpu_check_runs_every_part_on_the_cpu(tmp_path):
    env = {**os.environ, "OUT": str(tmp_path), "PYTHON": sys.executable}
    result = subprocess.run(["bash", str(SCRIPT), "--dry-run"], env=env, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stdout + result.stderr
    rows = [line.split("|")[1:3] for line in result.stdout.splitlines() if line.startswith("| ")]
    status = {name.strip(): value.strip() for name, value in rows}
    parts = [
        "data",
        "cuda-tests",
        "ddp-step",
        "bf16-step",
        "train-loop-fp32",
        "train-loop-bf16",
        "depth-net",
        "predict",
    ]
    assert all(status[part] == "ok" for part in parts), status
    assert {"baseline", "all", "loader alone", "depth"} <= set(status)  # the benchmarks' own rows follow
    assert "trained 2 steps" in (tmp_path / "ddp-step.log").read_text()
    assert len(list((tmp_path / "predict").glob("**/*.png"))) >= 12  # a depth image per frame
