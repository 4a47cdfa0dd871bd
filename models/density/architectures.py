"""Density-map networks (PyTorch, training only): the paper's MCNN-like CCNN, our cheaper embedded networks, and one
whose early layers come from a network trained on real photographs (issue 52).

Each maps a normalised RGB image of shape (N, 3, H, W), H and W multiples of 4, to a density map of shape
(N, 1, H/4, W/4) whose cells hold people per cell (its sum is the count). Batch normalisation is used for training
and folded into the convolutions by onnxruntime at load.
"""

from __future__ import annotations

import enum

import torch
from torch import nn

OUTPUT_STRIDE = 4


class Architecture(str, enum.Enum):
    """The networks we train."""

    CCNN = "ccnn"
    """The paper's: three single-layer head columns (9x9, 7x7, 5x5) at full resolution, then a 6-layer backbone."""
    LITE = "lite"
    """Ours: strided stem to stride 4, then depthwise-separable dilated blocks; about 15x fewer operations."""
    LITE_WIDE = "lite-wide"
    """The same design, wider and deeper (64 channels, six blocks, receptive field about 110 px): twice the
    operations of ``lite``, for real ground (issue 32)."""
    YOLOX_LITE = "yolox-lite"
    """YOLOX-nano's stride-4 and stride-8 stages (COCO-trained, ``models/density/pretrained.py``), then ``lite``'s
    separable blocks on both at stride 4 (issue 52: features learned on real photographs)."""
    YOLOX_CONTEXT = "yolox-context"
    """``yolox-lite`` with YOLOX-nano's stride-16 stage as well (its receptive field several times wider): the
    surroundings that tell a person from a person-sized patch of roof or crown (issue 52)."""


def _conv_bn_relu(
    c_in: int, c_out: int, kernel: int, stride: int = 1, dilation: int = 1, groups: int = 1
) -> nn.Sequential:
    padding = dilation * (kernel - 1) // 2
    return nn.Sequential(
        nn.Conv2d(c_in, c_out, kernel, stride=stride, padding=padding, dilation=dilation, groups=groups, bias=False),
        nn.BatchNorm2d(c_out),
        nn.ReLU(inplace=True),
    )


class _Abs(nn.Module):
    """Element-wise absolute value (ONNX ``Abs``)."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.abs(x)


def _density_head(c_in: int) -> nn.Sequential:
    """1x1 conv to one channel, then the absolute value, as the Bayesian Loss authors do.

    A final ReLU died here within a hundred steps (a map negative everywhere passes no gradient); a leaky ReLU let
    negative cells cancel positive ones inside the loss's sums, then vanish at inference. The absolute value always
    passes gradient. It leaves a small positive floor on empty ground, which the export removes with a floor
    fitted on training frames (``models/density/export.py``). The conv starts near zero (an empty map).
    """
    conv = nn.Conv2d(c_in, 1, 1)
    nn.init.normal_(conv.weight, std=0.01)
    assert conv.bias is not None
    nn.init.constant_(conv.bias, 0.01)
    return nn.Sequential(conv, _Abs())


class Ccnn(nn.Module):
    """MCNN-like compact CNN after the paper (9 convolution layers, about 0.07 M parameters).

    Head: three parallel columns of one convolution each, 10 filters 9x9, 14 filters 7x7 and 16 filters 5x5, at
    full resolution, concatenated (40 channels). Backbone: 2x2 max-pool, 3x3 conv 40->64, 2x2 max-pool, 3x3 convs
    64->40->32->16->8, and a 1x1 conv to one channel, made non-negative (see ``_density_head``).
    """

    def __init__(self) -> None:
        super().__init__()
        self.small = _conv_bn_relu(3, 10, 9)
        self.medium = _conv_bn_relu(3, 14, 7)
        self.large = _conv_bn_relu(3, 16, 5)
        self.backbone = nn.Sequential(
            nn.MaxPool2d(2),
            _conv_bn_relu(40, 64, 3),
            nn.MaxPool2d(2),
            _conv_bn_relu(64, 40, 3),
            _conv_bn_relu(40, 32, 3),
            _conv_bn_relu(32, 16, 3),
            _conv_bn_relu(16, 8, 3),
            _density_head(8),
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(N, 3, H, W) -> (N, 1, H/4, W/4)."""
        return self.backbone(torch.cat([self.small(x), self.medium(x), self.large(x)], dim=1))


class _SeparableBlock(nn.Module):
    """Depthwise 3x3 (dilated) then pointwise 1x1, with a residual connection when the width is kept."""

    def __init__(self, c_in: int, c_out: int, dilation: int) -> None:
        super().__init__()
        self.depthwise = _conv_bn_relu(c_in, c_in, 3, dilation=dilation, groups=c_in)
        self.pointwise = _conv_bn_relu(c_in, c_out, 1)
        self.residual = c_in == c_out

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = self.pointwise(self.depthwise(x))
        return x + y if self.residual else y


class Lite(nn.Module):
    """Our embedded network, same output contract at about a fifteenth of the operations.

    A stride-2 3x3 stem (16 channels) and a stride-2 3x3 conv (32), then depthwise-separable blocks at stride 4
    with dilations 1, 2, 3, 1 (48, 48, 48, 32 channels; receptive field about 60 px), a 1x1 head, made
    non-negative (see ``_density_head``).
    """

    BLOCKS: tuple[tuple[int, int, int], ...] = ((32, 48, 1), (48, 48, 2), (48, 48, 3), (48, 32, 1))
    """The separable blocks after the stem: (input channels, output channels, dilation); the last gives 32."""

    def __init__(self) -> None:
        super().__init__()
        self.body = nn.Sequential(
            _conv_bn_relu(3, 16, 3, stride=2),
            _conv_bn_relu(16, 32, 3, stride=2),
            *(_SeparableBlock(c_in, c_out, dilation) for c_in, c_out, dilation in self.BLOCKS),
            _density_head(32),
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(N, 3, H, W) -> (N, 1, H/4, W/4)."""
        return self.body(x)


class LiteWide(Lite):
    """``Lite`` widened and deepened: the same stem, then depthwise-separable blocks at stride 4 with dilations
    1, 2, 3, 4, 2, 1 (64 channels, then 32), a 1x1 head made non-negative. More context (about 110 px) to tell a
    person from a bush, a pipe or a patch of gravel of the same size."""

    BLOCKS = ((32, 64, 1), (64, 64, 2), (64, 64, 3), (64, 64, 4), (64, 64, 2), (64, 32, 1))


class YoloxLite(nn.Module):
    """Pretrained early layers, a density head of our own.

    YOLOX-nano's stages up to stride 8 (``dark2``: 32 channels at stride 4; ``dark3``: 64 at stride 8, upsampled by
    2) are concatenated (96 channels), reduced by a 1x1 conv to 48, then depthwise-separable blocks at stride 4 with
    dilations 1, 2, 3, 1 (48, 48, 48, 32 channels) and a 1x1 head made non-negative (see ``_density_head``). The
    pretrained part is ``self.backbone`` (train it with a lower learning rate, or freeze it: ``train.py
    --backbone-lr-scale``). H and W must be multiples of 8. With ``context`` (``yolox-context``) the stride-16 stage
    (``dark4``, 128 channels, upsampled by 4) joins the concatenation (224 channels); H and W multiples of 16.
    """

    BLOCKS = ((48, 48, 1), (48, 48, 2), (48, 48, 3), (48, 32, 1))

    def __init__(self, context: bool = False) -> None:
        super().__init__()
        from models.density.preprocess import MEAN, STD
        from models.density.pretrained import YOLOX_NANO, YOLOX_NANO_CONTEXT, PretrainedStages

        spec = YOLOX_NANO_CONTEXT if context else YOLOX_NANO
        self.backbone = PretrainedStages(spec, MEAN, STD)
        self.reduce = _conv_bn_relu(sum(spec.channels), 48, 1)
        self.head = nn.Sequential(
            *(_SeparableBlock(c_in, c_out, dilation) for c_in, c_out, dilation in self.BLOCKS),
            _density_head(32),
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(N, 3, H, W) -> (N, 1, H/4, W/4)."""
        stride4, *coarser = self.backbone(x)
        strides = self.backbone.spec.strides
        up = []
        for c, stride in zip(coarser, strides[1:], strict=True):
            factor = stride // strides[0]
            if tuple(stride4.shape[-2:]) == (factor * c.shape[-2], factor * c.shape[-1]):
                # By a constant factor where the sides divide (always at export): the ONNX Resize then runs at any
                # input size, so a shrunk frame runs cropped (models.density.receptive_field.input_extent_px).
                up.append(nn.functional.interpolate(c, scale_factor=float(factor), mode="nearest"))
            else:  # sides that do not divide (a whole validation frame): to stride4's size, as before
                up.append(nn.functional.interpolate(c, size=stride4.shape[-2:], mode="nearest"))
        return self.head(self.reduce(torch.cat([stride4, *up], dim=1)))


def build(architecture: Architecture) -> nn.Module:
    """A freshly initialised network (the pretrained part of ``yolox-lite`` from its graph)."""
    if architecture is Architecture.CCNN:
        return Ccnn()
    if architecture in (Architecture.YOLOX_LITE, Architecture.YOLOX_CONTEXT):
        return YoloxLite(context=architecture is Architecture.YOLOX_CONTEXT)
    return LiteWide() if architecture is Architecture.LITE_WIDE else Lite()


def parameter_count(model: nn.Module) -> int:
    """Trainable parameters."""
    return sum(p.numel() for p in model.parameters() if p.requires_grad)
