"""How far posecons' float32 arithmetic is from Monodepth2's where the two compute the same thing in
another order (README, "Precision"; docs/training.md): the SSIM of the photometric loss (posecons: the
3×3 means as separable sums of shifted views; Monodepth2: ``nn.AvgPool2d(3, 1)``) and, on the CPU, the
depth network's disparities (posecons: ELU's e^x − 1 as float32 ``exp`` minus one; Monodepth2:
``nn.ELU``, which uses ``expm1``). Prints the largest |posecons − Monodepth2| of each, in float32 and
float64.

    OMP_NUM_THREADS=1 PYTHONPATH=src python experiments/tools/monodepth2_fp32.py

The reference SSIM is typed from its published definition (reflection padding, 3×3 mean pooling,
C1 = 0.01², C2 = 0.03², clamp((1 − SSIM)/2, 0, 1)), not copied. Inputs: two consecutive real KITTI
frames (../shared/kitti) at 640×192, and random images; the network is a ResNet-18 posecons model with
random weights and BatchNorm statistics, its ELUs swapped for ``nn.ELU`` as the reference.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from PIL import Image

from posecons.config import load_config
from posecons.losses import ssim_dissimilarity
from posecons.model import PoseConsModel
from posecons.networks import ELU

FRAMES = Path(__file__).resolve().parents[3] / "shared/kitti/raw_samples/2011_09_26/2011_09_26_drive_0002_sync"


def monodepth2_ssim(x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    """clamp((1 − SSIM(x, y)) / 2, 0, 1) with ``avg_pool2d`` means, as Monodepth2 defines it."""
    x, y = F.pad(x, (1, 1, 1, 1), mode="reflect"), F.pad(y, (1, 1, 1, 1), mode="reflect")
    mu_x, mu_y = F.avg_pool2d(x, 3, 1), F.avg_pool2d(y, 3, 1)
    sigma_x = F.avg_pool2d(x**2, 3, 1) - mu_x**2
    sigma_y = F.avg_pool2d(y**2, 3, 1) - mu_y**2
    sigma_xy = F.avg_pool2d(x * y, 3, 1) - mu_x * mu_y
    c1, c2 = 0.01**2, 0.03**2
    n = (2 * mu_x * mu_y + c1) * (2 * sigma_xy + c2)
    d = (mu_x**2 + mu_y**2 + c1) * (sigma_x + sigma_y + c2)
    return torch.clamp((1 - n / d) / 2, 0, 1)


def image_pairs(width: int = 640, height: int = 192) -> list[tuple[torch.Tensor, torch.Tensor]]:
    """(1, 3, height, width) pairs in [0, 1]: two consecutive KITTI frames, and random images."""

    def load(name: str) -> torch.Tensor:
        with Image.open(FRAMES / "image_02" / "data" / name) as img:
            rgb = np.asarray(img.convert("RGB").resize((width, height), Image.LANCZOS), dtype=np.float32) / 255
        return torch.from_numpy(rgb).permute(2, 0, 1)[None]

    rng = torch.Generator().manual_seed(0)
    return [(load("0000000000.png"), load("0000000001.png"))] + [
        (torch.rand(1, 3, height, width, generator=rng), torch.rand(1, 3, height, width, generator=rng))
        for _ in range(2)
    ]


def ssim_differences(dtype: torch.dtype, pairs) -> list[tuple[float, float]]:
    """(max over pixels, difference of the means) of |posecons − Monodepth2| SSIM terms, per pair."""
    out = []
    for x, y in pairs:
        ours, theirs = ssim_dissimilarity(x.to(dtype), y.to(dtype)), monodepth2_ssim(x.to(dtype), y.to(dtype))
        out.append(((ours - theirs).abs().max().item(), (ours.mean() - theirs.mean()).abs().item()))
    return out


def disparity_difference(images: torch.Tensor, num_layers: int = 18) -> float:
    """max |Δ| of the disparities (sigmoid of the logits) at every scale of a random-weight model on the
    CPU in float32, posecons' ELU against ``nn.ELU``."""
    config = load_config(overrides=[f"model.num_layers={num_layers}", "model.pretrained=false"])
    config.model.height, config.model.width = images.shape[-2:]
    torch.manual_seed(0)
    model = PoseConsModel(config).eval()
    for name, buffer in model.named_buffers():
        if "running" in name:
            buffer.copy_(torch.rand_like(buffer) + 0.5)
    with torch.no_grad():
        ours = model.depth_net(images)
        for module in list(model.modules()):
            for child_name, child in module.named_children():
                if isinstance(child, ELU):
                    setattr(module, child_name, torch.nn.ELU())
        theirs = model.depth_net(images)
    return max((torch.sigmoid(ours[s]) - torch.sigmoid(theirs[s])).abs().max().item() for s in ours)


def main() -> None:
    pairs = image_pairs()
    for dtype in (torch.float32, torch.float64):
        (kitti, _), *random = differences = ssim_differences(dtype, pairs)
        print(
            f"SSIM {str(dtype).split('.')[1]}: max |Δ| per pixel {kitti:.2g} on the KITTI pair, "
            f"{max(r[0] for r in random):.2g} on random images; image means within {max(d[1] for d in differences):.2g}"
        )
    images = torch.cat([pairs[0][0], pairs[1][0]])
    print(f"disparities float32 (CPU, random-weight ResNet-18): max |Δ| {disparity_difference(images):.2g}")


if __name__ == "__main__":
    main()
