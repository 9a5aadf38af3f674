"""Augmentation: per-sample draws in the dataset (cheap, reproducible), colour jitter on the device.

The dataset only *draws* the parameters (flip and four jitter factors) from a generator seeded by
(seed, epoch, index), so a resumed run sees bit-identical augmentation whatever the worker layout.
:func:`jitter_batch` applies the colour jitter to whole batches on their device, before the model.
"""

from __future__ import annotations

import numpy as np
import torch
from torchvision.transforms.v2 import functional as TF

IDENTITY_JITTER = (1.0, 1.0, 1.0, 0.0)  # brightness, contrast, saturation, hue
JITTER_RANGES = ((0.8, 1.2), (0.8, 1.2), (0.8, 1.2), (-0.1, 0.1))


def sample_rng(seed: int, epoch: int, index: int) -> np.random.Generator:
    """A generator that depends only on (seed, epoch, index)."""
    return np.random.default_rng([seed, epoch, index])


def draw_augmentation(rng: np.random.Generator, flip_prob: float, jitter_prob: float) -> tuple[bool, np.ndarray]:
    """Draw (flip, jitter params (4,) float32); the same number of draws happens whatever the outcome."""
    flip = rng.random() < flip_prob
    jitter = rng.random() < jitter_prob
    factors = np.array([rng.uniform(lo, hi) for lo, hi in JITTER_RANGES], dtype=np.float32)
    return bool(flip), factors if jitter else np.array(IDENTITY_JITTER, dtype=np.float32)


def color_jitter(frames: torch.Tensor, params: torch.Tensor) -> torch.Tensor:
    """Jitter each sample's frames with its own (brightness, contrast, saturation, hue) factors,
    applied in that fixed order to all F frames of the sample.

    frames: (B, F, 3, H, W) in [0, 1]; params: (B, 4). Returns (B, F, 3, H, W); samples with
    identity params (1, 1, 1, 0) are returned unchanged.
    """
    out = frames.clone()
    for b, factors in enumerate(params.tolist()):  # one copy to the host, not one per sample
        if tuple(factors) == IDENTITY_JITTER:
            continue
        brightness, contrast, saturation, hue = factors
        x = TF.adjust_brightness(frames[b], brightness)
        x = TF.adjust_contrast(x, contrast)
        x = TF.adjust_saturation(x, saturation)
        out[b] = TF.adjust_hue(x, hue)
    return out


def jitter_batch(batch: dict) -> dict:
    """The batch plus ``net_frames``: its frames jittered by their ``color_aug`` factors, on the
    batch's device. The networks see ``net_frames``; the losses keep the un-augmented ``frames``."""
    if "color_aug" not in batch:
        return batch
    return {**batch, "net_frames": color_jitter(batch["frames"], batch["color_aug"])}
