"""The one prediction path: the networks of a checkpoint (PyTorch) or of an export directory (ONNX
Runtime) behind one interface (network-size images in, scaled disparity and relative poses out), and
:func:`predict_batches` / :class:`StepChain`, which turn decoded frames into those predictions with one
resizing, batching and device handling for ``predict``, ``evaluate-depth`` and ``evaluate-pose``.

Neither path unpickles arbitrary objects: checkpoints go through ``load_model``
(``torch.load(weights_only=True)`` or safetensors), ONNX files are protobuf.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Iterator
from pathlib import Path

import numpy as np
import torch

from ..checkpoint import load_model
from ..data.images import resize_rgb
from ..errors import PoseconsError
from .media import Frame

EXPORT_INFO = "export.json"
DEPTH_ONNX = "depth.onnx"
POSE_ONNX = "pose.onnx"


class Predictor:
    """Common interface. Images are (B, 3, height, width) float32 in [0, 1]."""

    name: str
    height: int
    width: int
    has_pose: bool
    metric: bool = False  # depth in metres: trained with the true camera motion (model.known_motion)

    def disparity(self, images: np.ndarray) -> torch.Tensor:
        """→ scaled disparity (B, 1, height, width) at full scale (depth = 1 / disparity)."""
        raise NotImplementedError

    def pose(self, image_a: np.ndarray, image_b: np.ndarray) -> np.ndarray:
        """Ordered pairs → T_{b←a} as (B, 4, 4) float64."""
        raise NotImplementedError


class TorchPredictor(Predictor):
    """A :class:`~posecons.model.PoseConsModel` (in eval mode) on ``device``; ``name`` for reports."""

    def __init__(self, model, name: str, device: str = "cpu"):
        self.device = torch.device(device)
        self.model, self.config, self.name = model, model.config, name
        self.height, self.width = self.config.model.height, self.config.model.width
        m = self.config.model
        self.metric = m.known_motion
        self.has_pose = not (m.known_motion or m.known_rotation)  # their pose net's rotation is never trained

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
            self.metric = bool(info.get("config", {}).get("model", {}).get("known_motion", False))
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise PoseconsError(
                f"{info_path}: missing or unreadable export description ({exc}); "
                f"ONNX models are run from a `posecons export` directory"
            ) from exc
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


def load_predictor(path: str | Path, device: str = "cpu", entry: str = "model") -> Predictor:
    """A checkpoint (.pt / .safetensors), an export directory, or its depth.onnx → a :class:`Predictor`
    on ``device`` (``"auto"``: cuda if available, else cpu); ``entry``: which weights of a ``.pt``
    checkpoint (:func:`~posecons.checkpoint.load_model`), named after it unless they are its ``model``."""
    path = Path(path)
    if device == "auto":
        device = "cuda" if torch.cuda.is_available() else "cpu"
    if device.startswith("cuda") and not torch.cuda.is_available():
        raise PoseconsError(f"--device {device}: CUDA is not available on this machine")
    if path.is_dir():
        return OnnxPredictor(path, device)
    if path.suffix == ".onnx":
        return OnnxPredictor(path.parent, device)
    name = str(path) if entry == "model" else f"{path}: {entry}"
    return TorchPredictor(load_model(path, map_location=device, entry=entry)[0], name, device)


def post_process_disparity(disp: torch.Tensor, disp_flipped: torch.Tensor) -> torch.Tensor:
    """Blend (B, 1, H, W) disparities of an image and of its mirror (already flipped back).

    The middle is their mean; near each side border the prediction that did not see that
    border at the image edge takes over (a ramp over 5–10 % of the width), as Monodepth does.
    """
    x = torch.linspace(0, 1, disp.shape[-1], device=disp.device)
    left = 1.0 - torch.clamp(20.0 * (x - 0.05), 0.0, 1.0)  # 1 at the left border, 0 beyond 10 %
    right = left.flip(0)
    return left * disp_flipped + right * disp + (1.0 - left - right) * 0.5 * (disp + disp_flipped)


def predict_batches(
    predictor: Predictor, frames: Iterable[Frame], batch_size: int, depth: bool = True, post_process: bool = False
) -> Iterator[tuple[list[Frame], np.ndarray, torch.Tensor | None]]:
    """Per batch of up to ``batch_size`` frames: (frames, network images (B, 3, h, w) float32 in [0, 1],
    scaled disparities (B, 1, h, w), or None with ``depth=False``).

    Frames stream through, so a whole sequence never sits in memory. Images are resized to the
    network size like the training data (:func:`~posecons.data.images.resize_rgb`); ``post_process``
    also runs the mirrored images and blends (:func:`post_process_disparity`).
    """
    batch: list[Frame] = []
    for frame in frames:
        batch.append(frame)
        if len(batch) == batch_size:
            yield _predict(predictor, batch, depth, post_process)
            batch = []
    if batch:
        yield _predict(predictor, batch, depth, post_process)


def _predict(predictor: Predictor, frames: list[Frame], depth: bool, post_process: bool):
    images = np.stack([resize_rgb(f.image, predictor.height, predictor.width) for f in frames])
    if not depth:
        return frames, images, None
    if not post_process:
        return frames, images, predictor.disparity(images)
    disp = predictor.disparity(np.concatenate([images, images[..., ::-1]]))
    return frames, images, post_process_disparity(disp[: len(images)], disp[len(images) :].flip(-1))


class StepChain:
    """Relative poses T_{i+1←i} of consecutive frames that arrive in batches: the last frame of a
    batch is paired with the first frame of the next."""

    def __init__(self, predictor: Predictor):
        self.predictor = predictor
        self.previous: np.ndarray | None = None
        self.parts: list[np.ndarray] = []

    def add(self, images: np.ndarray) -> np.ndarray:
        """The next (B, 3, h, w) network images of the sequence → the steps into them (B − 1 for the
        first batch, B after it)."""
        a = images[:-1] if self.previous is None else np.concatenate([self.previous, images[:-1]])
        steps = self.predictor.pose(a, images[len(images) - len(a) :]) if len(a) else np.zeros((0, 4, 4))
        self.parts.append(steps)
        self.previous = images[-1:]
        return steps

    def steps(self) -> np.ndarray:
        """(N−1, 4, 4) float64 steps of the N frames added so far."""
        return np.concatenate(self.parts) if self.parts else np.zeros((0, 4, 4))
