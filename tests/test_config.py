import pytest

from posecons.config import load_config
from posecons.errors import PoseconsError


def test_defaults_are_the_paper_setting():
    c = load_config()
    assert (c.model.height, c.model.width, c.train.batch_size, c.train.lr, c.train.epochs) == (192, 640, 12, 1e-4, 20)
    assert c.train.lr_decay_epochs == [15] and c.model.frame_ids == [0, -1, 1]
    assert (c.loss.fb_weight, c.loss.id_weight, c.loss.cyc_weight) == (0.1, 0.1, 0.1)


def test_preset_with_base_and_overrides(tmp_path):
    (tmp_path / "base.yaml").write_text("model:\n  height: 96\n  width: 320\ntrain:\n  lr: 3.0e-4\n")
    (tmp_path / "cyc.yaml").write_text("base: base.yaml\nloss:\n  constraints: [cyc]\n")
    c = load_config(tmp_path / "cyc.yaml", ["train.lr=1e-3", "loss.fb_weight=1"])
    assert (c.model.height, c.model.width, c.loss.constraints) == (96, 320, ["cyc"])
    assert c.train.lr == 1e-3 and c.loss.fb_weight == 1.0 and isinstance(c.loss.fb_weight, float)


@pytest.mark.parametrize("override,message", [
    ("model.heigth=96", "unknown config key 'model.heigth'"),
    ("train.batch_size=big", "train.batch_size: expected int"),
    ("model.height=100", "multiples of 32"),
    ("loss.constraints=[cycle]", "unknown \\['cycle'\\]"),
    ("train.keep_epochs=-2", "train.keep_epochs must be -1"),
    ("model.frame_ids=[0,1]", None),  # valid without fb/cyc
])
def test_bad_values_are_rejected(override, message):
    if message is None:
        assert load_config(overrides=[override]).model.frame_ids == [0, 1]
        with pytest.raises(PoseconsError, match="needs model.frame_ids to hold a past and a future"):
            load_config(overrides=[override, "loss.constraints=[cyc]"])
        return
    with pytest.raises(PoseconsError, match=message):
        load_config(overrides=[override])


def test_missing_or_malformed_preset_names_the_file(tmp_path):
    with pytest.raises(PoseconsError, match="nope.yaml"):
        load_config(tmp_path / "nope.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("model: [1, 2\n")
    with pytest.raises(PoseconsError, match="bad.yaml: not valid YAML"):
        load_config(bad)
