"""A study spec: one training preset, variants (name → config overrides) × seeds, and the data.

```yaml
preset: synth/demo                  # every run's preset: a bundled name or a file (relative to the spec)
overrides: ["train.max_steps=600"]  # applied to every run, before the variant's
data:                               # either synth (generated once into OUT/data) ...
  synth: {drives: 6, frames: 120, width: 384, height: 128, neighbours: 3, seed: 0}
# ... or an RGB-D sequence (--data-path overrides input), prepared once into OUT/data by
# `posecons prepare-rgbd` with a held-out test stretch and scored on its dense depth and poses:
#   rgbd: {input: ../shared/real/7scenes, color: "frame-*.color.jpg", depth: "frame-*.depth.png",
#          depth_scale: 1000, poses: "frame-*.pose.txt", calib: camera-intrinsics.txt (in input),
#          every: 5, test_from: 620, gap: 20, min_depth: 0.1, max_depth: 10}
# ... or a KITTI raw root (--data-path overrides it) and its test split, with optional pose data:
#   path: /data/kitti_raw
#   test_split: eigen                 # bundled name or file
#   odometry: /data/kitti_odometry    # optional (--odometry-path): the pose table
#   odometry_sequences: [9, 10]
seeds: [0, 1, 2]                    # train.seed of the runs
threads: 1                          # optional: the compute threads of every run (the outcome depends on
                                    # them as much as on the seed); unset, a run gets the process's share
variants:                           # the first is the reference of the paired differences
  baseline: ["loss.constraints=[]"]
  cyc: ["loss.constraints=[cyc]"]
```

:func:`load_spec` checks all of it, each variant's config included, before any work; a problem is
one :class:`~posecons.errors.PoseconsError` naming the spec file.
"""

from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from ..config import STUDY_SPECS, Config, load_config, resolve_preset
from ..errors import PoseconsError

KEYS = {"preset", "overrides", "data", "seeds", "variants", "threads"}
SYNTH_ARGS = ("drives", "frames", "width", "height", "neighbours", "seed", "ext", "profile")  # generate_synth's
OPTIONAL_SYNTH_ARGS = ("ext", "profile")
PATH_KEYS = {"path", "test_split", "odometry", "odometry_sequences"}
RGBD_TEXTS = ("color", "depth", "poses", "calib")  # prepare-rgbd's patterns and calibration file, required
RGBD_NUMBERS = {"depth_scale": None, "every": 1, "test_from": None, "gap": 20, "min_depth": 0.1, "max_depth": None}
UNTRAINED = "untrained"  # the name of the reference row: no variant may take it
FLOOR = "renderer_depth"  # synthetic data: the renderer's own depth evaluated as a prediction (the floor)
CONSTANT = "constant_depth"  # one depth everywhere, evaluated as a prediction: what a collapsed run scores
NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]*")  # variant names become folder and file names


@dataclass
class StudySpec:
    file: Path  # the spec file
    preset: str  # as written in the spec
    preset_file: Path
    overrides: list[str]
    data: dict[str, Any]  # {"synth": {...}}, {"rgbd": {...prepare_rgbd arguments}} or {"path", "test_split", ...}
    seeds: list[int]
    variants: dict[str, list[str]]
    threads: int | None = None  # compute threads of every run; None: the process's share

    @property
    def reference(self) -> str:
        """The variant every other one is compared with: the first."""
        return next(iter(self.variants))

    def run_overrides(self, variant: str, seed: int) -> list[str]:
        """Every override of the run (variant, seed): the spec's, the variant's, then its seed."""
        return [*self.overrides, *self.variants[variant], f"train.seed={seed}"]

    def config(self, variant: str, seed: int) -> Config:
        return load_config(self.preset_file, self.run_overrides(variant, seed))

    def runs(self) -> list[tuple[str, int]]:
        """(variant, seed) of every run, seed by seed: a study stopped early still has complete pairs."""
        return [(variant, seed) for seed in self.seeds for variant in self.variants]

    def select(self, variants: list[str] | None = None, seeds: list[int] | None = None) -> StudySpec:
        """The spec with only ``variants`` and the reference (in the spec's order: the untrained row
        and every paired difference are defined by the reference, which a finished run skips) and
        with ``seeds`` in place of its own: e.g. more seeds for two variants."""
        unknown = [v for v in variants or [] if v not in self.variants]
        if unknown:
            raise PoseconsError(f"--variants {unknown[0]!r}: not in {self.file.name} ({', '.join(self.variants)})")
        chosen = {v: o for v, o in self.variants.items() if not variants or v in variants or v == self.reference}
        try:
            return dataclasses.replace(self, variants=chosen, seeds=_seeds(seeds) if seeds else self.seeds)
        except PoseconsError as exc:
            raise PoseconsError(f"--seeds: {exc}") from None

    def describe(self) -> dict[str, Any]:
        """What the report's header and the regeneration of tables need (``study.json``)."""
        return {
            "spec": str(self.file),
            "preset": self.preset,
            "overrides": self.overrides,
            "data": self.data,
            "seeds": self.seeds,
            "variants": self.variants,
            "reference": self.reference,
            "threads": self.threads,
        }


def resolve_spec(name: str | Path) -> Path:
    """A spec file path, or a bundled spec name such as ``study/synth``."""
    path = Path(name)
    if path.is_file():
        return path
    bundled = STUDY_SPECS.parent / f"{str(name).removesuffix('.yaml')}.yaml"
    if bundled.is_file() and STUDY_SPECS in bundled.parents:
        return bundled
    names = ", ".join(sorted(f"study/{p.stem}" for p in STUDY_SPECS.glob("*.yaml")))
    raise PoseconsError(f"study spec {str(name)!r} is neither a file nor a bundled spec ({names})")


def _strings(value: Any, what: str) -> list[str]:
    if value is None:
        return []
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise PoseconsError(f"{what} must be a list of KEY=VALUE strings, got {value!r}")
    return list(value)


def _path(value: Any, base: Path, what: str) -> Path:
    """A path from the spec (relative to the spec's folder) or the command line (absolute already)."""
    if not isinstance(value, (str, Path)) or not str(value):
        raise PoseconsError(f"{what} must be a path, got {value!r}")
    path = Path(value).expanduser()
    return (path if path.is_absolute() else base / path).resolve()


def _synth_data(args: Any) -> dict[str, Any]:
    from ..data.synth import check_synth_args

    if not isinstance(args, dict):
        raise PoseconsError(f"data.synth must be a mapping of generator arguments, got {args!r}")
    unknown = sorted(set(args) - set(SYNTH_ARGS))
    if unknown:
        raise PoseconsError(f"data.synth: unknown key {unknown[0]!r}; known: {list(SYNTH_ARGS)}")
    required = [key for key in SYNTH_ARGS if key not in OPTIONAL_SYNTH_ARGS]
    missing = [key for key in required if key not in args]
    if missing:
        raise PoseconsError(f"data.synth: missing key {missing[0]!r} (give {', '.join(required)})")
    merged = {"ext": "png", **args}
    for key, value in merged.items():
        kind = str if key in OPTIONAL_SYNTH_ARGS else int
        if not isinstance(value, kind) or isinstance(value, bool) or (kind is int and value < 0):
            raise PoseconsError(
                f"data.synth.{key} must be {'a word' if kind is str else 'an integer ≥ 0'}, got {value!r}"
            )
    check_synth_args(**{k: v for k, v in merged.items() if k != "seed"})
    if merged.get("profile") == "street":  # the default: spelt out or not, the same data (and study.json)
        del merged["profile"]
    return {"synth": merged}


def _root(value: Any, data_path: Path | None, base: Path, key: str, what: str) -> Path:
    """The data folder: --data-path, else the spec's ``key`` (relative to the spec)."""
    if data_path is None and not value:
        raise PoseconsError(f"{key} is not set: pass {what} with --data-path")
    root = data_path.resolve() if data_path else _path(value, base, key)
    if not root.is_dir():
        raise PoseconsError(f"{key} {root} is not a directory")
    return root


def _rgbd_data(args: Any, base: Path, data_path: Path | None) -> dict[str, Any]:
    if not isinstance(args, dict):
        raise PoseconsError(f"data.rgbd must be a mapping of prepare-rgbd arguments, got {args!r}")
    known = ["input", *RGBD_TEXTS, *RGBD_NUMBERS]
    unknown = sorted(set(args) - set(known))
    if unknown:
        raise PoseconsError(f"data.rgbd: unknown key {unknown[0]!r}; known: {', '.join(known)}")
    missing = [key for key in (*RGBD_TEXTS, "depth_scale", "max_depth") if args.get(key) is None]
    if missing:
        raise PoseconsError(f"data.rgbd: missing key {missing[0]!r}")
    root = _root(args.get("input"), data_path, base, "data.rgbd.input", "the sequence's folder")
    out = {"input": str(root), **RGBD_NUMBERS, **{k: v for k, v in args.items() if k != "input"}}
    for key in RGBD_TEXTS:
        if not isinstance(out[key], str):
            raise PoseconsError(f"data.rgbd.{key} must be a text, got {out[key]!r}")
    for key in RGBD_NUMBERS:
        value = out[key]
        kind = int if key in ("every", "test_from", "gap") else (int, float)
        if value is not None and (isinstance(value, bool) or not isinstance(value, kind) or value < (key == "every")):
            what = "an integer" if kind is int else "a number"
            raise PoseconsError(f"data.rgbd.{key} must be {what} ≥ {int(key == 'every')}, got {value!r}")
    if not 0 < out["min_depth"] < out["max_depth"]:
        raise PoseconsError(
            f"data.rgbd: min_depth {out['min_depth']} and max_depth {out['max_depth']} must be 0 < min < max"
        )
    if not (root / out["calib"]).is_file():
        raise PoseconsError(f"data.rgbd.calib: {root / out['calib']} does not exist (a file in the input folder)")
    return {"rgbd": out}


def _kitti_data(data: dict, base: Path, data_path: Path | None, odometry_path: Path | None) -> dict[str, Any]:
    from ..data.kitti_odometry import sequence_dir
    from ..data.splits import find_split_file

    unknown = sorted(set(data) - PATH_KEYS)
    if unknown:
        raise PoseconsError(f"data: unknown key {unknown[0]!r}; known: synth, or {sorted(PATH_KEYS)}")
    root = _root(data.get("path"), data_path, base, "data.path", "the KITTI raw root")
    split = str(data.get("test_split", "eigen"))
    split_file = find_split_file(base / split if (base / split).is_file() else split)
    out = {"path": str(root), "test_split": str(split_file.resolve())}
    odometry = odometry_path.resolve() if odometry_path else data.get("odometry")
    if odometry:
        odometry = _path(odometry, base, "data.odometry")
        sequences = data.get("odometry_sequences")
        if not isinstance(sequences, list) or not sequences:
            raise PoseconsError("data.odometry needs data.odometry_sequences, a list such as [9, 10]")
        names = []
        for seq in sequences:
            if not str(seq).isdigit():
                raise PoseconsError(f"data.odometry_sequences: {seq!r} is not a sequence number")
            names.append(f"{int(seq):02d}")
            for need in (sequence_dir(odometry, seq), odometry / "poses" / f"{names[-1]}.txt"):
                if not need.exists():
                    raise PoseconsError(f"data.odometry: {need} does not exist")
        out.update(odometry=str(odometry), odometry_sequences=names)
    return out


def _data(data: Any, base: Path, data_path: Path | None, odometry_path: Path | None) -> dict[str, Any]:
    generated = [key for key in ("synth", "rgbd") if key in data] if isinstance(data, dict) else []
    if not isinstance(data, dict) or len(generated) + bool(set(data) & {"path", "test_split"}) != 1:
        raise PoseconsError(
            "data: give one of synth: {generator arguments}, rgbd: {sequence}, or path: (and test_split:)"
        )
    if "rgbd" in data:
        if odometry_path or len(data) > 1:
            raise PoseconsError("data.rgbd: the sequence's own poses are its odometry; no other data keys apply")
        return _rgbd_data(data["rgbd"], base, data_path)
    if "synth" in data:
        if data_path or odometry_path:
            raise PoseconsError("this spec generates synthetic data: --data-path and --odometry-path do not apply")
        if len(data) > 1:
            raise PoseconsError(f"data: synth takes no other keys, got {sorted(set(data) - {'synth'})}")
        return _synth_data(data["synth"])
    return _kitti_data(data, base, data_path, odometry_path)


def _seeds(seeds: Any) -> list[int]:
    if not isinstance(seeds, list) or not seeds:
        raise PoseconsError(f"seeds must be a non-empty list of integers ≥ 0, got {seeds!r}")
    if not all(type(s) is int and s >= 0 for s in seeds) or len(set(seeds)) != len(seeds):
        raise PoseconsError(f"seeds must be distinct integers ≥ 0, got {seeds!r}")
    return seeds


def _threads(threads: Any) -> int | None:
    if threads is not None and (type(threads) is not int or threads < 1):
        raise PoseconsError(f"threads must be an integer ≥ 1, got {threads!r}")
    return threads


def _variants(variants: Any) -> dict[str, list[str]]:
    if not isinstance(variants, dict) or not variants:
        raise PoseconsError(f"variants must be a non-empty mapping of name → overrides, got {variants!r}")
    out = {}
    for name, overrides in variants.items():
        if not isinstance(name, str) or not NAME.fullmatch(name) or name in (UNTRAINED, FLOOR, CONSTANT):
            raise PoseconsError(
                f"variant name {name!r}: use letters, digits, '_', '.', '-' (it names folders), not {UNTRAINED!r}, {FLOOR!r} or {CONSTANT!r}"
            )
        out[name] = _strings(overrides, f"variant {name!r}")
    return out


def load_spec(name: str | Path, data_path: Path | None = None, odometry_path: Path | None = None) -> StudySpec:
    """Read and check a spec (file or bundled name); ``data_path`` / ``odometry_path`` replace its
    ``data.path`` / ``data.odometry``. Every variant's config is loaded once to check it."""
    file = resolve_spec(name).resolve()
    try:
        raw = yaml.safe_load(file.read_text())
    except OSError as exc:
        raise PoseconsError(f"{file}: cannot read the study spec ({exc.strerror})") from exc
    except yaml.YAMLError as exc:
        raise PoseconsError(f"{file}: not valid YAML: {str(exc).splitlines()[0]}") from exc
    try:
        if not isinstance(raw, dict):
            raise PoseconsError(f"a study spec is a mapping with keys {sorted(KEYS)}, got {type(raw).__name__}")
        unknown = sorted(set(raw) - KEYS)
        if unknown:
            raise PoseconsError(f"unknown key {unknown[0]!r}; known: {sorted(KEYS)}")
        missing = sorted({"preset", "data", "seeds", "variants"} - set(raw))
        if missing:
            raise PoseconsError(f"missing key {missing[0]!r}")
        preset = raw["preset"]
        if not isinstance(preset, str):
            raise PoseconsError(f"preset must name a preset, got {preset!r}")
        relative = file.parent / preset
        spec = StudySpec(
            file=file,
            preset=preset,
            preset_file=relative if relative.is_file() else resolve_preset(preset),
            overrides=_strings(raw.get("overrides"), "overrides"),
            data=_data(raw["data"], file.parent, data_path, odometry_path),
            seeds=_seeds(raw["seeds"]),
            variants=_variants(raw["variants"]),
            threads=_threads(raw.get("threads")),
        )
        for variant in spec.variants:
            if any(o.split("=", 1)[0].strip() == "train.seed" for o in spec.run_overrides(variant, 0)[:-1]):
                raise PoseconsError(f"variant {variant!r}: train.seed is set by seeds:, not by an override")
            try:
                config = spec.config(variant, spec.seeds[0])
            except PoseconsError as exc:
                raise PoseconsError(f"variant {variant!r}: {exc}") from None
            if "rgbd" in spec.data and (config.data.split, config.data.dataset) != ("custom", "kitti_raw"):
                raise PoseconsError(
                    f"variant {variant!r}: an RGB-D sequence trains on data.split=custom (dataset kitti_raw), "
                    f"but its config has split {config.data.split!r}, dataset {config.data.dataset!r}"
                )
            if "synth" in spec.data and (config.data.split, config.data.dataset) != ("synth", "kitti_raw"):
                raise PoseconsError(
                    f"variant {variant!r}: synthetic data trains on data.split=synth (dataset kitti_raw), "
                    f"but its config has split {config.data.split!r}, dataset {config.data.dataset!r}"
                )
    except PoseconsError as exc:
        raise PoseconsError(f"{file}: {exc}") from None
    return spec
