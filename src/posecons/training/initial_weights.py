"""The network a run starts from: built right after the RNGs are seeded with the run's seed (every
variant of a study with one seed starts from the same weights), with ImageNet weights or those of
``train.init_from`` (read by :mod:`.init_from`), and saved untrained as an evaluation's step-0
reference. Kept apart from the trainer because studies and the demo build these weights without
training."""

from __future__ import annotations

import copy
import random
from pathlib import Path

import torch

from ..checkpoint import save_checkpoint
from ..config import Config
from ..model import PoseConsModel
from .init_from import load_initial_weights


def initial_model(config: Config, seed: int | None = None) -> PoseConsModel:
    """The network a run of ``config`` starts from. The RNGs are seeded with ``seed`` (default
    ``train.seed``) right before it is built, so nothing set up earlier (data, validation, a
    variant's options) can shift the initial weights: every variant of a study with the same seed
    starts from the same weights, and training continues the RNG streams from here. With
    ``train.init_from`` the weights are that file's."""
    seed = config.train.seed if seed is None else seed
    random.seed(seed)
    torch.manual_seed(seed)
    if config.train.init_from is None:
        return PoseConsModel(config)
    model = PoseConsModel(without_imagenet(config))  # the weights come from train.init_from
    model.initialisation = load_initial_weights(model, config.train.init_from)
    return model


def save_initial_weights(path: str | Path, config: Config) -> None:
    """The untrained network of ``config`` (:func:`initial_model`) as a weights checkpoint at step 0,
    the reference row of an evaluation."""
    config = copy.deepcopy(config)
    model = initial_model(config)
    config.model.pretrained = model.initialisation.startswith("ImageNet")  # what "auto" resolved to
    save_checkpoint(
        path,
        {"config": config.to_dict(), "model": model.state_dict(), "step": 0, "initialisation": model.initialisation},
    )


def without_imagenet(config):
    """A copy of a Config (or its dict) that builds the networks without fetching ImageNet weights
    (or, a Config, reading train.init_from)."""
    config = copy.deepcopy(config)
    if isinstance(config, dict):
        config["model"]["pretrained"] = False
    else:
        config.model.pretrained = False
        config.train.init_from = None
    return config
