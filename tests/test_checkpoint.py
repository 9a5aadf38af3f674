import pickle

import pytest
import torch

from posecons.checkpoint import describe_checkpoint, load_checkpoint, load_model, save_checkpoint, save_safetensors
from posecons.config import load_config
from posecons.errors import PoseconsError
from posecons.model import PoseConsModel


def small_model(layers=10):
    cfg = load_config(
        overrides=["model.height=64", "model.width=96", "model.pretrained=false", f"model.num_layers={layers}"]
    )
    return PoseConsModel(cfg), cfg


def test_round_trip_pt_and_safetensors(tmp_path):
    model, cfg = small_model()
    save_checkpoint(tmp_path / "m.pt", {"config": cfg.to_dict(), "model": model.state_dict(), "step": 7})
    assert [p.name for p in tmp_path.iterdir()] == ["m.pt"]  # no temp file left behind
    save_safetensors(tmp_path / "m.safetensors", model.state_dict(), cfg)
    x = torch.rand(1, 3, 64, 96)
    expected = model.eval().predict_depth(x)[1]
    for name in ("m.pt", "m.safetensors"):
        loaded, loaded_cfg = load_model(tmp_path / name)
        assert loaded_cfg.model.num_layers == 10
        assert torch.allclose(loaded.predict_depth(x)[1], expected)


class Evil:
    def __reduce__(self):
        return (print, ("pwned",))


def test_malicious_pickle_is_refused(tmp_path):
    path = tmp_path / "evil.pt"
    torch.save({"config": {}, "model": Evil()}, path)
    with pytest.raises(PoseconsError, match="refused to load"):
        load_checkpoint(path)
    (tmp_path / "plain.pkl").write_bytes(pickle.dumps(Evil()))
    with pytest.raises(PoseconsError, match="plain.pkl"):
        load_model(tmp_path / "plain.pkl")


def test_architecture_mismatch_and_missing_file(tmp_path):
    model, cfg = small_model(10)
    wrong = cfg.to_dict()
    wrong["model"]["num_layers"] = 18
    save_checkpoint(tmp_path / "m.pt", {"config": wrong, "model": model.state_dict()})
    with pytest.raises(PoseconsError, match="do not fit the architecture.*ResNet-18"):
        load_model(tmp_path / "m.pt")
    with pytest.raises(PoseconsError, match="does not exist"):
        load_model(tmp_path / "missing.pt")


def test_description_says_whether_the_weights_are_raw_or_an_ema(tmp_path):
    from posecons.evaluation.compare import checkpoint_note

    model, cfg = small_model()
    save_checkpoint(tmp_path / "old.pt", {"config": cfg.to_dict(), "model": model.state_dict(), "step": 3})
    save_checkpoint(
        tmp_path / "ema.pt",
        {"config": cfg.to_dict(), "model": model.state_dict(), "step": 5, "weights": "EMA (decay 0.99)"},
    )
    assert describe_checkpoint(tmp_path / "old.pt")["weights"] == "raw"  # written before the EMA option
    info = describe_checkpoint(tmp_path / "ema.pt")
    assert info["weights"] == "EMA (decay 0.99)" and checkpoint_note(info).endswith("; weights: EMA (decay 0.99)")
