"""Monodepth2 model folders read as posecons models: the same networks (SPEC §2) under other names.

Monodepth2 (Godard et al. 2019) saves each network's state dict in a file of its own; the depth
encoder's also holds the training size (``height``, ``width``) and ``use_stereo``. A mono or
mono+stereo model has a "separate_resnet" pose network, a stereo-only model none. The names,
learnt from Monodepth2's public code (P: ``weight`` / ``bias``, K: torchvision ResNet keys):

=====================================  ===============================================
posecons                               Monodepth2 file: key
=====================================  ===============================================
depth_net.encoder.net.K                encoder.pth: encoder.K (its encoder.fc is unused)
depth_net.decoder.up_in.i.1.P          depth.pth: decoder.{2·(4−i)}.conv.conv.P
depth_net.decoder.up_out.i.1.P         depth.pth: decoder.{2·(4−i)+1}.conv.conv.P
depth_net.decoder.disp_convs.s.1.P     depth.pth: decoder.{10+s}.conv.P
pose_net.encoder.net.K                 pose_encoder.pth: encoder.K (conv1 takes the 6-channel pair)
pose_net.decoder.net.{0,2,4,6}.P       pose.pth: net.{0,1,2,3}.P (squeeze, pose_0, pose_1, pose_2)
=====================================  ===============================================

Monodepth2's pose_2 predicts two 6-vectors of which its training uses only the first: those 6
output channels are the posecons pose decoder's last layer.
"""

from __future__ import annotations

import re
from pathlib import Path

import torch

from .checkpoint import load_weights_file, save_checkpoint, save_safetensors
from .config import Config
from .errors import PoseconsError
from .model import PoseConsModel

FILES = ("encoder", "depth", "pose_encoder", "pose")
EXTRAS = ("height", "width", "use_stereo")  # encoder.pth's entries that are no weights
POSE_OUT = "pose_net.decoder.net.6."  # Monodepth2's pose_2: 12 output channels, the first 6 imported
# (blocks per ResNet stage, bottleneck blocks) → num_layers
RESNETS = {((1, 1, 1, 1), False): 10, ((2, 2, 2, 2), False): 18, ((3, 4, 6, 3), False): 34, ((3, 4, 6, 3), True): 50}


def monodepth2_name(key: str) -> tuple[str, str]:
    """A posecons state-dict key → (Monodepth2 file stem, key in that file), by the table above."""
    for prefix, file in (("depth_net.encoder.net.", "encoder"), ("pose_net.encoder.net.", "pose_encoder")):
        if key.startswith(prefix):
            return file, "encoder." + key[len(prefix) :]
    if m := re.fullmatch(r"depth_net\.decoder\.(up_in|up_out|disp_convs)\.(\d)\.1\.(weight|bias)", key):
        kind, i, param = m[1], int(m[2]), m[3]
        if kind == "disp_convs":
            return "depth", f"decoder.{10 + i}.conv.{param}"
        return "depth", f"decoder.{2 * (4 - i) + (kind == 'up_out')}.conv.conv.{param}"
    if m := re.fullmatch(r"pose_net\.decoder\.net\.(\d)\.(weight|bias)", key):
        return "pose", f"net.{int(m[1]) // 2}.{m[2]}"
    raise KeyError(f"{key} has no Monodepth2 counterpart")


def read_monodepth2(folder: str | Path, map_location: str = "cpu") -> tuple[Config, dict[str, torch.Tensor], str]:
    """A Monodepth2 model folder → (its posecons config, posecons state dict, where the weights came
    from in words). Every file is read with ``weights_only``; a missing file, a missing, unexpected or
    misshapen tensor raises a one-line PoseconsError naming the file. A stereo-only model (no pose
    files) gives its depth network and an untrained pose network, which the description says."""
    folder = Path(folder)
    if not folder.is_dir():
        raise PoseconsError(f"{folder}: not a Monodepth2 model folder (encoder.pth, depth.pth, …)")
    paths = {name: folder / f"{name}.pth" for name in FILES}
    for name in ("encoder", "depth"):
        if not paths[name].is_file():
            raise PoseconsError(f"{paths[name]} is missing: a Monodepth2 model folder has {name}.pth")
    files = {name: load_weights_file(p, map_location) for name, p in paths.items() if p.is_file()}
    for name, content in files.items():
        if not isinstance(content, dict):
            raise PoseconsError(f"{paths[name]}: not a Monodepth2 state dict ({type(content).__name__})")
    encoder = files["encoder"]
    height, width, stereo = (encoder.get(k) for k in EXTRAS)
    if type(height) is not int or type(width) is not int or not isinstance(stereo, bool):
        raise PoseconsError(f"{paths['encoder']}: no integer height and width and boolean use_stereo entries")
    pose_files = [n for n in ("pose_encoder", "pose") if n in files]
    depth_only = not pose_files and stereo
    if len(pose_files) < 2 and not depth_only:
        missing = ", ".join(str(paths[n]) for n in ("pose_encoder", "pose") if n not in files)
        raise PoseconsError(
            f"{missing} missing: a mono or mono+stereo Monodepth2 model has pose_encoder.pth and pose.pth"
        )

    config = Config()
    m = config.model
    m.num_layers, m.height, m.width, m.pretrained = _num_layers(encoder, paths["encoder"]), height, width, False
    try:
        config.validate()
    except PoseconsError as exc:
        raise PoseconsError(f"{paths['encoder']}: {exc}") from exc
    with torch.random.fork_rng(devices=[]):  # the untrained pose net of a stereo model is the same every time
        torch.manual_seed(0)
        state = PoseConsModel(config).state_dict()
    used: dict[str, set[str]] = {name: set() for name in files}
    for key, ours in state.items():
        file, name = monodepth2_name(key)
        if depth_only and file in ("pose_encoder", "pose"):
            continue
        if name not in files[file]:
            if name.endswith("num_batches_tracked"):  # absent from files of PyTorch before 0.4.1
                continue
            raise PoseconsError(f"{paths[file]}: no {name} (a Monodepth2 ResNet-{m.num_layers} model has it)")
        value = files[file][name]
        expected = (12, *ours.shape[1:]) if key.startswith(POSE_OUT) else ours.shape
        if not isinstance(value, torch.Tensor) or value.shape != expected:
            shape = tuple(value.shape) if isinstance(value, torch.Tensor) else type(value).__name__
            raise PoseconsError(
                f"{paths[file]}: {name} is {shape}, a Monodepth2 ResNet-{m.num_layers} model has {tuple(expected)}"
            )
        state[key] = (value[:6].clone() if key.startswith(POSE_OUT) else value).to(ours.dtype)
        used[file].add(name)
    for file, content in files.items():
        extra = [k for k in content if k not in used[file] and not _unused(file, k)]
        if extra:
            raise PoseconsError(
                f"{paths[file]}: unexpected entries {', '.join(extra[:3])}{' …' if len(extra) > 3 else ''} "
                "(not a Monodepth2 model with a separate_resnet pose network)"
            )
    kind = "stereo" if depth_only else "mono+stereo" if stereo else "mono"
    untrained = (
        "; only depth is imported: a stereo model has no pose network, this pose net is untrained" if depth_only else ""
    )
    return config, state, f"Monodepth2 {folder} (ResNet-{m.num_layers}, {kind}, {width}×{height}{untrained})"


def import_monodepth2(folder: str | Path, out: str | Path) -> str:
    """Write a Monodepth2 model folder as the posecons checkpoint ``out`` (atomically, after every
    check): safetensors where its name ends in ``.safetensors``, as :func:`read_weights` reads it back,
    else a ``.pt`` checkpoint; returns where its weights came from, in words."""
    config, state, origin = read_monodepth2(folder)
    initialisation = f"imported: {origin}"
    if Path(out).suffix == ".safetensors":
        save_safetensors(out, state, config, initialisation)
    else:
        save_checkpoint(out, {"config": config.to_dict(), "model": state, "initialisation": initialisation})
    return origin


def _unused(file: str, key: str) -> bool:
    """Entries of a Monodepth2 file that posecons has no place for: the encoders' ImageNet
    classifier (kept by Monodepth2, never used) and encoder.pth's size and stereo flag."""
    return key.startswith("encoder.fc.") or (file == "encoder" and key in EXTRAS)


def _num_layers(encoder: dict, path: Path) -> int:
    """The ResNet depth of encoder.pth, from its blocks per stage and their type."""
    blocks = tuple(
        1 + max((int(k.split(".")[2]) for k in encoder if k.startswith(f"encoder.layer{stage}.")), default=-1)
        for stage in (1, 2, 3, 4)
    )
    bottleneck = "encoder.layer1.0.conv3.weight" in encoder
    if (blocks, bottleneck) not in RESNETS:
        raise PoseconsError(
            f"{path}: a ResNet of {list(blocks)} {'bottleneck' if bottleneck else 'basic'} blocks per stage; "
            "posecons builds ResNet-18, 34 and 50 (and its demo ResNet-10)"
        )
    return RESNETS[blocks, bottleneck]
