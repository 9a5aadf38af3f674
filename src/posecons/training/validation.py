"""Validation during training: photometric loss on the val split and, where the data has LiDAR
scans, the depth metrics and scale consistency σ/μ of ``posecons.evaluation``.

Ground truth is exported once per run (``RUN/val_gt.npz``), never per training sample.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch.utils.data import DataLoader, Subset

from ..config import Config
from ..data.datasets import build_dataset
from ..data.gt import export_gt, load_gt
from ..fileio import append_record, write_json
from ..geometry import disp_to_depth
from ..metrics.depth import depth_metrics


class Validator:
    def __init__(self, config: Config, data_path: str | Path, val_file: Path, out: Path, device: torch.device):
        self.config, self.out, self.device = config, Path(out), device
        dataset = build_dataset(config, data_path, val_file, train=False)
        n = min(len(dataset), config.train.val_samples)
        # An even spread over the split, so every drive is represented.
        self.indices = np.linspace(0, len(dataset) - 1, n).round().astype(int).tolist() if n else []
        self.dataset = Subset(dataset, self.indices)
        self.gt = self._ground_truth(data_path, [dataset.lines[i] for i in self.indices])

    def _ground_truth(self, data_path, lines) -> list[np.ndarray] | None:
        if self.config.data.dataset != "kitti_raw" or not lines:
            return None
        first = Path(data_path) / lines[0].folder / "velodyne_points" / "data" / f"{lines[0].frame:010d}.bin"
        if not first.is_file():
            return None
        path = self.out / "val_gt.npz"
        if not path.is_file():
            export_gt(Path(data_path), [str(line) for line in lines], path)
        return load_gt(path)[0]

    @torch.no_grad()
    def run(self, model, step: int) -> dict[str, Any]:
        """Validate ``model``; the global RNG streams are left as they were (the DataLoader draws its
        base seed from them), so how often a run validates does not change its training."""
        if not self.indices:
            return {}
        with torch.random.fork_rng(devices=[self.device] if self.device.type == "cuda" else []):
            return self._run(model, step)

    def _run(self, model, step: int) -> dict[str, Any]:
        model.eval()
        m = self.config.model
        loader = DataLoader(
            self.dataset,
            batch_size=self.config.train.batch_size,
            shuffle=False,
            num_workers=self.config.data.num_workers,
        )
        photometric, disps, folders = [], [], []
        for batch in loader:
            batch = {k: v.to(self.device) if torch.is_tensor(v) else v for k, v in batch.items()}
            outputs, losses = model(batch, step=step, with_constraints=False)  # only the photometric loss is used
            photometric.append(float(losses["photometric"]) * len(batch["frames"]))
            disps.append(disp_to_depth(outputs["disp"][0], m.min_depth, m.max_depth)[0][:, 0].float().cpu().numpy())
            folders += list(batch["folder"])
        metrics: dict[str, Any] = {"step": step, "val_photometric": sum(photometric) / len(self.indices)}
        if self.gt is not None:
            result = depth_metrics(np.concatenate(disps), self.gt, folders)
            metrics.update(
                {
                    k: result[k]
                    for k in (
                        "abs_rel",
                        "sq_rel",
                        "rmse",
                        "rmse_log",
                        "a1",
                        "a2",
                        "a3",
                        "scale_cv",
                        "scale_cv_pooled",
                        "n_frames",
                    )
                }
            )
        write_json(self.out / "metrics" / f"step_{step:06d}.json", metrics)
        append_record(self.out / "metrics.jsonl", metrics)  # a resumed run replaces the rows it repeats
        return metrics


def describe_selection(best_metric: str) -> str:
    """How best.pt is chosen, in words for logs and reports."""
    return {
        "val_photometric": "the validation photometric loss (self-supervised, no ground truth)",
        "abs_rel": "the validation abs rel against LiDAR ground truth (supervised selection)",
    }[best_metric]
