"""Run a trained model over evaluation images: disparities for split lines, steps for a sequence.

Images are read with PIL and resized bilinearly to the network size; frames stream through in
batches so a whole sequence never sits in memory.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np
import torch

from ..data.io import load_rgb, resize_rgb
from ..errors import PoseconsError


def load_image(path: Path, height: int, width: int) -> torch.Tensor:
    """RGB image resized bilinearly to (height, width) → (3, height, width) float in [0, 1]."""
    return torch.from_numpy(resize_rgb(np.asarray(load_rgb(path)), height, width))


def _batches(paths: Sequence[Path], height: int, width: int, size: int) -> Iterator[torch.Tensor]:
    for start in range(0, len(paths), size):
        yield torch.stack([load_image(p, height, width) for p in paths[start : start + size]])


def post_process_disparity(disp: torch.Tensor, disp_flipped: torch.Tensor) -> torch.Tensor:
    """Blend (B, 1, H, W) disparities of an image and of its mirror (already flipped back).

    The middle is their mean; near each side border the prediction that did not see that
    border at the image edge takes over (a ramp over 5–10 % of the width), as Monodepth does.
    """
    x = torch.linspace(0, 1, disp.shape[-1], device=disp.device)
    left = 1.0 - torch.clamp(20.0 * (x - 0.05), 0.0, 1.0)  # 1 at the left border, 0 beyond 10 %
    right = left.flip(0)
    return left * disp_flipped + right * disp + (1.0 - left - right) * 0.5 * (disp + disp_flipped)


@torch.no_grad()
def predict_disparities(
    model, paths: Sequence[Path], height: int, width: int,
    batch_size: int = 8, post_process: bool = False, device: str | torch.device = "cpu",
) -> np.ndarray:
    """Scaled disparities (N, height, width) float32 of N images via ``model.predict_depth``."""
    out = []
    for images in _batches(paths, height, width, batch_size):
        images = images.to(device)
        if post_process:
            disp = model.predict_depth(torch.cat([images, images.flip(-1)]))[0]
            disp = post_process_disparity(disp[: len(images)], disp[len(images) :].flip(-1))
        else:
            disp = model.predict_depth(images)[0]
        out.append(disp[:, 0].float().cpu().numpy())
    return np.concatenate(out)


@torch.no_grad()
def predict_steps(
    model, paths: Sequence[Path], height: int, width: int, batch_size: int = 8, device: str | torch.device = "cpu",
) -> np.ndarray:
    """Relative poses (N−1, 4, 4) float64, T_{i+1←i} from ``model.predict_pose(I_i, I_{i+1})``."""
    if len(paths) < 2:
        raise PoseconsError(f"pose evaluation needs at least 2 frames, got {len(paths)}")
    steps = []
    previous = None  # the last frame of the previous batch starts the next pair
    for images in _batches(paths, height, width, batch_size):
        frames = images if previous is None else torch.cat([previous, images])
        if len(frames) > 1:
            frames = frames.to(device)
            steps.append(model.predict_pose(frames[:-1], frames[1:]).double().cpu().numpy())
        previous = images[-1:]
    return np.concatenate(steps)
