from pathlib import Path

import pytest
import torch

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
