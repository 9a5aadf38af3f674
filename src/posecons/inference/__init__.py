"""Inference and export: :mod:`.predict` (``predict``: depth, trajectory, point clouds for images or a
video), :mod:`.backend` (``load_predictor``) and :mod:`.export` (``export_model``: ONNX + safetensors).
See docs/inference.md."""
