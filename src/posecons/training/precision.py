"""How a run computes: ``train.precision`` resolved for the device (bf16 where it is native, float16
on a GPU only), the autocast region of the forward pass that follows from it, and the
deterministic kernels of ``train.deterministic`` that make a resume exact. Kept apart from the
trainer as the one place that knows which device supports which number format and kernel."""

from __future__ import annotations

import os
import platform
from pathlib import Path

import torch

from ..errors import PoseconsError


def native_bf16(device: torch.device) -> tuple[bool, str]:
    """Whether ``device`` computes bf16 natively (a CUDA GPU that supports it; a CPU with AVX-512 BF16 or
    AMX, as torch reports), and that in words. Elsewhere bf16 is emulated: on an AVX2-only CPU a bf16
    training step took 10× as long as an fp32 one (docs/performance.md)."""
    if device.type == "cuda":
        native = torch.cuda.is_bf16_supported()
        return native, f"{torch.cuda.get_device_name(device)} {'has' if native else 'lacks'} bf16"
    native = _cpu_has("_is_avx512_bf16_supported") or _cpu_has("_is_amx_tile_supported")
    return native, f"this CPU {'has' if native else 'lacks'} AVX-512 BF16 / AMX"


def _cpu_has(probe: str) -> bool:
    """torch.cpu's ``probe`` (e.g. ``_is_amx_tile_supported``); False in a torch without it."""
    check = getattr(getattr(torch, "cpu", None), probe, None)
    return check is not None and bool(check())


def cpu_kind() -> str:
    """The CPU's vector capability as torch dispatches on it (e.g. AVX2, AVX512), whether its bf16 is
    native, and whether oneDNN may use AMX tiles (and the ISA cap ``ONEDNN_MAX_CPU_ISA`` where one is
    set): a run's kernels, and so its rounding, follow from all of them. The same run with and without
    AMX ended 0.06 apart in abs rel (docs/results.md §8)."""
    native, _ = native_bf16(torch.device("cpu"))
    kind = f"{torch.backends.cpu.get_cpu_capability()}, bf16 {'native' if native else 'emulated'}"
    cap = os.environ.get("ONEDNN_MAX_CPU_ISA", "")
    if _cpu_has("_is_amx_tile_supported") and (not cap or "AMX" in cap.upper() or cap.upper() in ("ALL", "DEFAULT")):
        kind += ", AMX"
    return kind + (f", ONEDNN_MAX_CPU_ISA={cap}" if cap else "")


def processor_name() -> str:
    """The processor's model name ("model name" of /proc/cpuinfo on Linux): beyond :func:`cpu_kind`, two
    processors of one kind still round differently (an AMD and an Intel CPU, both AVX-512 with native
    bf16 and AMX off, ended the same run 0.012 apart in abs rel, docs/results.md §8)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def resolve_precision(precision: str, device: torch.device) -> tuple[str, str]:
    """``train.precision`` on ``device``: "auto" becomes "bf16" where the device computes bf16 natively
    (:func:`native_bf16`) and "32" elsewhere, where emulated bf16 would be slower than fp32; float16
    ("16") is an error off a GPU. Returns (precision, why): why says what "auto" found, or warns that an
    asked-for bf16 is emulated here; empty otherwise."""
    if precision == "16" and device.type != "cuda":
        raise PoseconsError(
            "train.precision=16 (float16 with a gradient scaler) needs a GPU; "
            "on a CPU use bf16 (fast where the CPU has AVX-512 BF16 or AMX) or 32"
        )
    if precision not in ("auto", "bf16"):
        return precision, ""
    native, where = native_bf16(device)
    if precision == "bf16":
        return "bf16", "" if native else f"emulated: {where}, so bf16 is much slower than 32 here"
    return ("bf16" if native else "32"), f"auto: {where}"


def autocast(precision: str, device: torch.device) -> torch.autocast:
    """The autocast region of the forward pass and loss at a resolved ``precision``; off at "32"."""
    dtype = {"bf16": torch.bfloat16, "16": torch.float16}.get(precision)
    return torch.autocast(device.type, dtype=dtype, enabled=dtype is not None)


def adam(params, lr: float, device: torch.device) -> torch.optim.Adam:
    """Adam with the fused kernel where the build has it for ``device`` (CPU and CUDA): one pass over all
    parameters instead of a loop of small ones, 4–6× faster on the development CPU (docs/performance.md),
    the same update up to float rounding."""
    return torch.optim.Adam(params, lr=lr, fused=device.type in ("cpu", "cuda"))


def use_deterministic_algorithms(device: torch.device) -> None:
    """Deterministic kernels for exact resume. On CUDA, cuBLAS needs a fixed workspace and some
    backward kernels (grid_sample, reflection padding, bilinear interpolation) have no
    deterministic version: PyTorch then warns instead of raising, and results can differ in
    the last bits between runs."""
    if device.type == "cuda":
        os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")
        torch.backends.cudnn.benchmark = False
    torch.use_deterministic_algorithms(True, warn_only=device.type == "cuda")
