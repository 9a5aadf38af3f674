"""Export a checkpoint: the depth and pose networks to ONNX (dynamic batch axis), checked against
PyTorch with ONNX Runtime, plus safetensors weights and ``export.json``.

Graphs:
    depth.onnx  images (B, 3, H, W) in [0, 1] → disparity (B, 1, H, W), the scaled disparity at full
                scale (depth = 1 / disparity, in the model's units)
    pose.onnx   image_a, image_b (B, 3, H, W) → pose (B, 6) [axis-angle, translation] and
                matrix (B, 4, 4) T_{b←a}, mapping points of camera a into camera b
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import torch
import torch.nn as nn

from ..checkpoint import load_model, save_safetensors
from ..errors import PoseconsError
from ..fileio import output_dir
from ..geometry import pose_vec_to_mat
from .backend import DEPTH_ONNX, EXPORT_INFO, POSE_ONNX

OPSET = 17
WEIGHTS = "weights.safetensors"


class DepthGraph(nn.Module):
    def __init__(self, model: nn.Module):
        super().__init__()
        self.model = model

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        return self.model.predict_depth(images)[0]


class PoseGraph(nn.Module):
    def __init__(self, model: nn.Module):
        super().__init__()
        self.model = model

    def forward(self, image_a: torch.Tensor, image_b: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        axisangle, translation = self.model.pose_net(image_a, image_b)
        return torch.cat([axisangle, translation], -1)[:, 0], pose_vec_to_mat(axisangle, translation)


def _export(graph: nn.Module, inputs: tuple, path: Path, input_names: list[str], output_names: list[str]) -> None:
    # The TorchScript-based exporter (dynamo=False) works offline without onnxscript and has stable
    # dynamic_axes; the exporter's warnings about traced shape checks are expected (sizes are fixed).
    dynamic = {name: {0: "batch"} for name in input_names + output_names}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        torch.onnx.export(
            graph.eval(),
            inputs,
            str(path),
            dynamo=False,
            opset_version=OPSET,
            input_names=input_names,
            output_names=output_names,
            dynamic_axes=dynamic,
        )
    graph.eval()  # the exporter restores the wrapper's original mode on its children


def _max_diff(graph: nn.Module, path: Path, inputs: dict[str, torch.Tensor]) -> dict[str, float]:
    """Largest |ONNX Runtime − PyTorch| per output on ``inputs``."""
    import onnxruntime as ort

    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    names = [o.name for o in session.get_outputs()]
    got = session.run(names, {k: v.numpy() for k, v in inputs.items()})
    with torch.no_grad():
        want = graph(*inputs.values())
    want = want if isinstance(want, tuple) else (want,)
    return {n: float(np.abs(g - w.numpy()).max()) for n, g, w in zip(names, got, want)}


OUTPUTS = {
    "depth": "disparity (B,1,H,W): scaled disparity, depth = 1/disparity",
    "pose": "pose (B,6) axis-angle+translation; matrix (B,4,4) T_{b<-a}",
}
METRES = " (metres: trained with the true motion)"


def export_model(checkpoint: str | Path, out: str | Path, tolerance: float = 1e-4, batch: int = 2) -> dict:
    """Write depth.onnx, pose.onnx (not for a known_motion or known_rotation run), weights.safetensors and
    export.json into ``out``.

    The ONNX graphs are traced with batch 1 and verified with ``batch`` random frames (so the
    dynamic batch axis is exercised); a difference above ``tolerance`` raises PoseconsError and
    leaves ``out`` untouched. Returns the export.json content.
    """
    model, config = load_model(checkpoint)
    h, w = config.model.height, config.model.width
    generator = torch.Generator().manual_seed(0)
    sample = torch.rand(3, batch, 3, h, w, generator=generator)
    # known_motion and known_rotation runs never train their pose net's rotation; known_motion's depth is metric.
    metric = config.model.known_motion
    graphs = {"depth": (DepthGraph(model), DEPTH_ONNX, {"images": sample[0]}, ["disparity"])}
    if not (metric or config.model.known_rotation):
        graphs["pose"] = (PoseGraph(model), POSE_ONNX, {"image_a": sample[1], "image_b": sample[2]}, ["pose", "matrix"])
    with output_dir(out) as tmp:
        diffs = {}
        for name, (graph, file, inputs, outputs) in graphs.items():
            _export(graph, tuple(x[:1] for x in inputs.values()), tmp / file, list(inputs), outputs)
            diffs[name] = _max_diff(graph, tmp / file, inputs)
        worst = max(v for d in diffs.values() for v in d.values())
        if not worst <= tolerance:  # also catches NaN
            raise PoseconsError(
                f"{checkpoint}: ONNX Runtime differs from PyTorch by {worst:.3g} (tolerance {tolerance:g}): {diffs}"
            )
        save_safetensors(tmp / WEIGHTS, model.state_dict(), config)
        info = {
            "checkpoint": str(checkpoint),
            "height": h,
            "width": w,
            "min_depth": config.model.min_depth,
            "max_depth": config.model.max_depth,
            "opset": OPSET,
            "batch_verified": batch,
            "tolerance": tolerance,
            "max_abs_diff": diffs,
            "files": {**{name: g[1] for name, g in graphs.items()}, "weights": WEIGHTS},
            "outputs": {name: OUTPUTS[name] + (METRES if name == "depth" and metric else "") for name in graphs},
            "config": config.to_dict(),
        }
        (tmp / EXPORT_INFO).write_text(json.dumps(info, indent=2))
    return info
