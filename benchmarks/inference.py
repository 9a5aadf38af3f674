"""Inference images/s of the depth network (and pose pairs/s of the pose network) at the paper's
640×192, batch 1 and 16, in PyTorch and in ONNX Runtime, beside the architecture's cost
(parameters and multiply-accumulates per image, which are Monodepth2's: the same ResNet encoders
and decoders).

    python benchmarks/inference.py                       # CPU, ResNet-18, 640×192
    python benchmarks/inference.py --device cuda --batches 1 16 64

Random weights (the cost does not depend on them). Prints a Markdown table with the machine,
PyTorch build and thread count; run it on an otherwise idle machine.
"""

from __future__ import annotations

import argparse
import platform
import statistics
import tempfile
import time
from pathlib import Path

import torch
from torch.utils.flop_counter import FlopCounterMode

from posecons.checkpoint import load_model
from posecons.config import load_config
from posecons.inference.export import export_model
from posecons.training.initial_weights import save_initial_weights


def _median_seconds(run, warmup: int, repeats: int, device: torch.device) -> float:
    times = []
    for i in range(warmup + repeats):
        start = time.perf_counter()
        run()
        if device.type == "cuda":
            torch.cuda.synchronize(device)
        if i >= warmup:
            times.append(time.perf_counter() - start)
    return statistics.median(times)


def _runs(model, sessions: dict, x: torch.Tensor) -> dict:
    """(network, runtime) → a call that runs it on the batch ``x``."""
    runs = {("depth", "PyTorch"): lambda: model.predict_depth(x), ("pose", "PyTorch"): lambda: model.pose_net(x, x)}
    if sessions:
        feed = x.cpu().numpy()
        runs[("depth", "ONNX Runtime")] = lambda: sessions["depth"].run(None, {"images": feed})
        runs[("pose", "ONNX Runtime")] = lambda: sessions["pose"].run(None, {"image_a": feed, "image_b": feed})
    return runs


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--layers", type=int, default=18)
    p.add_argument("--height", type=int, default=192)
    p.add_argument("--width", type=int, default=640)
    p.add_argument("--batches", type=int, nargs="+", default=[1, 16])
    p.add_argument("--device", default="cpu", choices=("cpu", "cuda"))
    p.add_argument("--warmup", type=int, default=2)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--no-onnx", action="store_true", help="PyTorch rows only")
    args = p.parse_args()
    device = torch.device(args.device)
    config = load_config(
        overrides=[
            f"model.num_layers={args.layers}",
            f"model.height={args.height}",
            f"model.width={args.width}",
            "model.pretrained=false",
        ]
    )
    with tempfile.TemporaryDirectory() as tmp:
        checkpoint = Path(tmp) / "untrained.pt"
        save_initial_weights(checkpoint, config)
        model = load_model(checkpoint, map_location=device)[0].eval()
        image = torch.rand(1, 3, args.height, args.width, device=device)
        with torch.no_grad(), FlopCounterMode(display=False) as depth_flops:
            model.predict_depth(image)
        with torch.no_grad(), FlopCounterMode(display=False) as pose_flops:
            model.pose_net(image, image)
        count = {name: sum(p.numel() for p in getattr(model, name).parameters()) for name in ("depth_net", "pose_net")}
        print(
            f"ResNet-{args.layers}, {args.width}×{args.height}, {args.device}, {platform.processor() or platform.machine()}, "
            f"torch {torch.__version__}, {torch.get_num_threads()} threads, median of {args.repeats} after {args.warmup}"
        )
        print(
            f"depth net: {count['depth_net'] / 1e6:.2f} M parameters, {depth_flops.get_total_flops() / 2e9:.2f} GMAC per image; "
            f"pose net: {count['pose_net'] / 1e6:.2f} M parameters, {pose_flops.get_total_flops() / 2e9:.2f} GMAC per pair"
        )
        sessions = {}
        if not args.no_onnx:
            import onnxruntime as ort

            export_model(checkpoint, Path(tmp) / "export")
            providers = ["CPUExecutionProvider"] if device.type == "cpu" else ["CUDAExecutionProvider"]
            sessions = {
                name: ort.InferenceSession(str(Path(tmp) / "export" / f"{name}.onnx"), providers=providers)
                for name in ("depth", "pose")
            }
        print("| network | runtime | batch | images/s (pairs/s for pose) |\n|---|---|---|---|")
        for batch in args.batches:
            x = torch.rand(batch, 3, args.height, args.width, device=device)
            for (net, runtime), run in sorted(_runs(model, sessions, x).items()):
                with torch.no_grad():
                    seconds = _median_seconds(run, args.warmup, args.repeats, device)
                print(f"| {net} | {runtime} | {batch} | {batch / seconds:.1f} |", flush=True)


if __name__ == "__main__":
    main()
