"""Block raytracing (kernels_cl/iso/raytrace.cl) against clvis.reference.iso.

A full single-pass raycast is built from the kernel and a simple host loop:
every block of a ZFP-compressed volume is decoded into the cache; each ray
starts at its box entry (the reference's entry rule) in the block of its first
cell; per round the rays are grouped by the block they wait at, the kernel
traces them through it, and the host steps the block DDA of the rays that left
their block, until every ray has hit or left the volume. The image must agree
with the reference on the decoded volume by clvis.reference.iso.agreement."""

import numpy as np
import pytest

from clvis import datasets, runtime, zfp
from clvis._arrays import to_device
from clvis.camera import Camera, ray_buffer
from clvis.iso.raytrace import raytrace_blocks
from clvis.reference import iso
from clvis.reference.camera import camera_rays

TINY = np.float32(iso.TINY_DIR)


def _upload(q, a, dtype):
    return to_device(q, "test array", np.ascontiguousarray(a, dtype))


def _raycast(
    q,
    vol,
    cam,
    w,
    h,
    isovalue,
    spacing=(1, 1, 1),
    origin=(0, 0, 0),
    rate=24,
    permute_slots=False,
    absent=False,
):
    """The kernel's image (hit, t, depth, rgba as (H, W[, 4])), the reference
    image of the decoded volume and stats (rounds, the most rays in a group).
    absent: slot_of_block all -1 (nothing cached)."""
    z = zfp.compress(vol, rate)
    decoded = zfp.decode(z, queue=q)
    nblocks = z.nblocks
    _, nby, nbx = z.blocks
    slot_of_block = np.arange(nblocks, dtype=np.int32)
    if permute_slots:  # the cache holds the blocks in another order
        slot_of_block = np.random.default_rng(1).permutation(nblocks).astype(np.int32)
    order = np.argsort(slot_of_block)  # slot s holds block order[s]
    bricks = zfp.decode_blocks(z, order, queue=q)
    if absent:
        slot_of_block[:] = -1
    slots_d = _upload(q, slot_of_block, np.int32)
    buf = ray_buffer(cam, w, h)
    cam_d = _upload(q, buf, np.float32)

    # the reference's entry rule, in float32 as the kernel computes it
    o, d = camera_rays(buf, w, h)
    sp = np.asarray(spacing, np.float32)[::-1].copy()
    org = np.asarray(origin, np.float32)
    n = np.array(vol.shape[::-1], np.int64)
    d_safe = np.where(np.abs(d) < TINY, np.copysign(TINY, d), d).astype(np.float32)
    inv = sp / d_safe
    O = (o - org) / sp
    D = d / sp
    t0 = (np.float32(0) - O) * inv
    t1 = ((n - 1).astype(np.float32) - O) * inv
    t_enter = np.maximum(np.float32(0), np.minimum(t0, t1).max(axis=1))
    t_exit = np.maximum(t0, t1).min(axis=1)
    active = np.nonzero(t_enter <= t_exit)[0]
    with np.errstate(invalid="ignore", over="ignore"):
        c = np.clip(np.floor(O[active] + t_enter[active, None] * D[active]), 0, n - 2).astype(np.int64)
    blk = np.zeros((w * h, 3), np.int64)
    blk[active] = c // 4
    ncell_blocks = -(-(n - 1) // 4)

    npix = w * h
    ray_t = _upload(q, np.where(t_enter <= t_exit, t_enter, np.inf), np.float32)
    ray_hit = _upload(q, np.zeros(npix), np.uint8)
    hit_t = _upload(q, np.full(npix, np.inf), np.float32)
    rgba = _upload(q, np.zeros((npix, 4)), np.float32)
    depth = _upload(q, np.full(npix, np.inf), np.float32)
    rounds = most = 0
    while active.size:
        rounds += 1
        assert rounds < 4 * ncell_blocks.sum() + 8
        ids = blk[active, 0] + nbx * (blk[active, 1] + nby * blk[active, 2])
        srt = np.argsort(ids, kind="stable")
        rays = active[srt]
        blocks, offsets, counts = np.unique(ids[srt], return_index=True, return_counts=True)
        most = max(most, int(counts.max()))
        groups = tuple(_upload(q, a, np.uint32) for a in (blocks, offsets, counts))
        raytrace_blocks(
            q,
            bricks,
            slots_d,
            vol.shape,
            spacing,
            origin,
            isovalue,
            cam_d,
            w,
            groups,
            _upload(q, rays, np.uint32),
            ray_t,
            (ray_hit, hit_t, rgba, depth),
        )
        t_now, hit_now = ray_t.get(queue=q), ray_hit.get(queue=q)
        active = rays[(hit_now[rays] == 0) & np.isfinite(t_now[rays])]
        # the block DDA: step the axis whose block boundary comes first (ties x < y < z)
        b = blk[active]
        up = inv[active] > 0
        bound = np.minimum(4 * (b + up), n - 1).astype(np.float32)
        t_next = (bound - O[active]) * inv[active]
        axis = np.argmin(t_next, axis=1)
        rows = np.arange(active.size)
        b[rows, axis] += np.where(up[rows, axis], 1, -1)
        inside = ((b >= 0) & (b < ncell_blocks)).all(axis=1)
        blk[active] = b
        active = active[inside]

    ref = iso.render(decoded, cam, w, h, isovalue, spacing, origin)
    out = {
        "hit": ray_hit.get(queue=q).reshape(h, w).astype(bool),
        "t": hit_t.get(queue=q).reshape(h, w),
        "depth": depth.get(queue=q).reshape(h, w),
        "rgba": rgba.get(queue=q).reshape(h, w, 4),
    }
    return out, ref, {"rounds": rounds, "most": most}


def _check(out, ref, name, min_hits=0.0, colour_tol=2e-3, colour_frac=0.002):
    agree = iso.agreement(ref, out["hit"], out["depth"])
    rel = iso.reliable(ref)
    both = rel & out["hit"] & ref.hit
    cerr = np.abs(out["rgba"][both] - ref.rgba[both]).max(axis=-1) if both.any() else np.zeros(0)
    print(
        f"{name}: hits {ref.hit.mean():.3f}, unreliable {agree['unreliable'] / ref.hit.size:.4f}, "
        f"mask mismatches {agree['mask_mismatches']}, depth error / diagonal {agree['depth_error']:.2e}, "
        f"colour max {cerr.max() if cerr.size else 0:.2e}, "
        f"> {colour_tol}: {(cerr > colour_tol).mean() if cerr.size else 0:.4f}"
    )
    assert agree["ok"], agree
    assert ref.hit.mean() >= min_hits
    # hit t agrees as well as depth does; misses keep +inf, zero colour
    if both.any():
        assert np.abs(out["t"][both] - ref.t[both]).max() <= iso.DEPTH_TOLERANCE * ref.diagonal
    assert np.isinf(out["depth"][~out["hit"]]).all() and (out["rgba"][~out["hit"]] == 0).all()
    assert (out["rgba"][out["hit"], 3] == 1).all()
    # colours agree except near cell faces (the normal is discontinuous there)
    if cerr.size:
        assert (cerr > colour_tol).mean() <= colour_frac
        assert cerr.max() < 0.05


CAM = Camera.look_at((1.7, -2.2, 1.5), (0, 0, 0), (0, 0, 1), fov_y=40, near=0.1, far=20)


def test_marschner_lobb(queue):
    ds = datasets.marschner_lobb(41)
    out, ref, stats = _raycast(queue, ds["volume"], CAM, 48, 40, 0.5, ds["spacing"], ds["origin"])
    _check(out, ref, "marschner_lobb 41", min_hits=0.3)
    assert stats["rounds"] > 3 and stats["most"] > 64  # work-items loop over their group's rays


def test_turbulence_with_permuted_cache_slots(queue):
    ds = datasets.turbulence(30)
    out, ref, _ = _raycast(
        queue, ds["volume"], CAM, 48, 40, 0.5, ds["spacing"], ds["origin"], permute_slots=True
    )
    _check(out, ref, "turbulence 30", min_hits=0.3)


def _sphere(shape, spacing, origin, centre):
    nz, ny, nx = shape
    dz, dy, dx = spacing
    zz, yy, xx = np.meshgrid(
        np.arange(nz) * dz + origin[2],
        np.arange(ny) * dy + origin[1],
        np.arange(nx) * dx + origin[0],
        indexing="ij",
    )
    return np.sqrt((xx - centre[0]) ** 2 + (yy - centre[1]) ** 2 + (zz - centre[2]) ** 2).astype(np.float32)


@pytest.mark.parametrize("where", ["outside", "inside_volume", "inside_sphere"])
def test_sphere_on_block_boundaries(queue, where):
    """Distance to a sample at a block corner; radius 8 samples along x, so the
    surface passes through block faces, edges and corners."""
    shape, spacing, origin = (29, 27, 33), (0.5, 0.5, 0.5), (-8.0, -6.0, -9.0)
    centre = np.array(origin) + np.array((16, 12, 16)) * 0.5  # sample (16, 12, 16): a block corner
    vol = _sphere(shape, spacing, origin, centre)
    if where == "outside":
        cam = Camera.look_at(centre + (13.0, -11.0, 8.0), centre, (0, 0, 1), fov_y=35, near=0.5, far=100)
    elif where == "inside_volume":  # camera in the volume, outside the sphere
        eye = centre + (6.5, -0.3, 0.2)
        cam = Camera.look_at(eye, centre, (0, 0, 1), fov_y=70, near=0.05, far=100)
    else:  # camera inside the sphere: sees its first crossing
        eye = centre + (0.4, -0.3, 0.2)
        cam = Camera.look_at(eye, eye + (1.0, 0.3, -0.2), (0, 0, 1), fov_y=90, near=0.05, far=100)
    out, ref, _ = _raycast(queue, vol, cam, 40, 32, 4.0, spacing, origin, rate=32)
    _check(out, ref, f"sphere {where}", min_hits=0.2)
    if where == "inside_sphere":
        assert ref.hit.all() and out["hit"].all()


@pytest.mark.parametrize("axis", [0, 2])
def test_plane_on_a_block_boundary(queue, axis):
    shape, spacing, origin = (21, 23, 34), (0.7, 1.1, 0.9), np.array((-2.0, 1.5, 0.25))
    grid = np.meshgrid(*(np.arange(s) for s in shape), indexing="ij")[2 - axis]
    vol = (grid - 8).astype(np.float32)
    sp = np.asarray(spacing, np.float32).astype(np.float64)[::-1]
    target = origin + 0.5 * (np.array(shape[::-1]) - 1) * sp
    target[axis] = origin[axis] + 8 * sp[axis]
    eye = target.copy()
    eye[axis] += 40.0
    eye[(axis + 1) % 3] += 3.0
    up = np.zeros(3)
    up[(axis + 2) % 3] = 1.0
    cam = Camera.look_at(eye, target, up, fov_y=20, near=1.0, far=200)
    out, ref, _ = _raycast(queue, vol, cam, 40, 30, 0.0, spacing, tuple(origin), rate=32)
    _check(out, ref, f"plane axis {axis}", min_hits=0.9)
    # the hits lie on a cell face (|f| = 0 there, so the reference calls them
    # unreliable), yet every one is found, at the right t
    assert (out["hit"] == ref.hit).all()
    assert np.abs(out["t"][ref.hit] - ref.t[ref.hit]).max() <= iso.DEPTH_TOLERANCE * ref.diagonal


@pytest.mark.parametrize(
    "name, view", [("marschner_lobb", (0.0, 0.0, -1.0)), ("turbulence", (1.0, 0.0, 0.0))]
)
def test_axis_parallel_orthographic_rays(queue, name, view):
    ds = datasets.marschner_lobb(33) if name == "marschner_lobb" else datasets.turbulence(25)
    view = np.array(view)
    up = (0, 1, 0) if view[2] else (0, 0, 1)
    cam = Camera.ortho(-3.0 * view, (0, 0, 0), up, height=2.3, aspect=48 / 40, near=0.5, far=10)
    out, ref, _ = _raycast(queue, ds["volume"], cam, 48, 40, 0.5, ds["spacing"], ds["origin"])
    _check(out, ref, f"ortho {name} {view}", min_hits=0.3)


@pytest.mark.parametrize("view", [(0.0, 0.0, -1.0), (0.0, 1.0, 0.0)])
def test_rays_along_grid_lines_and_block_faces(queue, view):
    """Orthographic rays one sample apart, exactly on sample lines: on block
    faces, block edges and the volume box's faces (a zero direction component
    decides whether a ray in a box face enters)."""
    shape = (18, 17, 19)
    vol = _sphere(shape, (1, 1, 1), (0, 0, 0), (8.3, 7.9, 8.6))
    view = np.array(view)
    up = (0, 1, 0) if view[2] else (0, 0, 1)
    w, h = 24, 22
    target = np.array((7.5, 7.5, 8.5))  # pixel centres on integer coordinates across the view
    cam = Camera.ortho(target - 30.0 * view, target, up, height=float(h), aspect=w / h, near=0.5, far=100)
    o, _ = camera_rays(ray_buffer(cam, w, h), w, h)
    across = [a for a in range(3) if view[a] == 0]
    assert (o[:, across] == np.round(o[:, across])).all()
    out, ref, _ = _raycast(queue, vol, cam, w, h, 6.0, rate=32)
    _check(out, ref, f"grid lines {view}", min_hits=0.2)


def test_isovalue_outside_the_range_hits_nothing(queue):
    ds = datasets.marschner_lobb(33)
    level = float(ds["volume"].max()) + 0.01
    out, ref, stats = _raycast(queue, ds["volume"], CAM, 32, 24, level, ds["spacing"], ds["origin"])
    assert not ref.hit.any() and not out["hit"].any()
    assert np.isinf(out["depth"]).all() and (out["rgba"] == 0).all()
    assert stats["rounds"] > 3  # the rays walked every block on their way


def test_absent_blocks_read_as_nan_and_give_no_hits(queue):
    ds = datasets.marschner_lobb(17)
    out, ref, stats = _raycast(
        queue, ds["volume"], CAM, 16, 12, 0.5, ds["spacing"], ds["origin"], absent=True
    )
    assert ref.hit.any() and not out["hit"].any()
    assert stats["rounds"] > 1  # and the rays still walk on through the volume


def test_no_groups_launches_nothing(queue):
    empty = tuple(runtime.empty(queue, 1, np.uint32, "x")[:0] for _ in range(3))
    assert (
        raytrace_blocks(
            queue, None, None, (4, 4, 4), (1, 1, 1), (0, 0, 0), 0.5, None, 4, empty, None, None, (None,) * 4
        )
        is None
    )


_PACKET_SCENES = {
    "marschner_lobb": lambda: (datasets.marschner_lobb(41), CAM, 48, 40, 0.5, {}),
    "turbulence_permuted": lambda: (datasets.turbulence(30), CAM, 48, 40, 0.5, {"permute_slots": True}),
    "sphere_partial_blocks": lambda: (
        {
            "volume": _sphere((29, 27, 33), (0.5,) * 3, (-8.0, -6.0, -9.0), (0.0, 0.0, -1.0)),
            "spacing": (0.5,) * 3,
            "origin": (-8.0, -6.0, -9.0),
        },
        Camera.look_at((3.0, -3.5, 1.0), (0.0, 0.0, -1.0), (0, 0, 1), fov_y=70, near=0.05, far=100),
        40,
        32,
        4.0,
        {"rate": 32},
    ),
    "ortho_grid_lines": lambda: (
        {
            "volume": _sphere((18, 17, 19), (1, 1, 1), (0, 0, 0), (8.3, 7.9, 8.6)),
            "spacing": (1, 1, 1),
            "origin": (0, 0, 0),
        },
        Camera.ortho(
            (7.5, 7.5, 38.5), (7.5, 7.5, 8.5), (0, 1, 0), height=22.0, aspect=24 / 22, near=0.5, far=100
        ),
        24,
        22,
        6.0,
        {"rate": 32},
    ),
    "absent_blocks": lambda: (datasets.marschner_lobb(17), CAM, 16, 12, 0.5, {"absent": True}),
}


@pytest.mark.parametrize("scene", sorted(_PACKET_SCENES))
def test_packets_equal_one_ray_a_work_item(queue, scene):
    """The cpu profile's 8-ray packets (PACKET=8) give every pixel's hit, t,
    depth and colour bit for bit as one ray a work-item (the gpu profile's
    PACKET=0) on the same device, and take the same rounds."""
    ds, cam, w, h, level, kw = _PACKET_SCENES[scene]()
    got = {}
    for profile in ("cpu", "gpu"):
        with runtime.configure(tuning=profile):
            out, _, stats = _raycast(queue, ds["volume"], cam, w, h, level, ds["spacing"], ds["origin"], **kw)
        got[profile] = (out, stats)
    (a, sa), (b, sb) = got["cpu"], got["gpu"]
    for name in ("hit", "t", "depth", "rgba"):
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)
    assert sa == sb
    if scene != "absent_blocks":
        assert a["hit"].any()
