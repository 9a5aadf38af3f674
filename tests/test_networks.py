from urllib.error import URLError

import pytest
import torch
import torchvision.models as tvm

from posecons import networks
from posecons.config import load_config
from posecons.errors import PoseconsError
from posecons.geometry import pose_vec_to_mat
from posecons.model import PoseConsModel
from posecons.networks import DepthNet, PoseNet, ResnetEncoder


@pytest.mark.parametrize(
    "layers,channels", [(10, [64, 64, 128, 256, 512]), (18, [64, 64, 128, 256, 512]), (50, [64, 256, 512, 1024, 2048])]
)
def test_encoder_feature_pyramid(layers, channels):
    enc = ResnetEncoder(layers)
    feats = enc(torch.rand(1, 3, 64, 96))
    assert [f.shape[1] for f in feats] == channels == enc.num_ch_enc
    assert [f.shape[-2:] for f in feats] == [(64 // 2**i, 96 // 2**i) for i in range(1, 6)]


def test_depth_net_outputs_four_sigmoid_scales():
    disps = DepthNet(10)(torch.rand(2, 3, 64, 128))
    assert sorted(disps) == [0, 1, 2, 3]
    for s, d in disps.items():
        assert d.shape == (2, 1, 64 // 2**s, 128 // 2**s)
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
    imagenet = networks.load_imagenet_state(18, True)
    pose = ResnetEncoder(18, imagenet, num_input_images=2)
    w = pose.net.conv1.weight.detach()
    assert w.shape == (64, 6, 7, 7)
    assert torch.allclose(w[:, :3], state["conv1.weight"] / 2) and torch.allclose(w[:, 3:], state["conv1.weight"] / 2)
    depth = ResnetEncoder(18, imagenet)
    assert torch.equal(imagenet["conv1.weight"], state["conv1.weight"])  # the shared dict is not altered
    assert torch.equal(depth.net.layer4[1].conv2.weight, state["layer4.1.conv2.weight"])


def test_offline_pretrained_auto_warns_and_required_raises(monkeypatch):
    def offline(*args, **kwargs):
        raise URLError("no network")

    monkeypatch.setattr(tvm.ResNet18_Weights.IMAGENET1K_V1, "get_state_dict", offline)
    with pytest.warns(UserWarning, match="Training from scratch"):
        assert networks.load_imagenet_state(18, "auto") is None
    with pytest.raises(PoseconsError, match="from scratch on purpose with --set model.pretrained=false"):
        networks.load_imagenet_state(18, True)
    assert networks.load_imagenet_state(18, False) is None


def test_grouped_pose_batch_equals_separate_calls_and_tracks_only_the_first_groups():
    torch.manual_seed(1)
    batched, separate = PoseNet(10), PoseNet(10)
    separate.load_state_dict(batched.state_dict())
    a, b = torch.rand(3, 2, 3, 64, 96), torch.rand(3, 2, 3, 64, 96)  # 3 groups of 2 pairs
    aa, t = batched(a.flatten(0, 1), b.flatten(0, 1), groups=3, tracked=2)
    # Monodepth2 called the pose net once per source: the first two groups, one after the other.
    singles = [separate(a[g], b[g]) for g in range(2)]
    assert torch.allclose(aa[:4], torch.cat([s[0] for s in singles]), atol=1e-6)
    assert torch.allclose(t[:4], torch.cat([s[1] for s in singles]), atol=1e-6)
    for (name, buf), other in zip(batched.named_buffers(), separate.buffers()):
        assert torch.allclose(buf.float(), other.float(), atol=1e-6), name
    # The third group is normalised on its own: it matches a separate call too.
    third = PoseNet(10)
    third.load_state_dict(batched.state_dict())
    assert torch.allclose(t[4:], third(a[2], b[2])[1], atol=1e-6)


@pytest.mark.parametrize("train", [False, True])
def test_mirrored_pose_net_is_exactly_mirror_equivariant(train):
    """Mutation caught: a wrong sign pattern in MIRROR_SIGN (e.g. the rotation's x negated like t_x)."""
    torch.manual_seed(4)
    net = PoseNet(10, mirror=True).train(train)
    a, b = torch.rand(4, 3, 64, 96), torch.rand(4, 3, 64, 96)
    # A mirror image is the view of the mirrored world: x ↦ −x turns T into S·T·S, S = diag(−1, 1, 1, 1).
    S = torch.diag(torch.tensor([-1.0, 1, 1, 1]))
    # Two groups of two pairs: each group is normalised with its own mirror images, so in training the
    # mirrored batch has the same statistics and must give exactly the mirrored motions.
    rot, t = net(a, b, groups=2)
    mirrored_back = S @ pose_vec_to_mat(*net(a.flip(-1), b.flip(-1), groups=2)) @ S
    assert torch.allclose(mirrored_back, pose_vec_to_mat(rot, t), atol=1e-6)
    plain = PoseNet(10).train(train)
    plain.load_state_dict(net.state_dict())
    assert not torch.allclose(plain(a, b, groups=2)[1], t, atol=1e-4)  # the average is not the plain output
    # ... it is the mean of the plain outputs for the pair and (mirrored back) for its mirror image
    if not train:
        direct, mirrored = plain(a, b), plain(a.flip(-1), b.flip(-1))
        t_back = (S @ pose_vec_to_mat(*mirrored) @ S)[:, :3, 3]
        assert torch.allclose(t[:, 0], (direct[1][:, 0] + t_back) / 2, atol=1e-6)


def test_pose_batch_must_split_into_equal_groups():
    with pytest.raises(ValueError, match="5 pairs.*2 equal groups"):
        PoseNet(10)(torch.rand(5, 3, 64, 96), torch.rand(5, 3, 64, 96), groups=2)


@pytest.mark.parametrize("rotation_scale", [None, 0.1])
def test_pose_decoder_scales_its_output_by_exactly_0_01_or_the_rotation_scale(rotation_scale):
    """Monodepth2's 0.01 on both by default; model.pose_rotation_scale on the axis-angle only."""
    dec = networks.PoseDecoder(512) if rotation_scale is None else networks.PoseDecoder(512, rotation_scale)
    last = dec.net[-1]
    torch.nn.init.zeros_(last.weight)
    with torch.no_grad():
        last.bias.copy_(torch.arange(1.0, 7.0))
    aa, t = dec(torch.rand(2, 512, 2, 3))
    assert torch.equal(aa, (rotation_scale or 0.01) * torch.tensor([1.0, 2, 3]).expand(2, 1, 3))
    assert torch.equal(t, 0.01 * torch.tensor([4.0, 5, 6]).expand(2, 1, 3))
    small = ["model.pretrained=false", "model.num_layers=10", f"model.pose_rotation_scale={rotation_scale or 0.01}"]
    model = PoseConsModel(load_config(overrides=small))
    assert model.pose_net.decoder.rotation_scale == (rotation_scale or 0.01)


def test_group_sizes_equal_to_a_number_of_groups_give_bit_identical_outputs_and_statistics():
    torch.manual_seed(2)
    by_count, by_sizes = PoseNet(10), PoseNet(10)
    by_sizes.load_state_dict(by_count.state_dict())
    a, b = torch.rand(6, 3, 64, 96), torch.rand(6, 3, 64, 96)
    for x, y in zip(by_count(a, b, groups=3, tracked=2), by_sizes(a, b, groups=[2, 2, 2], tracked=2)):
        assert torch.equal(x, y)
    for x, y in zip(by_count.buffers(), by_sizes.buffers()):
        assert torch.equal(x, y)


def test_groups_of_different_sizes_equal_separate_calls():
    torch.manual_seed(4)
    # One BatchNorm layer: exactly what a separate call per group computes, only tracked groups counted.
    bn, ref = networks.GroupedBatchNorm2d(4), torch.nn.BatchNorm2d(4)
    x = torch.randn(6, 4, 5, 7) * 3 + 1
    out = bn(x, networks.BatchGroups((3, 1, 2), 1))
    assert torch.equal(out[:3], ref(x[:3]))
    for lo, hi in ((3, 4), (4, 6)):  # untracked groups: their own batch statistics, no running update
        assert torch.equal(out[lo:hi], torch.nn.functional.batch_norm(x[lo:hi], None, None, bn.weight, bn.bias, True))
    assert torch.equal(bn.running_mean, ref.running_mean) and torch.equal(bn.running_var, ref.running_var)
    assert int(bn.num_batches_tracked) == 1
    # The whole pose net: temporal groups of 3 (tracked, one after the other) and constraint groups of 1.
    batched, separate = PoseNet(10), PoseNet(10)
    separate.load_state_dict(batched.state_dict())
    a, b = torch.rand(8, 3, 64, 96), torch.rand(8, 3, 64, 96)
    sizes = [3, 3, 1, 1]
    aa, t = batched(a, b, groups=sizes, tracked=2)
    singles = [separate(a[:3], b[:3]), separate(a[3:6], b[3:6])]
    for g in (6, 7):  # untracked: a separate call on a fresh copy that has seen both temporal groups
        other = PoseNet(10)
        other.load_state_dict(separate.state_dict())
        singles.append(other(a[g : g + 1], b[g : g + 1]))
    assert torch.allclose(aa, torch.cat([s[0] for s in singles]), atol=1e-6)
    assert torch.allclose(t, torch.cat([s[1] for s in singles]), atol=1e-6)
    for (name, buf), other in zip(batched.named_buffers(), separate.buffers()):
        assert torch.allclose(buf.float(), other.float(), atol=1e-6), name
    with pytest.raises(ValueError, match="8 pairs does not split into groups of sizes \\[3, 3, 1\\]"):
        batched(a, b, groups=[3, 3, 1])


@pytest.mark.parametrize("dtype", [torch.float32, torch.bfloat16])
def test_resnet_max_pool_equals_the_standard_operator_bit_for_bit(dtype):
    # Values rounded to a coarse grid after a ReLU: many ties, where the first maximum must win as in
    # F.max_pool2d; the gradient then flows to the same inputs.
    from posecons.networks import resnet_max_pool

    g = torch.Generator().manual_seed(0)
    x = (torch.relu(torch.randn(3, 5, 14, 22, generator=g)) * 4).round().div(4).to(dtype)
    grad = torch.randn(3, 5, 7, 11, generator=g).to(dtype)
    a, b = x.clone().requires_grad_(), x.clone().requires_grad_()
    out, expected = resnet_max_pool(a), torch.nn.functional.max_pool2d(b, 3, 2, 1)
    out.backward(grad)
    expected.backward(grad)
    assert out.is_contiguous() and torch.equal(out, expected)
    assert torch.equal(a.grad, b.grad)


def test_encoder_pools_as_its_resnet_declares():
    # The encoder's own pooling must be the torchvision ResNet's maxpool module, whatever route it takes.
    enc = ResnetEncoder(10).eval()
    x = torch.rand(2, 3, 64, 96)
    stem = enc.net.relu(enc.net.bn1(enc.net.conv1((x - 0.45) / 0.225)))
    with torch.no_grad():
        assert torch.equal(enc(x)[1], enc.net.layer1(enc.net.maxpool(stem)))


@pytest.mark.parametrize("dtype, atol", [(torch.float32, 1e-7), (torch.bfloat16, 8e-3)])
def test_elu_equals_torch_elu(dtype, atol):
    # e^x − 1 from exp in float32 instead of expm1: equal to float32 rounding near zero (bf16: one of
    # its steps at most), exact for x > 0; the gradient is nn.ELU's kernel on the same result.
    from posecons.networks import ELU

    g = torch.Generator().manual_seed(0)
    x = (torch.randn(2, 4, 9, 13, generator=g) * 3).to(dtype)
    grad = torch.randn(2, 4, 9, 13, generator=g).to(dtype)
    a, b = x.clone().requires_grad_(), x.clone().requires_grad_()
    out, expected = ELU()(a), torch.nn.functional.elu(b)
    out.backward(grad)
    expected.backward(grad)
    assert torch.equal(out[x > 0], x[x > 0]) and out.dtype == dtype
    assert torch.allclose(out.float(), expected.float(), rtol=0, atol=atol)
    assert torch.allclose(a.grad.float(), b.grad.float(), rtol=0, atol=2 * atol)
    assert (out[x < -1] < -0.6).all()  # the negative branch is e^x − 1, not e^x or x
