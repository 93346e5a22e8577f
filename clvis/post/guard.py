"""The guard: an inference-time self-check of the in-fill, LiDAR and
narvis-scan networks against their classical fills, from the network's own
input alone.

A network may fill data it never saw worse than the classical method it
replaces (issue 21: shapes at 95 % completion, where the in-fill network
paints the background rays still running; a smooth terrain, where push-pull
beats the LiDAR U-Net by 5 dB). The guard lets the frame itself say which
fill to trust, tile by tile:

1. *withhold*: some known pixels are marked unknown. LiDAR: a fraction
   (10 %) of the kept points, drawn by a hash of the pixel's coordinates
   (:func:`withheld`: no random state, the same subset on every run and
   machine); with the G-buffers' point index (a FilteredImage's ``index``)
   a hashed 10 % of the points, each whole (:func:`points_withheld`: a point
   drawn 2 or 3 pixels wide, withheld a pixel at a time, left its other
   pixels known, and every fill copied them back: the check was a tie).
   In-fill: the finished rays within ``ring`` (8) pixels of a running one
   (:func:`ring`), bands of the holes' own shapes; a random
   pixel subset is an isolated-hole problem the network never trained on,
   and push-pull wins it everywhere;
2. *score*: the network and each classical candidate fill that reduced
   input; per tile (LiDAR 64 x 64 pixels, in-fill 32 x 32), each
   candidate's mean squared RGB error on the withheld pixels, shrunk toward
   its error over the whole frame with ``prior`` pseudo-pixels (a tile
   with few withheld pixels follows the frame);
3. *blend*: each tile puts its weight on the candidate of the lowest error
   (the network keeps a tile unless a classical fill's error is below
   ``1 - margin`` times its own: LiDAR 0.5, in-fill 0); the tile weights
   are interpolated bilinearly between tile centres (no seams), and the
   frame is ``sum_k w_k candidate_k`` of the full input (only the
   candidates some tile took are run). In-fill: the finished rays keep
   their values exactly (only the rays still running are blended); LiDAR:
   every pixel (the network's output replaces the scan's pixels too).

narvis-scan (:func:`narvis_scan`; its spec has it off): the network and
the classical splat of clvis.post.splat, 5 % of the covered pixels
withheld, scored not on the withheld points' colours but on each
candidate's self-consistency (its frame of the reduced input against its
own frame of the full one): bench/results/README.md, 2026-11-28 session 7.

Each network's settings are ``PARAMS[name]``; the module constants are
:func:`blend`'s generic defaults. Whether a network's call uses the guard
by default is its spec's ``guard`` (clvis.post.specs: on for LiDAR, off for
in-fill, where it is not reliable: bench/results/post-guard.md).

Candidates: in-fill, the network, push-pull of the finished rays and the
partial image itself (the running rays left empty); LiDAR, the network and
push-pull of the kept points' colours, black beyond a reach of every kept
point (2.5 % of the frame's longer side, at least 16 pixels and 3 x the
kept pixels' mean spacing over the frame) and, outside the cloud's
footprint, beyond 3 x the kept points' local spacing (at least 4 pixels):
push-pull extrapolates into every empty pixel, and a tile that took it
painted the scan's blurred colours into the empty sky beside a real scan's
edge, first as blobs, then (within the reach) as a fringe 16-32 pixels
wide. Push-pull is the OpenCL kernel of clvis.post.pushpull; the rest is
NumPy.

The parameters were chosen on frames of the training families only
(clvis.training.data's "waves", "ripples", "blobs" volumes and "town"
scenes; never the held-out suite's), with the shipped networks and with
networks made bad on purpose: ``bench/guard_sweep.py``, whose output
``bench/results/post-guard.md`` shows.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
import pyopencl as cl

__all__ = [
    "EDGE_MIN",
    "MARGIN",
    "PARAMS",
    "PRIOR",
    "REACH_MIN",
    "RING",
    "TILE",
    "WITHHOLD",
    "blend",
    "points_withheld",
    "infill",
    "interpolate",
    "lidar",
    "narvis_scan",
    "nearest_running",
    "ring",
    "tile_weights",
    "withheld",
]

#: side of a scoring tile, pixels (defaults of :func:`blend`)
TILE = 32
#: the fraction of the known pixels withheld for the check
WITHHOLD = 0.1
#: pseudo-pixels of the frame's own error added to each tile's
PRIOR = 8.0
#: a classical fill takes a tile from the network where its error is below
#: (1 - MARGIN) x the network's
MARGIN = 0.0
#: :func:`ring`'s default width, pixels
RING = 8

#: each network's parameters, chosen on its training families
#: (bench/results/post-guard.md)
PARAMS: dict[str, dict[str, float]] = {
    "infill": {"tile": 32, "prior": 4.0, "margin": 0.0, "ring": 8},
    # reach: push-pull's candidate is black farther than this share of the
    # frame's longer side (at least REACH_MIN pixels, and `spacing` x the
    # kept pixels' spacing over the frame) from every kept point; edge:
    # outside the cloud's footprint, farther than `edge` x the kept points'
    # local spacing (at least EDGE_MIN pixels)
    "lidar": {
        "tile": 64,
        "prior": 16.0,
        "margin": 0.5,
        "fraction": 0.1,
        "reach": 0.025,
        "spacing": 3.0,
        "edge": 3.0,
    },
    # opacity: the splat candidate's, the targets' (clvis.training.data.SCAN_OPACITY);
    # chosen on training-family frames (town, photo_town, shapes; seeds 101, 202)
    "narvis-scan": {"tile": 64, "prior": 64.0, "margin": 0.8, "fraction": 0.05, "opacity": 0.8},
}
#: the least reach of LiDAR's push-pull candidate, pixels (a 1 % scan's
#: points are ~10 pixels apart)
REACH_MIN = 16.0
#: the least reach of that candidate outside the cloud's footprint, pixels
#: (two of the distance transform's 2 x 2 blocks)
EDGE_MIN = 4.0


def withheld(known: np.ndarray, fraction: float = WITHHOLD) -> np.ndarray:
    """(H, W) bool: about `fraction` of the `known` pixels, picked by a
    hash of (row, column): the same pixels for the same shape every time."""
    h, w = known.shape
    y = np.arange(h, dtype=np.uint32)[:, None]
    x = np.arange(w, dtype=np.uint32)[None, :]
    with np.errstate(over="ignore"):
        v = y * np.uint32(0x9E3779B1) ^ x * np.uint32(0x85EBCA77)
    return known & _hashed_below(v, fraction)


def points_withheld(known: np.ndarray, index: np.ndarray, fraction: float = WITHHOLD) -> np.ndarray:
    """(H, W) bool: the `known` pixels of about `fraction` of the points, each
    point whole: a hash of the point's index (the G-buffers' ``index``, which
    point each pixel shows) picks it, so every pixel of a point drawn 2 or 3
    pixels wide goes with it (withheld a pixel at a time, a point left its
    other pixels known and every fill copied them back: the check tied). No
    random state: the same points every run."""
    with np.errstate(over="ignore"):
        v = np.asarray(index).astype(np.uint32) * np.uint32(0x9E3779B1)
    return np.asarray(known, bool) & _hashed_below(v, fraction)


def _hashed_below(v: np.ndarray, fraction: float) -> np.ndarray:
    """Where the uint32 keys `v`, mixed (a murmur-style finaliser), fall in
    the lowest `fraction` of the range: withheld's and points_withheld's pick."""
    if not 0.0 < fraction < 1.0:
        raise ValueError(f"fraction: expected a number in (0, 1), got {fraction!r}")
    with np.errstate(over="ignore"):
        v = v ^ (v >> np.uint32(15))
        v *= np.uint32(0x2C1B3C6D)
        v ^= v >> np.uint32(12)
        v *= np.uint32(0x297A2D39)
        v ^= v >> np.uint32(15)
    return v < np.uint32(min(fraction * 2.0**32, 2.0**32 - 1))


def ring(known: np.ndarray, holes: np.ndarray, width: int = RING) -> np.ndarray:
    """(H, W) bool: the `known` pixels within `width` pixels (Chebyshev) of
    a hole: bands beside the holes, of the holes' own shapes (the in-fill
    guard's withheld pixels)."""
    from scipy.ndimage import maximum_filter

    if width < 1:
        raise ValueError(f"width: expected a whole number >= 1, got {width!r}")
    near = maximum_filter(np.asarray(holes, bool).view(np.uint8), size=2 * width + 1, mode="constant") > 0
    return known & near


def nearest_running(candidates: np.ndarray, active: np.ndarray, name: str = "candidates") -> np.ndarray:
    """(H, W) `candidates` (an IsoImage's candidate blocks left per running
    ray, uint8; or another per-running-ray plane, e.g. its next_t, named
    `name` in errors) with every finished pixel given the value of its
    nearest running ray (Euclidean; ties as scipy's distance transform
    breaks them), in the plane's dtype.

    The in-fill guard withholds finished rays and hands them to the network
    as running ones. Their own count is 0, and to a network that reads the
    CANDIDATES plane a running ray with no block left is a ray that misses:
    the network painted the withheld pixels as background and lost the
    guard's check there. The nearest running ray's count is what a ray in
    that band would have had. On the held-out suite (bench/results/README.md,
    2026-11-29 session 9) the guarded frame's margin over push-pull rose with
    it; the network alone is still better on average."""
    from scipy.ndimage import distance_transform_edt

    candidates = np.asarray(candidates)
    active = np.asarray(active, bool)
    if candidates.shape != active.shape:
        raise ValueError(f"{name}: expected the shape of active {active.shape}, got {candidates.shape}")
    if not active.any() or active.all():
        return candidates.copy()
    _, (iy, ix) = distance_transform_edt(~active, return_indices=True)
    return np.where(active, candidates, candidates[iy, ix]).astype(candidates.dtype)


def tile_weights(
    errors: Sequence[np.ndarray],
    mask: np.ndarray,
    *,
    tile: int = TILE,
    prior: float = PRIOR,
    margin: float = MARGIN,
) -> np.ndarray:
    """(K, ty, tx) float32 one-hot weights per tile: candidate 0 (the
    network) unless candidate k's shrunk mean error is below (1 - margin) x
    its own and the lowest. errors: K (H, W) squared errors, read where
    `mask` (the withheld pixels)."""
    ys, xs = np.nonzero(mask)
    return _weights([e[ys, xs] for e in errors], ys, xs, mask.shape, tile, prior, margin)


def _weights(
    errors: Sequence[np.ndarray],
    ys: np.ndarray,
    xs: np.ndarray,
    shape: tuple[int, ...],
    tile: int,
    prior: float,
    margin: float,
) -> np.ndarray:
    """tile_weights from the errors at the withheld pixels (ys, xs) alone."""
    h, w = shape
    ty, tx = -(-h // tile), -(-w // tile)
    where = (ys // tile) * tx + xs // tile
    count = np.bincount(where, minlength=ty * tx).astype(np.float64)
    scores = []
    for e in errors:
        sums = np.bincount(where, weights=e.astype(np.float64), minlength=ty * tx)
        frame = float(sums.sum()) / max(float(count.sum()), 1.0)
        scores.append((sums + prior * frame) / np.maximum(count + prior, 1e-12))
    sc = np.stack(scores)
    best = np.argmin(sc, axis=0)
    # the network keeps a tile unless the winner beats it by the margin
    beaten = sc[best, np.arange(ty * tx)] < (1.0 - margin) * sc[0]
    best = np.where(beaten, best, 0)
    out = np.zeros(sc.shape, np.float32)
    out[best, np.arange(ty * tx)] = 1.0
    return out.reshape(len(errors), ty, tx)


def _axis(n: int, tiles: int, tile: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bilinear interpolation from tile centres to the pixels 0..n-1 (edges
    clamped): each pixel's two tiles and the second's weight."""
    f = np.clip((np.arange(n) + 0.5) / tile - 0.5, 0, tiles - 1)
    i0 = np.floor(f).astype(np.int64)
    return i0, np.minimum(i0 + 1, tiles - 1), (f - i0).astype(np.float32)


def interpolate(weights: np.ndarray, h: int, w: int, tile: int = TILE) -> np.ndarray:
    """(K, H, W) float32: per-tile weights (K, ty, tx) interpolated
    bilinearly between tile centres; they still sum to 1 at every pixel."""
    k, ty, tx = weights.shape
    y0, y1, ay = _axis(h, ty, tile)
    x0, x1, ax = _axis(w, tx, tile)
    rows = weights[:, y0] * (1 - ay)[None, :, None] + weights[:, y1] * ay[None, :, None]  # (K, H, tx)
    return rows[:, :, x0] * (1 - ax) + rows[:, :, x1] * ax


def _at(weights: np.ndarray, ys: np.ndarray, xs: np.ndarray, tile: int) -> np.ndarray:
    """(K, N) float32: :func:`interpolate`'s weights at the pixels (ys, xs)."""
    k, ty, tx = weights.shape
    y0, y1, ay = _axis(int(ys.max()) + 1, ty, tile)
    x0, x1, ax = _axis(int(xs.max()) + 1, tx, tile)
    a, b = ay[ys], ax[xs]
    return (
        weights[:, y0[ys], x0[xs]] * ((1 - a) * (1 - b))
        + weights[:, y0[ys], x1[xs]] * ((1 - a) * b)
        + weights[:, y1[ys], x0[xs]] * (a * (1 - b))
        + weights[:, y1[ys], x1[xs]] * (a * b)
    )


def blend(
    fill: Callable[[np.ndarray, Sequence[int]], list[np.ndarray | None]],
    truth: np.ndarray | None,
    known: np.ndarray,
    *,
    names: Sequence[str],
    tile: int = TILE,
    fraction: float = WITHHOLD,
    prior: float = PRIOR,
    margin: float = MARGIN,
    held: np.ndarray | None = None,
    where: np.ndarray | None = None,
) -> tuple[np.ndarray, dict[str, float]]:
    """The guarded frame (steps 1-3 of the module doc), and the share of
    the frame's tiles each candidate took.

    fill(known', wanted) -> the candidates' frames (H, W, C) float32 of the
    input with only the pixels ``known'`` known, those of the indices
    `wanted` (None for the others); candidate 0 is the network. truth
    (H, W, 3): the known pixels' RGB; None: each candidate is scored by its
    self-consistency, its frame of the reduced input against its own frame
    of the whole input at the withheld pixels. held: the known pixels to withhold
    (default: :func:`withheld`'s `fraction`). where: the pixels to blend
    (default all), the candidates being equal elsewhere."""
    names = list(names)
    everyone = range(len(names))
    if held is None:
        held = withheld(known, fraction)
    h, w = known.shape
    if not held.any():  # nothing to check against: the network's frame
        return _first(fill(known, [0])), {n: float(i == 0) for i, n in enumerate(names)}
    ys, xs = np.nonzero(held)
    # what the withheld pixels are held to: their truth, or each
    # candidate's own frame of the whole input (made first, kept for the blend)
    whole = None
    if truth is not None:
        refs = [truth[ys, xs]] * len(names)
    else:
        whole = fill(known, everyone)
        refs = [_first([f])[ys, xs, :3] for f in whole]
    reduced = fill(known & ~held, everyone)
    errors = [np.sum((_first([c])[ys, xs, :3] - r) ** 2, axis=-1) for c, r in zip(reduced, refs, strict=True)]
    weights = _weights(errors, ys, xs, (h, w), tile, prior, margin)
    share = {n: float(weights[i].mean()) for i, n in enumerate(names)}
    used = [i for i in everyone if weights[i].any()]
    full = [f for f in (fill(known, used) if whole is None else [whole[i] for i in used]) if f is not None]
    if len(used) == 1:  # every tile took the same candidate
        return full[0], share
    if where is None:
        wp = interpolate(weights[used], h, w, tile)
        out = wp[0][..., None] * full[0]
        for j in range(1, len(used)):
            out += wp[j][..., None] * full[j]
        return out, share
    # outside `where` the candidates agree (the known pixels): the first's
    out = full[0].copy()
    py, px = np.nonzero(where)
    if len(py):
        wp = _at(weights[used], py, px, tile)
        acc = wp[0][:, None] * full[0][py, px]
        for j in range(1, len(used)):
            acc += wp[j][:, None] * full[j][py, px]
        out[py, px] = acc
    return out, share


def _first(frames: Sequence[np.ndarray | None]) -> np.ndarray:
    f = frames[0]
    assert f is not None, "the candidate asked for"
    return f


def infill(
    run: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray],
    rgba: np.ndarray,
    hit: np.ndarray,
    active: np.ndarray,
    queue: cl.CommandQueue | None = None,
    **params: float,
) -> tuple[np.ndarray, dict[str, float]]:
    """The guarded in-fill frame (H, W, 4) float32 (RGB premultiplied over
    black, coverage) of host planes rgba (H, W, 4), hit and active (H, W
    bool); run(rgba, hit, active) -> the network's (H, W, 4). The finished
    rays keep their values exactly. Candidates: "network", "pushpull",
    "input" (the partial image, the running rays empty). The withheld pixels:
    the finished rays within ``ring`` pixels of a running one; params
    override ``PARAMS["infill"]``."""
    from .pushpull import pushpull

    done = ~active
    shown = hit & done
    values = np.concatenate([rgba[..., :3] * shown[..., None], shown[..., None]], axis=2).astype(np.float32)

    def fill(known: np.ndarray, wanted: Sequence[int]) -> list[np.ndarray | None]:
        out: list[np.ndarray | None] = [None, None, None]
        if 0 in wanted:
            out[0] = run(values, hit & known, ~known)
        if 1 in wanted:
            out[1] = np.asarray(pushpull(values, known, queue=queue))
        if 2 in wanted:
            out[2] = values * known[..., None]
        return out

    p = _settings("infill", params)
    held = ring(done, active, int(p["ring"]))
    # blended at the running rays alone: every candidate passes the
    # finished ones through (the network in its graph's last blend)
    return blend(
        fill,
        values[..., :3],
        done,
        names=("network", "pushpull", "input"),
        held=held,
        where=active,
        tile=int(p["tile"]),
        prior=p["prior"],
        margin=p["margin"],
    )


def lidar(
    run: Callable[[np.ndarray], np.ndarray],
    rgbda: np.ndarray,
    queue: cl.CommandQueue | None = None,
    index: np.ndarray | None = None,
    **params: float,
) -> tuple[np.ndarray, dict[str, float]]:
    """The guarded LiDAR frame (H, W, 3) float32 of host rgbda (H, W, 5);
    run(rgbda) -> the network's (H, W, 3). Candidates: "network",
    "pushpull" (of the kept points' colours, black farther than ``reach`` x
    the frame's longer side, at least REACH_MIN pixels and ``spacing`` x the
    kept pixels' mean spacing over the frame, from every kept point, and
    outside the cloud's footprint farther than ``edge`` x the kept points'
    local spacing, at least EDGE_MIN pixels: :func:`_beyond`). The
    withheld pixels: a hashed ``fraction`` of the kept points, whole by
    their `index` (the G-buffers', (H, W)) where it is given, else a hashed
    ``fraction`` of the kept pixels; params override ``PARAMS["lidar"]``."""
    from .pushpull import pushpull

    kept = (rgbda[..., 4] > 0) & np.isfinite(rgbda[..., 3])
    rgb = np.ascontiguousarray(rgbda[..., :3], np.float32)
    far: list[np.ndarray] = []  # beyond every kept point's reach (made once, when first needed)

    def fill(known: np.ndarray, wanted: Sequence[int]) -> list[np.ndarray | None]:
        out: list[np.ndarray | None] = [None, None]
        if 0 in wanted:
            x = rgbda
            if not np.array_equal(known, kept):
                x = rgbda.copy()
                x[~known, 4] = 0.0
            out[0] = run(x)
        if 1 in wanted:
            pp = np.asarray(pushpull(rgb, known, queue=queue))
            # beyond the reach of every kept point push-pull extrapolates
            # the scan's colours into empty sky (the halos a guarded frame
            # showed beside a real scan's edge): nothing is there. The
            # scores read the withheld pixels alone, kept points all, so the
            # kept points' reach serves the reduced input too
            if not far:
                far.append(_beyond(kept, reach, float(p["edge"]), EDGE_MIN))
            if far[0].any():
                pp = pp.copy()
                pp[far[0]] = 0.0
            out[1] = pp
        return out

    p = _settings("lidar", params)
    # and at least `spacing` x the kept pixels' mean spacing were they spread
    # over the whole frame (a sparse scan's holes are a few spacings wide)
    spacing = math.sqrt(kept.size / max(int(kept.sum()), 1))
    reach = max(REACH_MIN, float(p["reach"]) * max(kept.shape), float(p["spacing"]) * spacing)
    held, prior = None, float(p["prior"])
    if index is not None:
        held = points_withheld(kept, index, float(p["fraction"]))
        # the prior counts points, as it did when each withheld pixel was one: a
        # point's pixels err together, so a tile's few points weigh no more
        points = len(np.unique(np.asarray(index)[held]))
        prior *= float(held.sum()) / max(points, 1)
    return blend(
        fill,
        rgb,
        kept,
        names=("network", "pushpull"),
        tile=int(p["tile"]),
        prior=prior,
        margin=p["margin"],
        fraction=p["fraction"],
        held=held,
    )


def narvis_scan(
    run: Callable[[np.ndarray], np.ndarray],
    index: np.ndarray,
    rgba: np.ndarray,
    radius_px: np.ndarray,
    **params: float,
) -> tuple[np.ndarray, dict[str, float]]:
    """The guarded narvis-scan frame (H, W, 3) float32 of the host G-buffer
    planes index (H, W) uint32 (0xFFFFFFFF where empty), rgba (H, W, 4)
    uint8 and radius_px (H, W) float32; run(index') -> the network's (H, W,
    3) of the same G-buffers with only the pixels index' marks covered.
    Candidates: "network", "splat" (clvis.post.splat: each covered pixel a
    round Gaussian of the radius plane's sigma, ``opacity``). The withheld
    pixels: a hashed ``fraction`` of the covered ones. Scores: each
    candidate's own *self-consistency*, its reduced input's frame against
    its full input's at the withheld pixels, not the points' colours (a
    withheld pixel's point colour is not the Gaussian render the network
    was trained on: on training frames that score picked the splat in 52 %
    of the tiles where the target says 17 %, bench/results/README.md).
    Both candidates run on both inputs; params override
    ``PARAMS["narvis-scan"]``."""
    from .._arrays import on_host
    from .splat import splat

    p = _settings("narvis-scan", params)
    empty = np.uint32(0xFFFFFFFF)
    covered = index != empty
    rgb = np.where(covered[..., None], rgba[..., :3] / np.float32(255), np.float32(0)).astype(np.float32)
    sigma = np.asarray(radius_px, np.float32)

    def fill(known: np.ndarray, wanted: Sequence[int]) -> list[np.ndarray | None]:
        out: list[np.ndarray | None] = [None, None]
        if 0 in wanted:
            out[0] = np.asarray(run(index if known is covered else np.where(known, index, empty)), np.float32)
        if 1 in wanted:
            out[1] = on_host(splat(rgb * known[..., None], known, None, opacity=p["opacity"], sigma=sigma))
        return out

    return blend(
        fill,
        None,
        covered,
        names=("network", "splat"),
        tile=int(p["tile"]),
        prior=p["prior"],
        margin=p["margin"],
        fraction=p["fraction"],
    )


def _beyond(known: np.ndarray, reach: float, spacing: float = 0.0, least: float = 0.0) -> np.ndarray:
    """(H, W) bool: the pixels farther than `reach` pixels from every
    `known` one and, with `spacing`, also the pixels outside the known
    pixels' footprint farther than `spacing` x the known pixels' local
    spacing around the nearest of them (at least `least`, at most `reach`).
    The footprint is the known pixels closed by a disc of radius `reach`
    (the holes and inlets narrower than twice the reach filled); outside it
    is what of the rest reaches the frame's border (the empty sky beside a
    cloud, not a hole inside it, which keeps the whole reach). The local
    spacing: the square root of the area a known pixel has in a window
    twice the reach wide. Distances come from the distance transforms of
    the 2 x 2 blocks (a block is known where any of its pixels is; within
    1.5 pixels of the full-resolution distance, at a quarter of its cost)."""
    from scipy.ndimage import distance_transform_edt, label, uniform_filter

    h, w = known.shape
    k = np.zeros(((h + 1) // 2 * 2, (w + 1) // 2 * 2), bool)
    k[:h, :w] = known
    count = k.reshape(k.shape[0] // 2, 2, k.shape[1] // 2, 2).sum(axis=(1, 3), dtype=np.float32)
    blocks = count > 0
    if not blocks.any():  # (scipy's transform of an array without a zero is not a distance)
        return np.ones((h, w), bool)
    d, nearest = distance_transform_edt(~blocks, return_indices=True)
    d *= 2.0
    far = d > reach
    if spacing > 0.0 and far.any():  # (none far: all of the frame is in the footprint)
        # closing = the dilation by the reach (~far), eroded by the reach
        # (less a block's slack: the block distances' rounding)
        closed = distance_transform_edt(~far) * 2.0 > reach - 2.0
        open_, _ = label(~closed)
        rim = np.concatenate([open_[0], open_[-1], open_[:, 0], open_[:, -1]])
        outside = np.isin(open_, rim[rim > 0])
        if outside.any():
            # (a window of `reach` blocks is twice the reach wide in pixels)
            share = uniform_filter(count / 4.0, size=max(3, int(reach) | 1), mode="constant")
            local = spacing / np.sqrt(np.maximum(share, 1e-6))
            local = np.clip(local[nearest[0], nearest[1]], least, reach)
            far |= outside & (d > local)
    return np.repeat(np.repeat(far, 2, axis=0), 2, axis=1)[:h, :w]


def _settings(name: str, params: dict[str, float]) -> dict[str, float]:
    """PARAMS[name] with `params` over it; TypeError for a name it has not."""
    unknown = set(params) - set(PARAMS[name])
    if unknown:
        raise TypeError(
            f"guard parameters of {name}: unknown {sorted(unknown)} (it has {sorted(PARAMS[name])})"
        )
    return {k: float(v) for k, v in {**PARAMS[name], **params}.items()}
