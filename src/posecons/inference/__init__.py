"""Inference and export: ``predict`` (depth, trajectory, point clouds for images or a video) and
``export_model`` (ONNX + safetensors). See docs/inference.md.

The names below load on first use, so the CLI can register ``posecons.inference.commands``
without importing torch.
"""

import importlib

_WHERE = {
    "PredictOptions": ".predict",
    "predict": ".predict",
    "Predictor": ".backend",
    "load_predictor": ".backend",
    "export_model": ".export",
}

__all__ = sorted(_WHERE)


def __getattr__(name: str):
    if name not in _WHERE:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    module = importlib.import_module(_WHERE[name], __name__)
    for key, where in _WHERE.items():  # also replaces the submodule `predict` the import bound to that name
        if where == _WHERE[name]:
            globals()[key] = getattr(module, key)
    return globals()[name]
