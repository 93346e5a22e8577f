"""NumPy reference of the NARVis kernel-prediction head (kernels_cl/post/kpn.cl,
clvis.post.kpn), written from clvis.post.nets.NarvisKPN's gather, _weights
and forward: what the exported graph leaves out and the kernel applies.

Inputs, all (1, C, Hp, Wp) float32 with Hp and Wp multiples of every scale s:

- ``planes``: the network's packed input; channels 0..2 are R, G, B and
  channel 3 the coverage (0 or 1).
- ``logits``: the head's 1x1 convolution, K + 1 (+ 1 with ``depth_select``)
  channels, K = sum of k*k over ``kernels``: one per candidate (in
  ``kernels``' order, within a scale row-major dy, dx), the background's,
  then gamma's raw value.
- ``nearness`` (``depth_select`` only): (1, 1, Hp, Wp), NarvisUNet.normalise's
  depth plane (1 nearest, 0 where empty).

Definitions (per output pixel (y, x)):

- block planes of scale s: p = [R*cov, G*cov, B*cov, nearness]; for s = 1 the
  pixels themselves and mask = cov; for s > 1, over each s x s block, n =
  the mean coverage, value = mean(p) / max(n, 1e-12), mask = min(4 s^2 n, 1).
- candidate (dy, dx) of a scale (k, s): the block (y // s + dy - k // 2,
  x // s + dx - k // 2); beyond the grid of Hp / s x Wp / s blocks its
  values and mask are 0.
- depth_select: ref = max over the in-grid candidates of every scale of
  their nearness; near_j = nearness_j - ref (<= 0).
- l_j = B tanh(o_j / B) (B = ``logit_bound``) for the K candidates and the
  background; with depth_select l_j += softplus(o_{K+1}) * depth_scale *
  near_j for the candidates (softplus(v) = v above 20, as torch's).
- e_j = exp(l_j) * mask_j (mask 1 for the background); w_j = e_j / sum e.
- out_c = clamp(sum_{j < K} w_j colour_c_j, 0, 1).

Returns (1, 3, Hp, Wp) float32 (sums in float64, so within float32
rounding of the graph's and the kernel's).
"""

from __future__ import annotations

import numpy as np

__all__ = ["kpn_head"]


def _blocks(p: np.ndarray, cov: np.ndarray, s: int) -> tuple[np.ndarray, np.ndarray]:
    """(values (4, Hp/s, Wp/s), mask (Hp/s, Wp/s)) of scale s."""
    if s == 1:
        return p, cov
    c, hp, wp = p.shape
    n = cov.reshape(hp // s, s, wp // s, s).mean(axis=(1, 3))
    v = p.reshape(c, hp // s, s, wp // s, s).mean(axis=(2, 4)) / np.maximum(n, 1e-12)
    return v, np.minimum(n * (4.0 * s * s), 1.0)


def _shift(a: np.ndarray, oy: int, ox: int, s: int) -> np.ndarray:
    """a (..., hb, wb) block grid read at (y // s + oy, x // s + ox) for every
    pixel (y, x) of the (hb*s, wb*s) image; 0 beyond the grid."""
    hb, wb = a.shape[-2:]
    pad = np.zeros(a.shape[:-2] + (hb + 2 * abs(oy), wb + 2 * abs(ox)), a.dtype)
    pad[..., abs(oy) : abs(oy) + hb, abs(ox) : abs(ox) + wb] = a
    b = pad[..., abs(oy) + oy : abs(oy) + oy + hb, abs(ox) + ox : abs(ox) + ox + wb]
    return np.repeat(np.repeat(b, s, axis=-2), s, axis=-1)


def kpn_head(
    planes: np.ndarray,
    logits: np.ndarray,
    nearness: np.ndarray | None,
    kernels: tuple[tuple[int, int], ...],
    *,
    depth_select: bool,
    depth_scale: float = 20.0,
    logit_bound: float = 6.0,
) -> np.ndarray:
    """The head's image (see the module doc)."""
    x = np.asarray(planes, np.float64)[0]
    o = np.asarray(logits, np.float64)[0]
    hp, wp = x.shape[1:]
    cov = x[3]
    p = [x[c] * cov for c in range(3)]
    if depth_select:
        assert nearness is not None
        p.append(np.asarray(nearness, np.float64)[0, 0])
    pv = np.stack(p)
    cols, masks, nears, inside = [], [], [], []
    for k, s in kernels:
        v, m = _blocks(pv, cov, s)
        ones = np.ones(m.shape)
        for dy in range(k):
            for dx in range(k):
                oy, ox = dy - k // 2, dx - k // 2
                sv = _shift(v, oy, ox, s)
                cols.append(sv[:3])
                masks.append(_shift(m, oy, ox, s))
                if depth_select:
                    nears.append(sv[3])
                    inside.append(_shift(ones, oy, ox, s) > 0)
    kk = len(masks)
    b = float(logit_bound)
    lg = b * np.tanh(o[: kk + 1] / b)
    if depth_select:
        near = np.stack(nears)
        ref = np.max(np.where(np.stack(inside), near, -np.inf), axis=0)
        g = o[kk + 1]
        gamma = np.where(g > 20.0, g, np.log1p(np.exp(np.minimum(g, 20.0)))) * float(depth_scale)
        lg[:kk] += gamma * (near - ref)
    e = np.exp(lg) * np.concatenate([np.stack(masks), np.ones((1, hp, wp))])
    w = e / e.sum(axis=0)
    col = np.stack(cols)  # (K, 3, Hp, Wp)
    out = np.einsum("khw,kchw->chw", w[:kk], col)
    return np.clip(out, 0.0, 1.0).astype(np.float32)[None]
