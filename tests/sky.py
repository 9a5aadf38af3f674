"""Views of a textured sky at infinity: points so far away that only the camera's rotation moves
them in the image, whatever its translation (the far-rotation loss's exact case)."""

import torch


def sky_view(R: torch.Tensor, K: torch.Tensor, height: int, width: int) -> torch.Tensor:
    """(3, H, W) float32: the view of a camera turned by R from the reference camera (a direction d
    of the reference frame is R·d in this one); K: float64 pixel K at this size (integer pixel
    centres, as geometry.warp samples them)."""
    v, u = torch.meshgrid(
        torch.arange(height, dtype=torch.float64), torch.arange(width, dtype=torch.float64), indexing="ij"
    )
    rays = torch.linalg.inv(K) @ torch.stack([u, v, torch.ones_like(u)]).reshape(3, -1)
    d = R.mT @ rays  # the same rays in the reference frame
    azimuth, elevation = torch.atan2(d[0], d[2]), torch.atan2(d[1], torch.hypot(d[0], d[2]))
    grey = (
        0.5
        + 0.2 * torch.sin(12 * azimuth + 0.4) * torch.sin(15 * elevation)
        + 0.15 * torch.cos(9 * azimuth - 11 * elevation)
    )
    return torch.stack([grey, 0.8 * grey + 0.1, 1 - grey]).reshape(3, height, width).float()
