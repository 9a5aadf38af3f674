"""How a run computes: ``train.precision`` resolved for the device (bf16 where it is native, float16
on a GPU only), the autocast region of the forward pass that follows from it, and the
deterministic kernels of ``train.deterministic`` that make a resume exact. Kept apart from the
trainer as the one place that knows which device supports which number format and kernel."""

from __future__ import annotations

import os

import torch

from ..errors import PoseconsError


def resolve_precision(precision: str, device: torch.device) -> tuple[str, str]:
    """``train.precision`` on ``device``: "auto" becomes "bf16" where the device computes bf16 natively
    (a CUDA GPU that supports it; a CPU with AVX-512 BF16 or AMX, as torch reports) and "32" elsewhere,
    where emulated bf16 would be slower than fp32; float16 ("16") is an error off a GPU. Returns
    (precision, why; why empty unless "auto")."""
    if precision == "16" and device.type != "cuda":
        raise PoseconsError(
            "train.precision=16 (float16 with a gradient scaler) needs a GPU; "
            "on a CPU use bf16 (fast where the CPU has AVX-512 BF16 or AMX) or 32"
        )
    if precision != "auto":
        return precision, ""
    if device.type == "cuda":
        native = torch.cuda.is_bf16_supported()
        where = f"{torch.cuda.get_device_name(device)} {'has' if native else 'lacks'} bf16"
    else:
        cpu = getattr(torch, "cpu", None)
        checks = [getattr(cpu, name, None) for name in ("_is_avx512_bf16_supported", "_is_amx_tile_supported")]
        native = any(check() for check in checks if check is not None)
        where = f"this CPU {'has' if native else 'lacks'} AVX-512 BF16 / AMX"
    return ("bf16" if native else "32"), f"auto: {where}"


def autocast(precision: str, device: torch.device) -> torch.autocast:
    """The autocast region of the forward pass and loss at a resolved ``precision``; off at "32"."""
    dtype = {"bf16": torch.bfloat16, "16": torch.float16}.get(precision)
    return torch.autocast(device.type, dtype=dtype, enabled=dtype is not None)


def use_deterministic_algorithms(device: torch.device) -> None:
    """Deterministic kernels for exact resume. On CUDA, cuBLAS needs a fixed workspace and some
    backward kernels (grid_sample, reflection padding, bilinear interpolation) have no
    deterministic version: PyTorch then warns instead of raising, and results can differ in
    the last bits between runs."""
    if device.type == "cuda":
        os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")
        torch.backends.cudnn.benchmark = False
    torch.use_deterministic_algorithms(True, warn_only=device.type == "cuda")
