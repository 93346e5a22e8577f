"""Macrocell traversal with speculation (kernels_cl/iso/traverse.cl) against
clvis.reference.iso.traverse (bit for bit), against a plain fine-grid block DDA
(the host loop of tests/iso/test_raytrace.py, zero-length blocks dropped), and
end to end: candidates handed to raytrace_blocks give the image of
clvis.reference.iso.render by clvis.reference.iso.agreement."""

from functools import lru_cache

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from clvis import datasets, runtime, zfp
from clvis._arrays import to_device
from clvis.camera import Camera, ray_buffer
from clvis.iso.macrocell import macrocell_grids, range_bits
from clvis.iso.raytrace import raytrace_blocks
from clvis.iso.traverse import init_rays, macro_traverse
from clvis.reference import iso
from clvis.reference.camera import camera_rays
from clvis.reference.iso import traverse as ref
from clvis.reference.iso.macrocell import range_bits as ref_range_bits

NO = 0xFFFFFFFF
CAM = Camera.look_at((1.7, -2.2, 1.5), (0, 0, 0), (0, 0, 1), fov_y=40, near=0.1, far=20)


def _upload(q, a, dtype):
    return to_device(q, "test array", np.ascontiguousarray(a, dtype))


@lru_cache(maxsize=8)
def _volume(name, n):
    ds = datasets.marschner_lobb(n) if name == "marschner_lobb" else datasets.turbulence(n)
    z = zfp.compress(ds["volume"], 24)
    return ds, z


def _grids(q, z, no_coarse=False):
    g = macrocell_grids(z, queue=q)
    coarse = g.coarse.copy()
    if no_coarse:  # every coarse cell (-inf, +inf): fine skipping only
        coarse[..., 0], coarse[..., 1] = -np.inf, np.inf
    return g.fine, coarse


class Scene:
    """A volume's grids and a camera on a queue; `passes` runs the pass loop."""

    def __init__(self, q, shape, spacing, origin, fine, coarse, cam, w, h, isovalue):
        self.q, self.shape, self.spacing, self.origin = q, shape, spacing, origin
        self.fine, self.coarse, self.w, self.h, self.iso = fine, coarse, w, h, isovalue
        self.buf = ray_buffer(cam, w, h).astype(np.float32)
        self.cam_d = _upload(q, self.buf, np.float32)
        self.fine_d, self.coarse_d = _upload(q, fine, np.float32), _upload(q, coarse, np.float32)

    def init(self):
        ray_t, active, count = init_rays(
            self.q, self.cam_d, self.w, self.h, self.shape, self.spacing, self.origin
        )
        rt_ref, enters = ref.init_rays(self.buf, self.w, self.h, self.shape, self.spacing, self.origin)
        cnt = int(count.get(queue=self.q)[0])
        assert np.array_equal(ray_t.get(queue=self.q), rt_ref)
        assert np.array_equal(active.get(queue=self.q)[:cnt], np.flatnonzero(enters))
        return rt_ref, np.flatnonzero(enters).astype(np.uint32)

    def step(self, ray_t, act, n_spec):
        """One pass, device == reference checked; returns (blocks, ts, new ray_t)."""
        q, cnt = self.q, len(act)
        rt_d = _upload(q, ray_t, np.float32)
        act_d = _upload(q, act, np.uint32)
        count_d = _upload(q, [cnt], np.uint32)
        cb = runtime.empty(q, max(cnt * n_spec, 1), np.uint32, "cand_block")
        ct = runtime.empty(q, max(cnt * n_spec, 1), np.float32, "cand_t")
        macro_traverse(
            q,
            self.shape,
            self.spacing,
            self.origin,
            self.iso,
            self.cam_d,
            self.w,
            self.fine_d,
            self.coarse_d,
            act_d,
            count_d,
            cnt,
            rt_d,
            n_spec,
            cb,
            ct,
        )
        # the renderer's way: the grids' range_bits made once and passed in
        rt2 = _upload(q, ray_t, np.float32)
        cb2, ct2 = (
            runtime.empty(q, cb.size, np.uint32, "cand_block"),
            runtime.empty(q, ct.size, np.float32, "cand_t"),
        )
        bits = tuple(range_bits(g, self.iso, queue=q) for g in (self.fine_d, self.coarse_d))
        for b, g in zip(bits, (self.fine, self.coarse), strict=True):
            assert np.array_equal(b.get(queue=q), ref_range_bits(g, self.iso))
        macro_traverse(
            q,
            self.shape,
            self.spacing,
            self.origin,
            self.iso,
            self.cam_d,
            self.w,
            *bits,
            act_d,
            count_d,
            cnt,
            rt2,
            n_spec,
            cb2,
            ct2,
        )
        rb, rt, rrt = ref.macro_traverse(
            self.shape,
            self.spacing,
            self.origin,
            self.iso,
            self.buf,
            self.w,
            self.fine,
            self.coarse,
            act,
            ray_t,
            n_spec,
        )
        for b_d, t_d, r_d in ((cb, ct, rt_d), (cb2, ct2, rt2)):
            if cnt:
                assert np.array_equal(b_d.get(queue=q)[: cnt * n_spec].reshape(cnt, n_spec), rb)
                assert np.array_equal(t_d.get(queue=q)[: cnt * n_spec].reshape(cnt, n_spec), rt)
            assert np.array_equal(r_d.get(queue=q), rrt)
        # candidates first, then padding; padding only when the ray is done
        have = rb != NO
        assert (np.sort(~have, axis=1, kind="stable") == ~have).all()
        assert np.isinf(rt[~have]).all()
        assert (np.isinf(rrt[act]) | have.all(axis=1)).all()
        return rb, rt, rrt

    def passes(self, n_spec):
        """The pass loop to the end: per pixel the list of (block, t) candidates."""
        ray_t, act = self.init()
        seqs = {int(p): [] for p in act}
        rounds = 0
        while act.size:
            rounds += 1
            assert rounds <= 200
            resume = ray_t[act].copy()
            rb, rt, ray_t = self.step(ray_t, act, n_spec)
            if rounds > 1:
                # a ray left running has a candidate left, entered at its resume t
                # (one without is finished at once: it cannot hit)
                assert (rb[:, 0] != NO).all() and np.array_equal(rt[:, 0], resume)
            for i, p in enumerate(act):
                seqs[int(p)] += [(int(b), float(t)) for b, t in zip(rb[i], rt[i], strict=True) if b != NO]
            act = act[np.isfinite(ray_t[act])]
        return seqs, rounds


def _scene(q, name, n, cam, w, h, isovalue, no_coarse=False):
    ds, z = _volume(name, n)
    fine, coarse = _grids(q, z, no_coarse)
    return Scene(q, ds["volume"].shape, ds["spacing"], ds["origin"], fine, coarse, cam, w, h, isovalue)


def _plain_dda(s: Scene):
    """The fine block DDA of tests/iso/test_raytrace.py (ties x < y < z) over
    every block, keeping active blocks with a segment of positive length."""
    O, D, inv, t_enter, t_exit = ref.ray_setup(s.buf, s.w, s.h, s.shape, s.spacing, s.origin)
    n = np.array(s.shape[::-1], np.int64)
    nb, ncb = (n + 3) // 4, (n + 2) // 4
    fine = s.fine.reshape(-1, 2)
    iso_v = np.float32(s.iso)
    out = {}
    for p in np.flatnonzero(t_enter <= t_exit):
        t_in = t_enter[p]
        with np.errstate(invalid="ignore", over="ignore"):
            b = np.clip(np.floor(O[p] + t_in * D[p]), 0, n - 2).astype(np.int64) // 4
        up = inv[p] > 0
        seq = []
        while True:
            bound = np.minimum(4 * (b + up), n - 1).astype(np.float32)
            tn = (bound - O[p]) * inv[p]
            axis = int(np.argmin(tn))
            t_out = max(t_in, min(t_exit[p], tn[axis]))
            bid = int(b[0] + nb[0] * (b[1] + nb[1] * b[2]))
            if t_out > t_in and fine[bid, 0] <= iso_v <= fine[bid, 1]:
                seq.append((bid, float(t_in)))
            if t_out >= t_exit[p]:
                break
            b[axis] += 1 if up[axis] else -1
            if b[axis] < 0 or b[axis] >= ncb[axis]:
                break
            t_in = t_out
        out[int(p)] = seq
    return out


def _check_plain(seqs, plain):
    assert set(seqs) == set(plain)
    assert all(seqs[p] == plain[p] for p in plain)


@settings(max_examples=15, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    name=st.sampled_from(["marschner_lobb", "turbulence"]),
    eye=st.tuples(*[st.floats(-1.0, 1.0)] * 3),
    dist=st.floats(1.8, 4.0),
    target=st.tuples(*[st.floats(-0.4, 0.4)] * 3),
    fov=st.floats(20, 70),
    level=st.floats(0.2, 0.8),
    n_spec=st.sampled_from([1, 2, 5, 64]),
)
def test_random_cameras_device_equals_reference(queue, name, eye, dist, target, fov, level, n_spec):
    eye = np.array(eye)
    if np.linalg.norm(eye) < 1e-3:
        eye = np.array([1.0, 0.3, 0.2])
    eye = eye / np.linalg.norm(eye) * dist
    up = (0, 0, 1) if abs(eye[2]) < 0.9 * dist else (0, 1, 0)
    cam = Camera.look_at(eye, target, up, fov_y=fov, near=0.1, far=20)
    s = _scene(queue, name, 33 if name == "marschner_lobb" else 30, cam, 12, 10, level)
    seqs, _ = s.passes(n_spec)
    _check_plain(seqs, _plain_dda(s))


@pytest.mark.parametrize("n_spec", [1, 2, 64])
def test_coarse_skipping_equals_fine_only(queue, n_spec):
    s = _scene(queue, "marschner_lobb", 41, CAM, 20, 16, 0.5)
    seqs, rounds = s.passes(n_spec)
    s2 = _scene(queue, "marschner_lobb", 41, CAM, 20, 16, 0.5, no_coarse=True)
    seqs2, rounds2 = s2.passes(n_spec)
    assert seqs == seqs2 and rounds == rounds2
    _check_plain(seqs, _plain_dda(s))
    assert sum(map(len, seqs.values())) > 100
    if n_spec == 1:
        assert rounds > 3
    # the coarse grid does skip something here
    assert not s.coarse.size or not ((s.coarse[..., 0] <= 0.5) & (0.5 <= s.coarse[..., 1])).all()


def test_camera_inside_the_volume(queue):
    cam = Camera.look_at((0.3, -0.2, 0.1), (1.0, 0.5, -0.3), (0, 0, 1), fov_y=90, near=0.01, far=20)
    s = _scene(queue, "turbulence", 30, cam, 16, 12, 0.5)
    ray_t, act = s.init()
    assert len(act) == 16 * 12 and (ray_t == 0).all()
    seqs, _ = s.passes(3)
    _check_plain(seqs, _plain_dda(s))
    assert all(seqs[p] for p in seqs)  # every ray has a candidate at some point


@pytest.mark.parametrize("view", [(0.0, 0.0, -1.0), (0.0, 1.0, 0.0), (-1.0, 0.0, 0.0)])
def test_axis_parallel_rays_on_grid_lines(queue, view):
    """Orthographic rays one sample apart, exactly on sample lines: on block
    faces and edges and on the volume box's faces."""
    shape = (18, 17, 19)
    zz, yy, xx = np.meshgrid(*(np.arange(k) for k in shape), indexing="ij")
    vol = np.sqrt((xx - 8.6) ** 2 + (yy - 7.9) ** 2 + (zz - 8.3) ** 2).astype(np.float32)
    z = zfp.compress(vol, 32)
    fine, coarse = _grids(queue, z)
    view = np.array(view)
    up = (0, 1, 0) if view[2] else (0, 0, 1)
    w, h = 24, 22
    target = np.array((7.5, 7.5, 8.5))
    cam = Camera.ortho(target - 30.0 * view, target, up, height=float(h), aspect=w / h, near=0.5, far=100)
    o, _ = camera_rays(ray_buffer(cam, w, h), w, h)
    across = [a for a in range(3) if view[a] == 0]
    assert (o[:, across] == np.round(o[:, across])).all()
    s = Scene(queue, shape, (1, 1, 1), (0, 0, 0), fine, coarse, cam, w, h, 6.0)
    for n_spec in (1, 64):
        seqs, _ = s.passes(n_spec)
        _check_plain(seqs, _plain_dda(s))
    assert sum(map(len, seqs.values())) > 50


@pytest.mark.parametrize("view", [(1.0, 1.0, 1.0), (-1.0, -1.0, -1.0), (1.0, 0.0, 0.0), (0.0, -1.0, 0.0)])
def test_runs_of_inactive_coarse_cells(queue, view):
    """The coarse walk: a volume active only near two opposite corners, so the
    rays cross runs of inactive 16^3 coarse cells, some along coarse faces,
    edges or through corners (the ortho rays lie on sample lines one sample
    or two apart; the diagonal view's central ray runs through (32, 32, 32)), and
    the last coarse cell along each axis is partial (n = 69, 66, 70 samples:
    18, 17, 18 blocks with cells). Against the plain fine DDA and fine-only."""
    shape = (70, 66, 69)
    zz, yy, xx = np.meshgrid(*(np.arange(k) for k in shape), indexing="ij")
    near = np.sqrt((xx - 5.3) ** 2 + (yy - 4.6) ** 2 + (zz - 6.1) ** 2)
    far = np.sqrt((xx - 62.4) ** 2 + (yy - 60.2) ** 2 + (zz - 63.7) ** 2)
    vol = np.minimum(near, far).astype(np.float32)
    z = zfp.compress(vol, 32)
    fine, coarse = _grids(queue, z)
    inactive = ~((coarse[..., 0] <= 4.0) & (4.0 <= coarse[..., 1]))
    assert inactive.sum() >= 100  # of 5 x 5 x 5: long runs to walk
    diagonal = np.count_nonzero(view) == 3
    view = np.array(view) / np.linalg.norm(view)
    up = (0, 0, 1) if abs(view[2]) < 0.9 else (0, 1, 0)
    # diagonal: rays 1 sample apart around (32, 32, 32); along an axis: rays on
    # the even sample lines -2 .. 68 (coarse faces and edges at 16, 32, 48, 64)
    w, h, height, target = (40, 36, 36.0, 32.0) if diagonal else (36, 36, 72.0, 33.0)
    target = np.full(3, target)
    cam = Camera.ortho(target - 150.0 * view, target, up, height=height, aspect=w / h, near=0.5, far=400)
    if not diagonal:
        o, _ = camera_rays(ray_buffer(cam, w, h), w, h)
        across = [a for a in range(3) if view[a] == 0]
        assert (o[:, across] == np.round(o[:, across])).all() and (o[:, across] % 2 == 0).all()
    s = Scene(queue, shape, (1, 1, 1), (0, 0, 0), fine, coarse, cam, w, h, 4.0)
    s2 = Scene(queue, shape, (1, 1, 1), (0, 0, 0), fine, _grids(queue, z, no_coarse=True)[1], cam, w, h, 4.0)
    plain = _plain_dda(s)
    for n_spec in (1, 64):
        seqs, rounds = s.passes(n_spec)
        seqs2, rounds2 = s2.passes(n_spec)
        assert seqs == seqs2 and rounds == rounds2
        _check_plain(seqs, plain)
    assert sum(map(len, seqs.values())) > 50


def test_rays_that_miss_the_box(queue):
    cam = Camera.look_at((3.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0, 0, 1), fov_y=80, near=0.1, far=20)
    s = _scene(queue, "marschner_lobb", 17, cam, 16, 12, 0.5)
    ray_t, act = s.init()
    assert 0 < len(act) < 16 * 12
    miss = np.setdiff1d(np.arange(16 * 12), act).astype(np.uint32)
    assert np.isinf(ray_t[miss]).all()
    rb, rt, rrt = s.step(ray_t, miss, 4)  # listed anyway: no candidates, ray_t stays +inf
    assert (rb == NO).all() and np.isinf(rt).all() and np.isinf(rrt[miss]).all()
    assert np.array_equal(rrt[act], ray_t[act])  # rays not listed are not touched
    # a NaN or a t beyond the exit is a finished ray too
    bad = ray_t.copy()
    bad[act[0]], bad[act[1]] = np.nan, 1e30
    rb, _, rrt = s.step(bad, act[:2], 2)
    assert (rb == NO).all() and np.isinf(rrt[act[:2]]).all()


def test_isovalue_outside_the_range(queue):
    ds, _ = _volume("marschner_lobb", 33)
    s = _scene(queue, "marschner_lobb", 33, CAM, 16, 12, float(ds["volume"].max()) + 0.5)
    ray_t, act = s.init()
    assert len(act) > 0
    rb, rt, rrt = s.step(ray_t, act, 8)
    assert (rb == NO).all() and np.isinf(rt).all() and np.isinf(rrt).all()


def test_no_rays_and_bad_n_spec(queue):
    s = _scene(queue, "marschner_lobb", 17, CAM, 4, 4, 0.5)
    ray_t, act = s.init()
    s.step(ray_t, act[:0], 3)
    z = _upload(queue, np.zeros(4), np.uint32)
    assert (
        macro_traverse(
            queue, s.shape, s.spacing, s.origin, 0.5, s.cam_d, 4, s.fine_d, s.coarse_d, z, z, 0, z, 1, z, z
        )
        is None
    )
    for bad in (0, 65):
        with pytest.raises(ValueError, match="n_spec"):
            macro_traverse(
                queue,
                s.shape,
                s.spacing,
                s.origin,
                0.5,
                s.cam_d,
                4,
                s.fine_d,
                s.coarse_d,
                z,
                z,
                1,
                z,
                bad,
                z,
                z,
            )


def _render_with_candidates(q, name, n, cam, w, h, isovalue, n_spec):
    """The pass loop: traversal, then the candidates in order through
    raytrace_blocks (all blocks cached); a ray stops at its first hit."""
    ds, z = _volume(name, n)
    s = _scene(q, name, n, cam, w, h, isovalue)
    bricks = zfp.decode_blocks(z, np.arange(z.nblocks), queue=q)
    slots = _upload(q, np.arange(z.nblocks), np.int32)
    npix = w * h
    trav_t, act = s.init()
    rt_d = _upload(q, np.zeros(npix), np.float32)
    ray_hit = _upload(q, np.zeros(npix), np.uint8)
    hit_t = _upload(q, np.full(npix, np.inf), np.float32)
    rgba = _upload(q, np.zeros((npix, 4)), np.float32)
    depth = _upload(q, np.full(npix, np.inf), np.float32)
    rounds = 0
    while act.size:
        rounds += 1
        rb, rt, trav_t = s.step(trav_t, act, n_spec)
        for k in range(n_spec):
            hit = ray_hit.get(queue=q)
            sel = np.flatnonzero((rb[:, k] != NO) & (hit[act] == 0))
            if not sel.size:
                break
            rays, blocks = act[sel], rb[sel, k]
            t_in = rt_d.get(queue=q)
            t_in[rays] = rt[sel, k]
            rt_d.set(t_in, queue=q)
            srt = np.argsort(blocks, kind="stable")
            ub, off, cnt = np.unique(blocks[srt], return_index=True, return_counts=True)
            groups = tuple(_upload(q, a, np.uint32) for a in (ub, off, cnt))
            raytrace_blocks(
                q,
                bricks,
                slots,
                s.shape,
                s.spacing,
                s.origin,
                isovalue,
                s.cam_d,
                w,
                groups,
                _upload(q, rays[srt], np.uint32),
                rt_d,
                (ray_hit, hit_t, rgba, depth),
            )
        hit = ray_hit.get(queue=q)
        act = act[(hit[act] == 0) & np.isfinite(trav_t[act])]
    decoded = zfp.decode(z, queue=q)
    image = iso.render(decoded, cam, w, h, isovalue, ds["spacing"], ds["origin"])
    return ray_hit.get(queue=q).reshape(h, w).astype(bool), depth.get(queue=q).reshape(h, w), image, rounds


@pytest.mark.parametrize("name, n_spec", [("marschner_lobb", 1), ("marschner_lobb", 8), ("turbulence", 8)])
def test_candidates_through_raytrace_blocks_match_the_reference(queue, name, n_spec):
    hit, depth, image, rounds = _render_with_candidates(
        queue, name, 41 if name == "marschner_lobb" else 30, CAM, 40, 32, 0.5, n_spec
    )
    agree = iso.agreement(image, hit, depth)
    assert agree["ok"], agree
    assert image.hit.mean() > 0.3
    assert rounds >= (3 if n_spec == 1 else 1)


@pytest.mark.parametrize("flip", range(8))
def test_view_key_is_an_involution_of_the_block_ids(flip):
    nb = (5, 3, 4)
    ids = np.arange(5 * 3 * 4, dtype=np.uint32)
    k = ref.view_key(ids, nb, flip)
    assert sorted(k.tolist()) == ids.tolist()
    assert np.array_equal(ref.view_key(k, nb, flip), ids)
    assert np.array_equal(k, ids) == (flip == 0)


@pytest.mark.parametrize(
    "eye, ortho",
    [
        ((1.7, -2.2, 1.5), False),
        ((-1.9, 2.3, -1.4), False),
        ((0.1, -2.5, 0.2), False),  # eye inside the x and z slabs: the view direction decides
        ((-2.0, -0.5, 1.8), True),
    ],
)
def test_view_key_orders_candidates_front_to_back(eye, ortho):
    """clvis.iso.render.view_flips's order: along every ray whose direction
    has the flipped signs (all of them, for an eye outside every slab), the
    candidate blocks come in ascending view key; the other rays are counted
    to show the case is not vacuous."""
    from clvis.iso.render import view_flips

    ds, z = _volume("turbulence", 30)
    fb = iso.block_ranges(zfp.decode(z))
    fine, coarse = np.stack(fb, -1), np.stack(iso.coarse_ranges(fb), -1)
    w, h = 24, 20
    make = Camera.ortho if ortho else Camera.look_at
    cam = make(eye, (0.0, 0.0, 0.0), (0, 0, 1), 2.2 if ortho else 40, near=0.1, far=20)
    flip = view_flips(cam, z.shape, ds["spacing"], ds["origin"])
    buf = ray_buffer(cam, w, h).astype(np.float32)
    rt, enters = ref.init_rays(buf, w, h, z.shape, ds["spacing"], ds["origin"])
    act = np.flatnonzero(enters).astype(np.uint32)
    blocks, _, _ = ref.macro_traverse(
        z.shape, ds["spacing"], ds["origin"], 0.5, buf, w, fine, coarse, act, rt, 64
    )
    _, d = camera_rays(buf, w, h)
    signs = np.stack([(d[act, a] < 0) == bool(flip >> a & 1) for a in range(3)], axis=1).all(axis=1)
    nb = [(s + 3) // 4 for s in z.shape[::-1]]
    checked = 0
    for row, ok in zip(blocks, signs, strict=True):
        row = row[row != NO]
        if ok and row.size > 1:
            keys = ref.view_key(row, nb, flip).astype(np.int64)
            assert (np.diff(keys) > 0).all()
            checked += 1
    assert checked > 0.25 * len(act)
    if not ortho and min(abs(e) for e in eye) > 1:  # outside every slab of the box [-1, 1]^3
        assert signs.all()


def _profile_passes(q, s, n_spec, tile):
    """init_rays on the tile (p0, n) and macro_traverse passes to the end, device
    only: per round the active ids, candidates and ray_t (host copies)."""
    p0, npix = tile
    ray_t, active, count = init_rays(q, s.cam_d, s.w, s.h, s.shape, s.spacing, s.origin, pixels=tile)
    cnt = int(count.get(queue=q)[0])
    out = [ray_t.get(queue=q), active.get(queue=q)[:cnt]]
    act = out[1]
    while act.size:
        assert len(out) < 400
        # a sparse, uneven active list: every other ray this round, the rest the next
        for part in (act[::2], act[1::2]):
            if not part.size:
                continue
            cnt = len(part)
            cb = runtime.empty(q, cnt * n_spec, np.uint32, "cand_block")
            ct = runtime.empty(q, cnt * n_spec, np.float32, "cand_t")
            macro_traverse(
                q,
                s.shape,
                s.spacing,
                s.origin,
                s.iso,
                s.cam_d,
                s.w,
                s.fine_d,
                s.coarse_d,
                _upload(q, part, np.uint32),
                _upload(q, [cnt], np.uint32),
                cnt,
                ray_t,
                n_spec,
                cb,
                ct,
                first_pixel=p0,
            )
            out += [cb.get(queue=q), ct.get(queue=q)]
        rt = ray_t.get(queue=q)
        out.append(rt)
        act = act[np.isfinite(rt[act])]
    return out


_PROFILE_SCENES = {
    "turbulence": lambda: ("turbulence", 30, CAM, 21, 13, 0.5),
    "inside": lambda: (
        "turbulence",
        30,
        Camera.look_at((0.3, -0.2, 0.1), (1.0, 0.5, -0.3), (0, 0, 1), fov_y=90, near=0.01, far=20),
        19,
        11,
        0.5,
    ),
    "marschner_lobb": lambda: ("marschner_lobb", 33, CAM, 17, 15, 0.3),
}


@pytest.mark.parametrize("scene", sorted(_PROFILE_SCENES))
@pytest.mark.parametrize("n_spec", [1, 5])
def test_packets_equal_one_ray_a_work_item(queue, scene, n_spec):
    """The cpu profile's 8-ray set-up (PACKET=8: init_rays and macro_traverse
    take 8 pixels / 8 listed rays a work-item, ray set-up in float8 lanes)
    gives every ray_t, active id and candidate bit for bit as one ray a
    work-item (the gpu profile's PACKET=0) on the same device: whole images
    and tiles whose start and size are not multiples of 8, active lists of
    odd lengths."""
    name, n, cam, w, h, isovalue = _PROFILE_SCENES[scene]()
    s = _scene(queue, name, n, cam, w, h, isovalue)
    for tile in ((0, w * h), (3, w * h - 7), (w + 5, 2 * w + 3)):
        got = {}
        for profile in ("cpu", "gpu"):
            with runtime.configure(tuning=profile):
                got[profile] = _profile_passes(queue, s, n_spec, tile)
        a, b = got["cpu"], got["gpu"]
        assert len(a) == len(b)
        for x, y in zip(a, b, strict=True):
            np.testing.assert_array_equal(x, y)
        assert any(x.dtype == np.uint32 and (x != NO).any() for x in a[2:])  # cand_block arrays
