from pathlib import Path

import pytest
import torch

from posecons.cli import main as cli

REPO = Path(__file__).resolve().parents[1]
SHARED_KITTI = REPO.parent / "shared" / "kitti"


@pytest.fixture(autouse=True)
def _seed():
    torch.manual_seed(0)


@pytest.fixture
def kitti_dir() -> Path:
    """Real KITTI files beside the repository (../shared/kitti), used in place."""
    if not SHARED_KITTI.is_dir():
        pytest.fail(f"real KITTI test files are expected at {SHARED_KITTI}")
    return SHARED_KITTI


@pytest.fixture(scope="session")
def make_synth(tmp_path_factory):
    """``make_synth(drives=2, frames=12, width=192, height=64, seed=0, *extra_args)`` → a fresh
    synthetic KITTI-format dataset written by the real ``posecons synth`` command."""

    def make(drives: int = 2, frames: int = 12, width: int = 192, height: int = 64, seed: int = 0, *extra: str) -> Path:
        out = tmp_path_factory.mktemp("synth") / "data"
        args = [
            "synth",
            "--out",
            str(out),
            "--drives",
            str(drives),
            "--frames",
            str(frames),
            "--seed",
            str(seed),
            "--width",
            str(width),
            "--height",
            str(height),
            *extra,
        ]
        assert cli(args) == 0
        return out

    return make
