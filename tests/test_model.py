import itertools

import pytest
import torch
import torch.nn as nn

from posecons.config import load_config
from posecons.model import PoseConsModel

H, W = 64, 96
ALL = ["fb", "id", "cyc"]


def make_config(constraints=(), **extra):
    sets = [f"model.height={H}", f"model.width={W}", "model.pretrained=false", "model.num_layers=10",
            f"loss.constraints=[{','.join(constraints)}]"] + [f"{k}={v}" for k, v in extra.items()]
    return load_config(overrides=sets)


def random_batch(b=2):
    K = torch.tensor([[0.58, 0, 0.5], [0, 1.92, 0.5], [0, 0, 1]]).expand(b, 3, 3).clone()
    return {"frames": torch.rand(b, 3, 3, H, W), "intrinsics": K}


@pytest.mark.parametrize("constraints", [c for n in range(4) for c in itertools.combinations(ALL, n)])
def test_forward_backward_gives_finite_gradients_in_all_networks(constraints):
    model = PoseConsModel(make_config(constraints))
    outputs, losses = model(random_batch())
    assert set(constraints) <= set(losses) and {"photometric", "smoothness", "total"} <= set(losses)
    assert all(torch.isfinite(v) for v in losses.values())
    losses["total"].backward()
    for net in (model.depth_net.encoder, model.depth_net.decoder, model.pose_net.encoder, model.pose_net.decoder):
        grads = [p.grad for p in net.parameters()]
        assert all(g is not None and torch.isfinite(g).all() for g in grads)
        assert any(g.abs().sum() > 0 for g in grads)
    assert outputs["depth"].shape == (2, 1, H, W)
    assert set(outputs["poses"]) == {-1, 1} and outputs["poses"][1].shape == (2, 4, 4)


def test_all_pose_inputs_go_through_one_batched_pass():
    model = PoseConsModel(make_config(ALL))
    calls = []
    model.pose_net.encoder.register_forward_hook(lambda mod, inp, out: calls.append(inp[0].shape[0]))
    model(random_batch(b=3))
    # 2 temporal pairs + 2 reversed + identity + cycle = 6 pairs of 3 samples, in one call
    assert calls == [18]


class ConstantDepth(nn.Module):
    def __init__(self, sigmoid_value: float):
        super().__init__()
        self.value = sigmoid_value

    def forward(self, images):
        b, _, h, w = images.shape
        return {s: torch.full((b, 1, h // 2 ** s, w // 2 ** s), self.value) for s in range(4)}


class TruePoses(nn.Module):
    """Returns T_{b←a} of a camera moving +v along x each frame, for the pairs the model asks for."""

    def __init__(self, model, v, sign=1.0):
        super().__init__()
        self.model, self.v, self.sign = model, v, sign
        self.pairs = None
        original = model.pose_pairs

        def record(constraints):
            self.pairs = original(constraints)
            return self.pairs
        model.pose_pairs = record

    def forward(self, a, b):
        n = a.shape[0] // len(self.pairs)
        t = torch.tensor([[[-self.sign * (pb - pa) * self.v, 0.0, 0.0]] for _, pa, pb in self.pairs])
        return torch.zeros(len(self.pairs) * n, 1, 3), t.repeat_interleave(n, 0)


def sliding_scene(shift_px: int, frame_ids, b: int = 2):
    """Fronto-parallel textured plane; frame f sees the texture shifted by f·shift_px pixels."""
    tex = torch.nn.functional.avg_pool2d(torch.rand(b, 3, H, W + 8 * shift_px), 3, 1, 1)
    frames = [tex[..., 4 * shift_px + f * shift_px: 4 * shift_px + f * shift_px + W] for f in frame_ids]
    return torch.stack(frames, 1)


@pytest.mark.parametrize("n", [1, 2])
def test_pose_conventions_with_true_motion(n):
    z, fx_norm = 10.0, 0.5
    v = 2 * z / (fx_norm * W)  # 2-pixel shift per frame: fx·v/Z = 2
    frame_ids = [0, -n, n]
    frames = sliding_scene(2, frame_ids)
    K = torch.tensor([[fx_norm, 0, 0.5], [0, fx_norm * W / H, 0.5], [0, 0, 1]]).expand(2, 3, 3).clone()
    results = {}
    for sign in (1.0, -1.0):
        model = PoseConsModel(make_config(ALL, **{"loss.automask": "false", "model.frame_ids": f"[0,-{n},{n}]"}))
        min_d, max_d = 1 / 100.0, 1 / 0.1
        model.depth_net = ConstantDepth((1 / z - min_d) / (max_d - min_d))
        model.pose_net = TruePoses(model, v, sign)
        _, losses = model({"frames": frames, "intrinsics": K})
        results[sign] = losses
    good, flipped = results[1.0], results[-1.0]
    assert good["fb"].item() == pytest.approx(0, abs=1e-6)
    assert good["cyc"].item() == pytest.approx(0, abs=1e-6)
    assert good["id"].item() == pytest.approx(0, abs=1e-7)
    assert good["photometric"] < 0.3 * flipped["photometric"]  # the right direction explains the motion


def test_mixed_precision_keeps_geometry_and_losses_in_fp32():
    model = PoseConsModel(make_config(ALL))
    with torch.autocast("cpu", dtype=torch.bfloat16):
        outputs, losses = model(random_batch())
    assert outputs["disp"][0].dtype == torch.bfloat16  # the networks ran in bf16 ...
    assert all(T.dtype == torch.float32 for T in outputs["poses"].values())  # ... poses, warping
    assert all(v.dtype == torch.float32 and torch.isfinite(v) for v in losses.values())  # and losses in fp32
    losses["total"].backward()
