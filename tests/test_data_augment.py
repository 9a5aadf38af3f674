"""Colour jitter on batches and the reproducible augmentation draws."""

from __future__ import annotations

import numpy as np
import torch
from torchvision.transforms.v2 import functional as TF

from posecons.data.augment import color_jitter, draw_augmentation, sample_rng


def test_identity_params_return_input_unchanged() -> None:
    frames = torch.rand(2, 3, 3, 8, 10)
    out = color_jitter(frames, torch.tensor([[1.0, 1.0, 1.0, 0.0]] * 2))
    assert torch.equal(out, frames)


def test_jitter_is_per_sample_and_shared_by_its_frames() -> None:
    frames = torch.rand(2, 3, 3, 8, 10)
    params = torch.tensor([[1.1, 0.9, 1.2, 0.05], [1.0, 1.0, 1.0, 0.0]])
    out = color_jitter(frames, params)
    assert out.shape == frames.shape and torch.equal(out[1], frames[1])
    for f in range(3):  # each frame of sample 0 gets b, c, s, h in that order
        x = TF.adjust_hue(
            TF.adjust_saturation(TF.adjust_contrast(TF.adjust_brightness(frames[0, f], 1.1), 0.9), 1.2), 0.05
        )
        torch.testing.assert_close(out[0, f], x)


def test_draws_depend_only_on_seed_epoch_index() -> None:
    a = draw_augmentation(sample_rng(1, 2, 3), 0.5, 0.5)
    b = draw_augmentation(sample_rng(1, 2, 3), 0.5, 0.5)
    assert a[0] == b[0] and np.array_equal(a[1], b[1])
    draws = [draw_augmentation(sample_rng(0, 0, i), 0.5, 0.5) for i in range(200)]
    assert 60 < sum(flip for flip, _ in draws) < 140
    jittered = [p for _, p in draws if not np.array_equal(p, [1, 1, 1, 0])]
    assert 60 < len(jittered) < 140
    assert all(0.8 <= v <= 1.2 for p in jittered for v in p[:3]) and all(-0.1 <= p[3] <= 0.1 for p in jittered)
