"""Depth and pose networks (SPEC §2): torchvision ResNet encoders, a U-Net depth decoder
with four sigmoid disparity scales, and a small pose decoder.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import NamedTuple
from urllib.error import URLError

import torch
import torch.nn as nn
import torch.nn.functional as F
import torchvision.models as tvm

from .errors import PoseconsError
from .geometry import check_tensor

# num_layers → (torchvision constructor, ImageNet weights enum); 10 is a small demo encoder
# (one basic block per stage) that has no published ImageNet weights.
_RESNETS = {
    10: (lambda **kw: tvm.resnet.ResNet(tvm.resnet.BasicBlock, [1, 1, 1, 1], **kw), None),
    18: (tvm.resnet18, tvm.ResNet18_Weights.IMAGENET1K_V1),
    34: (tvm.resnet34, tvm.ResNet34_Weights.IMAGENET1K_V1),
    50: (tvm.resnet50, tvm.ResNet50_Weights.IMAGENET1K_V1),
}


def load_imagenet_state(num_layers: int, pretrained: bool | str) -> dict | None:
    """ImageNet weights for a ResNet, through torchvision's download cache.

    ``pretrained``: True (required: raise if unavailable), False, or "auto" (warn and train
    from scratch when the weights cannot be had, e.g. offline).
    """
    if pretrained is False:
        return None
    weights = _RESNETS[num_layers][1]
    try:
        if weights is None:
            raise LookupError(f"no ImageNet weights exist for the ResNet-{num_layers} demo encoder")
        return weights.get_state_dict(progress=False, check_hash=True)
    except (URLError, OSError, RuntimeError, LookupError) as exc:
        message = (
            f"ImageNet weights for ResNet-{num_layers} are not available ({exc}). "
            "With internet access torchvision downloads them into $TORCH_HOME/hub/checkpoints; "
            "offline, copy the file there, or train from scratch on purpose with "
            "--set model.pretrained=false."
        )
        if pretrained is True:
            raise PoseconsError(message) from exc
        warnings.warn(message + " Training from scratch.", stacklevel=2)
        return None


def imagenet_weights_name(num_layers: int) -> str:
    """torchvision's name of the ImageNet weights of a ResNet, e.g. ``ResNet18_Weights.IMAGENET1K_V1``."""
    weights = _RESNETS[num_layers][1]
    return f"torchvision {type(weights).__name__}.{weights.name}" if weights is not None else "none"


class BatchGroups(NamedTuple):
    """How a training batch of the pose net splits into groups for :class:`GroupedBatchNorm2d`."""

    sizes: tuple[int, ...]  # of the consecutive groups, summing to the batch
    tracked: int  # the first groups, which update the running statistics


class GroupedBatchNorm2d(nn.BatchNorm2d):
    """BatchNorm2d that, in training, normalises each group of consecutive samples (``groups.sizes``)
    on its own and lets only the first ``groups.tracked`` update the running statistics, one after the
    other — what separate calls per group would do, in one pass of the surrounding network.

    The pose net sees every pair of a step in one batch (temporal pairs first, then the
    constraints' reversed, identity and skip pairs): grouping keeps the constraint pairs from
    changing the warping poses, and tracking only the temporal pairs keeps them out of the
    statistics used at evaluation. Groups may differ in size. In eval mode, or without ``groups``
    (or with one group), it is a plain BatchNorm2d.
    """

    def forward(self, x: torch.Tensor, groups: BatchGroups | None = None) -> torch.Tensor:
        if not self.training or groups is None or len(groups.sizes) <= 1:
            return super().forward(x)
        out = []
        for i, chunk in enumerate(x.split(groups.sizes)):
            track = i < groups.tracked
            out.append(
                F.batch_norm(
                    chunk,
                    self.running_mean if track else None,
                    self.running_var if track else None,
                    self.weight,
                    self.bias,
                    True,
                    self.momentum,
                    self.eps,
                )
            )
        self.num_batches_tracked.add_(groups.tracked)
        return torch.cat(out)


def _grouped_block(block: nn.Module, x: torch.Tensor, groups: BatchGroups | None) -> torch.Tensor:
    """torchvision's BasicBlock / Bottleneck forward, the same ops in the same order, with ``groups``
    given to each of its GroupedBatchNorm2d layers."""
    out = block.relu(block.bn1(block.conv1(x), groups))
    out = block.bn2(block.conv2(out), groups)
    if isinstance(block, tvm.resnet.Bottleneck):
        out = block.bn3(block.conv3(block.relu(out)), groups)
    identity = x if block.downsample is None else block.downsample[1](block.downsample[0](x), groups)
    out += identity
    return block.relu(out)


class GroupedLayer(nn.Sequential):
    """A ResNet stage (the same blocks and keys) that passes the batch's groups on to its blocks."""

    def forward(self, x: torch.Tensor, groups: BatchGroups | None = None) -> torch.Tensor:
        for block in self:
            x = _grouped_block(block, x, groups)
        return x


def _exporting() -> bool:
    return torch.jit.is_tracing() or torch.onnx.is_in_onnx_export()


class _ChannelsLastMaxPool(torch.autograd.Function):
    """ResNet's 3×3, stride-2, padding-1 max pooling, equal bit for bit to ``F.max_pool2d`` (the same
    maxima, the same first-maximum indices, the same backward kernel), but pooled in the channels-last
    layout. PyTorch's CPU kernel for contiguous NCHW tensors is not vectorised over channels: on the
    development CPU it took about a tenth of a study-setting step, the layout copy and the
    channels-last kernel together about a third of that (docs/performance.md)."""

    @staticmethod
    def forward(ctx, x: torch.Tensor) -> torch.Tensor:
        out, indices = F.max_pool2d(x.contiguous(memory_format=torch.channels_last), 3, 2, 1, return_indices=True)
        ctx.save_for_backward(x, indices)
        return out.contiguous()

    @staticmethod
    def backward(ctx, grad: torch.Tensor) -> torch.Tensor:
        x, indices = ctx.saved_tensors
        pool = ([3, 3], [2, 2], [1, 1], [1, 1], False)  # kernel, stride, padding, dilation, ceil_mode
        return torch.ops.aten.max_pool2d_with_indices_backward(grad.contiguous(), x, *pool, indices.contiguous())


def resnet_max_pool(x: torch.Tensor) -> torch.Tensor:
    """The encoder's max pooling: through the channels-last layout on the CPU, the plain operator
    elsewhere and while exporting (ONNX and tracing see the standard operator)."""
    if x.device.type != "cpu" or _exporting():
        return F.max_pool2d(x, 3, 2, 1)
    return _ChannelsLastMaxPool.apply(x)


class ResnetEncoder(nn.Module):
    """ResNet features at 1/2, 1/4, 1/8, 1/16, 1/32 of the input.

    ``imagenet``: the ResNet's ImageNet state dict (:func:`load_imagenet_state`) or None for a
    random initialisation. ``num_input_images=2`` widens conv1 to a 6-channel frame pair (the pose
    encoder); ImageNet conv1 weights are then tiled over both images and halved, so a pair of
    equal images gives the pretrained response. ``grouped``: GroupedBatchNorm2d layers and stages
    that take the batch's :class:`BatchGroups` (the pose encoder; the same keys).
    """

    def __init__(
        self,
        num_layers: int = 18,
        imagenet: dict | None = None,
        num_input_images: int = 1,
        grouped: bool = False,
    ):
        super().__init__()
        if num_layers not in _RESNETS:
            raise PoseconsError(f"num_layers must be one of {sorted(_RESNETS)}, got {num_layers}")
        self.net = _RESNETS[num_layers][0](norm_layer=GroupedBatchNorm2d if grouped else nn.BatchNorm2d)
        for name in ("layer1", "layer2", "layer3", "layer4") if grouped else ():
            setattr(self.net, name, GroupedLayer(*getattr(self.net, name)))
        self.num_input_images = num_input_images
        state = None if imagenet is None else dict(imagenet)  # the caller's dict stays as it was
        if num_input_images > 1:
            self.net.conv1 = nn.Conv2d(3 * num_input_images, 64, kernel_size=7, stride=2, padding=3, bias=False)
            if state is not None:
                state["conv1.weight"] = state["conv1.weight"].repeat(1, num_input_images, 1, 1) / num_input_images
        if state is not None:
            self.net.load_state_dict(state)
        del self.net.fc, self.net.avgpool  # classification head unused
        expansion = 4 if num_layers >= 50 else 1
        self.num_ch_enc = [64] + [c * expansion for c in (64, 128, 256, 512)]

    def forward(self, images: torch.Tensor, groups: BatchGroups | None = None) -> list[torch.Tensor]:
        """images (B, 3·n, H, W) in [0, 1], H and W multiples of 32 → five feature maps; ``groups``
        (a ``grouped`` encoder only) reach every BatchNorm layer."""
        check_tensor("images", images, (None, 3 * self.num_input_images, None, None))
        h, w = images.shape[-2:]
        if h % 32 or w % 32:
            raise PoseconsError(
                f"image size {h}×{w} is not a multiple of 32: resize to e.g. "
                f"{max(32, round(h / 32) * 32)}×{max(32, round(w / 32) * 32)} (height×width)"
            )
        n = self.net
        grouping = () if groups is None else (groups,)  # a plain BatchNorm2d takes no groups
        x = n.relu(n.bn1(n.conv1((images - 0.45) / 0.225), *grouping))
        feats = [x]
        x = n.layer1(resnet_max_pool(x), *grouping)  # n.maxpool's 3×3, stride 2, padding 1
        feats.append(x)
        for layer in (n.layer2, n.layer3, n.layer4):
            x = layer(x, *grouping)
            feats.append(x)
        return feats


def fp32_output(layer: nn.Module, x: torch.Tensor) -> torch.Tensor:
    """Run a network's output layer in float32 even under autocast, so that disparities and the
    pose 6-vector leave the networks in full precision (the geometry after them is fp32)."""
    with torch.autocast(x.device.type, enabled=False):
        return layer(x.float())


class _ELUFunction(torch.autograd.Function):
    @staticmethod
    def forward(ctx, x: torch.Tensor) -> torch.Tensor:
        out = torch.where(x > 0, x, torch.exp(x.float()).sub_(1).to(x.dtype))
        ctx.save_for_backward(out)
        return out

    @staticmethod
    def backward(ctx, grad: torch.Tensor) -> torch.Tensor:
        (out,) = ctx.saved_tensors
        return torch.ops.aten.elu_backward(grad, 1.0, 1, 1, True, out)  # α, scale, input scale, from the result


class ELU(nn.Module):
    """ELU (α = 1) whose e^x − 1 is ``exp`` in float32 minus one on the CPU: PyTorch's CPU ``expm1``, which
    ``nn.ELU`` uses, is not vectorised and took 30× as long as ``exp`` on the development CPU (43 against
    1.4 ms for 1.6 M values), the decoder's largest element-wise cost. Equal to ``nn.ELU`` to float32
    rounding of e^x near 1 (6e-8); the backward is ``nn.ELU``'s own kernel. GPUs and export use ``F.elu``."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if x.device.type != "cpu" or _exporting():
            return F.elu(x, inplace=True)
        return _ELUFunction.apply(x)


class Conv3x3(nn.Sequential):
    """Reflection-padded 3×3 convolution, optionally followed by ELU."""

    def __init__(self, cin: int, cout: int, elu: bool = True):
        super().__init__(nn.ReflectionPad2d(1), nn.Conv2d(cin, cout, 3), *([ELU()] if elu else []))


class DepthDecoder(nn.Module):
    """U-Net decoder: returns disparity logits ``{s: (B, 1, H/2^s, W/2^s)}`` for each scale (fp32)."""

    def __init__(self, num_ch_enc: list[int], scales: tuple[int, ...] = (0, 1, 2, 3)):
        super().__init__()
        self.scales = tuple(scales)
        ch = [16, 32, 64, 128, 256]
        self.up_in = nn.ModuleList()
        self.up_out = nn.ModuleList()
        for i in range(5):
            cin = num_ch_enc[4] if i == 4 else ch[i + 1]
            self.up_in.append(Conv3x3(cin, ch[i]))
            self.up_out.append(Conv3x3(ch[i] + (num_ch_enc[i - 1] if i > 0 else 0), ch[i]))
        self.disp_convs = nn.ModuleDict({str(s): Conv3x3(ch[s], 1, elu=False) for s in self.scales})

    def forward(self, feats: list[torch.Tensor]) -> dict[int, torch.Tensor]:
        out = {}
        x = feats[4]
        for i in range(4, -1, -1):
            x = F.interpolate(self.up_in[i](x), scale_factor=2, mode="nearest")
            if i > 0:
                x = torch.cat([x, feats[i - 1]], 1)
            x = self.up_out[i](x)
            if i in self.scales:
                out[i] = fp32_output(self.disp_convs[str(i)], x)
        return out


class PoseDecoder(nn.Module):
    """Deepest pose-encoder feature → (axis-angle (B, 1, 3), translation (B, 1, 3)), scaled by
    ``rotation_scale`` and 0.01 (Monodepth2: 0.01 both)."""

    def __init__(self, num_ch_in: int, rotation_scale: float = 0.01):
        super().__init__()
        self.rotation_scale = rotation_scale
        self.net = nn.Sequential(
            nn.Conv2d(num_ch_in, 256, 1),
            nn.ReLU(inplace=True),
            nn.Conv2d(256, 256, 3, padding=1),
            nn.ReLU(inplace=True),
            nn.Conv2d(256, 256, 3, padding=1),
            nn.ReLU(inplace=True),
            nn.Conv2d(256, 6, 1),
        )

    def forward(self, feature: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        out = fp32_output(self.net[-1], self.net[:-1](feature)).mean((2, 3)).view(-1, 1, 6)
        return self.rotation_scale * out[..., :3], 0.01 * out[..., 3:]


class DepthNet(nn.Module):
    """One RGB frame (B, 3, H, W) → sigmoid disparities per scale, or their logits (``logits=True``)."""

    def __init__(self, num_layers: int = 18, imagenet: dict | None = None, scales=(0, 1, 2, 3)):
        super().__init__()
        self.encoder = ResnetEncoder(num_layers, imagenet)
        self.decoder = DepthDecoder(self.encoder.num_ch_enc, scales)

    def forward(self, images: torch.Tensor, logits: bool = False) -> dict[int, torch.Tensor]:
        out = self.decoder(self.encoder(images))
        return out if logits else {s: torch.sigmoid(x) for s, x in out.items()}


# (axis-angle, translation) sign changes of a motion seen in the mirror image (x ↦ −x).
MIRROR_SIGN = torch.tensor([[1.0, -1.0, -1.0], [-1.0, 1.0, 1.0]])


class PoseNet(nn.Module):
    """Ordered frame pair (a, b), each (B, 3, H, W) → T_{b←a} as (axis-angle, translation)."""

    def __init__(
        self, num_layers: int = 18, imagenet: dict | None = None, mirror: bool = False, rotation_scale: float = 0.01
    ):
        super().__init__()
        self.encoder = ResnetEncoder(num_layers, imagenet, num_input_images=2, grouped=True)
        self.mirror = mirror
        self.decoder = PoseDecoder(self.encoder.num_ch_enc[-1], rotation_scale)

    def forward(
        self,
        image_a: torch.Tensor,
        image_b: torch.Tensor,
        groups: int | Sequence[int] = 1,
        tracked: int | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """In training, each group of the batch gets its own BatchNorm statistics and the first
        ``tracked`` (default all) update the running ones (see GroupedBatchNorm2d). ``groups``:
        a number of equal groups, or the sizes of consecutive groups."""
        n = image_a.shape[0]
        if isinstance(groups, int):
            if n % groups:
                raise ValueError(f"batch of {n} pairs does not split into {groups} equal groups")
            groups = [n // groups] * groups
        if sum(groups) != n or min(groups) < 1:
            raise ValueError(f"batch of {n} pairs does not split into groups of sizes {list(groups)}")
        pairs = torch.cat([image_a, image_b], 1)
        if self.mirror:  # each group followed by its mirror image, so that it shares the group's statistics
            pairs = torch.cat([torch.cat([g, g.flip(-1)]) for g in pairs.split(list(groups))])
            groups = [2 * g for g in groups]
        batch = BatchGroups(tuple(groups), len(groups) if tracked is None else tracked)
        axisangle, translation = self.decoder(self.encoder(pairs, batch)[-1])
        if not self.mirror:
            return axisangle, translation
        # The mirror image of a motion (x ↦ −x) has t_x, and the axis-angle's y and z, negated: averaging
        # each pair's pose with its mirror's mirrored pose makes the estimate exactly mirror-equivariant.
        sign = MIRROR_SIGN.to(pairs.device)

        def average(out: torch.Tensor, sign: torch.Tensor) -> torch.Tensor:
            direct, mirrored = zip(*(g.chunk(2) for g in out.split(groups)))
            return (torch.cat(direct) + sign * torch.cat(mirrored)) / 2

        return average(axisangle, sign[0]), average(translation, sign[1])
