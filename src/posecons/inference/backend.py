"""Run the networks from a checkpoint (PyTorch) or from an export directory (ONNX Runtime) behind
one interface: network-size images in, scaled disparity and relative poses out.

Neither path unpickles arbitrary objects: checkpoints go through ``load_model``
(``torch.load(weights_only=True)`` or safetensors), ONNX files are protobuf.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import torch

from ..checkpoint import load_model
from ..errors import PoseconsError

EXPORT_INFO = "export.json"
DEPTH_ONNX = "depth.onnx"
POSE_ONNX = "pose.onnx"


class Predictor:
    """Common interface. Images are (B, 3, height, width) float32 in [0, 1]."""

    name: str
    height: int
    width: int
    has_pose: bool

    def disparity(self, images: np.ndarray) -> torch.Tensor:
        """→ scaled disparity (B, 1, height, width) at full scale (depth = 1 / disparity)."""
        raise NotImplementedError

    def pose(self, image_a: np.ndarray, image_b: np.ndarray) -> np.ndarray:
        """Ordered pairs → T_{b←a} as (B, 4, 4) float64."""
        raise NotImplementedError


class TorchPredictor(Predictor):
    def __init__(self, path: Path, device: str = "cpu"):
        self.device = torch.device(device)
        self.model, self.config = load_model(path, map_location=self.device)
        self.name = str(path)
        self.height, self.width = self.config.model.height, self.config.model.width
        self.has_pose = True

    @torch.no_grad()
    def disparity(self, images: np.ndarray) -> torch.Tensor:
        return self.model.predict_depth(torch.from_numpy(images).to(self.device))[0]

    @torch.no_grad()
    def pose(self, image_a: np.ndarray, image_b: np.ndarray) -> np.ndarray:
        a, b = (torch.from_numpy(x).to(self.device) for x in (image_a, image_b))
        return self.model.predict_pose(a, b).double().cpu().numpy()


class OnnxPredictor(Predictor):
    """The ``depth.onnx`` / ``pose.onnx`` pair written by ``posecons export``; sizes from export.json."""

    def __init__(self, directory: Path, device: str = "cpu"):
        import onnxruntime as ort

        info_path = directory / EXPORT_INFO
        try:
            info = json.loads(info_path.read_text())
            self.height, self.width = int(info["height"]), int(info["width"])
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise PoseconsError(f"{info_path}: missing or unreadable export description ({exc}); "
                                f"ONNX models are run from a `posecons export` directory") from exc
        providers = ["CPUExecutionProvider"]
        if device.startswith("cuda") and "CUDAExecutionProvider" in ort.get_available_providers():
            providers.insert(0, "CUDAExecutionProvider")
        self.name = str(directory / DEPTH_ONNX)
        self.depth_session = _session(directory / DEPTH_ONNX, providers)
        pose_path = directory / POSE_ONNX
        self.pose_session = _session(pose_path, providers) if pose_path.is_file() else None
        self.has_pose = self.pose_session is not None

    def disparity(self, images: np.ndarray) -> torch.Tensor:
        return torch.from_numpy(self.depth_session.run(["disparity"], {"images": images})[0])

    def pose(self, image_a: np.ndarray, image_b: np.ndarray) -> np.ndarray:
        if self.pose_session is None:
            raise PoseconsError(f"{self.name}: no {POSE_ONNX} beside it, so no ego-motion")
        return self.pose_session.run(["matrix"], {"image_a": image_a, "image_b": image_b})[0].astype(np.float64)


def _session(path: Path, providers: list[str]):
    import onnxruntime as ort

    if not path.is_file():
        raise PoseconsError(f"{path}: ONNX model not found")
    try:
        return ort.InferenceSession(str(path), providers=providers)
    except Exception as exc:  # onnxruntime raises its own untyped errors for bad files
        raise PoseconsError(f"{path}: not a loadable ONNX model ({str(exc).splitlines()[0]})") from exc


def load_predictor(path: str | Path, device: str = "cpu") -> Predictor:
    """A checkpoint (.pt / .safetensors), an export directory, or its depth.onnx → a :class:`Predictor`."""
    path = Path(path)
    if device.startswith("cuda") and not torch.cuda.is_available():
        raise PoseconsError(f"--device {device}: CUDA is not available on this machine")
    if path.is_dir():
        return OnnxPredictor(path, device)
    if path.suffix == ".onnx":
        return OnnxPredictor(path.parent, device)
    return TorchPredictor(path, device)
