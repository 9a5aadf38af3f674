"""How fast a training step could be on this machine: the convolution FLOPs of one step (counted by
``torch.utils.flop_counter``) against the rates the device reaches — a large matrix product and the
ResNet-18 encoder forward and backward — in fp32 and under bf16 autocast (docs/performance.md).

    python benchmarks/compute_bound.py                      # the paper's 640×192, batch 12
    python benchmarks/compute_bound.py --height 64 --width 192 --batch 8 --layers 10

Run it on an otherwise idle machine.
"""

from __future__ import annotations

import argparse
import time
from functools import partial

import torch
from torch.utils.flop_counter import FlopCounterMode
from train_step import make_batch, make_model, setting, setting_arguments

from posecons.data.augment import jitter_batch
from posecons.networks import ResnetEncoder


def seconds(fn, repeats: int) -> float:
    fn()
    start = time.perf_counter()
    for _ in range(repeats):
        fn()
    return (time.perf_counter() - start) / repeats


def flops(fn) -> int:
    with FlopCounterMode(display=False) as counter:
        fn()
    return counter.get_total_flops()


def model_step(model, batch: dict) -> None:
    _, losses = model(jitter_batch(batch), step=0)
    losses["total"].backward()


def encoder_step(encoder, x: torch.Tensor, bf16: bool) -> None:
    encoder.zero_grad(set_to_none=True)
    with torch.autocast(x.device.type, dtype=torch.bfloat16, enabled=bf16):
        features = encoder(x)
    sum(f.float().sum() for f in features).backward()
    if x.is_cuda:
        torch.cuda.synchronize()


def product(a: torch.Tensor, b: torch.Tensor) -> None:
    a @ b
    if a.is_cuda:
        torch.cuda.synchronize()


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    setting_arguments(p)
    p.add_argument("--repeats", type=int, default=3)
    args = p.parse_args()
    device = torch.device(args.device)
    print(f"{args.device}, {torch.get_num_threads()} threads, torch {torch.__version__}")
    for constraints in ([], ["fb", "id", "cyc"]):
        cfg = setting(constraints, args)
        step = partial(model_step, make_model(cfg, device), make_batch(cfg, device))
        print(f"step FLOPs, constraints {constraints or 'none'}: {flops(step) / 1e12:.3f} TFLOP")
    for dtype in (torch.float32, torch.bfloat16):
        a, b = (torch.randn(2048, 2048, dtype=dtype, device=device) for _ in range(2))
        print(
            f"matrix product 2048³, {dtype}: {2 * 2048**3 / seconds(partial(product, a, b), args.repeats) / 1e9:.0f} GFLOP/s"
        )
    m = cfg.model
    encoder = ResnetEncoder(m.num_layers).to(device).train()
    x = torch.randn(cfg.train.batch_size, 3, m.height, m.width, device=device)
    for bf16 in (False, True):
        run = partial(encoder_step, encoder, x, bf16)
        n, s = flops(run), seconds(run, args.repeats)
        print(
            f"ResNet-{m.num_layers} encoder forward+backward, bf16 {bf16}: "
            f"{n / 1e9:.0f} GFLOP in {s:.2f} s = {n / s / 1e9:.0f} GFLOP/s"
        )


if __name__ == "__main__":
    main()
