"""Typed, documented defaults for every setting, and YAML presets that name only what differs.

A preset is a small YAML file with the same nesting as :class:`Config`; it may name a
``base:`` preset (path relative to itself) that it extends. ``--set key=value`` overrides
use dotted keys (``loss.constraints=[cyc]``). Unknown keys and wrong types are rejected
before anything runs.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional, Union

import yaml

from .errors import PoseconsError

CONSTRAINTS = ("fb", "id", "cyc")
PRESETS = Path(__file__).resolve().parent / "configs"  # bundled presets; the repository's configs/ links here
STUDY_SPECS = PRESETS / "study"  # bundled `posecons study` specs (study/NAME), which are not training presets
Check = Callable[[str, Any], Optional[str]]  # (key, value) → the error message, or None for a valid value


def _rule(test: Callable[[Any], Any], text: str) -> Check:
    """A check whose error reads '<key> <text>, got <value>'."""
    return lambda key, value: None if test(value) else f"{key} {text}, got {value!r}"


def _at_least(low: float) -> Check:
    return _rule(lambda v: v >= low, f"must be ≥ {low:g}")


def _one_of(*values: Any) -> Check:
    spelled = [str(v).lower() if isinstance(v, bool) else repr(v) for v in values]  # as YAML writes them
    return _rule(lambda v: v in values, f"must be {', '.join(spelled[:-1])} or {spelled[-1]}")


def _known_constraints(key: str, value: list[str]) -> str | None:
    bad = [c for c in value if c not in CONSTRAINTS]
    return f"{key}: unknown {bad}; choose from {list(CONSTRAINTS)}" if bad else None


def _val_every(key: str, value: Any) -> str | None:
    if value in ("epoch", "off") or (type(value) is int and value >= 1):
        return None
    return f'{key} must be a number of steps ≥ 1, "epoch" (after each epoch) or "off"; got {value!r}'


_FRACTION = _rule(lambda v: 0 <= v <= 1, "must be in [0, 1]")
_POSITIVE = _rule(lambda v: v > 0, "must be > 0")
# The one place that says which value of a key is valid: "section.key" → its check. Every float
# must also be finite; checks that relate several keys are in Config.validate.
RULES: dict[str, Check] = {
    "model.num_layers": _one_of(10, 18, 34, 50),
    "model.pretrained": _one_of(True, False, "auto"),
    "model.min_depth": _POSITIVE,
    "model.pose_rotation_scale": _POSITIVE,
    "model.max_depth": _POSITIVE,
    "model.scales": _rule(
        lambda v: v and len(set(v)) == len(v) and set(v) <= {0, 1, 2, 3},
        "must be distinct scales from 0–3, e.g. [0, 1, 2, 3]",
    ),
    "model.frame_ids": _rule(
        lambda v: v and v[0] == 0 and len(set(v)) == len(v), "must start with 0 and have no repeats"
    ),
    "loss.ssim_weight": _FRACTION,
    "loss.identity_fraction": _FRACTION,
    "loss.constraints": _known_constraints,
    "loss.smoothness_weight": _at_least(0),
    "loss.fb_weight": _at_least(0),
    "loss.id_weight": _at_least(0),
    "loss.cyc_weight": _at_least(0),
    "loss.constraint_start_step": _at_least(0),
    "loss.automask_start_step": _at_least(0),
    "loss.depth_consistency_weight": _at_least(0),
    "loss.depth_consistency_form": _one_of("one_way", "sc_depth"),
    "loss.skip_weight": _at_least(0),
    "loss.velocity_weight": _at_least(0),
    "loss.far_rotation_weight": _at_least(0),
    "loss.far_rotation_fraction": _rule(lambda v: 0 < v <= 1, "must be in (0, 1]"),
    "loss.far_rotation_start_step": _at_least(0),
    "loss.saturation_weight": _at_least(0),
    "loss.saturation_bound": _POSITIVE,
    "data.dataset": _one_of("kitti_raw", "kitti_odom"),
    "data.split": _rule(bool, "must name a split"),
    "data.img_ext": _rule(bool, "must be an extension such as .png"),
    "data.flip_prob": _FRACTION,
    "data.jitter_prob": _FRACTION,
    "data.num_workers": _at_least(0),
    "train.batch_size": _at_least(1),
    "train.lr": _POSITIVE,
    "train.epochs": _at_least(1),
    "train.lr_decay_epochs": _rule(lambda v: all(e >= 1 for e in v), "must be epochs ≥ 1"),
    "train.lr_decay": _POSITIVE,
    "train.grad_accum": _at_least(1),
    "train.warmup_steps": _at_least(0),
    "train.seed": _at_least(0),
    "train.precision": _one_of("32", "bf16", "16", "auto"),
    "train.max_steps": _at_least(0),
    "train.log_every": _at_least(1),
    "train.image_every": _at_least(0),
    "train.val_every": _val_every,
    "train.val_samples": _at_least(1),
    "train.best_metric": _one_of("val_photometric", "abs_rel"),
    "train.checkpoint_every": _at_least(0),
    "train.keep_epochs": _rule(lambda v: v >= -1, "must be -1 (keep all), 0 (none) or a count"),
    "train.max_bad_steps": _at_least(1),
    "train.ema_decay": _rule(lambda v: 0 <= v < 1, "must be in [0, 1)"),
}
# Older spellings that are still read, as (that value, the one spelling a config holds): YAML 1.1
# reads a bare `off` as false, and 0 meant "epoch" in the configs of earlier runs.
RESPELLED = {"train.val_every": ((False, "off"), (0, "epoch"))}

# Options an investigation tried and did not keep (experiments/README.md). The configs stored before
# their removal (checkpoints, runs' config.yaml) hold them at the one value the code still implements,
# which is accepted and dropped; any other value needs the commit named, the last to have the option.
RETIRED = {  # "section.key": (the value every run now has, that commit)
    "model.constraint_norm": ("own", "1be435b"),
    "loss.constraint_fraction": (1.0, "1be435b"),
    "loss.translation_norm": ("sum", "1be435b"),
    "model.pose_zero_init": (False, "7f7a6ba"),
}


@dataclass
class ModelConfig:
    num_layers: int = 18  # ResNet depth for both encoders: 18, 34, 50; 10 is the small demo encoder
    pretrained: Union[bool, str] = "auto"  # ImageNet weights: true (required), false, or "auto" (if reachable)
    height: int = 192  # network input size in pixels; multiples of 32, at least 64
    width: int = 640
    min_depth: float = 0.1  # metres (up to the unknown scale of monocular training)
    max_depth: float = 100.0
    scales: list[int] = field(default_factory=lambda: [0, 1, 2, 3])  # decoder outputs at 1/2^s size; any of 0-3
    frame_ids: list[int] = field(default_factory=lambda: [0, -1, 1])  # target first, then sources
    # Pose of a pair = mean of the pose net's output for it and the mirrored output for its mirror image:
    # mirror-equivariant by construction (sideways motion, yaw and roll cannot hold a constant bias)
    pose_mirror: bool = False
    # The pose decoder's axis-angle is this × its output (Monodepth2: 0.01, as for the translation). A
    # rotation of 0.2 rad then needs an output of 20, which a scratch net reaches slowly; the translation
    # needs no such size, its scale being free
    pose_rotation_scale: float = 0.01
    # Warp with the data set's true camera motion (raw: oxts/ through the date's calibration files;
    # odometry: poses/NN.txt) instead of the pose net's. Not self-supervised: the depth learns metres
    # (set min/max_depth in metres) and the pose net is not trained, so no pose-net loss may be on
    known_motion: bool = False
    # Warp with the data set's rotation (what a rig's gyro measures) and the pose net's translation: the
    # rotation of each T_{f←0} replaced by the true one's (the same files as known_motion)
    known_rotation: bool = False


@dataclass
class LossConfig:
    ssim_weight: float = 0.85  # photometric error = a·(1-SSIM)/2 + (1-a)·L1
    smoothness_weight: float = 1e-3  # divided by 2^s at scale s
    automask: bool = True
    # The auto-mask from this step on; before it every pixel counts (experiments/investigation.md §30)
    automask_start_step: int = 0
    v1_multiscale: bool = False  # compute the photometric loss at each scale's native size
    constraints: list[str] = field(default_factory=list)  # any of "fb", "id", "cyc"
    fb_weight: float = 0.1
    id_weight: float = 0.1
    cyc_weight: float = 0.1
    constraint_start_step: int = 0  # the authors' released code waited 2000 steps
    identity_fraction: float = 1.0  # fraction of batches that get the identity constraint
    # SC-SfMLearner's depth consistency |D_0→f − D_f'| / (D_0→f + D_f') at scale 0 (not in the paper);
    # > 0 runs the depth net on the sources too; 0 (off) leaves every other loss as it was
    depth_consistency_weight: float = 0.0
    # one_way: the above, target → sources only (the form the studies measured); sc_depth: SC-Depth as
    # published — the mean over both directions (also each source's depth into the target), and the
    # self-discovered mask 1 − D_diff (detached) weighting each source's photometric error
    depth_consistency_form: str = "one_way"
    # View synthesis of the cycle's skip pair (−n, +n): frame +n warped into frame −n with D_{−n} and
    # T_{+n←−n}, auto-masked photometric error at scale 0 (not in the paper). Without it that pose is
    # taught by the cycle constraint alone (experiments/investigation.md §5); > 0 runs the depth net on
    # the sources too and the pose net on (−n, +n) every step
    skip_weight: float = 0.0
    # Velocity supervision (PackNet-SfM's, one scale a batch left free; not in the paper, not
    # self-supervised): each source pair's translation length in proportion to the metres travelled
    # (raw: oxts/, odometry: poses/NN.txt; losses.velocity_loss). One scale for every training pair,
    # not metres; needs those files for the training split
    velocity_weight: float = 0.0
    # The pose net's rotation taught by the far pixels (losses.far_rotation_loss; not in the paper): each
    # source warped by T_{f←0}'s rotation alone, photometric error over the target's farthest
    # far_rotation_fraction of pixels by its predicted depth, averaged over the scales at their own sizes
    far_rotation_weight: float = 0.0
    far_rotation_fraction: float = 0.3333
    far_rotation_start_step: int = 0  # the term counts from this step on, as constraint_start_step
    # A wall on the depth net's disparity logits (losses.saturation_loss; not in the paper): weight ×
    # the mean squared excess beyond ±saturation_bound (4.6: the sigmoid's 0.01 and 0.99), so that a
    # disparity driven to either end of its range is not pinned there by a vanishing gradient
    saturation_weight: float = 0.0
    saturation_bound: float = 4.6


@dataclass
class DataConfig:
    dataset: str = "kitti_raw"  # kitti_raw (also synth and prepared custom data) or kitti_odom
    split: str = "eigen_zhou"  # split files are read from <data_path>/splits/<split> unless --split-dir
    img_ext: str = ".png"
    calib_intrinsics: bool = True  # K from each drive's calibration; false: KITTI's fixed normalised K
    flip_prob: float = 0.5  # probability in [0, 1]
    jitter_prob: float = 0.5
    num_workers: int = 2  # DataLoader worker processes; 0 loads in the training process
    # Folder written by `posecons cache` for this config (same size, data path and splits): the loader
    # reads its resized frames instead of decoding the images; null: decode the images.
    cache_dir: Optional[str] = None
    # Drop split lines whose frames (model.frame_ids) are not all on disk, printing how many, instead
    # of stopping at the first: e.g. frame offsets ±3 on a split made for ±1 near drive ends.
    skip_incomplete: bool = False
    # Decode JPEG frames by DCT scaling at the smallest 1/2, 1/4 or 1/8 of their size that still covers
    # model.width × height, then resize: about 4× faster at 192×64 from KITTI's 1242×375, but other
    # pixels (a mean 1.5–3 grey levels) than the full decode that evaluation and inference use; no
    # effect above half the frame size (the paper's 640×192) or on PNGs (docs/performance.md).
    jpeg_draft: bool = False


@dataclass
class TrainConfig:
    batch_size: int = 12
    lr: float = 1e-4  # Adam learning rate
    epochs: int = 20
    lr_decay_epochs: list[int] = field(default_factory=lambda: [15])  # lr × lr_decay at these epochs
    lr_decay: float = 0.1
    warmup_steps: int = 0  # linear learning-rate warm-up over the first steps; 0: none (Monodepth2)
    grad_accum: int = 1
    seed: int = 0
    deterministic: bool = False
    # "32", "bf16" (GPU or CPU), "16" (GPU) or "auto" (bf16 where the device computes it natively, else 32):
    # the networks under autocast, their outputs fp32.
    precision: str = "32"
    # torch.compile the photometric error (SSIM + L1, the largest element-wise part of a step at the
    # paper's resolution): the first steps take longer while it compiles; where it cannot compile (no
    # C++ compiler, an unsupported build) the losses run eagerly, with one warning (docs/performance.md)
    compile_losses: bool = False
    sync_bn: bool = False  # SyncBatchNorm in the depth net across processes (the pose net's stays per group)
    max_steps: int = 0  # 0: run all epochs
    log_every: int = 50
    image_every: int = 500  # steps between TensorBoard images; 0: none
    # Steps between validations, "epoch" (after each epoch) or "off" (never; no best.pt).
    val_every: Union[int, str] = "epoch"
    val_samples: int = 500  # validation uses at most this many val-split samples, spread evenly
    # best.pt: lowest "val_photometric" (self-supervised, the default) or "abs_rel" (needs LiDAR
    # ground truth in the val split: supervised model selection, named as such in every report)
    best_metric: str = "val_photometric"
    checkpoint_every: int = 500  # steps between `last` checkpoints (and at every epoch end); 0: epoch ends only
    keep_epochs: int = -1  # per-epoch weight files kept (the newest); -1 keeps all, 0 none
    max_bad_steps: int = 5  # consecutive non-finite losses before the run stops
    # EMA of the weights and BatchNorm buffers after every optimiser step, ema ← d·ema + (1 − d)·w, for
    # validation, best.pt and the final weights (last.pt also keeps the raw ones); 0: off
    ema_decay: float = 0.0
    # Start from the weights, and only the weights, of a posecons checkpoint (.pt, .safetensors) or a Monodepth2
    # model folder of the run's architecture (model.num_layers, scales, pose_mirror): fine-tuning, with a new
    # optimiser, schedule and step count, instead of model.pretrained's initialisation; null: none
    init_from: Optional[str] = None


@dataclass
class Config:
    model: ModelConfig = field(default_factory=ModelConfig)
    loss: LossConfig = field(default_factory=LossConfig)
    data: DataConfig = field(default_factory=DataConfig)
    train: TrainConfig = field(default_factory=TrainConfig)

    def validate(self) -> Config:
        self._check_rules()
        m, lo = self.model, self.loss
        if m.min_depth >= m.max_depth:
            raise PoseconsError(f"model.min_depth ({m.min_depth}) must be below model.max_depth ({m.max_depth})")
        if m.height % 32 or m.width % 32 or m.height <= 0 or m.width <= 0:
            raise PoseconsError(
                f"model.height/width must be positive multiples of 32 (the encoder downsamples 32×); "
                f"got {m.height}×{m.width}. Nearby sizes that work: "
                f"{max(32, round(m.height / 32) * 32)}×{max(32, round(m.width / 32) * 32)}"
            )
        if min(m.height, m.width) < 64:  # the 1/32-size features must be ≥ 2 pixels for their reflection padding
            raise PoseconsError(f"model.height/width must be at least 64, got {m.height}×{m.width}")
        if m.known_motion and (
            lo.constraints or lo.skip_weight > 0 or lo.velocity_weight > 0 or lo.far_rotation_weight > 0
        ):
            raise PoseconsError(
                "model.known_motion=true leaves the pose net untrained: set loss.constraints=[], "
                "loss.skip_weight=0, loss.velocity_weight=0 and loss.far_rotation_weight=0"
            )
        if m.known_rotation and lo.far_rotation_weight > 0:
            raise PoseconsError(
                "model.known_rotation=true warps with the data's rotation, so loss.far_rotation_weight "
                "would train a rotation nothing uses: set it to 0"
            )
        if m.known_motion and m.known_rotation:
            raise PoseconsError(
                "model.known_motion=true already warps with the true rotation: leave model.known_rotation false"
            )
        if "cyc" in lo.constraints and not (min(m.frame_ids) < 0 < max(m.frame_ids)):
            raise PoseconsError(
                "the cyc constraint needs model.frame_ids to hold a past and a future frame, "
                f"e.g. [0, -1, 1]; got {m.frame_ids}"
            )
        return self

    def _check_rules(self) -> None:
        for section in dataclasses.fields(self):
            for item in dataclasses.fields(getattr(self, section.name)):
                key, value = f"{section.name}.{item.name}", getattr(getattr(self, section.name), item.name)
                numbers = value if isinstance(value, list) else [value]
                if any(isinstance(v, float) and not math.isfinite(v) for v in numbers):
                    raise PoseconsError(f"{key} must be a finite number, got {value!r}")
                error = RULES[key](key, value) if key in RULES else None
                if error:
                    raise PoseconsError(error)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


def _check_type(value: Any, hint: Any, key: str) -> Any:
    """Return ``value`` converted to ``hint`` where lossless (int → float), else raise."""
    origin = typing.get_origin(hint)
    if origin is Union:
        for option in typing.get_args(hint):
            try:
                return _check_type(value, option, key)
            except PoseconsError:
                pass
        raise PoseconsError(f"config key {key}: {value!r} is not a valid {hint}")
    if origin is list:
        (item,) = typing.get_args(hint)
        if not isinstance(value, list):
            raise PoseconsError(f"config key {key}: expected a list, got {value!r}")
        return [_check_type(v, item, f"{key}[{i}]") for i, v in enumerate(value)]
    if hint is float and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if hint is float and isinstance(value, str):  # YAML 1.1 reads "1e-3" (no dot) as a string
        try:
            return float(value)
        except ValueError:
            pass
    if not isinstance(value, hint) or (hint is int and isinstance(value, bool)):
        raise PoseconsError(f"config key {key}: expected {hint.__name__}, got {value!r}")
    return value


def _respelled(key: str, value: Any) -> Any:
    """``value`` in the one spelling a config holds (:data:`RESPELLED`)."""
    return next((new for old, new in RESPELLED.get(key, ()) if type(value) is type(old) and value == old), value)


def _merge(obj: Any, updates: dict[str, Any], prefix: str = "") -> None:
    hints = typing.get_type_hints(type(obj))
    names = {f.name for f in dataclasses.fields(obj)}
    for key, value in updates.items():
        full = f"{prefix}{key}"
        if key not in names and _retired(full, value):
            continue
        if key not in names:
            raise PoseconsError(f"unknown config key {full!r}; known: {sorted(names)}")
        current = getattr(obj, key)
        if dataclasses.is_dataclass(current):
            if not isinstance(value, dict):
                raise PoseconsError(f"config key {full}: expected a mapping, got {value!r}")
            _merge(current, value, full + ".")
        else:
            setattr(obj, key, _check_type(_respelled(full, value), hints[key], full))


def _retired(key: str, value: Any) -> bool:
    """True for a retired option at the value every run now has (nothing to set); an error for another."""
    if key not in RETIRED:
        return False
    kept, commit = RETIRED[key]
    if value != kept:
        raise PoseconsError(
            f"config key {key} was removed (experiments/README.md): every run now has {kept!r}; "
            f"{value!r} needs posecons at commit {commit}"
        )
    return True


def without_retired(data: dict[str, Any]) -> dict[str, Any]:
    """A copy of a stored config dict without the retired keys it holds at their kept value (an
    error for another value), to compare with today's ``Config.to_dict()``."""
    out = {}
    for section, values in data.items():
        if isinstance(values, dict):
            values = {k: v for k, v in values.items() if not _retired(f"{section}.{k}", v)}
        out[section] = values
    return out


def _read_preset(path: Path, seen: tuple[Path, ...] = ()) -> list[dict[str, Any]]:
    path = path.resolve()
    if path in seen:
        raise PoseconsError(f"{path}: preset includes itself through 'base'")
    try:
        data = yaml.safe_load(path.read_text()) or {}
    except OSError as exc:
        raise PoseconsError(f"cannot read config {path}: {exc.strerror}") from exc
    except yaml.YAMLError as exc:
        raise PoseconsError(f"{path}: not valid YAML: {exc}") from exc
    if not isinstance(data, dict):
        raise PoseconsError(f"{path}: a preset must be a mapping of sections, got {type(data).__name__}")
    base = data.pop("base", None)
    layers = _read_preset(path.parent / base, seen + (path,)) if base else []
    return layers + [data]


def resolve_preset(name: str | Path) -> Path:
    """A preset file path, or a bundled preset name such as ``kitti/cycle``."""
    path = Path(name)
    if path.is_file():
        return path
    name = str(name)
    bundled = PRESETS / (name if name.endswith(".yaml") else f"{name}.yaml")
    if bundled.is_file() and STUDY_SPECS not in bundled.parents:
        return bundled
    raise PoseconsError(f"config {name!r} is neither a file nor a bundled preset ({', '.join(preset_names())})")


def preset_names() -> list[str]:
    """Names of the bundled presets, e.g. ``kitti/cycle``."""
    files = [p for p in PRESETS.rglob("*.yaml") if STUDY_SPECS not in p.parents]
    return sorted(str(p.relative_to(PRESETS).with_suffix("")) for p in files)


def parse_override(item: str) -> dict[str, Any]:
    """``"loss.constraints=[cyc]"`` → ``{"loss": {"constraints": ["cyc"]}}`` (value parsed as YAML)."""
    if "=" not in item:
        raise PoseconsError(f"--set expects key=value, got {item!r}")
    key, raw = item.split("=", 1)
    value = yaml.safe_load(raw) if raw else ""
    for part in reversed(key.strip().split(".")):
        value = {part: value}
    return value


def load_config(
    path: str | Path | None = None, overrides: list[str] | tuple[str, ...] = (), base: dict[str, Any] | None = None
) -> Config:
    """Defaults ← ``base`` dict (e.g. a checkpoint's config) ← preset file (and its bases) ← overrides."""
    config = Config()
    layers = ([base] if base else []) + (_read_preset(Path(path)) if path else [])
    layers += [parse_override(o) for o in overrides]
    for layer in layers:
        _merge(config, layer)
    return config.validate()


def config_from_dict(data: dict[str, Any]) -> Config:
    return load_config(base=data)
