"""`predict`'s frames/s on a 1242×375 video against the frames/s of the networks it runs, alone, at
the same batch: decoding, resizing, writing the outputs (depth .npy, 16-bit PNG, colour PNG, the
side-by-side MP4) and the trajectory are what predict adds to the networks.

    python benchmarks/predict_speed.py                      # PyTorch and ONNX Runtime, ResNet-18, 640×192
    python benchmarks/predict_speed.py --backends torch --frames 24

Random weights (the cost does not depend on them) and a synthetic clip (a texture panning across the
frame, H.264). Rows: predict with --no-trajectory against the depth network; predict as the README
runs it (trajectory on) against the depth network plus the pose network on each consecutive pair.
Run it on an otherwise idle machine.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import av
import numpy as np
import torch

from posecons.config import load_config
from posecons.inference.backend import load_predictor
from posecons.inference.export import export_model
from posecons.inference.predict import PredictOptions, predict
from posecons.training.initial_weights import save_initial_weights


def write_clip(path: Path, frames: int, height: int = 375, width: int = 1242) -> None:
    """A texture panning 8 px a frame, as H.264 at 10 fps (odd sizes are padded to even by the encoder)."""
    rng = np.random.default_rng(0)
    texture = rng.integers(0, 256, (height // 8 + 1, (width + 8 * frames) // 8 + 1, 3), dtype=np.uint8)
    texture = texture.repeat(8, 0).repeat(8, 1)[:height]
    with av.open(str(path), mode="w") as container:
        stream = container.add_stream("libx264" if "libx264" in av.codecs_available else "mpeg4", rate=10)
        stream.height, stream.width, stream.pix_fmt = height + height % 2, width, "yuv420p"
        for i in range(frames):
            image = np.ascontiguousarray(np.pad(texture[:, 8 * i : 8 * i + width], ((0, height % 2), (0, 0), (0, 0))))
            for packet in stream.encode(av.VideoFrame.from_ndarray(image, format="rgb24")):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)


def network_seconds(predictor, batch: int, pose: bool, repeats: int = 5) -> float:
    """Median seconds of the networks alone on one batch of ``batch`` frames (plus ``batch`` pose pairs)."""
    images = np.random.default_rng(0).random((batch, 3, predictor.height, predictor.width), dtype=np.float32)
    times = []
    for i in range(repeats + 1):
        start = time.perf_counter()
        predictor.disparity(images)
        if pose:
            predictor.pose(images, images)
        if i:
            times.append(time.perf_counter() - start)
    return statistics.median(times)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--backends", nargs="+", default=["torch", "onnx"], choices=["torch", "onnx"])
    p.add_argument("--frames", type=int, default=40)
    p.add_argument("--batch", type=int, default=PredictOptions.batch_size)
    p.add_argument("--layers", type=int, default=18)
    args = p.parse_args()
    print(
        f"ResNet-{args.layers}, 640×192 networks, 1242×375 clip of {args.frames} frames, batch {args.batch}, "
        f"torch {torch.__version__}, {torch.get_num_threads()} threads"
    )
    print("| backend | what runs | networks alone (frames/s) | predict (frames/s) | ratio |\n|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        write_clip(tmp / "clip.mp4", args.frames)
        config = load_config(overrides=[f"model.num_layers={args.layers}", "model.pretrained=false"])
        save_initial_weights(tmp / "untrained.pt", config)
        for backend in args.backends:
            path = tmp / "untrained.pt"
            if backend == "onnx":
                export_model(path, tmp / "export")
                path = tmp / "export"
            predictor = load_predictor(path)
            for trajectory in (False, True):
                options = PredictOptions(batch_size=args.batch, trajectory=trajectory, progress=False)
                summary = predict(predictor, tmp / "clip.mp4", tmp / f"out_{backend}_{trajectory}", options)
                alone = args.batch / network_seconds(predictor, args.batch, trajectory)
                rate = summary["frames"] / summary["seconds"]
                what = "depth + pose (trajectory)" if trajectory else "depth (--no-trajectory)"
                print(f"| {backend} | {what} | {alone:.2f} | {rate:.2f} | {rate / alone:.2f} |", flush=True)


if __name__ == "__main__":
    main()
