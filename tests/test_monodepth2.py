"""`posecons import-monodepth2`: Monodepth2's file layout (names and shapes as its public code writes
them), a round trip that keeps every output bit for bit, and one error line per wrong folder."""

import json
import re
from pathlib import Path

import numpy as np
import pytest
import torch

from posecons.checkpoint import describe_checkpoint, load_checkpoint, load_model
from posecons.cli import main
from posecons.config import load_config
from posecons.errors import PoseconsError
from posecons.model import PoseConsModel
from posecons.monodepth2 import FILES, POSE_OUT, monodepth2_name

DRIVE = "2011_09_26/2011_09_26_drive_0002_sync"


def random_model(num_layers: int = 10) -> PoseConsModel:
    """An untrained model whose BatchNorm statistics are random too, so that every buffer matters."""
    cfg = load_config(
        overrides=["model.height=64", "model.width=192", "model.pretrained=false", f"model.num_layers={num_layers}"]
    )
    model = PoseConsModel(cfg)
    for name, buffer in model.named_buffers():
        if "running" in name:
            buffer.copy_(torch.rand_like(buffer) + 0.5)
        elif "num_batches_tracked" in name:
            buffer.fill_(7)
    return model.eval()


def to_monodepth2(model: PoseConsModel, folder: Path, use_stereo: bool = False, pose: bool = True) -> dict:
    """Write ``model`` as Monodepth2's trainer saves a model folder; returns the files' dicts."""
    files = {name: {} for name in FILES}
    for key, value in model.state_dict().items():
        file, name = monodepth2_name(key)
        if key.startswith(POSE_OUT):  # Monodepth2's pose_2 also predicts a second, unused 6-vector
            value = torch.cat([value, torch.rand_like(value)])
        files[file][name] = value.clone()
    for file in ("encoder", "pose_encoder"):  # the ImageNet classifier Monodepth2's encoders keep
        width = files[file]["encoder.layer4.0.conv1.weight"].shape[0] * (
            4 if model.config.model.num_layers >= 50 else 1
        )
        files[file].update({"encoder.fc.weight": torch.zeros(1000, width), "encoder.fc.bias": torch.zeros(1000)})
    m = model.config.model
    files["encoder"].update(height=m.height, width=m.width, use_stereo=use_stereo)
    folder.mkdir(parents=True, exist_ok=True)
    for name in FILES if pose else ("encoder", "depth"):
        torch.save(files[name], folder / f"{name}.pth")
    return files


def outputs(model: PoseConsModel, images: torch.Tensor) -> list[torch.Tensor]:
    with torch.no_grad():
        return [*model.depth_net(images).values(), *model.pose_net(images, images.flip(0))]


def test_the_files_have_monodepth2s_names_and_shapes(tmp_path):
    """Pins the layout to what Monodepth2's code writes (ResnetEncoder, DepthDecoder's ModuleList of
    upconv (i, 0), (i, 1) for i = 4…0 then dispconv 0…3, PoseDecoder's squeeze, pose_0–2 for two frames),
    independently of the mapping table. Catches: up_in/up_out swapped or the ModuleList order
    reversed in ``monodepth2_name``, disp convs numbered from 0, the pose convs numbered as posecons'
    Sequential (net.0/2/4/6), the encoder prefix dropped, upconv (4, 0) / (4, 1) or pose_0 / pose_1
    swapped (same shapes)."""
    files = to_monodepth2(random_model(18), tmp_path)
    expected = {
        "encoder": {"encoder.conv1.weight": (64, 3, 7, 7), "encoder.layer4.1.bn2.running_var": (512,)},
        "depth": {
            "decoder.0.conv.conv.weight": (256, 512, 3, 3),  # upconv (4, 0)
            "decoder.1.conv.conv.weight": (256, 512, 3, 3),  # upconv (4, 1): 256 + the 256 skip channels
            "decoder.7.conv.conv.weight": (32, 96, 3, 3),  # upconv (1, 1): 32 + 64
            "decoder.8.conv.conv.weight": (16, 32, 3, 3),  # upconv (0, 0)
            "decoder.9.conv.conv.bias": (16,),  # upconv (0, 1), no skip
            "decoder.10.conv.weight": (1, 16, 3, 3),  # dispconv 0
            "decoder.13.conv.weight": (1, 128, 3, 3),  # dispconv 3
        },
        "pose_encoder": {"encoder.conv1.weight": (64, 6, 7, 7)},
        "pose": {
            "net.0.weight": (256, 512, 1, 1),
            "net.1.weight": (256, 256, 3, 3),
            "net.2.weight": (256, 256, 3, 3),
            "net.3.weight": (12, 256, 1, 1),
            "net.3.bias": (12,),
        },
    }
    for file, entries in expected.items():
        assert {k: tuple(files[file][k].shape) for k in entries} == entries, file
    assert len(files["depth"]) == 2 * 14 and len(files["pose"]) == 2 * 4
    # Where shapes cannot tell two layers apart: upconv (4, 0) and (4, 1), pose_0 and pose_1.
    assert monodepth2_name("depth_net.decoder.up_in.4.1.weight") == ("depth", "decoder.0.conv.conv.weight")
    assert monodepth2_name("depth_net.decoder.up_out.4.1.bias") == ("depth", "decoder.1.conv.conv.bias")
    assert monodepth2_name("pose_net.decoder.net.2.weight") == ("pose", "net.1.weight")
    assert monodepth2_name("pose_net.decoder.net.4.bias") == ("pose", "net.2.bias")


@pytest.mark.parametrize("num_layers", [10, 50])
def test_a_model_exported_to_monodepth2_and_imported_gives_identical_outputs(tmp_path, num_layers):
    """The importer against its own table read backwards (the table itself is pinned above and
    checked against Monodepth2's networks outside the suite). Catches: pose_2's first and second
    6-vector confused, a file's tensor (e.g. every running_var) not loaded, encoder.pth's height and
    width not taken, the ResNet depth misread."""
    model = random_model(num_layers)
    to_monodepth2(model, tmp_path / "md2")
    assert main(["import-monodepth2", str(tmp_path / "md2"), "--out", str(tmp_path / "m.pt")]) == 0
    imported, config = load_model(tmp_path / "m.pt")
    assert (config.model.num_layers, config.model.height, config.model.width) == (num_layers, 64, 192)
    images = torch.rand(2, 3, 64, 192)
    ours, theirs = outputs(model, images), outputs(imported, images)
    assert len(ours) == len(theirs) == 6  # four disparity scales, axis-angle, translation
    assert all(torch.equal(a, b) for a, b in zip(ours, theirs))
    info = describe_checkpoint(tmp_path / "m.pt")
    assert info["initialisation"] == f"imported: Monodepth2 {tmp_path / 'md2'} (ResNet-{num_layers}, mono, 192×64)"


def test_a_safetensors_name_gets_safetensors_that_predict_reads(tmp_path, kitti_dir):
    """``--out m.safetensors`` writes what the name says, and predict reads it as it reads the .pt import.
    Catches: a torch pickle written under that name (safetensors cannot open it: "header too large"),
    the origin of the weights lost in the other format."""
    from safetensors import safe_open

    to_monodepth2(random_model(), tmp_path / "md2")
    frame = kitti_dir / "raw_samples" / DRIVE / "image_02" / "data" / "0000000000.png"
    for name in ("m.pt", "m.safetensors"):
        assert main(["import-monodepth2", str(tmp_path / "md2"), "--out", str(tmp_path / name)]) == 0
        predict = ["predict", "--checkpoint", str(tmp_path / name), "--input", str(frame), "--quiet"]
        assert main([*predict, "--out", str(tmp_path / f"pred_{name}")]) == 0
    with safe_open(str(tmp_path / "m.safetensors"), framework="pt") as f:
        assert set(f.keys()) == set(load_checkpoint(tmp_path / "m.pt")["model"])
    depth = sorted((tmp_path / "pred_m.pt").rglob("*.npy"))
    assert depth and all(
        np.array_equal(np.load(p), np.load(tmp_path / "pred_m.safetensors" / p.relative_to(tmp_path / "pred_m.pt")))
        for p in depth
    )
    info = describe_checkpoint(tmp_path / "m.safetensors")
    assert info["initialisation"] == describe_checkpoint(tmp_path / "m.pt")["initialisation"]


def test_an_existing_out_file_is_refused_and_kept(tmp_path, capsys):
    """The README's output rule: posecons replaces no file of yours. Catches: --out overwritten (the
    file's bytes change), refused only after the import's work, or with more than one line."""
    to_monodepth2(random_model(), tmp_path / "md2")
    out = tmp_path / "trained.pt"
    out.write_bytes(b"the user's checkpoint")
    with pytest.raises(SystemExit) as exc:  # refused while the command line is read: before any work
        main(["import-monodepth2", str(tmp_path / "md2"), "--out", str(out)])
    assert exc.value.code == 2 and out.read_bytes() == b"the user's checkpoint"
    message = capsys.readouterr().err.strip().splitlines()[-1]
    assert message == f"posecons import-monodepth2: error: argument --out: {out}: exists; give a new file name " + (
        "(posecons replaces no file of yours)"
    )


def test_a_stereo_model_imports_its_depth_network_and_says_so(tmp_path, capsys):
    """Catches: a stereo folder refused for its missing pose files, or imported without saying that
    the pose net is untrained; the untrained pose net depending on the caller's random state."""
    model = random_model()
    to_monodepth2(model, tmp_path / "md2", use_stereo=True, pose=False)
    for out in ("a.pt", "b.pt"):
        assert main(["import-monodepth2", str(tmp_path / "md2"), "--out", str(tmp_path / out)]) == 0
        torch.rand(3)  # the caller's random state moves on: the second import must not depend on it
    assert "only depth is imported: a stereo model has no pose network" in capsys.readouterr().out
    imported = load_model(tmp_path / "a.pt")[0]
    images = torch.rand(1, 3, 64, 192)
    assert all(torch.equal(a, b) for a, b in zip(outputs(model, images)[:4], outputs(imported, images)[:4]))
    a, b = (load_checkpoint(tmp_path / f)["model"] for f in ("a.pt", "b.pt"))
    assert all(torch.equal(a[k], b[k]) for k in a)


def test_a_monodepth2_folder_is_a_start_for_training(tmp_path):
    """``train --init-from FOLDER``. Catches: a folder not read as a Monodepth2 model, its
    architecture not compared with the run's."""
    from posecons.training.initial_weights import initial_model

    model = random_model()
    to_monodepth2(model, tmp_path / "md2")
    run = ["model.num_layers=10", "model.pretrained=false", "model.height=128", "model.width=416"]
    start = initial_model(load_config(overrides=[*run, f"train.init_from={tmp_path / 'md2'}"]))
    assert all(torch.equal(v, start.state_dict()[k]) for k, v in model.state_dict().items())
    assert start.initialisation == f"weights of Monodepth2 {tmp_path / 'md2'} (ResNet-10, mono, 192×64)"
    with pytest.raises(PoseconsError, match="model.num_layers 10 \\(the run: 18\\)"):
        initial_model(load_config(overrides=[*run, "model.num_layers=18", f"train.init_from={tmp_path / 'md2'}"]))


def test_files_without_batchnorm_counters_import(tmp_path):
    """State dicts of PyTorch before 0.4.1 have no num_batches_tracked. Catches: the importer
    requiring them."""
    model = random_model()
    files = to_monodepth2(model, tmp_path / "md2")
    for name, content in files.items():
        torch.save(
            {k: v for k, v in content.items() if not k.endswith("num_batches_tracked")},
            tmp_path / "md2" / f"{name}.pth",
        )
    assert main(["import-monodepth2", str(tmp_path / "md2"), "--out", str(tmp_path / "m.pt")]) == 0
    images = torch.rand(1, 3, 64, 192)
    assert all(
        torch.equal(a, b) for a, b in zip(outputs(model, images), outputs(load_model(tmp_path / "m.pt")[0], images))
    )


def _drop(files, file, key):
    del files[file][key]


WRONG = {  # what is done to a mono ResNet-10 folder → the error line
    "missing depth.pth": (lambda d, f: (d / "depth.pth").unlink(), "depth.pth is missing"),
    "mono without pose files": (
        lambda d, f: [(d / f"{n}.pth").unlink() for n in ("pose_encoder", "pose")],
        "pose_encoder.pth, .*pose.pth missing: a mono or mono\\+stereo Monodepth2 model has",
    ),
    "pose.pth alone missing": (lambda d, f: (d / "pose.pth").unlink(), "pose.pth missing"),
    "misshapen disparity conv": (
        lambda d, f: f["depth"].update({"decoder.10.conv.weight": torch.zeros(1, 32, 3, 3)}),
        "depth.pth: decoder.10.conv.weight is \\(1, 32, 3, 3\\), a Monodepth2 ResNet-10 model has \\(1, 16, 3, 3\\)",
    ),
    "pose decoder of one frame": (
        lambda d, f: f["pose"].update({"net.3.weight": f["pose"]["net.3.weight"][:6]}),
        "pose.pth: net.3.weight is \\(6, 256, 1, 1\\)",
    ),
    "three-frame pose encoder": (
        lambda d, f: f["pose_encoder"].update({"encoder.conv1.weight": torch.zeros(64, 9, 7, 7)}),
        "pose_encoder.pth: encoder.conv1.weight is \\(64, 9, 7, 7\\)",
    ),
    "missing tensor": (
        lambda d, f: _drop(f, "depth", "decoder.3.conv.conv.bias"),
        "depth.pth: no decoder.3.conv.conv.bias",
    ),
    "unexpected tensor": (
        lambda d, f: f["pose"].update({"net.4.weight": torch.zeros(1)}),
        "pose.pth: unexpected entries net.4.weight",
    ),
    "no size entries": (lambda d, f: _drop(f, "encoder", "height"), "encoder.pth: no integer height and width"),
    "size not a multiple of 32": (
        lambda d, f: f["encoder"].update(height=100),
        "encoder.pth: model.height/width must be positive multiples of 32",
    ),
    "a ResNet posecons does not build": (
        lambda d, f: [_drop(f, "encoder", k) for k in list(f["encoder"]) if k.startswith("encoder.layer4.")],
        "encoder.pth: a ResNet of \\[1, 1, 1, 0\\] basic blocks per stage",
    ),
    "not a state dict": (lambda d, f: f.update(pose=[1, 2]), "pose.pth: not a Monodepth2 state dict \\(list\\)"),
    "pickled object": (
        lambda d, f: f["depth"].update({"decoder.0.conv.conv.weight": Path("x")}),
        "depth.pth: refused to load",
    ),
}


@pytest.mark.parametrize("case", list(WRONG))
def test_a_wrong_folder_is_refused_with_one_line_and_nothing_written(tmp_path, capsys, case):
    """Each check of ``read_monodepth2``: removing any one lets its case through (a checkpoint gets
    written) or fail with another message."""
    folder = tmp_path / "md2"
    files = to_monodepth2(random_model(), folder)
    change, message = WRONG[case]
    change(folder, files)
    for name, content in files.items():  # write back what the change edited (a deleted file stays deleted)
        if (folder / f"{name}.pth").exists():
            torch.save(content, folder / f"{name}.pth")
    capsys.readouterr()
    assert main(["import-monodepth2", str(folder), "--out", str(tmp_path / "m.pt")]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and err.startswith("posecons import-monodepth2: error: ")
    assert re.search(message, err), err
    assert not (tmp_path / "m.pt").exists()


def test_evaluate_depth_and_predict_give_an_imported_model_the_originals_results(tmp_path, kitti_dir):
    """Catches: an imported checkpoint that the evaluation or prediction path reads differently from
    a posecons one (another size, depth range or network)."""
    from posecons.checkpoint import save_checkpoint

    model = random_model()
    save_checkpoint(tmp_path / "own.pt", {"config": model.config.to_dict(), "model": model.state_dict()})
    to_monodepth2(model, tmp_path / "md2")
    assert main(["import-monodepth2", str(tmp_path / "md2"), "--out", str(tmp_path / "imp.pt")]) == 0
    split = tmp_path / "split.txt"
    split.write_text(f"{DRIVE} 0000000000 l\n{DRIVE} 0000000003 l\n")
    frames = kitti_dir / "raw_samples" / DRIVE / "image_02" / "data"
    for name in ("own", "imp"):
        ckpt = str(tmp_path / f"{name}.pt")
        evaluate = ["evaluate-depth", "--checkpoint", ckpt, "--data-path", str(kitti_dir / "raw_samples")]
        evaluate += ["--split-file", str(split), "--device", "cpu", "--save-disps", str(tmp_path / f"{name}.npy")]
        assert main([*evaluate, "--json", str(tmp_path / f"{name}.json")]) == 0
        predict = ["predict", "--checkpoint", ckpt, "--input", str(frames / "0000000000.png")]
        assert main([*predict, "--out", str(tmp_path / f"pred_{name}"), "--quiet"]) == 0
    assert np.array_equal(np.load(tmp_path / "own.npy"), np.load(tmp_path / "imp.npy"))
    own, imp = (json.loads((tmp_path / f"{n}.json").read_text()) for n in ("own", "imp"))
    assert own["abs_rel"] == imp["abs_rel"] and imp["checkpoint"]["initialisation"].startswith("imported: Monodepth2")
    depth = sorted((tmp_path / "pred_own").rglob("*.npy"))
    assert depth and all(
        np.array_equal(np.load(p), np.load(tmp_path / "pred_imp" / p.relative_to(tmp_path / "pred_own"))) for p in depth
    )
