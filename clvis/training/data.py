"""Training and validation pairs for the post networks, made with clvis's own
renderers from closed-form scenes with deterministic seeds (no downloads).

In-fill (``iso_frames``): procedural volumes of random parameters and
isovalues, each seen from orbit cameras, rendered by IsoRenderer without
speculation (one candidate block per ray and pass, so the completion grows in
small steps) and snapshotted after the first pass that reaches each asked
completion; the target is the same render run to the end. A finished ray's
pixel is the complete render's (IsoRenderer's rule, asserted here), so a
frame keeps the complete image and, per completion, the mask of the rays
still running and the candidate blocks left on each (IsoImage.candidates).

Volume kinds: "waves" (sums of rotated sine products of random
frequencies, the embedded turbulence's form with random parameters),
"ripples" (Marschner–Lobb with random frequency, depth and axis), "blobs"
(sums of random Gaussians) for training; "gyroid" (a triply periodic minimal
surface of random scale and offset) and the embedded ``turbulence`` are never
trained on: the held-out set (and the suite's "noise", "shapes", "layers").
MORE_TRAIN_VOLUMES, never held out either: "sinusoids" (sums of random plane
waves), "metaballs" (inverse-square falloffs, some ellipsoidal), "csg" (tori,
capsules, capped cylinders and octahedra joined by unions, smooth unions,
subtractions and shells, at isovalues near the solid's own surface: flat
faces, sharp rims) and "labels" (Voronoi cells of random values, smoothed).
``iso_frames(vary=IsoVariety())`` draws per volume its side and frame size
and per view speculation and a surface colour (issue 21's retrain, with
TRAIN_COMPLETIONS; not what the shipped W-Net trained on).

LiDAR (``lidar_frames``): a closed-form scene sampled densely (a random town:
hills, box buildings and tree crowns; or the embedded terrain, which is held
out), one random subset of it as the sparse scan. Input: the scan rendered
with one pixel per point and depth-filtered (FilteredImage.rgbda); target:
the dense cloud rendered with 3x3-pixel points from the same camera, so the
pair is registered exactly.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .. import datasets
from ..camera import Camera

#: what the shipped in-fill W-Net trained on (``clvis train infill``)
TRAIN_VOLUMES = ("waves", "ripples", "blobs")
#: more training families (never held out), made for issue 21's retrain with
#: IsoVariety and TRAIN_COMPLETIONS; trained on them alone with the three the
#: W-Net lost 1 dB on the card's 1280x720 held-out frames at 85 %
#: (bench/results/README.md, "in-fill with more training families"); the
#: shipped W-Net takes a quarter of its last run's crops from them and the
#: three (clvis train infill --mix: clvis.training.train.MIX_VOLUMES)
MORE_TRAIN_VOLUMES = ("sinusoids", "metaballs", "csg", "labels")
HELD_OUT_VOLUMES = ("gyroid", "turbulence")
#: volume families made for ``clvis eval``'s held-out suite alone (never trained on)
EVAL_VOLUMES = ("noise", "shapes", "layers")
VOLUME_KINDS = TRAIN_VOLUMES + MORE_TRAIN_VOLUMES + HELD_OUT_VOLUMES + EVAL_VOLUMES
COMPLETIONS = (0.85, 0.9, 0.95)
#: the completions issue 21's retrain took its pairs at (80-97 %)
TRAIN_COMPLETIONS = (0.8, 0.85, 0.9, 0.95, 0.97)


def _axes(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    c = np.linspace(-1.0, 1.0, n)
    z, y, x = np.meshgrid(c, c, c, indexing="ij")
    return x, y, z


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    return q * np.sign(np.diag(r))


def procedural_volume(kind: str, rng: np.random.Generator, n: int = 64) -> tuple[np.ndarray, float]:
    """(volume [z, y, x] float32 over [-1, 1]^3, isovalue) of the given kind
    with parameters drawn from `rng`; the isovalue is a random quantile of
    the samples (so the surface exists)."""
    x, y, z = _axes(n)
    p = np.stack([x, y, z], axis=-1)
    lo: float | None  # the isovalue's quantile range (lo None: hi is the isovalue)
    hi: float
    if kind == "waves":
        v = np.zeros(x.shape)
        for o in range(int(rng.integers(2, 5))):
            f = rng.uniform(2.0, 5.0) * 1.9**o
            q = p @ _random_rotation(rng).T
            ph = rng.uniform(0, 2 * np.pi, 4)
            v += 0.6**o * (
                np.sin(f * q[..., 0] + ph[0]) * np.sin(f * q[..., 1] + ph[1]) * np.sin(f * q[..., 2] + ph[2])
                + 0.5 * np.sin(f * q.sum(-1) / math.sqrt(3) + ph[3])
            )
        lo, hi = 0.3, 0.7
    elif kind == "ripples":
        q = p @ _random_rotation(rng).T
        fm, alpha = rng.uniform(2.0, 7.0), rng.uniform(0.1, 0.5)
        r = np.sqrt(q[..., 0] ** 2 + q[..., 1] ** 2)
        rho_r = np.cos(2 * np.pi * fm * np.cos(np.pi * r / 2))
        v = (1 - np.sin(np.pi * q[..., 2] / 2) + alpha * (1 + rho_r)) / (2 * (1 + alpha))
        lo, hi = 0.4, 0.6
    elif kind == "blobs":
        v = np.zeros(x.shape)
        for _ in range(int(rng.integers(4, 24))):
            c = rng.uniform(-0.9, 0.9, 3)
            s = rng.uniform(0.08, 0.4)
            v += rng.uniform(0.5, 1.0) * np.exp(-((p - c) ** 2).sum(-1) / (2 * s * s))
        lo, hi = 0.6, 0.9
    elif kind == "sinusoids":  # a sum of random plane waves (directions, wavelengths, phases)
        v = np.zeros(x.shape)
        for _ in range(int(rng.integers(3, 9))):
            d = rng.normal(size=3)
            k = rng.uniform(2.0, 12.0) * d / np.linalg.norm(d)
            v += np.cos(p @ k + rng.uniform(0, 2 * np.pi)) / np.linalg.norm(k)
        lo, hi = 0.3, 0.7
    elif kind == "metaballs":  # Blinn's metaballs: sums of inverse-square falloffs, some ellipsoidal
        v = np.zeros(x.shape)
        for _ in range(int(rng.integers(3, 12))):
            c = rng.uniform(-0.7, 0.7, 3)
            q = ((p - c) @ _random_rotation(rng).T) / rng.uniform(0.6, 1.6, 3)
            r = rng.uniform(0.08, 0.25)
            v += r * r / ((q**2).sum(-1) + 1e-3)
        lo, hi = 0.75, 0.95
    elif kind == "csg":  # CSG of tori, capsules, capped cylinders and octahedra (no spheres or boxes)
        v = _csg(p, rng)
        lo, hi = None, rng.uniform(-0.06, 0.01)  # near the solid's own surface: flat caps and sharp rims
    elif kind == "labels":  # a smoothed label volume: Voronoi cells of random densities
        from scipy.ndimage import gaussian_filter
        from scipy.spatial import cKDTree

        seeds = rng.uniform(-1.0, 1.0, (int(rng.integers(8, 40)), 3))
        _, cell = cKDTree(seeds).query(p.reshape(-1, 3))
        v = rng.random(len(seeds))[cell].reshape(x.shape)
        v = gaussian_filter(v, rng.uniform(0.6, 1.6) * n / 64)
        lo, hi = 0.4, 0.75
    elif kind == "gyroid":
        k = rng.uniform(4.0, 10.0)
        q = p @ _random_rotation(rng).T * k + rng.uniform(0, 2 * np.pi, 3)
        v = (
            np.sin(q[..., 0]) * np.cos(q[..., 1])
            + np.sin(q[..., 1]) * np.cos(q[..., 2])
            + np.sin(q[..., 2]) * np.cos(q[..., 0])
        )
        lo, hi = 0.3, 0.7
    elif kind == "turbulence":
        v = datasets.turbulence(n)["volume"]
        lo, hi = 0.35, 0.65
    elif kind == "noise":  # a smoothed white-noise field (band-limited at a random scale)
        from scipy.ndimage import gaussian_filter

        v = gaussian_filter(rng.normal(size=x.shape), rng.uniform(1.5, 4.0) * n / 64, mode="wrap")
        lo, hi = 0.35, 0.65
    elif kind == "shapes":  # the distance field of a union of random spheres and boxes
        v = np.full(x.shape, np.inf)
        for _ in range(int(rng.integers(3, 9))):
            c, s = rng.uniform(-0.6, 0.6, 3), rng.uniform(0.12, 0.4)
            q = (p - c) @ _random_rotation(rng).T
            if rng.random() < 0.5:
                d = np.sqrt((q**2).sum(-1)) - s
            else:
                e = np.abs(q) - s * rng.uniform(0.5, 1.0, 3)
                d = np.sqrt((np.maximum(e, 0) ** 2).sum(-1)) + np.minimum(e.max(-1), 0)
            v = np.minimum(v, d)
        v = -v
        lo, hi = 0.55, 0.75
    elif kind == "layers":  # CT-like: nested tissue shells of random density, noise, a bone core
        from scipy.ndimage import gaussian_filter

        q = (p @ _random_rotation(rng).T) / rng.uniform(0.5, 0.9, 3)
        r = np.sqrt((q**2).sum(-1))
        v = np.zeros(x.shape)
        for k, level in enumerate(np.sort(rng.uniform(0.2, 1.0, int(rng.integers(2, 5))))[::-1]):
            v = np.where(r < level, 0.3 + 0.25 * k + 0.05 * rng.random(), v)
        v = gaussian_filter(v + 0.04 * rng.normal(size=x.shape), 1.0)
        lo, hi = 0.55, 0.85
    else:
        raise ValueError(f"volume kind: expected one of {VOLUME_KINDS}, got {kind!r}")
    v = v.astype(np.float32)
    if lo is None:  # `hi` is the isovalue itself
        return v, float(hi)
    iso = float(np.quantile(v, rng.uniform(lo, hi)))
    return v, iso


def _csg(p: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Minus the signed distance (inside > 0) of a random constructive solid:
    4-9 primitives (torus, capsule, capped cylinder, octahedron) of random
    pose, each joined to the rest by a union, a smooth union, an
    intersection with its dilation or a subtraction."""
    v: np.ndarray | None = None
    for _ in range(int(rng.integers(4, 10))):
        c, s = rng.uniform(-0.55, 0.55, 3), rng.uniform(0.12, 0.4)
        q = (p - c) @ _random_rotation(rng).T
        shape = int(rng.integers(0, 4))
        if shape == 0:  # torus about z
            ring = np.sqrt(q[..., 0] ** 2 + q[..., 1] ** 2) - s
            d = np.sqrt(ring**2 + q[..., 2] ** 2) - s * rng.uniform(0.2, 0.5)
        elif shape == 1:  # capsule along z
            h = s * rng.uniform(0.5, 2.0)
            z = q[..., 2] - np.clip(q[..., 2], -h, h)
            d = np.sqrt(q[..., 0] ** 2 + q[..., 1] ** 2 + z**2) - s * rng.uniform(0.2, 0.5)
        elif shape == 2:  # capped cylinder along z (flat caps, sharp rims)
            e = np.stack(
                [np.sqrt(q[..., 0] ** 2 + q[..., 1] ** 2) - s, np.abs(q[..., 2]) - s * rng.uniform(0.2, 1.2)],
                -1,
            )
            d = np.sqrt((np.maximum(e, 0) ** 2).sum(-1)) + np.minimum(e.max(-1), 0)
        else:  # octahedron (bound): flat faces at 45 degrees
            d = (np.abs(q).sum(-1) - 1.5 * s) / math.sqrt(3)
        if v is None:
            v = d
            continue
        op = rng.random()
        if op < 0.45:
            v = np.minimum(v, d)
        elif op < 0.7:  # smooth union (polynomial smooth minimum)
            k = rng.uniform(0.05, 0.2)
            t = np.clip(0.5 + 0.5 * (d - v) / k, 0, 1)
            v = d + (v - d) * t - k * t * (1 - t)
        elif op < 0.85:
            v = np.maximum(v, -d)  # carve the primitive out
        else:
            v = np.minimum(v, np.maximum(d, -(d + 0.15)))  # a shell of it
    assert v is not None
    return -v


def orbit_camera(
    rng: np.random.Generator,
    lo: Sequence[float],
    hi: Sequence[float],
    aspect: float,
    zoom: tuple[float, float],
) -> Camera:
    """A camera on a random orbit position around the box [lo, hi], looking at
    a point near its centre, at zoom x the distance that frames its bounding
    sphere (zoom < 1: closer, the surface fills the frame)."""
    lo_, hi_ = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    centre, radius = (lo_ + hi_) / 2, float(np.linalg.norm(hi_ - lo_)) / 2
    fov = rng.uniform(30.0, 50.0)
    d = rng.normal(size=3)
    d[2] *= 0.6
    d /= np.linalg.norm(d)
    half = min(math.radians(fov) / 2, math.atan(aspect * math.tan(math.radians(fov) / 2)))
    dist = rng.uniform(*zoom) * radius / math.sin(half)
    target = centre + rng.uniform(-0.15, 0.15, 3) * radius
    eye = target + dist * d
    near = max(dist - 1.1 * radius, 0.02 * radius)
    return Camera.look_at(eye, target, (0, 0, 1), fov, aspect, near, dist + 1.1 * radius)


@dataclass
class IsoFrame:
    """One in-fill frame: the complete render (``rgb`` premultiplied over
    black, float32 (H, W, 3); ``hit`` bool), per completion the rays still
    running (``active[c]``) and the render's device seconds to reach it
    (``seconds[c]``, 1.0 for the complete one); what it shows (``source``);
    per completion the candidate blocks left on each running ray
    (``candidates[c]``, uint8: IsoImage.candidates) and where the next one
    begins (``next_t[c]``, float32: IsoImage.next_t); the complete render's
    hits' ray parameter (``t``: IsoImage.t, the same at a partial image's
    finished hits)."""

    rgb: np.ndarray
    hit: np.ndarray
    active: dict[float, np.ndarray]
    seconds: dict[float, float]
    source: str
    candidates: dict[float, np.ndarray] = field(default_factory=dict)
    #: per completion the candidate blocks the render had tested (its pass
    #: items; clvis.post.pack.crossing_rate)
    tested: dict[float, int] = field(default_factory=dict)
    t: np.ndarray | None = None
    next_t: dict[float, np.ndarray] = field(default_factory=dict)

    def planes(self, completion: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(rgba, hit, active) of the partial image: what pack_iso takes."""
        a = self.active[completion]
        rgba = np.concatenate([self.rgb, self.hit[..., None].astype(np.float32)], axis=2)
        rgba[a] = 0.0
        return rgba, self.hit & ~a, a

    def candidates_at(self, completion: float) -> np.ndarray:
        """IsoImage.candidates of the partial image (H, W) uint8."""
        return self.candidates[completion]

    def crossing_rate(self, completion: float) -> float:
        """The partial image's crossing rate (clvis.post.pack.crossing_rate)."""
        from ..post.pack import crossing_rate

        return crossing_rate(self.hit, self.active[completion], self.tested[completion])


def iso_frames(
    kinds: Sequence[str],
    count: int,
    seed: int,
    width: int,
    height: int,
    *,
    views: int = 2,
    n: int = 64,
    completions: Sequence[float] = COMPLETIONS,
    progress: Callable[[str], None] | None = None,
    vary: IsoVariety | None = None,
) -> list[IsoFrame]:
    """`count` volumes (kinds in turn) x `views` orbit views each; `vary`:
    what the training randomises per volume and view (None: nothing, the
    renderer's colour, `n`^3 volumes, `width` x `height`, no speculation)."""
    from ..iso import IsoRenderer, color_surface

    rng = np.random.default_rng(seed)
    frames = []
    for i in range(count):
        kind = kinds[i % len(kinds)]
        side = n if vary is None else int(vary.sides[int(rng.integers(0, len(vary.sides)))])
        vol, iso = procedural_volume(kind, rng, side)
        noise = 0.0
        if vary is not None:
            vol, noise = vary.noisy(vol, rng)
        step = 2.0 / (side - 1)
        r = IsoRenderer(vol, rate=8, spacing=(step, step, step), origin=(-1.0, -1.0, -1.0))
        w, h = width, height
        if vary is not None:
            scale = float(vary.scales[int(rng.integers(0, len(vary.scales)))])
            w, h = (
                max(int(round(width * scale)), vary.smallest),
                max(int(round(height * scale)), vary.smallest),
            )
        for v in range(views):
            cam = orbit_camera(rng, (-1, -1, -1), (1, 1, 1), w / h, (0.45, 0.95))
            speculate = vary is not None and bool(rng.random() < vary.speculation)
            color = vary.color(rng) if vary is not None else None
            snaps: dict[float, Any] = {}
            seconds: dict[float, float] = {}
            tested: dict[float, int] = {}
            img = None
            for img in r.passes(cam, w, h, iso, speculation=speculate):
                for c in completions:
                    if c not in snaps and img.completion >= c:
                        snaps[c] = img
                        seconds[c] = float(img.stats["seconds"])
                        tested[c] = int(sum(img.stats["items_per_pass"]))
            assert img is not None
            seconds[1.0] = float(img.stats["seconds"])
            shaded = img.rgba[..., :3] if color is None else color_surface(img, color)[..., :3]
            rgb = np.where(img.hit[..., None], shaded, np.float32(0)).astype(np.float32)
            active, left, nexts = {}, {}, {}
            for c in completions:
                s = snaps.get(c, img)
                done = ~s.active
                # a finished ray's pixel is the complete render's
                assert np.array_equal(s.hit[done], img.hit[done])
                active[c] = s.active.copy()
                left[c] = s.candidates.copy()
                nexts[c] = s.next_t.copy()
                tested.setdefault(c, int(sum(img.stats["items_per_pass"])))
            extra = ""
            if vary is not None:
                extra = f" {side}^3 {w}x{h}" + (" speculation" if speculate else "")
                extra += f" noise {noise:.3f}" if noise else ""
                extra += f" colour {tuple(round(float(c), 2) for c in color)}" if color is not None else ""
            frames.append(
                IsoFrame(
                    rgb,
                    img.hit.copy(),
                    active,
                    seconds,
                    f"{kind} #{i} view {v} iso {iso:.4g}{extra}",
                    left,
                    tested,
                    img.t.copy(),
                    nexts,
                )
            )
            if progress is not None:
                progress(f"iso frame {len(frames)}/{count * views}")
        queues = (r.queue,)
        del r
        _free_held(queues)
    return frames


@dataclass(frozen=True)
class IsoVariety:
    """What the in-fill training draws per volume (its side from `sides`,
    its frames' size the asked one times one of `scales`, never a side below
    `smallest`) and per view (speculation with probability `speculation`; a
    random surface colour, shaded as the renderer shades, with probability
    `colors`, else the renderer's own)."""

    sides: tuple[int, ...] = (48, 64, 96)
    #: of the asked size (1280x720 in the release: 1.5 is 1920x1080, the
    #: largest frame issue 21's targets name)
    scales: tuple[float, ...] = (1.5, 1.0, 0.75, 0.5)
    smallest: int = 64
    speculation: float = 0.3
    colors: float = 0.5
    #: per volume, with probability `noise`, acquisition noise: white noise
    #: smoothed over a Gaussian of sigma `noise_sigma` voxels (a range),
    #: scaled to `noise_amp` (a range) x the volume's standard deviation, as
    #: a CT or MRI scan carries it; the isovalue stays the clean volume's, so
    #: where the field is flat near it the surface breaks into speckle that
    #: rays pass by (none of the smooth training families has any)
    noise: float = 0.0
    noise_amp: tuple[float, float] = (0.02, 0.12)
    noise_sigma: tuple[float, float] = (0.6, 1.5)

    def noisy(self, volume: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, float]:
        """(the volume with acquisition noise, its amplitude over the
        volume's standard deviation; `volume` itself and 0.0 where none is
        drawn); `rng` is not drawn from where `noise` is 0 (the frames are
        those drawn without it)."""
        if self.noise <= 0.0 or rng.random() >= self.noise:
            return volume, 0.0
        from scipy.ndimage import gaussian_filter

        amp = float(rng.uniform(*self.noise_amp))
        sigma = float(rng.uniform(*self.noise_sigma))
        w = gaussian_filter(rng.normal(size=volume.shape), sigma, mode="wrap")
        w *= amp * float(volume.std()) / max(float(w.std()), 1e-12)
        return (volume + w).astype(np.float32), amp

    def color(self, rng: np.random.Generator) -> tuple[float, float, float] | None:
        """A surface colour (r, g, b) or None (the renderer's); one draw of
        `rng` more where it is random."""
        if rng.random() >= self.colors:
            return None
        c = rng.uniform(0.15, 1.0, 3)
        return (float(c[0]), float(c[1]), float(c[2]))


# ---------------------------------------------------------------------------
# LiDAR scenes

_RAMP = np.array([[40, 90, 40], [120, 160, 70], [190, 170, 120], [235, 235, 230]], np.float64)


def _ramp(level: np.ndarray) -> np.ndarray:
    at = np.linspace(0.0, 1.0, len(_RAMP))
    return np.stack([np.interp(level, at, _RAMP[:, c]) for c in range(3)], axis=1)


def town(n: int, seed: int) -> dict:
    """A random town of `n` points over 200 x 200 m: rolling hills, 5-14 box
    buildings of random size and roof colour (roofs and walls), 10-40 tree
    crowns; ground coloured by height like the terrain. positions (n, 3)
    float32, colors (n, 4) uint8."""
    rng = np.random.default_rng(seed)
    hills = [(rng.uniform(-100, 100, 2), rng.uniform(20, 70), rng.uniform(-8, 15)) for _ in range(4)]

    def ground(x, y):
        z = np.zeros_like(x)
        for (cx, cy), s, h in hills:
            z += h * np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * s * s))
        return z

    nb = int(rng.integers(5, 15))
    b = np.stack(
        [rng.uniform(-80, 80, nb), rng.uniform(-80, 80, nb), rng.uniform(5, 20, nb), rng.uniform(5, 20, nb)],
        axis=1,
    )
    bh = rng.uniform(6, 35, nb)
    roof = rng.uniform(60, 230, (nb, 3))
    nt = int(rng.integers(10, 40))
    trees = np.stack([rng.uniform(-95, 95, nt), rng.uniform(-95, 95, nt), rng.uniform(3, 8, nt)], axis=1)
    n_wall = n // 10
    n_top = n - n_wall
    x, y = rng.uniform(-100, 100, n_top), rng.uniform(-100, 100, n_top)
    z = ground(x, y)
    col = _ramp(np.clip((z + 8) / 50, 0, 1))
    for (tx, ty, tr), th in zip(trees, rng.uniform(6, 14, nt), strict=True):
        d2 = (x - tx) ** 2 + (y - ty) ** 2
        m = d2 < tr * tr
        z[m] = ground(np.array(tx), np.array(ty)) + th + 2 * np.sqrt(1 - d2[m] / (tr * tr))
        col[m] = (50, 110 + 30 * rng.random(), 45)
    for k in range(nb):
        m = (np.abs(x - b[k, 0]) <= b[k, 2]) & (np.abs(y - b[k, 1]) <= b[k, 3])
        z[m] = ground(b[k, 0], b[k, 1]) + bh[k]
        col[m] = roof[k]
    wall = rng.integers(0, nb, n_wall)  # the building of each wall point
    side = rng.integers(0, 4, n_wall)
    along = rng.uniform(-1, 1, n_wall)
    sign = np.where(side % 2 == 0, -1.0, 1.0)
    wx = np.where(side < 2, b[wall, 0] + along * b[wall, 2], b[wall, 0] + sign * b[wall, 2])
    wy = np.where(side < 2, b[wall, 1] + sign * b[wall, 3], b[wall, 1] + along * b[wall, 3])
    wz = ground(b[wall, 0], b[wall, 1]) + rng.random(n_wall) * bh[wall]
    wcol = roof[wall] * 0.6
    pos = np.stack([np.concatenate([x, wx]), np.concatenate([y, wy]), np.concatenate([z, wz])], 1)
    colors = np.concatenate([col, wcol])
    rgba = np.concatenate([np.clip(np.rint(colors), 0, 255), np.full((n, 1), 255.0)], 1).astype(np.uint8)
    return {"positions": pos.astype(np.float32), "colors": rgba}


#: scikit-image's bundled sample photographs (no download) for ``photo_town``
PHOTOS = ("astronaut", "coffee", "chelsea", "rocket")


def photo_town(n: int, seed: int) -> dict:
    """A random town's geometry (``town``) coloured by a photograph of
    scikit-image's samples draped over it from above (walls a darker shade of
    the photo at their foot): natural-image textures the LiDAR network never
    trained on, for the held-out suite."""
    from skimage import data as skdata

    rng = np.random.default_rng(seed)
    photo = np.asarray(getattr(skdata, PHOTOS[int(rng.integers(0, len(PHOTOS)))])(), np.float64)[..., :3]
    return _draped_town(n, seed, photo)


def _draped_town(n: int, seed: int, image: np.ndarray) -> dict:
    """``town(n, seed)``'s geometry under `image` ((H, W, 3) RGB 0..255)
    draped from above over its 200 x 200 m, its walls (town's last n // 10
    points) a darker shade (0.6) of the image at their foot."""
    pos = town(n, seed)["positions"]
    h, w = image.shape[:2]
    u = np.clip(((pos[:, 0] + 100) / 200 * (w - 1)).astype(int), 0, w - 1)
    v = np.clip(((100 - pos[:, 1]) / 200 * (h - 1)).astype(int), 0, h - 1)
    col = image[v, u]
    col[np.arange(n) >= n - n // 10] *= 0.6
    rgba = np.concatenate([np.clip(np.rint(col), 0, 255), np.full((n, 1), 255.0)], 1).astype(np.uint8)
    return {"positions": pos, "colors": rgba}


def procedural_texture(rng: np.random.Generator, size: int = 512) -> np.ndarray:
    """A (size, size, 3) float64 RGB 0..255 texture with a natural image's
    statistics but no photograph in it: a luminance field of power spectrum
    1/f^beta (beta 1.6-2.4, as photographs have), two smoother chroma
    fields about a random base colour, and 8-60 Voronoi regions of their own
    colour offset and contrast (the hard edges between objects)."""
    from scipy.spatial import cKDTree

    f = np.fft.fftfreq(size)
    r = np.hypot(*np.meshgrid(f, f))
    r[0, 0] = 1.0

    def field(beta: float) -> np.ndarray:
        spec = r ** (-beta / 2) * np.exp(2j * np.pi * rng.random((size, size)))
        spec[0, 0] = 0.0
        v = np.real(np.fft.ifft2(spec))
        return v / max(float(v.std()), 1e-12)

    lum = field(float(rng.uniform(1.6, 2.4)))
    chroma = [field(float(rng.uniform(2.4, 3.2))) for _ in range(2)]
    yy, xx = np.mgrid[0:size, 0:size]
    seeds = rng.uniform(0, size, (int(rng.integers(8, 61)), 2))
    cell = cKDTree(seeds).query(np.stack([yy.ravel(), xx.ravel()], 1))[1].reshape(size, size)
    base = rng.uniform(40, 200, 3)
    offset = rng.normal(0, 30, (len(seeds), 3))[cell]
    contrast = rng.uniform(10, 45, len(seeds))[cell]
    # the chroma axes: two random directions orthogonal to grey
    a = np.cross(np.ones(3), rng.normal(size=3))
    a /= np.linalg.norm(a)
    b = np.cross(np.ones(3) / math.sqrt(3), a)
    rgb = (
        base
        + offset
        + contrast[..., None] * lum[..., None]
        + rng.uniform(5, 25) * (chroma[0][..., None] * a + chroma[1][..., None] * b)
    )
    return np.clip(rgb, 0, 255)


def texture_town(n: int, seed: int) -> dict:
    """A random town's geometry (``town``) under a procedural texture
    (procedural_texture) draped from above, walls a darker shade of the
    texture at their foot, as ``photo_town`` drapes a photograph: the
    LiDAR network's training sees natural-image statistics without the
    held-out suite's photographs."""
    return _draped_town(n, seed, procedural_texture(np.random.default_rng(seed + 1)))


@dataclass
class LidarFrame:
    """One LiDAR frame: ``rgbda`` (H, W, 5) float32, the depth-filtered sparse
    scan (FilteredImage.rgbda); ``rgb`` (H, W, 3) float32 in [0, 1], the dense
    render; ``source``; ``index``: the scan's G-buffer point index (H, W)
    uint32 where lidar_frames was asked for it (the guard's whole points),
    else None."""

    rgbda: np.ndarray
    rgb: np.ndarray
    source: str
    index: np.ndarray | None = None

    def filtered(self) -> Any:
        """The frame's scan as the FilteredImage a network's call takes
        (rgbda and the point index)."""
        from ..raster.depth_filter import FilteredImage

        kept = self.rgbda[..., 4] > 0
        return FilteredImage(kept, self.rgbda[..., 3], None, self.rgbda, self.index)


def lidar_frames(
    scenes: Sequence[str],
    count: int,
    seed: int,
    width: int,
    height: int,
    *,
    views: int = 3,
    dense_points: int = 3_000_000,
    sparse: tuple[float, float] = (0.03, 0.12),
    point_size: int | tuple[int, int] = 1,
    progress: Callable[[str], None] | None = None,
    index: bool = False,
) -> list[LidarFrame]:
    """`count` scenes ("town": a random town per scene; "terrain": the
    embedded terrain) x `views` oblique views each; the scan's points are
    drawn `point_size` pixels a side before the depth filter (lo, hi: drawn
    per view from lo..hi); `index`: keep each scan's point index (LidarFrame.index)."""
    from ..raster import Rasterizer, depth_filter

    rng = np.random.default_rng(seed)
    frames = []
    for i in range(count):
        kind = scenes[i % len(scenes)]
        s = int(rng.integers(0, 2**31))
        if kind == "town":
            cloud = town(dense_points, s)
        elif kind == "terrain":
            cloud = datasets.terrain(dense_points, s)
        elif kind == "photo":
            cloud = photo_town(dense_points, s)
        elif kind == "texture_town":
            cloud = texture_town(dense_points, s)
        else:
            raise ValueError(f"scene: expected 'town', 'texture_town', 'terrain' or 'photo', got {kind!r}")
        pos, col = cloud["positions"], cloud["colors"]
        keep = rng.random(len(pos)) < rng.uniform(*sparse)
        dense = Rasterizer(pos, colors=col)
        scan = Rasterizer(pos[keep], colors=col[keep])
        lo, hi = pos.min(0), pos.max(0)
        centre = (lo + hi) / 2
        extent = float(np.linalg.norm(hi[:2] - lo[:2])) / 2
        for v in range(views):
            az = rng.uniform(0, 2 * np.pi)
            el = np.radians(rng.uniform(20, 60))
            dist = extent * rng.uniform(0.5, 1.2)
            target = centre + np.r_[rng.uniform(-0.3, 0.3, 2) * extent, 0.0]
            target[2] = lo[2]
            eye = target + dist * np.array([np.cos(az) * np.cos(el), np.sin(az) * np.cos(el), np.sin(el)])
            cam = Camera.look_at(eye, target, (0, 0, 1), rng.uniform(40, 60), width / height, 1.0, 4 * extent)
            g = dense.render(cam, width, height, point_size=3, planes=[])
            rgb = np.where((g.index != 0xFFFFFFFF)[..., None], g.rgba[..., :3] / np.float32(255), 0)
            ps = (
                int(rng.integers(point_size[0], point_size[1] + 1))
                if isinstance(point_size, tuple)
                else point_size
            )
            f = depth_filter(scan.render(cam, width, height, point_size=ps, planes=[]))
            frames.append(
                LidarFrame(
                    np.asarray(f.rgbda),
                    rgb.astype(np.float32),
                    f"{kind} seed {s} view {v}",
                    np.asarray(f.index).copy() if index and f.index is not None else None,
                )
            )
            if progress is not None:
                progress(f"lidar frame {len(frames)}/{count * views}")
        queues = (dense.queue, scan.queue)
        del dense, scan
        _free_held(queues)
    return frames


# ---------------------------------------------------------------------------
# NARVis: rasterizer G-buffers -> the Gaussian renderer's image

#: the slow renderer NARVis replaces ("GR"): one Gaussian per particle, its
#: standard deviation NARVIS_SIGMA x the median distance to the 4 nearest
#: neighbours across the flow and NARVIS_STRETCH times that along the
#: velocity, opacity NARVIS_OPACITY, composited front to back (max response)
#: with the transfer function the rasterizer colours by
NARVIS_STRETCH = 4.0
NARVIS_SIGMA = 1.0
NARVIS_OPACITY = 0.5
NARVIS_ATTRIBUTE = "temperature"
#: the models GR may render NARVis's targets with (``clvis train narvis
#: --target``): "max_response" (the ray model, the default) or "splat" (3DGS's
#: forward pass, the paper's own GR)
NARVIS_TARGETS = ("max_response", "splat")
NARVIS_COLORMAP = "viridis"
#: the generalisation set: the storm this many seconds later (the rain bands
#: wound up by the differential rotation), from other particles
NARVIS_STORM_TIME = 1200.0


#: the subsample (seed 0) whose median 4-NN distance gives GR's spacing
NARVIS_SPACING_SAMPLE = 200_000


def narvis_sigma(positions: Any) -> float:
    """GR's base standard deviation (world units) for a cloud: NARVIS_SIGMA x
    the median distance to the 4 nearest neighbours of a subsample
    (NARVIS_SPACING_SAMPLE points, seed 0), scaled to the whole cloud's
    density. The one number both GR's Gaussians (across the flow; x
    NARVIS_STRETCH along it) and the narvis radius plane (narvis_radius,
    projected to pixels by the rasterizer: GBuffers.radius_px) are made of.
    positions: (N, 3) finite coordinates."""
    from ..gauss.points import knn_mean_distance

    pos = np.asarray(positions)
    sample = pos[np.random.default_rng(0).permutation(len(pos))[:NARVIS_SPACING_SAMPLE]]
    # the median 4-NN distance of a subsample, scaled to the whole cloud's density
    spacing = float(np.median(knn_mean_distance(sample, 4))) * (len(sample) / max(len(pos), 1)) ** (1 / 3)
    return NARVIS_SIGMA * spacing


def narvis_radius(positions: Any, sigma: float | None = None) -> np.ndarray:
    """(N,) float32: every point's world radius for the rasterizer's radius
    plane as narvis sees it, GR's sigma (narvis_sigma(positions), or `sigma`
    when already known)."""
    pos = np.asarray(positions)
    return np.full(len(pos), narvis_sigma(pos) if sigma is None else sigma, np.float32)


@dataclass
class NarvisScene:
    """A particle cloud and how both renderers colour it: by ``attribute``
    through ``colormap`` over ``value_range``. ``sigma``: GR's base sigma
    (narvis_sigma of the cloud's positions, computed on first use when not
    given)."""

    cloud: Any
    attribute: str
    value_range: tuple[float, float]
    colormap: str
    source: str
    sigma: float | None = None

    def gr_sigma(self) -> float:
        """GR's base sigma (world units): ``sigma``, computed once."""
        if self.sigma is None:
            self.sigma = narvis_sigma(self.cloud.positions)
        return self.sigma

    def rasterizer(self, queue: Any = None) -> Any:
        from ..raster import Rasterizer

        return Rasterizer(self.cloud, queue=queue)

    def gbuffers(
        self, ras: Any, camera: Camera, width: int, height: int, planes: Sequence[str], **kw: Any
    ) -> Any:
        """The MACR G-buffers of a view, one pixel per point, coloured by the
        transfer function, with the attribute planes `planes` names."""
        from ..post.names import GBUFFER_PLANES

        kw.setdefault("colormap", self.colormap)
        kw.setdefault("value_range", self.value_range)
        return ras.render(
            camera,
            width,
            height,
            color_by=self.attribute,
            planes=[p for p in planes if p not in GBUFFER_PLANES],
            **kw,
        )

    def gaussian_renderer(self, queue: Any = None, model: str = "max_response") -> Any:
        """The Gaussian renderer over the velocity-elongated Gaussians (GR),
        rendering with `model` (one of NARVIS_TARGETS)."""
        from ..colormap import TransferFunction
        from ..gauss import GaussianRenderer, gaussians_from_points

        if model not in NARVIS_TARGETS:
            raise ValueError(f"target: expected one of {', '.join(NARVIS_TARGETS)}, got {model!r}")
        g = gaussians_from_points(
            self.cloud,
            velocity="cloud",
            stretch=NARVIS_STRETCH,
            scale=self.gr_sigma(),
            opacity=NARVIS_OPACITY,
            color_by=self.attribute,
        )
        tf = TransferFunction(self.colormap, value_range=self.value_range)
        return GaussianRenderer(g, tf, queue=queue, colors=False, model=model)


def narvis_scene(kind: str, n: int, seed: int) -> NarvisScene:
    """The scene "hurricane" (the embedded one at time 0) or "storm" (the hurricane
    NARVIS_STORM_TIME seconds later, the generalisation set), `n` particles
    from `seed`, with the velocity's components as attribute planes vx, vy,
    vz (the paper's Vel3D) beside pressure, temperature and speed."""
    from ..io import PointCloud

    if kind not in ("hurricane", "storm"):
        raise ValueError(f"scene: expected 'hurricane' or 'storm', got {kind!r}")
    d = datasets.hurricane(n, seed, time=NARVIS_STORM_TIME if kind == "storm" else 0.0)
    v = d["velocity"]
    attrs = {**d["attributes"], "vx": v[:, 0], "vy": v[:, 1], "vz": v[:, 2]}
    cloud = PointCloud(d["positions"], colors=d["colors"], attributes=attrs, velocity=v)
    # the radius plane narvis reads: GR's sigma, the same number its Gaussians are made of
    sigma = narvis_sigma(cloud.positions)
    cloud.radius = narvis_radius(cloud.positions, sigma)
    a = attrs[NARVIS_ATTRIBUTE]
    vr = (float(a.min()), float(a.max()))
    t = f", t = {NARVIS_STORM_TIME:g} s" if kind == "storm" else ""
    return NarvisScene(
        cloud, NARVIS_ATTRIBUTE, vr, NARVIS_COLORMAP, f"{kind} ({n:,} particles, seed {seed}{t})", sigma
    )


def narvis_cameras(scene: NarvisScene, sampler: str, aspect: float = 1.0) -> list[Camera]:
    """The NARVis sampler's cameras around the scene ("hemisphere": 128;
    "grid": grid_cameras with count 2, 96, keeping those that look at the
    storm: the centre of the box within 40 degrees of the view axis)."""
    from ..camera import grid_cameras, hemisphere_cameras

    pos = scene.cloud.positions
    lo, hi = pos.min(0), pos.max(0)
    if sampler == "hemisphere":
        return list(hemisphere_cameras(lo, hi, aspect=aspect))
    if sampler != "grid":
        raise ValueError(f"sampler: expected 'hemisphere' or 'grid', got {sampler!r}")
    centre = (lo + hi) / 2
    keep = []
    for cam in grid_cameras(lo, hi, count=2, aspect=aspect):
        eye = np.asarray(cam.eye, np.float64)
        fwd = np.asarray(cam.forward, np.float64)
        to = centre - eye
        if np.dot(fwd, to) / np.linalg.norm(to) > math.cos(math.radians(40)):
            keep.append(cam)
    return keep


@dataclass
class NarvisFrame:
    """One NARVis pair: ``x`` the packed G-buffers (C, H, W) float32 (the
    channels of clvis.post.names.gbuffer_channels(planes)), ``rgb`` the
    Gaussian renderer's image (H, W, 3) premultiplied over black; the seconds
    each renderer took and what it shows."""

    x: np.ndarray
    rgb: np.ndarray
    seconds: dict[str, float]
    source: str


#: the colormaps NARVis's training may colour a view with (``looks``);
#: "magma" stays out: clvis eval's unseen-colormap family uses it
NARVIS_TRAIN_COLORMAPS = (
    "viridis",
    "plasma",
    "inferno",
    "cividis",
    "turbo",
    "coolwarm",
    "gray",
    "YlGnBu",
    "Spectral",
    "RdBu",
    "PiYG",
    "jet",
    "hot",
    "cool",
    "spring",
    "summer",
    "autumn",
    "winter",
    "twilight",
    "ocean",
    "terrain",
    "rainbow",
    "Blues",
    "Oranges",
    "copper",
    "bone",
    "cubehelix",
    "gnuplot",
)


def narvis_flow_scene(kind: str, n: int, seed: int, colormap: str = NARVIS_COLORMAP) -> NarvisScene:
    """A scene of clvis.training.flows' flow `kind` (`n` particles from
    `seed`), coloured by its scalar ("temperature") through `colormap` over
    the scalar's range."""
    from ..io import PointCloud
    from . import flows

    d = flows.flow(kind, n, seed)
    cloud = PointCloud(d["positions"], attributes=d["attributes"], velocity=d["velocity"])
    sigma = narvis_sigma(cloud.positions)
    cloud.radius = narvis_radius(cloud.positions, sigma)
    a = d["attributes"]["temperature"]
    return NarvisScene(
        cloud,
        "temperature",
        (float(a.min()), float(a.max())),
        colormap,
        f"{kind} ({n:,} particles)",
        sigma,
    )


def narvis_looks(
    scene: NarvisScene, count: int, rng: np.random.Generator
) -> list[tuple[str, tuple[float, float]]]:
    """`count` random transfer functions for the scene's views: a colormap of
    NARVIS_TRAIN_COLORMAPS (reversed half the time) and a value range
    from 40 % inside to 20 % beyond the attribute's (the colour arrives in
    the input planes: the network must carry it, not memorise it)."""
    lo, hi = scene.value_range
    span = hi - lo
    out = []
    for _ in range(count):
        cmap = NARVIS_TRAIN_COLORMAPS[int(rng.integers(0, len(NARVIS_TRAIN_COLORMAPS)))]
        cmap += "_r" if rng.random() < 0.5 else ""
        a, b = lo + span * rng.uniform(-0.2, 0.4), hi - span * rng.uniform(-0.2, 0.4)
        out.append((cmap, (float(a), float(max(b, a + 0.05 * span)))))
    return out


def narvis_frames(
    scene: NarvisScene,
    cameras: Sequence[Camera],
    width: int,
    height: int,
    planes: Sequence[str],
    *,
    looks: Sequence[tuple[str, tuple[float, float]]] | None = None,
    progress: Callable[[str], None] | None = None,
    target: str = "max_response",
) -> list[NarvisFrame]:
    """Both renders of each camera's view; `looks`: per camera a (colormap,
    value range) both renderers colour it with (default the scene's);
    `target`: the Gaussian renderer's model (NARVIS_TARGETS)."""
    import time

    from ..colormap import TransferFunction
    from ..post.pack import pack_gbuffers

    if looks is not None and len(looks) != len(cameras):
        raise ValueError(f"looks: {len(looks)} for {len(cameras)} cameras")
    gr = scene.gaussian_renderer(model=target)
    ras = scene.rasterizer()
    frames = []
    for i, cam in enumerate(cameras):
        t0 = time.perf_counter()
        if looks is None:
            g = scene.gbuffers(ras, cam, width, height, planes)
            t1 = time.perf_counter()
            img = gr.render(cam, width, height)
        else:
            cmap, vr = looks[i]
            g = scene.gbuffers(ras, cam, width, height, planes, colormap=cmap, value_range=vr)
            t1 = time.perf_counter()
            img = gr.render(cam, width, height, transfer_function=TransferFunction(cmap, value_range=vr))
        t2 = time.perf_counter()
        rgb = np.clip(np.asarray(img.rgba)[..., :3], 0, 1).astype(np.float32)
        x = np.asarray(pack_gbuffers(g, planes))[0]
        frames.append(
            NarvisFrame(x, rgb, {"raster": t1 - t0, "gaussians": t2 - t1}, f"{scene.source} view {i}")
        )
        if progress is not None:
            progress(f"narvis frame {len(frames)}/{len(cameras)} ({t2 - t1:.1f} s Gaussians)")
    queues = (gr.queue, ras.queue)
    gr = ras = g = img = None
    _free_held(queues)
    return frames


def _free_held(queues: Sequence[Any]) -> None:
    """After a scene's renderers and images are dropped: give the buffers the
    queues' memory pools kept back (the pool keeps a freed block of each
    size, and the next scene's sizes differ: rendered one after another in
    one process, scenes grew it by each scene's Gaussians and G-buffers)."""
    from .. import runtime

    for q in dict.fromkeys(queues):
        runtime.free_held(q)


# ---------------------------------------------------------------------------
# narvis-scan: clouds without velocity (LAS/LAZ/PLY scans) -> isotropic Gaussians

#: what narvis-scan trains on: the random town (height-ramp colours), the
#: town's geometry under scikit-image's photographs, and random shapes (spheres,
#: boxes, cylinders on a floor) textured by those photographs
SCAN_TRAIN = ("town", "photo_town", "shapes")
#: its held-out generator families (never in its training): the embedded
#: terrain, a LAS-like aerial strip scan (fields, roads, roofs, trees along
#: scan lines) and a scanned-object-like closed surface of painted albedo
SCAN_HELD_OUT = ("terrain", "aerial", "object")
SCAN_KINDS = SCAN_TRAIN + SCAN_HELD_OUT
#: the target's Gaussians: isotropic, sigma the point's mean 4-NN distance
#: (clvis.gauss.points.knn_sigma: the paper's Morro Bay mapping), this opacity,
#: each carrying its point's colour, rendered by 3DGS's splatting (model "splat")
SCAN_K = 4
SCAN_OPACITY = 0.8
#: a scan scene's points per frame pixel at density 1 (n = density x this x W x H)
SCAN_POINTS_PER_PIXEL = 4.0


def _photo(rng: np.random.Generator) -> np.ndarray:
    """One of scikit-image's sample photographs (PHOTOS), float64 RGB 0..255."""
    from skimage import data as skdata

    return np.asarray(getattr(skdata, PHOTOS[int(rng.integers(0, len(PHOTOS)))])(), np.float64)[..., :3]


def _texture(photo: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The photo's colours at (u, v) in [0, 1] (wrapped)."""
    h, w = photo.shape[:2]
    return photo[(np.mod(v, 1.0) * (h - 1)).astype(int), (np.mod(u, 1.0) * (w - 1)).astype(int)]


def shapes_scene(n: int, seed: int) -> dict:
    """Random shapes on a floor, `n` points on their surfaces (by area): 3-8
    spheres, boxes and upright cylinders of random size over a 3 x 3 floor,
    each surface textured by a scikit-image photograph (a random crop and
    scale of it). positions (n, 3) float32, colors (n, 4) uint8."""
    rng = np.random.default_rng(seed)
    photos = [_photo(rng) for _ in range(3)]
    prims = []
    for _ in range(int(rng.integers(3, 9))):
        kind = ("sphere", "box", "cylinder")[int(rng.integers(0, 3))]
        c = np.r_[rng.uniform(-1.1, 1.1, 2), 0.0]
        s = rng.uniform(0.15, 0.5, 3)
        if kind == "sphere":
            area = 4 * math.pi * s[0] ** 2
        elif kind == "box":
            area = 2 * (s[0] * s[1] + s[1] * s[2] + s[0] * s[2]) * 4
        else:
            area = 2 * math.pi * s[0] * 2 * s[2] + math.pi * s[0] ** 2
        prims.append(
            (kind, c, s, area, photos[int(rng.integers(0, 3))], rng.uniform(0, 1, 2), rng.uniform(0.3, 1))
        )
    floor_area = 9.0
    areas = np.array([floor_area] + [p[3] for p in prims])
    counts = rng.multinomial(n, areas / areas.sum())
    pos_parts, col_parts = [], []
    m = counts[0]  # the floor
    x, y = rng.uniform(-1.5, 1.5, m), rng.uniform(-1.5, 1.5, m)
    pos_parts.append(np.stack([x, y, np.zeros(m)], 1))
    col_parts.append(_texture(photos[0], (x + 1.5) / 3, (1.5 - y) / 3) * 0.8)
    for (kind, c, s, _, photo, off, zoom), m in zip(prims, counts[1:], strict=True):
        if kind == "sphere":
            d = rng.normal(size=(m, 3))
            d /= np.linalg.norm(d, axis=1, keepdims=True)
            p = c + np.r_[0, 0, s[0]] + s[0] * d
            u, v = (
                np.arctan2(d[:, 1], d[:, 0]) / (2 * math.pi) + 0.5,
                np.arccos(np.clip(d[:, 2], -1, 1)) / math.pi,
            )
        elif kind == "box":
            q = rng.uniform(-1, 1, (m, 3))
            face = rng.integers(0, 3, m)
            q[np.arange(m), face] = np.where(rng.random(m) < 0.5, -1.0, 1.0)
            p = c + np.r_[0, 0, s[2]] + q * s
            u = np.where(face == 0, q[:, 1], q[:, 0]) * 0.5 + 0.5
            v = np.where(face == 2, q[:, 1], q[:, 2]) * 0.5 + 0.5
        else:
            a = rng.uniform(0, 2 * math.pi, m)
            side = rng.random(m) < (2 * s[2] / (2 * s[2] + s[0]))
            r = np.where(side, s[0], s[0] * np.sqrt(rng.random(m)))
            z = np.where(side, rng.uniform(0, 2 * s[2], m), 2 * s[2])
            p = c + np.stack([r * np.cos(a), r * np.sin(a), z], 1)
            u, v = a / (2 * math.pi), np.where(side, 1 - z / (2 * s[2]), r / s[0])
        pos_parts.append(p)
        col_parts.append(_texture(photo, off[0] + u * zoom, off[1] + v * zoom))
    pos = np.concatenate(pos_parts).astype(np.float32)
    col = np.concatenate(col_parts)
    rgba = np.concatenate([np.clip(np.rint(col), 0, 255), np.full((len(pos), 1), 255.0)], 1).astype(np.uint8)
    return {"positions": pos, "colors": rgba}


def aerial_scene(n: int, seed: int) -> dict:
    """A LAS-like airborne strip scan of `n` points over 300 x 300 m: the
    returns lie along scan lines across the flight (a line every ~0.5 %
    of the strip, jittered), over gently rolling farmland of Voronoi fields
    (each its crop colour and row stripes), two straight roads, 4-12 box
    buildings with red or grey roofs and clumps of dark trees."""
    rng = np.random.default_rng(seed)
    lines = max(int(math.sqrt(n) / 2), 8)
    li = rng.integers(0, lines, n)
    y = -150 + 300 * (li + 0.5 + rng.normal(0, 0.08, n)) / lines
    x = rng.uniform(-150, 150, n)
    bumps = [(rng.uniform(-150, 150, 2), rng.uniform(40, 120), rng.uniform(-4, 6)) for _ in range(5)]
    z = np.zeros(n)
    for (cx, cy), s, hgt in bumps:
        z += hgt * np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * s * s))
    seeds = rng.uniform(-150, 150, (int(rng.integers(12, 30)), 2))
    crop = np.array(
        [[95, 140, 60], [150, 170, 80], [200, 180, 110], [120, 95, 60], [170, 150, 70], [80, 120, 50]]
    )
    field_col = crop[rng.integers(0, len(crop), len(seeds))] * rng.uniform(0.85, 1.15, (len(seeds), 1))
    field_dir = rng.uniform(0, math.pi, len(seeds))
    from scipy.spatial import cKDTree

    f = cKDTree(seeds).query(np.stack([x, y], 1))[1]
    stripe = 0.85 + 0.15 * np.sin(
        (x * np.cos(field_dir[f]) + y * np.sin(field_dir[f])) * rng.uniform(1.5, 3.0)
    )
    col = field_col[f] * stripe[:, None]
    for _ in range(2):  # roads
        a, off, w = rng.uniform(0, math.pi), rng.uniform(-100, 100), rng.uniform(4, 8)
        on = np.abs(x * math.sin(a) - y * math.cos(a) - off) < w / 2
        col[on] = (120, 118, 115)
    for _ in range(int(rng.integers(4, 13))):  # buildings
        bx, by = rng.uniform(-130, 130, 2)
        sx, sy, bh = rng.uniform(6, 18), rng.uniform(6, 18), rng.uniform(4, 15)
        on = (np.abs(x - bx) < sx) & (np.abs(y - by) < sy)
        z[on] += bh
        col[on] = (170, 70, 55) if rng.random() < 0.5 else (150, 150, 155)
    for _ in range(int(rng.integers(5, 20))):  # tree clumps
        tx, ty, tr = rng.uniform(-140, 140), rng.uniform(-140, 140), rng.uniform(4, 12)
        d2 = (x - tx) ** 2 + (y - ty) ** 2
        on = d2 < tr * tr
        z[on] += rng.uniform(8, 16) * np.sqrt(1 - d2[on] / (tr * tr))
        col[on] = np.array([40, 75, 35]) * rng.uniform(0.8, 1.2, (int(on.sum()), 1))
    col *= rng.uniform(0.9, 1.1, (n, 1))  # return-to-return variation
    pos = np.stack([x, y, z + rng.normal(0, 0.05, n)], 1).astype(np.float32)
    rgba = np.concatenate([np.clip(np.rint(col), 0, 255), np.full((n, 1), 255.0)], 1).astype(np.uint8)
    return {"positions": pos, "colors": rgba}


def object_scene(n: int, seed: int) -> dict:
    """A scanned-object-like cloud: `n` points on a closed bumpy surface
    (a sphere whose radius is modulated by 4-9 random waves over the
    directions, stretched on random axes) with a painted albedo: hue bands
    along a random axis, a fine noise and dark spots; the points denser
    toward the top (a turntable scanner's), with range noise."""
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n, 3))
    d[:, 2] = np.abs(d[:, 2]) * np.where(rng.random(n) < 0.7, 1, -1)  # more returns on the upper half
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r = np.ones(n)
    for _ in range(int(rng.integers(4, 10))):
        k = rng.normal(size=3)
        k *= rng.uniform(2, 7) / np.linalg.norm(k)
        r += rng.uniform(0.03, 0.12) * np.sin(d @ k + rng.uniform(0, 2 * math.pi))
    p = d * r[:, None] * rng.uniform(0.6, 1.3, 3)
    p += rng.normal(0, 0.003, p.shape)
    axis = _random_rotation(rng)[0]
    t = p @ axis
    hues = rng.uniform(0, 255, (4, 3))
    band = np.clip(((t - t.min()) / max(np.ptp(t), 1e-9) * 4).astype(int), 0, 3)
    col = hues[band] * (0.8 + 0.2 * np.sin(p @ rng.normal(size=3) * 25))[:, None]
    for _ in range(int(rng.integers(5, 15))):
        c = rng.normal(size=3)
        c /= np.linalg.norm(c)
        col[(d @ c) > rng.uniform(0.97, 0.995)] *= 0.3
    rgba = np.concatenate([np.clip(np.rint(col), 0, 255), np.full((n, 1), 255.0)], 1).astype(np.uint8)
    return {"positions": p.astype(np.float32), "colors": rgba}


@dataclass
class ScanScene:
    """A scan-like cloud without velocity (colours, and ``radius``: its points'
    knn_sigma, the world radius the rasterizer projects to pixels) and how it
    is framed: "landscape" (oblique views over it) or "object" (orbits)."""

    cloud: Any
    framing: str
    source: str

    def rasterizer(self, queue: Any = None) -> Any:
        from ..raster import Rasterizer

        return Rasterizer(self.cloud, queue=queue)

    def gbuffers(
        self, ras: Any, camera: Camera, width: int, height: int, planes: Sequence[str], **kw: Any
    ) -> Any:
        """The G-buffers of a view (one pixel per point, the points' own
        colours), the splat radius in pixels among them."""
        from ..post.names import GBUFFER_PLANES

        return ras.render(camera, width, height, planes=[p for p in planes if p not in GBUFFER_PLANES], **kw)

    def gaussian_renderer(self, queue: Any = None) -> Any:
        """The target: isotropic Gaussians, sigma the radius (the mean 4-NN
        distance, clamped), opacity SCAN_OPACITY, the points' colours,
        rendered by 3DGS's splatting (GaussianRenderer model "splat", tiles)."""
        from ..gauss import GaussianRenderer, gaussians_from_points

        g = gaussians_from_points(self.cloud, scale=self.cloud.radius, opacity=SCAN_OPACITY, color_by="rgb")
        return GaussianRenderer(g, queue=queue, colors=True, model="splat")


def scan_cloud(positions: np.ndarray, colors: np.ndarray | None, **kw: Any) -> Any:
    """A PointCloud of a scan with ``radius`` its points' knn_sigma (SCAN_K)."""
    from ..gauss.points import knn_sigma
    from ..io import PointCloud

    return PointCloud(positions, colors=colors, radius=knn_sigma(positions, SCAN_K), **kw)


def scan_line_sample(
    positions: np.ndarray, n: int, rng: np.random.Generator, gap: tuple[float, float]
) -> tuple[np.ndarray, dict]:
    """The indices of `n` of `positions` (a cloud sampled uniformly by area,
    several times denser than `n`) that lie nearest a family of parallel
    vertical planes: scan lines, as an airborne or terrestrial scanner's
    returns (dense along a line, a gap between lines). The planes' normal is
    horizontal at a random angle, their phase random, their spacing `gap`
    (lo, hi: log-uniform) times the median nearest-neighbour distance of `n`
    points drawn uniformly (estimated on a subset). Returns (sorted indices,
    {"gap": the spacing in world units, "normal": (3,), "spacing": that
    nearest-neighbour distance})."""
    from scipy.spatial import cKDTree

    pos = np.asarray(positions, np.float64)
    if not 0 < n <= len(pos):
        raise ValueError(f"scan lines: {n} points of {len(pos)}")
    sub = pos[rng.choice(len(pos), size=min(n, 20_000), replace=False)]
    nn = cKDTree(sub).query(sub, k=2)[0][:, 1]
    spacing = float(np.median(nn)) * math.sqrt(len(sub) / n)  # a surface's: as 1 / sqrt(density)
    g = spacing * math.exp(rng.uniform(math.log(gap[0]), math.log(gap[1])))
    a = rng.uniform(0, math.pi)
    normal = np.array([math.cos(a), math.sin(a), 0.0])
    t = pos @ normal / g + rng.uniform(0, 1)
    keep = np.sort(np.argpartition(np.abs(t - np.rint(t)), n - 1)[:n])
    return keep, {"gap": g, "normal": normal, "spacing": spacing}


def scan_scene(kind: str, n: int, seed: int, scan_lines: tuple[float, float, int] | None = None) -> ScanScene:
    """A narvis-scan scene of generator `kind` (SCAN_KINDS), `n` points from
    `seed`; `scan_lines` (gap lo, gap hi, oversample): the generator drawn
    with oversample x `n` points and `n` of them kept along scan lines
    (scan_line_sample, its draws seeded by `seed`)."""
    framing = "object" if kind in ("shapes", "object") else "landscape"
    if scan_lines is None:
        d = _scan_points(kind, n, seed)
        cloud = scan_cloud(np.asarray(d["positions"], np.float32), d["colors"])
        return ScanScene(cloud, framing, f"{kind} ({n:,} points, seed {seed})")
    lo, hi, over = scan_lines
    d = _scan_points(kind, n * int(over), seed)
    keep, info = scan_line_sample(d["positions"], n, np.random.default_rng([seed, 1]), (lo, hi))
    cloud = scan_cloud(np.asarray(d["positions"][keep], np.float32), d["colors"][keep])
    apart = info["gap"] / info["spacing"]
    return ScanScene(cloud, framing, f"{kind} ({n:,} points on scan lines {apart:.1f}x apart, seed {seed})")


def _scan_points(kind: str, n: int, seed: int) -> dict:
    if kind == "town":
        d = town(n, seed)
    elif kind == "photo_town":
        d = photo_town(n, seed)
    elif kind == "terrain":
        d = datasets.terrain(n, seed)
    elif kind == "aerial":
        d = aerial_scene(n, seed)
    elif kind == "shapes":
        d = shapes_scene(n, seed)
    elif kind == "object":
        d = object_scene(n, seed)
    else:
        raise ValueError(f"scene: expected one of {SCAN_KINDS}, got {kind!r}")
    return d


def scan_cameras(scene: ScanScene, rng: np.random.Generator, count: int, aspect: float = 1.0) -> list[Camera]:
    """`count` random views of a scan scene: oblique views over a landscape
    (as the LiDAR frames', elevation 20-75 degrees, nearer or farther), orbits
    around an object (orbit_camera, zoom 0.3-0.8)."""
    pos = scene.cloud.positions
    lo, hi = pos.min(0).astype(np.float64), pos.max(0).astype(np.float64)
    cams = []
    for _ in range(count):
        if scene.framing == "object":
            cams.append(orbit_camera(rng, lo, hi, aspect, (0.3, 0.8)))
            continue
        centre = (lo + hi) / 2
        extent = float(np.linalg.norm(hi[:2] - lo[:2])) / 2
        az = rng.uniform(0, 2 * np.pi)
        el = np.radians(rng.uniform(20, 75))
        dist = extent * rng.uniform(0.4, 1.2)
        target = centre + np.r_[rng.uniform(-0.3, 0.3, 2) * extent, 0.0]
        target[2] = lo[2]
        eye = target + dist * np.array([np.cos(az) * np.cos(el), np.sin(az) * np.cos(el), np.sin(el)])
        cams.append(
            Camera.look_at(eye, target, (0, 0, 1), rng.uniform(40, 60), aspect, 0.01 * extent, 4 * extent)
        )
    return cams


def scan_frames(
    kinds: Sequence[str],
    count: int,
    seed: int,
    width: int,
    height: int,
    planes: Sequence[str],
    *,
    views: int = 2,
    densities: tuple[float, float] = (0.25, 4.0),
    scan_lines: dict | None = None,
    depth_filter: tuple[int, float] | None = None,
    progress: Callable[[str], None] | None = None,
) -> list[NarvisFrame]:
    """`count` scan scenes (kinds in turn, each at a density log-uniform in
    `densities` x SCAN_POINTS_PER_PIXEL points a frame pixel) x `views`
    random views: the packed G-buffers (`planes`) and the Gaussians' splat.
    `scan_lines` ({"share", "gap": (lo, hi), "oversample"}; None: none): that
    share of the scenes sampled along scan lines (scan_scene), each scene's
    choice drawn from its own seed. `depth_filter` (levels, strength; None:
    none): the G-buffers go through clvis.raster.filter_gbuffers first, as
    narvis-scan's pipeline has them (clvis.post.specs)."""
    import time

    from ..post.pack import pack_gbuffers
    from ..raster.depth_filter import filter_gbuffers

    rng = np.random.default_rng(seed)
    lo, hi = (math.log(float(d)) for d in densities)
    frames = []
    for i in range(count):
        kind = kinds[i % len(kinds)]
        d = math.exp(rng.uniform(lo, hi))
        n = max(int(d * SCAN_POINTS_PER_PIXEL * width * height), 1000)
        s = int(rng.integers(0, 2**31))
        lines = None
        if scan_lines is not None and np.random.default_rng([s, 2]).random() < scan_lines["share"]:
            lines = (*scan_lines["gap"], scan_lines["oversample"])
        sc = scan_scene(kind, n, s, lines)
        sc.source += f", {d:.2f}x points a pixel"
        ras, gr = sc.rasterizer(), sc.gaussian_renderer()
        for v, cam in enumerate(scan_cameras(sc, rng, views, width / height)):
            t0 = time.perf_counter()
            g = sc.gbuffers(ras, cam, width, height, planes)
            if depth_filter is not None:
                g = filter_gbuffers(g, *depth_filter, queue=ras.queue)
            t1 = time.perf_counter()
            img = gr.render(cam, width, height)
            t2 = time.perf_counter()
            rgb = np.clip(np.asarray(img.rgba)[..., :3], 0, 1).astype(np.float32)
            x = np.asarray(pack_gbuffers(g, planes))[0]
            frames.append(
                NarvisFrame(x, rgb, {"raster": t1 - t0, "gaussians": t2 - t1}, f"{sc.source} view {v}")
            )
            if progress is not None:
                progress(f"scan frame {len(frames)}/{count * views} ({t2 - t1:.1f} s Gaussians)")
        queues = (gr.queue, ras.queue)
        gr = ras = g = img = None
        _free_held(queues)
    return frames
