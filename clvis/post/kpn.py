"""The NARVis kernel-prediction head on the device (kernels_cl/post/kpn.cl):
what clvis.post.nets.NarvisKPN computes after its head's 1x1 convolution
(gather of candidate colours at the pyramid scales, bounded logits with the
depth-select term, masked softmax with a background weight, weighted sum),
written as two OpenCL kernels instead of the ~300 full-size graph
operations onnxruntime ran for it (issue 28). The shipped narvis model's
graph stops at the logits (its card's ``head`` entry); PostNetwork applies
this head to them. Definitions: clvis.reference.post.kpn.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pyopencl as cl
import pyopencl.array as cla

from .. import runtime
from .._arrays import buf, check_array, is_device, resolve_queue, result, to_device
from ..errors import DataError

__all__ = ["KPNHead", "kpn_head"]

_SRC = "post/kpn.cl"
_WG = 64
#: the largest k and s a card may ask for (the network's stride bounds s)
MAX_K, MAX_S = 15, 1024
#: the most scales kpn_apply unrolls
MAX_SCALES = 8


def _kernels(kernels: Any) -> tuple[tuple[int, int], ...]:
    try:
        ks = tuple((int(k), int(s)) for k, s in kernels)
        ok = bool(ks) and all(
            k == kk and s == ss
            for (k, s), (kk, ss) in zip(ks, kernels, strict=True)  # no 2.5 -> 2
        )
    except (TypeError, ValueError):
        ok, ks = False, ()
    if (
        not ok
        or len(ks) > MAX_SCALES
        or any(not 1 <= k <= MAX_K or k % 2 == 0 or not 1 <= s <= MAX_S or s & (s - 1) for k, s in ks)
    ):
        raise ValueError(
            f"kernels: expected 1..{MAX_SCALES} (k, s) pairs, k odd in 1..{MAX_K}, "
            f"s a power of two <= {MAX_S}, got {kernels!r}"
        )
    return ks


class KPNHead:
    """The head of one network: its scales (``kernels``, (k, s) pairs),
    ``depth_select``, ``depth_scale`` and ``logit_bound`` (a model card's
    ``head`` entry). Call it on device tensors (see :func:`kpn_head`)."""

    def __init__(
        self,
        kernels: Any,
        *,
        depth_select: bool,
        depth_scale: float = 20.0,
        logit_bound: float = 6.0,
    ) -> None:
        self.kernels = _kernels(kernels)
        if not isinstance(depth_select, bool):
            raise TypeError(f"depth_select: expected True or False, got {depth_select!r}")
        self.depth_select = depth_select
        self.depth_scale = float(depth_scale)
        self.logit_bound = float(logit_bound)
        if not np.isfinite(self.depth_scale) or self.depth_scale < 0:
            raise ValueError(f"depth_scale: expected a finite number >= 0, got {depth_scale!r}")
        if not np.isfinite(self.logit_bound) or self.logit_bound <= 0:
            raise ValueError(f"logit_bound: expected a finite number > 0, got {logit_bound!r}")
        self.candidates = sum(k * k for k, _ in self.kernels)
        #: the logits' channels: the candidates, the background, (gamma)
        self.channels = self.candidates + 1 + int(depth_select)
        self.stride = max(s for _, s in self.kernels)
        # kpn_apply's compile-time scales (kernels_cl/post/kpn.cl's ABI)
        self._defines: dict[str, object] = {
            "DEPTH_SELECT": int(depth_select),
            "WG": _WG,
            "KPN_SCALES": len(self.kernels),
            "KPN_CANDIDATES": self.candidates,
        }
        for i, (k, s) in enumerate(self.kernels):
            self._defines[f"KPN_K{i}"], self._defines[f"KPN_S{i}"] = k, s

    def __repr__(self) -> str:
        return f"KPNHead({[list(k) for k in self.kernels]}, depth_select={self.depth_select})"

    def __call__(
        self,
        planes: Any,
        logits: Any,
        nearness: Any = None,
        *,
        out: cla.Array | None = None,
        queue: cl.CommandQueue | None = None,
    ) -> np.ndarray | cla.Array:
        """(1, 3, Hp, Wp) float32: the head's image. planes: the network's
        input (1, C >= 4, Hp, Wp); logits: (1, :attr:`channels`, Hp, Wp);
        nearness: (1, 1, Hp, Wp) with ``depth_select`` (else None). Numpy or
        device arrays; out: a device array to write into (returned);
        otherwise the result is where the inputs were."""
        queue = resolve_queue(queue, planes=planes, logits=logits, out=out)
        host = not is_device(planes) and not is_device(logits)
        planes = check_array("planes", planes, dtypes=[np.float32], ndim=4)
        logits = check_array("logits", logits, dtypes=[np.float32], ndim=4)
        n, c, hp, wp = (int(v) for v in planes.shape)
        if n != 1 or c < 4:
            raise ValueError(f"planes: expected shape (1, C >= 4, H, W), got {tuple(planes.shape)}")
        if hp == 0 or wp == 0:
            raise DataError(f"planes: empty ({hp} x {wp} pixels)")
        if hp % self.stride or wp % self.stride:
            raise ValueError(
                f"planes: {hp} x {wp} is not a multiple of the head's largest scale {self.stride}"
            )
        if tuple(logits.shape) != (1, self.channels, hp, wp):
            raise ValueError(
                f"logits: expected shape {(1, self.channels, hp, wp)}, got {tuple(logits.shape)}"
            )
        if self.depth_select:
            if nearness is None:
                raise ValueError("nearness: the head selects by depth and needs the nearness plane")
            nearness = check_array("nearness", nearness, dtypes=[np.float32], ndim=4)
            if tuple(nearness.shape) != (1, 1, hp, wp):
                raise ValueError(f"nearness: expected shape {(1, 1, hp, wp)}, got {tuple(nearness.shape)}")
        elif nearness is not None:
            raise ValueError("nearness: this head does not select by depth (give None)")
        if out is None:
            dst = runtime.empty(queue, (1, 3, hp, wp), np.float32, "kpn head output")
        elif not is_device(out) or out.dtype != np.float32 or tuple(out.shape) != (1, 3, hp, wp):
            raise ValueError(f"out: expected a device array of shape {(1, 3, hp, wp)} float32")
        elif not out.flags.c_contiguous or out.offset:
            raise ValueError("out: expected a C-contiguous array without an offset (a whole buffer)")
        else:
            dst = out
        d_planes = to_device(queue, "planes", planes)
        d_logits = to_device(queue, "logits", logits)
        d_near = to_device(queue, "nearness", nearness) if self.depth_select else d_logits
        up = runtime.empty(queue, (len(self.kernels) * 5, hp, wp), np.float32, "kpn head up-sampled planes")
        u32 = np.uint32
        blocks = runtime.get_kernel(queue, _SRC, "kpn_blocks", self._defines, runtime.EXACT_FP)
        for i, (_, s) in enumerate(self.kernels):
            nb = (hp // s) * (wp // s)
            runtime.launch(
                queue,
                blocks,
                *runtime.items(queue, nb, _WG),
                buf(d_planes),
                buf(d_near),
                u32(wp),
                u32(hp),
                u32(s),
                u32(i),
                buf(up),
            )
        k = runtime.get_kernel(queue, _SRC, "kpn_apply", self._defines, runtime.EXACT_FP)
        runtime.launch(
            queue,
            k,
            *runtime.items(queue, hp * wp // 8, _WG),
            buf(up),
            buf(d_logits),
            u32(wp),
            u32(hp),
            np.float32(self.depth_scale),
            np.float32(self.logit_bound),
            buf(dst),
        )
        return dst if out is not None else result(dst, host)


def kpn_head(
    planes: Any,
    logits: Any,
    nearness: Any = None,
    *,
    kernels: Any,
    depth_select: bool,
    depth_scale: float = 20.0,
    logit_bound: float = 6.0,
    out: cla.Array | None = None,
    queue: cl.CommandQueue | None = None,
) -> np.ndarray | cla.Array:
    """The NARVis kernel-prediction head's image (1, 3, Hp, Wp) float32 from
    the network's input `planes`, its head's `logits` and (``depth_select``)
    the `nearness` plane: :class:`KPNHead` (kernels, depth_select,
    depth_scale, logit_bound) called once."""
    head = KPNHead(kernels, depth_select=depth_select, depth_scale=depth_scale, logit_bound=logit_bound)
    return head(planes, logits, nearness, out=out, queue=queue)
