"""The post family's networks, in PyTorch (the ``train`` extra): what ``clvis
train`` trains and exports, and the reference the exported ONNX graphs are
compared with (onnxruntime output = torch eager within 1e-4 in fp32).

Inference never imports this module: clvis.post.infer runs the exported
graphs with onnxruntime alone.

The three networks take NCHW float32 whose height and width are multiples
of their ``stride`` (32 for in-fill and LiDAR, 16 for NARVis; clvis.post.pack
pads, unpack crops back) and use only
convolutions, pooling, bilinear or nearest up-sampling, concatenation and
element-wise arithmetic, so the exported graphs have dynamic height and width
and no Gather-lowered ops (no ``F.unfold``).

In-fill and LiDAR start from the classical baseline: :class:`PushPull`, the push-pull
hole fill of clvis.post.pushpull written as graph operations, fills the holes
from the known pixels, and the U-Nets see that estimate beside their input
and add a correction to it (their last convolution starts at zero, so an
untrained network is push-pull, and training can only be judged by what it
adds).

- :class:`InfillWNet` (Dyken, Usher & Kumar 2024, after FoVolNet's W-Net): two
  small U-Nets in sequence with encoder blocks of 4, 8 and 16 channels, a
  32-channel bottleneck and decoder blocks of 16, 8 and 4 (one 3x3
  convolution + ReLU each, average-pool down, nearest up). Input: the partial
  isosurface image as 5 planes (R, G, B, hit, active; clvis.post.pack.pack_iso;
  with ``candidates=True`` a sixth, the candidate blocks left on each running ray);
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
- :class:`NarvisUNet` (NARVis, after NPBG's gated U-Net): the rasterizer's
  G-buffer planes (clvis.post.pack.pack_gbuffers) to RGB, with gated
  convolutions (:class:`GatedConv2d`) at five resolutions; no push-pull
  estimate (its input is dense where points were drawn).
"""

from __future__ import annotations

import math
from typing import Any

import torch
import torch.nn.functional as F
from torch import nn

from .names import GBUFFER_PLANES, gbuffer_channels

__all__ = [
    "GBUFFER_PLANES",
    "GatedConv2d",
    "InfillWNet",
    "KPNTrunk",
    "NarvisKPN",
    "NarvisUNet",
    "PushPull",
    "RgbdaUNet",
    "build",
    "count_parameters",
    "gbuffer_channels",
    "onehot_unfold",
    "shifted",
]


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
    active; ``candidates=True``: 6, + the candidate blocks left on each
    running ray, clvis.post.pack.pack_iso's CANDIDATES; ``prior=True``: 7,
    + its HIT_PRIOR, from the frame's crossing rate; ``depth=True``: 8, the
    candidates plane + pack_iso's DEPTH and NEXT, the finished hits' t and
    the running rays' next candidate t on one scale), 4 out (R, G, B,
    coverage), finished pixels passed through.

    The finished pixels are first push-pulled into the holes (:class:`PushPull`,
    5 levels); each U-Net sees the input beside the current estimate and adds
    a correction to it (its last convolution starts at zero, so an untrained
    network is the push-pull baseline). With ``depth`` the U-Nets also see the
    gap: at each running ray with a block left, NEXT minus the finished hits'
    DEPTH push-pulled to it (where the ray's next chance to hit lies against
    the surface its neighbours show: bench/infill_depth_cue.py)."""

    channels_out = 4

    def __init__(
        self,
        enc: tuple[int, ...] = (4, 8, 16),
        mid: int = 32,
        levels: int = 5,
        candidates: bool = False,
        prior: bool = False,
        depth: bool = False,
    ) -> None:
        super().__init__()
        if prior and not candidates:
            raise ValueError("prior: the hit-prior plane comes after the candidates plane (candidates=True)")
        if depth and (prior or not candidates):
            raise ValueError("depth: the two depth planes come after the candidates plane, without the prior")
        self.depth = depth
        self.channels_in = 8 if depth else 7 if prior else 6 if candidates else 5
        # depth: the U-Nets also see the gap, computed here: the running rays'
        # next candidate t minus the finished hits' t push-pulled to them
        unet_in = self.channels_in + 4 + int(depth)
        dec = tuple(reversed(enc))
        kw = {"bn": False, "convs": 1, "up": "nearest", "pool": "avg"}
        self.fill = PushPull(levels)
        self.first = _zero_last(_UNet(unet_in, 4, enc, mid, dec, **kw))  # type: ignore[arg-type]
        self.second = _zero_last(_UNet(unet_in, 4, enc, mid, dec, **kw))  # type: ignore[arg-type]
        self.stride = max(self.first.stride, 2**levels)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        known = x[:, 0:4]  # R, G, B, hit: the finished rays' values
        active = x[:, 4:5]
        if self.depth:
            hit = x[:, 3:4]
            near = self.fill(x[:, 6:7], hit)  # the finished hits' depth, spread
            has_next = (x[:, 5:6] > 0.0).to(x.dtype)
            x = torch.cat([x, has_next * (x[:, 7:8] - near)], dim=1)
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


class GatedConv2d(nn.Module):
    """Gated convolution (Yu et al. 2019): two k x k convolutions of the same
    input, a feature map and a gate, ``ELU(features) * sigmoid(gate)``. The
    gate lets the network learn per pixel and channel how much of a feature to
    pass, which is what sparse inputs (empty pixels between points) need."""

    def __init__(self, cin: int, cout: int, k: int = 3) -> None:
        super().__init__()
        self.features = nn.Conv2d(cin, cout, k, padding=k // 2)
        self.gate = nn.Conv2d(cin, cout, k, padding=k // 2)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return F.elu(self.features(x)) * torch.sigmoid(self.gate(x))


class NarvisUNet(nn.Module):
    """NARVis's gated U-Net (Han et al., after NPBG's): G-buffer planes in,
    RGB out (premultiplied over black, clipped to [0, 1]).

    - ``planes`` picks the G-buffers by name (:func:`gbuffer_channels` gives
      the layout; R, G, B and the coverage always come first). They are
      normalised in the graph: the depth to [0, 1] over the covered pixels'
      range (nearest 1, empty 0); the screen velocity and its length divided
      by the covered pixels' mean length, its angle by pi; the splat radius
      in pixels (``radius_px``) as log2(1 + r) / 4, absolute (1 at 15
      pixels: the network must know how far a point's Gaussian reaches, not
      only how it compares with the frame's others); any other plane (an
      attribute) to [0, 1] over its covered range.
    - A 1x1 convolution (channels kept) and four 2x2 average poolings give
      the planes at 5 resolutions; each is concatenated to the input of the
      encoder's first block at its resolution.
    - Encoder: a gated 3x3 convolution (ELU) at each of the 5 resolutions
      (NPBG's gated block), 2x2 average pooling between them (4
      down-sampling stages); widths ``widths`` (NPBG's 16..256 by default;
      the paper's text says 64..1024).
    - Decoder: up-sampling by 2 (``up``: "bilinear", NPBG's, or
      "transposed": a 2x2 transposed convolution, the paper's text), the
      encoder's output of the same size concatenated (skip), a gated 3x3
      convolution; then a 1x1 convolution to RGB.

    Height and width must be multiples of 16 (``stride``)."""

    channels_out = 3

    def __init__(
        self,
        planes: tuple[str, ...] = ("rgb", "depth", "vel2d"),
        widths: tuple[int, ...] = (16, 32, 64, 128, 256),
        up: str = "bilinear",
    ) -> None:
        super().__init__()
        if len(widths) != 5:
            raise ValueError(f"widths: expected 5 (one per resolution), got {len(widths)}")
        if up not in ("bilinear", "transposed"):
            raise ValueError(f"up: expected 'bilinear' or 'transposed', got {up!r}")
        self.planes = tuple(planes)
        self.layout = gbuffer_channels(self.planes)
        self.channels_in = c = len(self.layout)
        self.widths, self.up_mode = tuple(int(w) for w in widths), up
        self.inject = nn.Conv2d(c, c, 1)
        self.enc = nn.ModuleList()
        prev = 0
        for w in self.widths:
            self.enc.append(GatedConv2d(prev + c, w))
            prev = w
        self.ups = nn.ModuleList()
        self.dec = nn.ModuleList()
        for w_low, w in zip(reversed(self.widths[1:]), reversed(self.widths[:-1]), strict=True):
            self.ups.append(
                nn.ConvTranspose2d(w_low, w_low, 2, stride=2) if up == "transposed" else nn.Identity()
            )
            self.dec.append(GatedConv2d(w_low + w, w))
        self.out = nn.Conv2d(self.widths[0], 3, 1)
        self.stride = 16

    def normalise(self, x: torch.Tensor) -> torch.Tensor:
        """The planes as the network sees them (see the class doc)."""
        cov = x[:, 3:4]
        n = torch.clamp(torch.sum(cov, dim=(2, 3), keepdim=True), min=1.0)
        big = 3.0e38

        def unit(p: torch.Tensor) -> torch.Tensor:  # [0, 1] over the covered range
            lo = torch.amin(p * cov + (1.0 - cov) * big, dim=(2, 3), keepdim=True)
            hi = torch.amax(p * cov - (1.0 - cov) * big, dim=(2, 3), keepdim=True)
            return cov * (p - lo) / torch.clamp(hi - lo, min=1e-20)

        parts = [x[:, :4]]
        i = 4
        while i < self.channels_in:
            name = self.layout[i]
            if name == "depth":
                parts.append(cov * (1.0 - unit(x[:, i : i + 1])))
                i += 1
            elif name == "vel_x":
                v = x[:, i : i + 4]
                s = n / torch.clamp(torch.sum(v[:, 3:4] * cov, dim=(2, 3), keepdim=True), min=1e-20)
                parts += [v[:, 0:2] * s, v[:, 2:3] * (1.0 / math.pi), v[:, 3:4] * s]
                i += 4
            elif name == "radius_px":
                r = torch.clamp(x[:, i : i + 1], min=0.0)
                parts.append(cov * torch.log1p(r) * (0.25 / math.log(2.0)))
                i += 1
            else:
                parts.append(unit(x[:, i : i + 1]))
                i += 1
        return torch.cat(parts, dim=1)

    def features(self, x: torch.Tensor) -> torch.Tensor:
        """The decoder's last features (N, widths[0], H, W), before the 1x1 output."""
        return self._features(self.normalise(x))

    def _features(self, nx: torch.Tensor) -> torch.Tensor:
        """features() of the normalised planes `nx`."""
        g = self.inject(nx)
        skips: list[torch.Tensor] = []
        h = torch.zeros(0)
        for i, block in enumerate(self.enc):
            if i:
                g = F.avg_pool2d(g, 2)
                h = block(torch.cat([F.avg_pool2d(h, 2), g], dim=1))
            else:
                h = block(g)
            skips.append(h)
        for up, block, skip in zip(self.ups, self.dec, reversed(skips[:-1]), strict=True):
            if self.up_mode == "bilinear":
                h = F.interpolate(h, scale_factor=2.0, mode="bilinear", align_corners=False)
            else:
                h = up(h)
            h = block(torch.cat([h, skip], dim=1))
        return h

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.clamp(self.out(self.features(x)), 0.0, 1.0)


def onehot_unfold(k: int) -> torch.Tensor:
    """The fixed weights (k*k, 1, k, k) of a convolution that unfolds a
    plane's k x k neighbourhood into k*k channels: channel dy * k + dx is the
    pixel at offset (dy - k // 2, dx - k // 2) (zero beyond the border).
    ``F.unfold`` written as a convolution, so it exports to plain ONNX Conv."""
    w = torch.zeros(k * k, 1, k, k)
    for j in range(k * k):
        w[j, 0, j // k, j % k] = 1.0
    return w


def shifted(p: torch.Tensor, k: int, s: int = 1) -> torch.Tensor:
    """(N, k*k, H, W): the plane `p` (N, 1, H, W) shifted so that channel
    j = dy * k + dx holds the pixel at offset ((dy - k // 2) * s,
    (dx - k // 2) * s) (zero beyond the border): the k x k neighbourhood at
    spacing s, as one padding (a 1 x 1 convolution by 1 with pads) and k*k
    Slices with constant bounds (no shape arithmetic, no Gather; for s = 1
    the channels of a convolution with :func:`onehot_unfold`, without its
    k**4 multiply-adds a pixel)."""
    r = (k // 2) * s
    # zero padding as a 1 x 1 identity convolution with pads (F.pad exports shape arithmetic)
    pp = F.conv2d(p, torch.ones(1, 1, 1, 1, dtype=p.dtype, device=p.device), padding=r)
    outs = []
    for dy in range(k):
        for dx in range(k):
            y0, x0 = dy * s, dx * s
            y1, x1 = y0 - 2 * r, x0 - 2 * r  # <= 0: counted from the end
            outs.append(pp[:, :, y0 : (y1 or None), x0 : (x1 or None)])
    return torch.cat(outs, dim=1)


class NarvisKPN(NarvisUNet):
    """NARVis by per-pixel kernel prediction: the gated U-Net of
    :class:`NarvisUNet` predicts, per output pixel, softmax weights over the
    INPUT colours of a neighbourhood at a few pyramid scales and one
    background (black) weight, so the output is a convex combination of input
    colours and black: a colour that is not in the input cannot appear, and
    a transfer function never seen in training comes through as it is drawn.

    - ``kernels``: (k, s) pairs: a k x k neighbourhood of the colours
      averaged over s x s blocks (s a power of two, 1: the pixels
      themselves), the candidates of each output pixel those around its
      block. A block's colour is the mean of its covered pixels; a
      candidate with no covered pixel is masked out of the softmax.
    - Candidates are gathered by :func:`shifted` (Pad and constant Slices)
      of the block planes, up-sampled (nearest, 2**j) before the shift, so
      the graph is Conv, AveragePool, Resize, Pad, Slice and element-wise
      arithmetic (no Gather).
    - ``depth_select``: each candidate's (bounded) logit also gets
      ``gamma`` x its nearness less that of the pixel's nearest candidate
      (<= 0; the nearness is NarvisUNet.normalise's depth, 1 nearest; a
      block's: the mean of its covered pixels'), gamma >= 0 predicted per
      pixel (softplus of one more output channel, x ``depth_scale``). One
      pixel per point lets far points show between near ones where the
      Gaussian renderer's near splats cover them; this gives the network
      the visibility test as a single number a pixel to learn (on a
      hurricane view, the nearest of each 3 x 3 alone scores 25 dB against
      the Gaussian renderer where their mean scores 19).
    - The head's last 1x1 convolution starts at zero weights with a bias of
      ``prior`` on the finest scale's candidates: an untrained network is a
      box filter of the covered pixels around each one (a splat; with
      ``depth_select``, the coarser scales' at -``prior``, leaning to the
      nearest of them).

    No int8 variant (``int8 = False``): static int8 activations cannot hold
    both the logits and the -1e4 that masks an empty candidate out of the
    softmax, so empty candidates leak in (the release run's int8 lost 1.7 dB)."""

    int8 = False
    #: the logits pass through LOGIT_BOUND * tanh(. / LOGIT_BOUND): weights
    #: within a factor e**12 of each other, and exp within fp16's range
    LOGIT_BOUND = 6.0

    def __init__(
        self,
        planes: tuple[str, ...] = ("rgb", "depth", "vel2d"),
        widths: tuple[int, ...] = (16, 32, 64, 128, 256),
        up: str = "bilinear",
        kernels: tuple[tuple[int, int], ...] = ((5, 1), (3, 2), (3, 4)),
        prior: float = 2.0,
        depth_select: bool = False,
        depth_scale: float = 20.0,
    ) -> None:
        super().__init__(planes, widths, up)
        ks = tuple((int(k), int(s)) for k, s in kernels)
        if not ks or any(k < 1 or k % 2 == 0 or s < 1 or s & (s - 1) or s > self.stride for k, s in ks):
            raise ValueError(
                f"kernels: expected (odd k, power-of-two s <= {self.stride}) pairs, got {kernels!r}"
            )
        if depth_select and "depth" not in self.layout:
            raise ValueError("depth_select: needs the 'depth' plane in planes")
        self.kernels = ks
        self.candidates = sum(k * k for k, _ in ks)
        self.depth_select = bool(depth_select)
        self.depth_scale = float(depth_scale)
        self.out = nn.Conv2d(self.widths[0], self.candidates + 1 + int(self.depth_select), 1)
        nn.init.zeros_(self.out.weight)
        with torch.no_grad():
            self.out.bias.zero_()
            self.out.bias[: ks[0][0] ** 2] = prior
            if self.depth_select:  # the coarser scales start out of the way of the nearest-point prior
                self.out.bias[ks[0][0] ** 2 : self.candidates] = -prior

    def gather(
        self, x: torch.Tensor, nx: torch.Tensor | None = None
    ) -> tuple[list[torch.Tensor], torch.Tensor, torch.Tensor | None]:
        """The candidates of every output pixel: ([R, G, B] each (N, K, H, W),
        mask (N, K, H, W), nearness (N, K, H, W) or None without
        ``depth_select``), K = ``candidates``, in ``kernels``' order. The
        nearness is relative to the pixel's nearest candidate (<= 0; 0: the
        nearest), so the depth term of a logit is never positive. `nx`:
        normalise(x) where the caller has it."""
        cov = x[:, 3:4]
        planes = [x[:, 0:3] * cov]
        if self.depth_select:
            nx = self.normalise(x) if nx is None else nx
            d = self.layout.index("depth")
            planes.append(nx[:, d : d + 1])  # nearness, 0 where empty
        p = torch.cat(planes, dim=1)
        c = p.shape[1]
        parts: list[list[torch.Tensor]] = [[] for _ in range(c + 1)]  # R, G, B, (nearness,) mask
        refs: list[torch.Tensor] = []
        for k, s in self.kernels:
            if s > 1:
                n = F.avg_pool2d(cov, s)
                blocks = F.avg_pool2d(p, s) / torch.clamp(n, min=1e-12)
                m = torch.clamp(n * float(4 * s * s), max=1.0)
                u = F.interpolate(torch.cat([blocks, m], dim=1), scale_factor=float(s), mode="nearest")
            else:
                u = torch.cat([p, cov], dim=1)
            for i in range(c + 1):
                parts[i].append(shifted(u[:, i : i + 1], k, s))
            if self.depth_select:  # the nearest candidate of this scale: a k x k max-pool of its blocks
                if s > 1:
                    r = F.max_pool2d(blocks[:, 3:4], k, stride=1, padding=k // 2)
                    refs.append(F.interpolate(r, scale_factor=float(s), mode="nearest"))
                else:
                    refs.append(F.max_pool2d(p[:, 3:4], k, stride=1, padding=k // 2))
        out = [torch.cat(q, dim=1) for q in parts]
        if not self.depth_select:
            return out[:3], out[c], None
        ref = refs[0]
        for r in refs[1:]:
            ref = torch.maximum(ref, r)
        return out[:3], out[c], out[3] - ref

    def _weights(self, nx: torch.Tensor, mask: torch.Tensor, near: torch.Tensor | None) -> torch.Tensor:
        h = self._features(nx)
        o = self.out(h)
        k = self.candidates
        # softmax over the valid candidates and the background, written out:
        # onnxruntime's Softmax and ReduceSum over the channel axis transpose
        # NCHW (3/4 of a 512^2 frame's time); the logits are bounded by
        # LOGIT_BOUND * tanh, so exp needs no max subtracted (fp16 included)
        logits = self.LOGIT_BOUND * torch.tanh(o[:, : k + 1] * (1.0 / self.LOGIT_BOUND))
        if near is not None:  # near <= 0: behind the pixel's nearest candidate
            gamma = F.softplus(o[:, k + 1 :]) * self.depth_scale
            logits = torch.cat([logits[:, :k] + gamma * near, logits[:, k:]], dim=1)
        e = torch.exp(logits) * torch.cat([mask, torch.ones_like(mask[:, :1])], dim=1)
        return e / _channel_sum(e, k + 1)

    def weights(self, x: torch.Tensor) -> torch.Tensor:
        """The per-pixel softmax weights (N, K + 1, H, W): the candidates'
        (zero where masked), then the background's."""
        nx = self.normalise(x)
        _, mask, near = self.gather(x, nx)
        return self._weights(nx, mask, near)

    def trunk(self, x: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """What the exported graph outputs (:class:`KPNTrunk`): the head's
        logits (N, K + 1 (+ 1 with ``depth_select``), H, W), the output of
        ``self.out``, and with ``depth_select`` the nearness plane (N, 1, H,
        W) of :meth:`normalise`. The rest of :meth:`forward` (gather,
        bounded logits, masked softmax, weighted sum) is clvis.post.kpn's
        OpenCL kernel (clvis.reference.post.kpn its NumPy reference)."""
        nx = self.normalise(x)
        o = self.out(self._features(nx))
        if not self.depth_select:
            return (o,)
        d = self.layout.index("depth")
        return o, nx[:, d : d + 1]

    def head(self) -> dict[str, Any]:
        """The model card's "head" entry: how clvis.post.kpn applies the head."""
        return {
            "kind": "kpn",
            "kernels": [list(ks) for ks in self.kernels],
            "depth_select": self.depth_select,
            "depth_scale": self.depth_scale,
            "logit_bound": self.LOGIT_BOUND,
            "outputs": ["logits", "nearness"] if self.depth_select else ["logits"],
        }

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        nx = self.normalise(x)
        cols, mask, near = self.gather(x, nx)
        w = self._weights(nx, mask, near)[:, : self.candidates]
        out = torch.cat([_channel_sum(w * c, self.candidates) for c in cols], dim=1)
        return torch.clamp(out, 0.0, 1.0)


class KPNTrunk(nn.Module):
    """A :class:`NarvisKPN` up to its head's logits: ``forward`` is the net's
    :meth:`NarvisKPN.trunk` (what ``clvis train narvis`` exports; the
    shipped model's graph)."""

    def __init__(self, net: NarvisKPN) -> None:
        super().__init__()
        self.net = net

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, ...]:
        return self.net.trunk(x)


def _channel_sum(x: torch.Tensor, n: int) -> torch.Tensor:
    """(N, 1, H, W): the sum over the `n` channels of `x`, as a 1 x 1
    convolution by ones (onnxruntime's ReduceSum over axis 1 transposes)."""
    return F.conv2d(x, torch.ones(1, n, 1, 1, dtype=x.dtype, device=x.device))


#: the torch module of each shipped network, by name
NETWORKS: dict[str, type[nn.Module]] = {
    "infill": InfillWNet,
    "lidar": RgbdaUNet,
    "narvis": NarvisKPN,
    "narvis-scan": NarvisKPN,
}


def build(name: str, **kwargs: Any) -> nn.Module:
    """A network by its shipped name ("infill", "lidar", "narvis", "narvis-scan") with its
    architecture arguments (InfillWNet: none; RgbdaUNet: width, depth;
    NarvisUNet: planes, widths, up)."""
    cls = NETWORKS.get(name) if isinstance(name, str) else None
    if cls is None:
        raise ValueError(f"network: expected one of {tuple(NETWORKS)}, got {name!r}")
    kwargs = {k: tuple(v) if isinstance(v, list) else v for k, v in kwargs.items()}
    return cls(**kwargs)


def count_parameters(net: nn.Module) -> int:
    return sum(p.numel() for p in net.parameters())
