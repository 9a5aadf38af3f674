"""Where a training step's time goes: torch.profiler over whole steps (forward, losses, backward,
Adam), each operator's own time summed into the parts of the method — the forward pass of each loss
function, convolutions, Adam, kinds of operator, then single operators — every part of at least 3 % named.
The last line is the step's time over its convolutions' time (forward and backward), the ratio the
throughput issue asks to bring to 1.3×: the step timed without the profiler (median of --steps steps),
whose per-operator cost inflates a step of many small operators, over the convolutions' profiled time.

    python benchmarks/profile_step.py --bf16                        # the paper's 640×192, batch 12
    python benchmarks/profile_step.py --bf16 --preset synth/study   # the study setting (192×64, batch 8)
    python benchmarks/profile_step.py --bf16 --compile-losses       # with train.compile_losses
    python benchmarks/profile_step.py --bf16 --networks-only        # the floor no loss can go below

--networks-only replaces the view-synthesis losses by the plain mean of the networks' outputs: the
step is then the networks' forward and backward and Adam alone, and its ratio is the floor that the
networks' own non-convolution work (BatchNorm, activations, pooling, resizing, concatenation) sets —
however cheap the losses were made. Two ways to cut that work, measured rather than used in training:
--channels-last (the networks' weights and inputs in the channels-last layout) and --compile-networks
(torch.compile of the depth network and the pose encoder; the first step compiles).

Random frames (train_step.py's batch); run it on an otherwise idle machine.
"""

from __future__ import annotations

import argparse
import re
import statistics
import time
from collections import defaultdict

import torch
from torch.profiler import ProfilerActivity, profile, record_function
from train_step import VARIANTS, make_batch, make_model, setting, setting_arguments

import posecons.model
from posecons.data.augment import jitter_batch
from posecons.training.precision import adam

# Operator name → part of the method; the first pattern that matches wins. Everything else the
# forward pass and the losses run is element-wise arithmetic, reductions and copies.
PARTS = [
    ("convolutions", r"conv"),
    ("SSIM box filters (avg_pool2d)", r"avg_pool"),
    ("reflection padding (SSIM, decoder)", r"reflection_pad"),
    ("warps (grid_sample)", r"grid_sampler"),
    ("resizing (interpolate)", r"upsample|interpolate"),
    ("BatchNorm", r"batch_norm"),
    ("ReLU / ELU / sigmoid", r"relu|elu|sigmoid|threshold"),
    ("max pooling", r"max_pool"),
]


# The model's loss functions, each run under a profiler label: their forward operators, whatever they
# are, count as that part (their backward operators cannot be told apart from the networks').
LOSSES = {
    "photometric_error": "photometric error, forward (SSIM + L1)",
    "warp": "warps, forward (back-projection, grid_sample)",
    "smoothness_loss": "smoothness, forward",
    "min_reprojection": "minimum reprojection and auto-mask, forward",
}
PHASES = ("forward", "backward", "optimizer")


def labelled(fn, label: str):
    def run(*args, **kwargs):
        with record_function(label):
            return fn(*args, **kwargs)

    return run


def label_losses(model: posecons.model.PoseConsModel) -> None:
    """Label the loss functions the model calls (its compiled photometric error from outside)."""
    for name, label in LOSSES.items():
        if name in vars(model):  # the model's own (possibly compiled) photometric error
            setattr(model, name, labelled(getattr(model, name), label))
        else:
            setattr(posecons.model, name, labelled(getattr(posecons.model, name), label))


def part_of(event) -> str:
    """The part an operator belongs to: the loss it ran in, Adam, a named kind of operator, or the
    operator itself with its phase (forward / backward)."""
    labels, phase = set(LOSSES.values()), "forward"
    parent, loss = event.cpu_parent, None
    while parent is not None:
        if parent.name in labels and loss is None:
            loss = parent.name
        if parent.name in PHASES:
            phase = parent.name
            break
        parent = parent.cpu_parent
    if phase == "optimizer":
        return "Adam"
    if re.search(PARTS[0][1], event.name):
        return PARTS[0][0]  # convolutions, wherever they run
    if loss is not None:
        return loss
    for part, pattern in PARTS:
        if re.search(pattern, event.name):
            return part
    return f"{event.name} ({phase})"


def outputs_mean(frames, K, disps: dict, poses: dict, masks=None) -> tuple[dict, None]:
    """In place of the view-synthesis losses: a loss that reaches every disparity and pose, at the
    cost of a mean each."""
    total = sum(d.float().mean() for d in disps.values()) + sum(T.mean() for T in poses.values())
    return {"photometric": total, "smoothness": torch.zeros(()), "total": total}, None


def channels_last_input(forward):
    def run(images: torch.Tensor, *args):
        return forward(images.contiguous(memory_format=torch.channels_last), *args)

    return run


def profile_steps(constraints: list[str], args: argparse.Namespace) -> tuple[dict[str, float], float, float]:
    """Milliseconds per step of each part, the step's wall time in ms under the profiler, and its median
    wall time in ms without it (the profiler's cost per operator inflates a step of many small ones)."""
    device, cfg = torch.device(args.device), setting(constraints, args)
    model, batch = make_model(cfg, device), make_batch(cfg, device)
    label_losses(model)
    if args.networks_only:
        model._view_synthesis_losses = outputs_mean
    if args.channels_last:
        model.to(memory_format=torch.channels_last)
        for encoder in (model.depth_net.encoder, model.pose_net.encoder):
            encoder.forward = channels_last_input(encoder.forward)
    if args.compile_networks:
        model.depth_net, model.pose_net.encoder = torch.compile(model.depth_net), torch.compile(model.pose_net.encoder)
    optim = adam(model.parameters(), 1e-4, device)  # the trainer's optimiser

    def step(i: int) -> None:
        optim.zero_grad(set_to_none=True)
        with record_function("forward"), torch.autocast(device.type, dtype=torch.bfloat16, enabled=args.bf16):
            _, losses = model(jitter_batch(batch), step=i)
        with record_function("backward"):
            losses["total"].backward()
        with record_function("optimizer"):
            optim.step()

    for i in range(args.warmup):
        step(i)
    times = []
    for i in range(args.steps):
        start = time.perf_counter()
        step(i)
        times.append(time.perf_counter() - start)
    with profile(activities=[ProfilerActivity.CPU]) as prof:
        with record_function("steps"):
            for i in range(args.steps):
                step(i)
    parts: dict[str, float] = defaultdict(float)
    total = 0.0
    for event in prof.events():
        if event.name == "steps":
            total = event.cpu_time_total / 1e3 / args.steps
        elif event.name not in PHASES and event.name not in LOSSES.values():
            parts[part_of(event)] += event.self_cpu_time_total / 1e3 / args.steps
    return parts, total, 1e3 * statistics.median(times)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    setting_arguments(p)
    p.add_argument("--steps", type=int, default=3)
    p.add_argument("--warmup", type=int, default=1)
    p.add_argument("--bf16", action="store_true", help="autocast the networks to bfloat16 (losses stay fp32)")
    p.add_argument("--variants", nargs="+", default=["baseline"], choices=list(VARIANTS))
    p.add_argument("--networks-only", action="store_true", help="the losses replaced by the outputs' mean (see above)")
    p.add_argument("--channels-last", action="store_true", help="the networks in the channels-last layout")
    p.add_argument("--compile-networks", action="store_true", help="torch.compile of the networks")
    args = p.parse_args()
    m, batch = (cfg := setting([], args)).model, cfg.train.batch_size
    precision = "bf16 autocast" if args.bf16 else "fp32"
    what = "networks and Adam only, " if args.networks_only else ""
    what += "channels last, " if args.channels_last else ""
    what += "compiled networks, " if args.compile_networks else ""
    print(
        f"{args.preset or 'paper setting'}: ResNet-{m.num_layers}, {m.height}×{m.width}, batch {batch}, "
        f"{precision}, {args.device}, torch {torch.__version__}, {torch.get_num_threads()} threads, "
        f"{what}{args.steps} profiled steps after {args.warmup}"
    )
    for name in args.variants:
        parts, total, plain = profile_steps(VARIANTS[name], args)
        print(
            f"\n{name}: {plain:.0f} ms a step ({total:.0f} under the profiler; shares of the latter)"
            "\n\n| part | ms a step | share |\n|---|---|---|"
        )
        small = 0.0
        for part, ms in sorted(parts.items(), key=lambda kv: -kv[1]):
            if ms >= 0.03 * total:
                print(f"| {part} | {ms:.0f} | {100 * ms / total:.1f} % |")
            else:
                small += ms
        print(f"| each other part (< 3 % each), together | {small:.0f} | {100 * small / total:.1f} % |")
        conv = parts["convolutions"]
        print(f"\nstep ÷ convolutions: {plain / conv:.2f}× ({total / conv:.2f}× under the profiler)")


if __name__ == "__main__":
    main()
