"""`posecons train --init-from CKPT`: a run that starts from a checkpoint's weights only, records
where it started, resumes without reading that file again, and refuses another architecture."""

import re
from pathlib import Path

import pytest
import torch

from posecons.checkpoint import load_checkpoint, save_checkpoint
from posecons.cli import main
from posecons.config import load_config
from posecons.errors import PoseconsError
from posecons.model import PoseConsModel
from posecons.training.initial_weights import initial_model
from posecons.training.trainer import train
from tiny import TINY_MODEL

pytestmark = pytest.mark.slow
TINY = [
    *TINY_MODEL,
    "train.val_every=off",
    "train.image_every=0",
]


@pytest.fixture(scope="module")
def synth_data(make_synth) -> Path:
    return make_synth(2, 16, 192, 64, 3)


@pytest.fixture
def source(tmp_path) -> Path:
    """A checkpoint at step 40 whose weights no run of seed 0 starts from."""
    cfg = load_config(overrides=TINY)
    torch.manual_seed(123)
    model = PoseConsModel(cfg)
    state = {
        "config": cfg.to_dict(),
        "model": model.state_dict(),
        "step": 40,
        "initialisation": "random (trained from scratch)",
    }
    save_checkpoint(tmp_path / "source.pt", state)
    return tmp_path / "source.pt"


def weights_equal(a: dict, b: dict) -> bool:
    return a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


def test_a_run_starts_from_the_weights_only_and_records_where(synth_data, tmp_path, source, monkeypatch):
    """Catches: init_from ignored (the run's own random start), the optimiser state or step count
    taken over, ImageNet weights asked for or recorded instead, the start missing from config.yaml,
    the checkpoints or the summary."""
    import posecons.model

    def no_imagenet(num_layers, pretrained):
        assert pretrained is False, "ImageNet weights asked for although the weights come from init_from"

    monkeypatch.setattr(posecons.model, "load_imagenet_state", no_imagenet)
    cfg = load_config(overrides=TINY + ["model.pretrained=auto", "train.max_steps=1", f"train.init_from={source}"])
    assert weights_equal(initial_model(cfg).state_dict(), load_checkpoint(source)["model"])
    summary = train(cfg, synth_data, tmp_path / "run", quiet=True)
    run = tmp_path / "run"
    where = f"weights of {source} (step 40; initialised: random (trained from scratch))"
    assert summary["steps"] == 1 and summary["initialisation"] == where
    last = load_checkpoint(run / "checkpoints" / "last.pt")
    assert last["step"] == 1 and last["initialisation"] == where
    assert [int(s["step"]) for s in last["optimizer"]["state"].values()] == [1] * len(last["optimizer"]["state"])
    recorded = load_config(run / "config.yaml")
    assert recorded.train.init_from == str(source) and recorded.model.pretrained is False


def test_resume_continues_from_last_pt_without_reading_init_from_again(synth_data, tmp_path, source):
    """Catches: --resume applying train.init_from again (it fails here: the file is gone) or the
    resumed run forgetting where it started."""
    cfg = load_config(overrides=TINY + ["train.max_steps=1", f"train.init_from={source}"])
    train(cfg, synth_data, tmp_path / "run", quiet=True)
    source.unlink()
    resumed = load_config(tmp_path / "run" / "config.yaml", ["train.max_steps=2"])
    summary = train(resumed, synth_data, tmp_path / "run", resume=True, quiet=True)
    assert summary["steps"] == 2 and summary["initialisation"].startswith(f"weights of {source} (step 40;")


@pytest.mark.parametrize(
    ("override", "message"),
    [
        ("model.num_layers=18", "model.num_layers 10 \\(the run: 18\\)"),
        ("model.pose_mirror=true", "model.pose_mirror False \\(the run: True\\)"),
        ("model.scales=[0]", "model.scales \\[0, 1, 2, 3\\] \\(the run: \\[0\\]\\)"),
    ],
)
def test_another_architecture_is_refused_in_one_line(synth_data, tmp_path, capsys, source, override, message):
    """Catches: a key of ARCHITECTURE not compared (num_layers and scales would then fail in
    load_state_dict with a longer message, pose_mirror would silently change what the poses mean)."""
    sets = [a for o in TINY + [override] for a in ("--set", o)]
    args = ["train", "--config", "kitti/baseline", "--data-path", str(synth_data), "--out", str(tmp_path / "run")]
    assert main([*args, *sets, "--init-from", str(source), "--max-steps", "1", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1, err
    assert f"{source}: its architecture is not the run's: " in err
    assert re.search(message, err), err
    assert not (tmp_path / "run").exists()


def test_init_from_with_resume_or_a_missing_file_stops_before_anything_runs(synth_data, tmp_path, capsys, source):
    """Catches: --init-from combined with --resume (which would seem to restart a run from other
    weights), a missing file found only once the data is loaded."""
    args = ["train", "--config", "kitti/baseline", "--data-path", str(synth_data), "--out", str(tmp_path / "run")]
    assert main([*args, "--init-from", str(source), "--resume"]) == 2
    assert "--init-from starts a new run; --resume continues one" in capsys.readouterr().err
    assert main([*args, "--init-from", str(tmp_path / "nowhere.pt")]) == 2
    assert f"--init-from {tmp_path / 'nowhere.pt'}: no such checkpoint or folder" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


def test_exported_safetensors_weights_are_a_start_too(tmp_path, source):
    """Catches: init_from reading only .pt checkpoints."""
    from posecons.checkpoint import load_model, save_safetensors

    source_model, config = load_model(source)
    save_safetensors(tmp_path / "w.safetensors", source_model.state_dict(), config)
    model = initial_model(load_config(overrides=TINY + [f"train.init_from={tmp_path / 'w.safetensors'}"]))
    assert weights_equal(model.state_dict(), load_checkpoint(source)["model"])
    assert model.initialisation == f"weights of {tmp_path / 'w.safetensors'} (initialised: not recorded)"


def test_an_unreadable_init_from_names_the_file(tmp_path):
    """Catches: a file that is no posecons checkpoint loaded as one."""
    (tmp_path / "x.pt").write_bytes(b"not a checkpoint")
    cfg = load_config(overrides=TINY + [f"train.init_from={tmp_path / 'x.pt'}"])
    with pytest.raises(PoseconsError, match=f"{tmp_path / 'x.pt'}: not a readable checkpoint"):
        initial_model(cfg)
