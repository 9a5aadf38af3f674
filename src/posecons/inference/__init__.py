"""Inference and export: ``predict`` (depth, trajectory, point clouds for images or a video) and
``export_model`` (ONNX + safetensors). See docs/inference.md."""

from .backend import Predictor, load_predictor
from .export import export_model
from .predict import PredictOptions, predict

__all__ = ["PredictOptions", "Predictor", "export_model", "load_predictor", "predict"]
