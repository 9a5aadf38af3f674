"""Checkpoint files: written atomically, read without unpickling arbitrary objects.

A training checkpoint (``.pt``) is a plain dict of tensors, numbers, strings, lists and
dicts — ``{"config": Config.to_dict(), "model": state_dict, ...training state}`` — so
``torch.load(weights_only=True)`` reads it. Exported weights (``.safetensors``) hold the
model state dict with the config as JSON metadata, and where recorded the ``initialisation``.
"""

from __future__ import annotations

import json
import pickle
import warnings
from pathlib import Path
from typing import Any

import torch

from .config import Config, config_from_dict
from .errors import PoseconsError
from .fileio import atomic_write


def save_checkpoint(path: str | Path, state: dict[str, Any]) -> None:
    atomic_write(path, lambda tmp: torch.save(state, tmp))


def load_checkpoint(path: str | Path, map_location: str | torch.device = "cpu") -> dict[str, Any]:
    """Read a ``.pt`` checkpoint with ``weights_only=True``; clear errors for bad files."""
    path = Path(path)
    if not path.is_file():
        raise PoseconsError(f"checkpoint {path} does not exist")
    state = load_weights_file(path, map_location)
    if not isinstance(state, dict) or "config" not in state or "model" not in state:
        raise PoseconsError(f"{path}: not a posecons checkpoint (no 'config' and 'model' entries)")
    return state


def load_weights_file(path: Path, map_location: str | torch.device = "cpu") -> Any:
    """``torch.load(weights_only=True)`` of an existing file, with one-line errors for unsafe or damaged files."""
    try:
        with warnings.catch_warnings():  # torch warns about pickle protocols before refusing a file
            warnings.simplefilter("ignore", UserWarning)
            return torch.load(path, map_location=map_location, weights_only=True)
    except pickle.UnpicklingError as exc:
        unsafe = [line.strip() for line in str(exc).splitlines() if "GLOBAL" in line]  # a blocked import
        if unsafe:
            raise PoseconsError(
                f"{path}: refused to load — it holds objects other than weights and plain "
                f"data (not a posecons checkpoint, or unsafe): {unsafe[0]}"
            ) from exc
        raise PoseconsError(f"{path}: not a readable checkpoint (damaged, or not written by torch.save)") from exc
    except Exception as exc:  # damaged bytes surface as almost any error type inside torch.load
        raise PoseconsError(
            f"{path}: not a readable checkpoint (damaged, or not written by torch.save: {type(exc).__name__})"
        ) from exc


def read_weights(path: str | Path, map_location: str | torch.device = "cpu") -> tuple[Config, dict, dict]:
    """Checkpoint (``.pt``) or exported weights (``.safetensors``) → (config, model state dict, the
    checkpoint's other entries: for safetensors its metadata other than the config)."""
    path = Path(path)
    if path.suffix == ".safetensors":
        return _read_safetensors(path, map_location)
    state = load_checkpoint(path, map_location)
    return _config(state["config"], path), state["model"], state


def load_model(path: str | Path, map_location: str | torch.device = "cpu", entry: str = "model"):
    """Checkpoint (``.pt``) or exported weights (``.safetensors``) → (PoseConsModel in eval mode, Config);
    ``entry``: the checkpoint's weights to load, e.g. ``raw_model`` (the raw weights beside an EMA)."""
    from .model import PoseConsModel

    config, weights, state = read_weights(path, map_location)
    if entry != "model":
        if entry not in state:
            raise PoseconsError(f"{path}: no {entry!r} weights in this checkpoint")
        weights = state[entry]
    config.model.pretrained = False  # the weights come from the file
    model = PoseConsModel(config)
    load_state_into(model, weights, path)
    return model.to(map_location).eval(), config


def load_state_into(model, weights: dict, path: Path) -> None:
    """``model.load_state_dict(weights)``; weights of another shape are one error line naming ``path``."""
    try:
        model.load_state_dict(weights)
    except RuntimeError as exc:
        raise PoseconsError(
            f"{path}: weights do not fit the architecture in its config "
            f"(ResNet-{model.config.model.num_layers}): {str(exc).splitlines()[0]}"
        ) from exc


def describe_checkpoint(path: str | Path) -> dict[str, Any]:
    """What a report must say of the weights it evaluated: file, step, how they were chosen, how
    the encoders were initialised, and whether they are the raw or the EMA weights."""
    path = Path(path)
    if path.suffix == ".safetensors":
        return {
            "file": str(path),
            "selected_by": "exported weights (see the run they came from)",
            "initialisation": read_weights(path)[2].get("initialisation", "not recorded"),
        }
    state = load_checkpoint(path)
    criterion = state.get("selected_by")
    return {
        "file": str(path),
        "step": state.get("step"),
        "selected_by": (
            f"lowest validation {criterion}" + (" (ground truth)" if criterion == "abs_rel" else " (no ground truth)")
            if criterion
            else "none: the weights at that step"
        ),
        "initialisation": state.get("initialisation", "not recorded"),
        "weights": state.get("weights", "raw"),  # checkpoints from before the EMA option hold raw weights
    }


def _config(data: Any, path: Path) -> Config:
    try:
        return config_from_dict(data)
    except PoseconsError as exc:
        raise PoseconsError(f"{path}: its stored config is invalid: {exc}") from exc


def _read_safetensors(path: Path, map_location) -> tuple[Config, dict[str, torch.Tensor], dict[str, str]]:
    from safetensors import SafetensorError, safe_open

    if not path.is_file():
        raise PoseconsError(f"weights file {path} does not exist")
    try:
        with safe_open(str(path), framework="pt", device=str(map_location)) as f:
            meta = f.metadata() or {}
            weights = {k: f.get_tensor(k) for k in f.keys()}
    except (SafetensorError, OSError) as exc:
        raise PoseconsError(f"{path}: not a readable safetensors file ({exc})") from exc
    if "config" not in meta:
        raise PoseconsError(f"{path}: no posecons config in its metadata")
    return _config(json.loads(meta.pop("config")), path), weights, meta


def save_safetensors(
    path: str | Path, weights: dict[str, torch.Tensor], config: Config, initialisation: str | None = None
) -> None:
    """A model state dict as safetensors, its config (and ``initialisation``, where given) as metadata."""
    from safetensors.torch import save_file

    state = {k: v.detach().contiguous().cpu() for k, v in weights.items()}
    meta = {"config": json.dumps(config.to_dict())}
    if initialisation:
        meta["initialisation"] = initialisation
    atomic_write(path, lambda tmp: save_file(state, tmp, metadata=meta))
