"""NumPy reference of the iso family's macrocell traversal with speculation
(kernels_cl/iso/traverse.cl, wrapped by clvis.iso.traverse).

Everything is float32 with the kernel's operation order (FP_CONTRACT off,
correctly rounded division), so device and reference give the same block
ids and the same t values bit for bit; there are no documented tie cases.

Rules (see traverse.cl's ABI comment): the ray setup of :func:`ray_setup`
(O, D, inv with the tiny-direction rule, t_enter, t_exit) in float32; block
b_a spans [4 b_a, min(4 b_a + 4, n_a - 1)] in index space, for b_a <
ceil((n_a - 1) / 4); with T_a(x) = (x - O_a) inv_a the ray is in block b_a
along axis a for t in [T_a(entry bound), T_a(exit bound)). From the resume t
the block is located (the raytrace first-cell rule, floor and clamp, then
corrected per axis by those half-open intervals); a coarse cell (4^3 blocks)
whose range excludes the isovalue is left at once (t = its exit); a block
whose range holds it is a candidate entered at t; t moves on to the block's
exit. After the n_spec-th candidate the walk goes on to the next one and
the ray resumes at its entry t; where none is left the ray cannot hit and
its ray_t is +inf (finished in this pass). Blocks with a zero-length
segment (where the plain block DDA steps two axes at one t) are never
candidates, so the candidate sequence does not depend on how the passes
split it.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from ..camera import camera_rays

__all__ = ["NO_BLOCK", "init_rays", "macro_traverse", "ray_setup", "view_key"]

NO_BLOCK = np.uint32(0xFFFFFFFF)
_TINY = np.float32(1e-20)  # clvis/ray.h CLVIS_RAY_TINY_DIR
_F = np.float32


def ray_setup(
    cam: npt.ArrayLike,
    width: int,
    height: int,
    shape: Sequence[int],
    spacing: Sequence[float],
    origin: Sequence[float],
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per pixel (W * H rays): O, D, inv (R, 3) and t_enter, t_exit (R,), float32."""
    o, d = camera_rays(np.asarray(cam, np.float32), int(width), int(height))
    n = np.array(shape[::-1], np.int64)  # nx, ny, nz
    sp = np.asarray(spacing, np.float32)[::-1].copy()  # dx, dy, dz
    org = np.asarray(origin, np.float32)
    d_safe = np.where(np.abs(d) < _TINY, np.copysign(_TINY, d), d).astype(np.float32)
    inv = sp / d_safe
    O = (o - org) / sp
    D = d / sp
    t0 = (_F(0) - O) * inv
    t1 = (n - 1).astype(np.float32) - O
    t1 = t1 * inv
    t_enter = np.maximum(_F(0), np.minimum(t0, t1).max(axis=1))
    t_exit = np.maximum(t0, t1).min(axis=1)
    return O, D, inv, t_enter, t_exit


def init_rays(
    cam: npt.ArrayLike,
    width: int,
    height: int,
    shape: Sequence[int],
    spacing: Sequence[float],
    origin: Sequence[float],
) -> tuple[np.ndarray, np.ndarray]:
    """(ray_t float32 (W * H,): t_enter, +inf where the ray misses the box;
    enters uint8: 1 where it meets it), as the kernel init_rays."""
    _, _, _, t_enter, t_exit = ray_setup(cam, width, height, shape, spacing, origin)
    inside = t_enter <= t_exit
    return np.where(inside, t_enter, _F(np.inf)).astype(np.float32), inside.astype(np.uint8)


def _bound_t(b, size, n, O, inv, entry):
    """T_a of block b's exit bound along the ray (entry bound when `entry`), (M, 3) float32."""
    up = inv > 0
    hi = np.minimum(size * b + size, n - 1)
    lo = size * b
    x = np.where(up != entry, hi, lo).astype(np.float32)
    return (x - O) * inv


def macro_traverse(
    shape: Sequence[int],
    spacing: Sequence[float],
    origin: Sequence[float],
    isovalue: float,
    cam: npt.ArrayLike,
    width: int,
    fine: npt.ArrayLike,
    coarse: npt.ArrayLike,
    active: npt.ArrayLike,
    ray_t: npt.ArrayLike,
    n_spec: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Candidate blocks of the rays `active` (pixel ids).

    fine (nbz, nby, nbx, 2) and coarse (ncz, ncy, ncx, 2) float32 ranges
    (clvis.iso.macrocell_grids); ray_t float32 per pixel (resume t).
    Returns (cand_block uint32 (len(active), n_spec), 0xFFFFFFFF past the
    last; cand_t float32 (len(active), n_spec), +inf past the last; the new
    ray_t, a copy with the active pixels updated)."""
    nz, ny, nx = (int(s) for s in shape)
    width = int(width)
    active = np.asarray(active, np.int64).ravel()
    n_spec = int(n_spec)
    iso = _F(isovalue)
    fine = np.asarray(fine, np.float32).reshape(-1, 2)
    coarse = np.asarray(coarse, np.float32).reshape(-1, 2)
    n = np.array([nx, ny, nz], np.int64)
    nb = (n + 3) >> 2
    ncb = (n + 2) >> 2
    nc = (nb + 3) >> 2
    ray_t = np.array(ray_t, np.float32, copy=True)
    height = int(active.max()) // width + 1 if active.size else 1
    O, D, inv, _, t_exit = ray_setup(cam, width, height, shape, spacing, origin)
    O, D, inv, t_exit = O[active], D[active], inv[active], t_exit[active]
    R = len(active)
    cand_block = np.full((R, n_spec), NO_BLOCK, np.uint32)
    cand_t = np.full((R, n_spec), np.inf, np.float32)
    found = np.zeros(R, np.int64)
    resume = np.full(R, np.inf, np.float32)
    t = ray_t[active].copy()
    step = np.where(inv > 0, 1, -1)

    with np.errstate(invalid="ignore", over="ignore"):
        live = t < t_exit
        g = np.floor(O + t[:, None] * D)
        c = np.where(g >= 0, np.where(g <= (n - 2).astype(np.float32), np.nan_to_num(g), n - 2), 0)
        b = c.astype(np.int64) >> 2
        while True:  # back while t is before the block's entry
            nxt = b - step
            back = live[:, None] & (nxt >= 0) & (nxt < ncb) & (t[:, None] < _bound_t(b, 4, n, O, inv, True))
            if not back.any():
                break
            b = np.where(back, nxt, b)
        while True:
            live &= t < t_exit
            if not live.any():
                break
            while True:  # forward while t is at or past the block's exit
                nxt = b + step
                fwd = (
                    live[:, None]
                    & (nxt >= 0)
                    & (nxt < ncb)
                    & (t[:, None] >= _bound_t(b, 4, n, O, inv, False))
                )
                if not fwd.any():
                    break
                b = np.where(fwd, nxt, b)
            cc = b >> 2
            cr = coarse[cc[:, 0] + nc[0] * (cc[:, 1] + nc[1] * cc[:, 2])]
            skip = live & ~((cr[:, 0] <= iso) & (iso <= cr[:, 1]))
            tc = _bound_t(cc, 16, n, O, inv, False).min(axis=1)
            stuck = skip & ~(tc > t)
            live &= ~stuck
            t = np.where(skip & ~stuck, tc, t)
            walk = live & ~skip
            t_out = np.minimum(t_exit, _bound_t(b, 4, n, O, inv, False).min(axis=1))
            ids = b[:, 0] + nb[0] * (b[:, 1] + nb[1] * b[:, 2])
            fr = fine[np.where(walk, ids, 0)]
            cand = walk & (fr[:, 0] <= iso) & (iso <= fr[:, 1])
            # the candidate after the n_spec-th: the next pass resumes at its entry
            nxt_cand = cand & (found == n_spec)
            resume[nxt_cand] = t[nxt_cand]
            live &= ~nxt_cand
            k = np.nonzero(cand & ~nxt_cand)[0]
            cand_block[k, found[k]] = ids[k].astype(np.uint32)
            cand_t[k, found[k]] = t[k]
            found[k] += 1
            t = np.where(walk, t_out, t)
    ray_t[active] = resume
    return cand_block, cand_t, ray_t


def view_key(blocks: npt.ArrayLike, nb: Sequence[int], flip: int) -> np.ndarray:
    """The view-order key of block ids (kernels_cl/iso/pass.cl, View order):
    block b = bx + nbx (by + nby bz) with each axis a whose bit of `flip` is
    set mirrored (b_a -> nb_a - 1 - b_a), renumbered in the same way. nb =
    (nbx, nby, nbz). A bijection of [0, nbx nby nbz), its own inverse; a ray
    whose direction is < 0 along the flipped axes and >= 0 along the others
    meets its candidate blocks in ascending key order (along the ray each
    mirrored block coordinate only grows). uint32, the shape of `blocks`."""
    b = np.asarray(blocks, np.int64)
    nbx, nby, nbz = (int(v) for v in nb)
    c = [b % nbx, b // nbx % nby, b // nbx // nby]
    for a, m in enumerate((nbx, nby, nbz)):
        if int(flip) >> a & 1:
            c[a] = m - 1 - c[a]
    return (c[0] + nbx * (c[1] + nby * c[2])).astype(np.uint32)
