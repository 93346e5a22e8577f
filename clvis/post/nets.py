"""The post family's networks, in PyTorch (the ``train`` extra): what ``clvis
train`` trains and exports, and the reference the exported ONNX graphs are
compared with (onnxruntime output = torch eager within 1e-4 in fp32).

Inference never imports this module: clvis.post.infer runs the exported
graphs with onnxruntime alone.

Both networks take NCHW float32 whose height and width are multiples of
their ``stride`` (32; clvis.post.pack pads, unpack crops back) and use only
convolutions, pooling, bilinear or nearest up-sampling, concatenation and
element-wise arithmetic, so the exported graphs have dynamic height and width
and no Gather-lowered ops (no ``F.unfold``).

Both start from the classical baseline: :class:`PushPull`, the push-pull
hole fill of clvis.post.pushpull written as graph operations, fills the holes
from the known pixels, and the U-Nets see that estimate beside their input
and add a correction to it (their last convolution starts at zero, so an
untrained network is push-pull, and training can only be judged by what it
adds).

- :class:`InfillWNet` (Dyken, Usher & Kumar 2024, after FoVolNet's W-Net): two
  small U-Nets in sequence with encoder blocks of 4, 8 and 16 channels, a
  32-channel bottleneck and decoder blocks of 16, 8 and 4 (one 3x3
  convolution + ReLU each, average-pool down, nearest up). Input: the partial
  isosurface image as 5 planes (R, G, B, hit, active; clvis.post.pack.pack_iso);
  each U-Net sees the input beside the current estimate. Output: 4 planes
  (R, G, B premultiplied over black, coverage) in which the finished pixels
  keep their input values exactly and the active ones take the network's
  prediction (the blend is part of the graph).
- :class:`RgbdaUNet` (Vanherck, Zoomers et al. 2025): a U-Net of
  conv-BN-ReLU x 2 stages, max-pool down, bilinear up, on the R, G, B, A, D
  planes of the depth-filtered image (their code's conventions:
  clvis.post.pack.pack_rgbda) beside the push-pulled colours; output RGB
  clipped to [0, 1]. The authors' widths are 64..1024 (31 M parameters);
  ``width`` sets the first stage's.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

__all__ = ["InfillWNet", "PushPull", "RgbdaUNet", "build", "count_parameters"]


def _conv(cin: int, cout: int, bn: bool) -> list[nn.Module]:
    layers: list[nn.Module] = [nn.Conv2d(cin, cout, 3, padding=1, bias=not bn)]
    if bn:
        layers.append(nn.BatchNorm2d(cout))
    layers.append(nn.ReLU(inplace=True))
    return layers


class _Block(nn.Sequential):
    """conv 3x3 (+ BN) + ReLU, `convs` times."""

    def __init__(self, cin: int, cout: int, bn: bool, convs: int) -> None:
        layers = _conv(cin, cout, bn)
        for _ in range(convs - 1):
            layers += _conv(cout, cout, bn)
        super().__init__(*layers)


class _UNet(nn.Module):
    """Encoder widths ``enc`` (each block then a 2x2 down-sampling), a
    bottleneck of ``mid`` channels, decoder widths ``dec`` (up-sampling by 2,
    concatenation with the encoder block of the same size, then a block), a
    1x1 convolution to ``cout``. A block is ``convs`` 3x3 convolutions (with
    batch normalisation if ``bn``), each followed by ReLU. ``up``: "nearest"
    or "bilinear"; ``pool``: "max" or "avg"."""

    def __init__(
        self,
        cin: int,
        cout: int,
        enc: tuple[int, ...],
        mid: int,
        dec: tuple[int, ...],
        *,
        bn: bool,
        convs: int,
        up: str,
        pool: str,
    ) -> None:
        super().__init__()
        if len(enc) != len(dec):
            raise ValueError("enc and dec need as many blocks")
        self.up_mode = up
        self.pool = nn.MaxPool2d(2) if pool == "max" else nn.AvgPool2d(2)
        self.enc = nn.ModuleList()
        c = cin
        for w in enc:
            self.enc.append(_Block(c, w, bn, convs))
            c = w
        self.mid = _Block(c, mid, bn, convs)
        self.dec = nn.ModuleList()
        c = mid
        for w, skip in zip(dec, reversed(enc), strict=True):
            self.dec.append(_Block(c + skip, w, bn, convs))
            c = w
        self.out = nn.Conv2d(c, cout, 1)
        self.stride = 2 ** len(enc)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        skips = []
        for block in self.enc:
            x = block(x)
            skips.append(x)
            x = self.pool(x)
        x = self.mid(x)
        for block, skip in zip(self.dec, reversed(skips), strict=True):
            if self.up_mode == "bilinear":
                x = F.interpolate(x, scale_factor=2.0, mode="bilinear", align_corners=False)
            else:
                x = F.interpolate(x, scale_factor=2.0, mode="nearest")
            x = block(torch.cat([x, skip], dim=1))
        return self.out(x)


class PushPull(nn.Module):
    """Push-pull hole fill as graph operations (the classical baseline of
    clvis.post.pushpull, inside the networks): ``levels`` halvings by 2x2
    weighted averages, the coarsest level's holes filled with the weighted
    mean of the whole image, then bilinear 2x up-sampling blended back with
    each level's weight. Height and width must be multiples of
    2 ** ``levels``. Exact 2x operations only, so the exported graph keeps
    dynamic height and width without shape arithmetic. It differs from the
    OpenCL kernel (which halves down to 1 x 1) only in holes wider than
    2 ** ``levels`` pixels."""

    def __init__(self, levels: int) -> None:
        super().__init__()
        self.levels = levels

    def forward(self, colour: torch.Tensor, weight: torch.Tensor) -> torch.Tensor:
        eps = 1e-12
        c, w = colour * weight, weight
        pyramid = []
        for _ in range(self.levels):
            pyramid.append((c, w))
            wsum = F.avg_pool2d(w, 2)
            c = F.avg_pool2d(c * w, 2) / torch.clamp(wsum, min=eps)
            w = torch.clamp(wsum * 4.0, max=1.0)
        total = torch.sum(w, dim=(2, 3), keepdim=True)
        mean = torch.sum(c * w, dim=(2, 3), keepdim=True) / torch.clamp(total, min=eps)
        c = w * c + (1.0 - w) * mean
        for ck, wk in reversed(pyramid):
            e = F.interpolate(c, scale_factor=2.0, mode="bilinear", align_corners=False)
            c = wk * ck + (1.0 - wk) * e
        return c


def _zero_last(unet: _UNet) -> _UNet:
    """Start a residual U-Net at zero correction."""
    nn.init.zeros_(unet.out.weight)
    nn.init.zeros_(unet.out.bias)
    return unet


class InfillWNet(nn.Module):
    """In-fill of a partial isosurface image: 5 planes in (R, G, B, hit,
    active), 4 out (R, G, B, coverage), finished pixels passed through.

    The finished pixels are first push-pulled into the holes (:class:`PushPull`,
    5 levels); each U-Net sees the input beside the current estimate and adds
    a correction to it (its last convolution starts at zero, so an untrained
    network is the push-pull baseline)."""

    channels_in = 5
    channels_out = 4

    def __init__(self, enc: tuple[int, ...] = (4, 8, 16), mid: int = 32, levels: int = 5) -> None:
        super().__init__()
        dec = tuple(reversed(enc))
        kw = {"bn": False, "convs": 1, "up": "nearest", "pool": "avg"}
        self.fill = PushPull(levels)
        self.first = _zero_last(_UNet(5 + 4, 4, enc, mid, dec, **kw))  # type: ignore[arg-type]
        self.second = _zero_last(_UNet(5 + 4, 4, enc, mid, dec, **kw))  # type: ignore[arg-type]
        self.stride = max(self.first.stride, 2**levels)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        known = x[:, 0:4]  # R, G, B, hit: the finished rays' values
        active = x[:, 4:5]
        y = self.fill(known, 1.0 - active)
        y = torch.clamp(y + self.first(torch.cat([x, y], dim=1)), 0.0, 1.0)
        y = torch.clamp(y + self.second(torch.cat([x, y], dim=1)), 0.0, 1.0)
        return known * (1.0 - active) + y * active


class RgbdaUNet(nn.Module):
    """The LiDAR RGBDA U-Net: R, G, B, A, D in, RGB out.

    The kept pixels' colours are first push-pulled into the empty ones
    (:class:`PushPull`, 5 levels); the U-Net sees the five planes beside that
    estimate and adds a correction (its last convolution starts at zero), the
    result clipped to [0, 1]."""

    channels_in = 5
    channels_out = 3

    def __init__(self, width: int = 16, depth: int = 4, levels: int = 5) -> None:
        super().__init__()
        enc = tuple(width * 2**i for i in range(depth))
        self.fill = PushPull(levels)
        self.net = _zero_last(
            _UNet(
                5 + 3,
                3,
                enc,
                width * 2**depth,
                tuple(reversed(enc)),
                bn=True,
                convs=2,
                up="bilinear",
                pool="max",
            )
        )
        self.stride = max(self.net.stride, 2**levels)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        kept = (x[:, 3:4] > 0).to(x.dtype)
        y = self.fill(x[:, 0:3], kept)
        return torch.clamp(y + self.net(torch.cat([x, y], dim=1)), 0.0, 1.0)


def build(name: str, **kwargs: int) -> nn.Module:
    """A network by its shipped name ("infill", "lidar") with its
    architecture arguments (InfillWNet: none; RgbdaUNet: width, depth)."""
    if name == "infill":
        return InfillWNet(**kwargs)  # type: ignore[arg-type]
    if name == "lidar":
        return RgbdaUNet(**kwargs)
    raise ValueError(f"network: expected 'infill' or 'lidar', got {name!r}")


def count_parameters(net: nn.Module) -> int:
    return sum(p.numel() for p in net.parameters())
