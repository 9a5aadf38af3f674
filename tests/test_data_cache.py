"""The frame cache (`posecons cache`, `data.cache_dir`): the loader gives the same batches, bit for bit,
from the cache as from the images; a cache made for another setting, an unfinished one and one with
a frame missing are refused with one line; an interrupted build is finished by running it again."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
from torch.utils.data import DataLoader

from posecons.cli import main
from posecons.config import load_config
from posecons.data import frames as frames_module
from posecons.data.cache import MANIFEST
from posecons.data.cache_build import build_cache
from posecons.data.datasets import build_dataset, split_files
from posecons.errors import PoseconsError

# The synthetic frames are 200×90: the loader shrinks them (antialiased) to 128×64.
SETS = ["data.split=synth", "model.height=64", "model.width=128", "model.num_layers=10", "model.pretrained=false"]


def config(*extra: str):
    return load_config(overrides=SETS + list(extra))


@pytest.fixture(scope="module")
def data(make_synth) -> Path:
    return make_synth(2, 12, 200, 90, 5)


@pytest.fixture(scope="module")
def cache(data, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("cache") / "frames"
    sets = [arg for s in SETS for arg in ("--set", s)]
    argv = ["cache", "--data-path", str(data), "--config", "kitti/baseline", *sets, "--out", str(out)]
    assert main(argv + ["--workers", "2"]) == 0
    return out


def dataset(cfg, data: Path, train: bool = True):
    train_file, val_file = split_files(cfg, data, None)
    return build_dataset(cfg, data, train_file if train else val_file, train=train)


def batches(cfg, data: Path, train: bool, epoch: int) -> list[dict]:
    ds = dataset(cfg, data, train)
    order = torch.randperm(len(ds), generator=torch.Generator().manual_seed(epoch)).tolist()
    return list(DataLoader(ds, batch_size=2, sampler=[(epoch, i) for i in order]))


def test_cached_batches_are_bit_identical_with_flips_and_jitter(data, cache, monkeypatch):
    plain = {(train, e): batches(config(), data, train, e) for train in (True, False) for e in (0, 1)}

    def no_decoding(*args, **kwargs):
        raise AssertionError("the cached loader decoded an image")

    monkeypatch.setattr(frames_module, "load_resized", no_decoding)
    cached_config = config(f"data.cache_dir={cache}")
    for (train, epoch), expected in plain.items():
        got = batches(cached_config, data, train, epoch)
        assert len(got) == len(expected) > 0
        for a, b in zip(expected, got):
            assert a.keys() == b.keys() == {"frames", "intrinsics", "color_aug", "index", "folder", "frame", "side"}
            for key in a:
                same = torch.equal(a[key], b[key]) if torch.is_tensor(a[key]) else a[key] == b[key]
                assert same, (train, epoch, key)
    # The comparison saw both flipped and unflipped samples, jittered and plain ones.
    train_samples = [b for e in (0, 1) for b in plain[(True, e)]]
    cx = torch.cat([b["intrinsics"][:, 0, 2] for b in train_samples])
    jitter = torch.cat([b["color_aug"] for b in train_samples])
    assert len(cx.unique()) == 2
    assert (jitter == torch.tensor([1.0, 1, 1, 0])).all(1).any() and (jitter != torch.tensor([1.0, 1, 1, 0])).any()


def test_cache_holds_the_resized_uint8_frames_and_a_manifest(data, cache):
    manifest = json.loads((cache / MANIFEST).read_text())
    assert manifest["complete"] and (manifest["height"], manifest["width"]) == (64, 128)
    files = sorted((cache / "frames").rglob("*.npy"))
    assert len(files) == manifest["frames"]
    lines = {
        (line.folder, line.side, line.frame + o)
        for t in (True, False)
        for line in dataset(config(), data, t).lines
        for o in (0, -1, 1)
    }
    assert len(files) == len(lines)  # each frame of each split line once, neighbours shared
    frame = np.load(files[0])
    assert frame.dtype == np.uint8 and frame.shape == (64, 128, 3)
    assert files[0].stat().st_size == manifest["bytes_per_frame"] == 128 + 64 * 128 * 3


@pytest.mark.parametrize(
    "extra,fragments",
    [
        (["model.width=96"], ["model.width 128 (now 96)"]),
        (["model.frame_ids=[0,-2,2]", "data.skip_incomplete=true"], ["model.frame_ids [0, -1, 1] (now [0, -2, 2])"]),
        (["data.img_ext=.jpg"], ["data.img_ext '.png' (now '.jpg')"]),
        (["data.jpeg_draft=true"], ["resize ", "to uint8' (now ", "JPEGs decoded at the smallest DCT scale"]),
    ],
)
def test_cache_for_another_setting_is_refused(data, cache, extra, fragments):
    with pytest.raises(PoseconsError) as exc:
        dataset(config(f"data.cache_dir={cache}", *extra), data)
    message = str(exc.value)
    assert "\n" not in message and message.startswith(f"{cache}: frame cache made for another setting")
    for fragment in fragments:
        assert fragment in message


def test_cache_for_another_split_is_refused(data, cache, tmp_path):
    cfg = config(f"data.cache_dir={cache}")
    train_file, _ = split_files(cfg, data, None)
    (tmp_path / "train_files.txt").write_text("".join(train_file.read_text().splitlines(True)[1:]))
    with pytest.raises(PoseconsError, match=f"train split {train_file} \\(now {tmp_path}/train_files.txt, other lines"):
        build_dataset(cfg, data, tmp_path / "train_files.txt", train=True)


def test_stale_cache_stops_train_with_exit_2_and_one_line(data, cache, tmp_path, capsys):
    sets = [arg for s in SETS + [f"data.cache_dir={cache}", "model.height=96"] for arg in ("--set", s)]
    argv = ["train", "--config", "kitti/baseline", "--data-path", str(data), "--out", str(tmp_path / "run"), *sets]
    assert main(argv + ["--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "model.height 64 (now 96)" in err[0] and str(cache) in err[0]
    assert not (tmp_path / "run").exists()


def test_missing_cached_frame_is_one_line_naming_the_split_line(data, cache, tmp_path):
    damaged = tmp_path / "cache"
    shutil.copytree(cache, damaged)
    line = dataset(config(), data).lines[0]
    victim = damaged / "frames" / line.folder / "image_02" / "data" / f"{line.frame + 1:010d}.npy"
    victim.unlink()
    with pytest.raises(PoseconsError, match=f"frame {line.frame}\\+1 of '{line}' is not in the frame cache {damaged}"):
        dataset(config(f"data.cache_dir={damaged}"), data)


def test_interrupted_build_is_refused_then_finished_by_the_same_command(data, cache, tmp_path, monkeypatch):
    from posecons.data import cache_build

    out, done = tmp_path / "cache", []
    real = cache_build._cache_frame

    def interrupted(job):
        if len(done) == 3:
            raise KeyboardInterrupt
        real(job)
        done.append(job)

    monkeypatch.setattr(cache_build, "_cache_frame", interrupted)
    with pytest.raises(KeyboardInterrupt):
        build_cache(config(), data, out, workers=1)
    monkeypatch.setattr(cache_build, "_cache_frame", real)
    folder = done[0][2].parent
    (folder / ".0000000099.a1b2c3d4.npy").write_bytes(b"half a frame")  # what a SIGKILL leaves behind
    assert len(list(out.rglob("*.npy"))) == 4 and not json.loads((out / MANIFEST).read_text())["complete"]
    with pytest.raises(PoseconsError, match=f"{out}: incomplete frame cache .* run the same `posecons cache`"):
        dataset(config(f"data.cache_dir={out}"), data)

    info = build_cache(config(), data, out, workers=1)
    assert info["complete"] and info["written"] == info["frames"] - 3
    assert not (folder / ".0000000099.a1b2c3d4.npy").exists()
    finished = sorted(p.relative_to(out) for p in (out / "frames").rglob("*") if p.is_file())
    assert finished == sorted(p.relative_to(cache) for p in (cache / "frames").rglob("*") if p.is_file())
    assert all((out / p).read_bytes() == (cache / p).read_bytes() for p in finished)
    assert build_cache(config(), data, out, workers=1)["written"] == 0


def test_build_refuses_a_cache_of_another_setting_or_a_foreign_folder(data, cache, tmp_path):
    before = (cache / MANIFEST).read_text()
    with pytest.raises(PoseconsError, match="holds a frame cache made for another setting: model.height 64 .now 96"):
        build_cache(config("model.height=96"), data, cache)
    assert (cache / MANIFEST).read_text() == before
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("the user's")
    with pytest.raises(PoseconsError, match="not empty and holds no frame cache"):
        build_cache(config(), data, tmp_path / "mine")
    assert sorted(p.name for p in (tmp_path / "mine").iterdir()) == ["notes.txt"]
