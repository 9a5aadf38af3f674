from urllib.error import URLError

import pytest
import torch
import torchvision.models as tvm

from posecons import networks
from posecons.errors import PoseconsError
from posecons.networks import DepthNet, PoseNet, ResnetEncoder


@pytest.mark.parametrize("layers,channels", [(10, [64, 64, 128, 256, 512]), (18, [64, 64, 128, 256, 512]),
                                             (50, [64, 256, 512, 1024, 2048])])
def test_encoder_feature_pyramid(layers, channels):
    enc = ResnetEncoder(layers)
    feats = enc(torch.rand(1, 3, 64, 96))
    assert [f.shape[1] for f in feats] == channels == enc.num_ch_enc
    assert [f.shape[-2:] for f in feats] == [(64 // 2 ** i, 96 // 2 ** i) for i in range(1, 6)]


def test_depth_net_outputs_four_sigmoid_scales():
    disps = DepthNet(10)(torch.rand(2, 3, 64, 128))
    assert sorted(disps) == [0, 1, 2, 3]
    for s, d in disps.items():
        assert d.shape == (2, 1, 64 // 2 ** s, 128 // 2 ** s)
        assert (d > 0).all() and (d < 1).all()


def test_pose_net_output_is_small_at_init():
    aa, t = PoseNet(10)(torch.rand(3, 3, 64, 96), torch.rand(3, 3, 64, 96))
    assert aa.shape == t.shape == (3, 1, 3)
    assert aa.abs().max() < 0.05 and t.abs().max() < 0.05  # × 0.01 output scaling


def test_size_not_multiple_of_32_is_rejected_with_working_sizes():
    with pytest.raises(PoseconsError, match=r"100×200 is not a multiple of 32.*96×192"):
        DepthNet(10)(torch.rand(1, 3, 100, 200))


def fake_imagenet(monkeypatch):
    state = tvm.resnet18().state_dict()
    monkeypatch.setattr(tvm.ResNet18_Weights.IMAGENET1K_V1, "get_state_dict", lambda *a, **k: dict(state))
    return state


def test_pretrained_pose_conv1_is_tiled_and_halved(monkeypatch):
    state = fake_imagenet(monkeypatch)
    pose = ResnetEncoder(18, pretrained=True, num_input_images=2)
    w = pose.net.conv1.weight.detach()
    assert w.shape == (64, 6, 7, 7)
    assert torch.allclose(w[:, :3], state["conv1.weight"] / 2) and torch.allclose(w[:, 3:], state["conv1.weight"] / 2)
    depth = ResnetEncoder(18, pretrained=True)
    assert torch.equal(depth.net.layer4[1].conv2.weight, state["layer4.1.conv2.weight"])


def test_offline_pretrained_auto_warns_and_required_raises(monkeypatch):
    def offline(*args, **kwargs):
        raise URLError("no network")
    monkeypatch.setattr(tvm.ResNet18_Weights.IMAGENET1K_V1, "get_state_dict", offline)
    with pytest.warns(UserWarning, match="Training from scratch"):
        assert networks.load_imagenet_state(18, "auto") is None
    with pytest.raises(PoseconsError, match="model.pretrained=false"):
        ResnetEncoder(18, pretrained=True)
    assert networks.load_imagenet_state(18, False) is None
