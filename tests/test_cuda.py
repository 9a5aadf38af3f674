"""On a CUDA device (skipped elsewhere; `benchmarks/gpu_check.sh` runs them as `pytest -m cuda`): the model
computes on the GPU what it computes on the CPU, and its mixed-precision steps keep losses finite and fp32."""

from __future__ import annotations

import pytest
import torch

from posecons.model import PoseConsModel
from posecons.training.precision import autocast
from test_model import ALL, make_config, random_batch

pytestmark = [
    pytest.mark.cuda,
    pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device"),
]


def cpu_and_cuda(constraints=ALL, **extra) -> tuple[PoseConsModel, PoseConsModel, dict, dict]:
    torch.manual_seed(0)
    cpu = PoseConsModel(make_config(constraints, **extra))
    gpu = PoseConsModel(make_config(constraints, **extra)).cuda()
    gpu.load_state_dict(cpu.state_dict())
    batch = random_batch(b=3)
    return cpu, gpu, batch, {k: v.cuda() for k, v in batch.items()}


def test_a_training_step_on_the_gpu_equals_the_cpu_step_in_fp32():
    """Losses and every gradient (cuDNN's convolutions round differently: a relative tolerance).
    Caught: a device-dependent code path, e.g. intrinsics or a constant left on the CPU."""
    torch.backends.cudnn.allow_tf32 = torch.backends.cuda.matmul.allow_tf32 = False
    cpu, gpu, batch, on_gpu = cpu_and_cuda(**{"loss.skip_weight": 0.5, "loss.depth_consistency_weight": 0.1})
    _, losses = cpu(batch, step=1)
    _, gpu_losses = gpu(on_gpu, step=1)
    assert set(losses) == set(gpu_losses)
    for name, value in losses.items():
        assert gpu_losses[name].item() == pytest.approx(value.item(), rel=1e-3, abs=1e-6), name
    losses["total"].backward()
    gpu_losses["total"].backward()
    for (name, p), q in zip(cpu.named_parameters(), gpu.parameters()):
        torch.testing.assert_close(q.grad.cpu(), p.grad, rtol=2e-2, atol=1e-4, msg=name)


@pytest.mark.parametrize("precision", ["bf16", "16"])
def test_mixed_precision_steps_on_the_gpu_keep_finite_fp32_losses_near_fp32s(precision):
    cpu, gpu, batch, on_gpu = cpu_and_cuda()
    _, reference = gpu(on_gpu)
    with autocast(precision, torch.device("cuda")):
        _, losses = gpu(on_gpu)
    for name, value in losses.items():
        assert value.dtype == torch.float32 and torch.isfinite(value), name
    assert losses["photometric"].item() == pytest.approx(reference["photometric"].item(), rel=5e-2)
    losses["total"].backward()
    assert all(torch.isfinite(p.grad).all() for p in gpu.parameters() if p.grad is not None)
