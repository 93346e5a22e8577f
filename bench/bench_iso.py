"""Benchmarks of the iso family (progressive isosurface raycasting over a
ZFP-compressed volume) with their peers in one session.

The volume: clvis.datasets.turbulence(256) (a labyrinth of sheets filling the
volume), isovalue 0.5, ZFP rate 8, seen whole by Camera.fit. Each clvis round
starts from a cold block cache (IsoRenderer.reset_cache), so the times
include decoding; compression and the macrocell grids are set-up.

- iso[..., to 100%] / [..., to 85%]: IsoRenderer.render with speculation,
  at 512x512 and 1280x720; the clvis row records passes with and without
  speculation, blocks decoded against the blocks whose range holds the
  isovalue (what an extract-everything method such as BCMC decodes), and the
  device memory against the decoded volume.
- iso_surface[...]: clvis.iso.sample_hits, a second field (the same grid)
  sampled at the hits of the 100% frame, against its NumPy reference.
- peers: scikit-image marching_cubes of the decoded volume (the whole
  surface, once), and the dense NumPy reference raycaster
  (clvis.reference.iso.render_rays) on a subset of the rays, scaled to the
  frame ("time_scale").

    clvis bench iso
"""

import numpy as np
import pytest
from benchutil import run, scaled

from clvis import Camera, datasets, iso, zfp
from clvis.camera import ray_buffer
from clvis.reference import iso as ref
from clvis.reference.camera import camera_rays

N = max(32, round(256 * min(1.0, scaled(1 << 24) / (1 << 24)) ** (1 / 3)))
RATE = 8
ISO = 0.5
SIZES = {"512x512": (512, 512), "1280x720": (1280, 720)}
_cache = {}


def scene(queue):
    if "scene" not in _cache:
        d = datasets.turbulence(N)
        zv = zfp.compress(d["volume"], RATE)
        r = iso.IsoRenderer(zv, spacing=d["spacing"], origin=d["origin"], queue=queue)
        lo = np.asarray(d["origin"], np.float64)
        hi = lo + (np.array(d["volume"].shape[::-1]) - 1) * np.asarray(d["spacing"][::-1])
        _cache["scene"] = (d, zv, r, lo, hi)
    return _cache["scene"]


def _camera(lo, hi, w, h):
    return Camera.fit(lo, hi, direction=(-0.6, 1.0, -0.45), aspect=w / h, fov_y=35)


def _cold(r, cam, w, h, completion, speculation=True):
    r.reset_cache()
    return r.render(cam, w, h, ISO, completion=completion, speculation=speculation)


# the peers render whole frames / extract the whole surface: compared at 100% only
CASES = [
    (s, c, i)
    for s in SIZES
    for c in (1.0, 0.85)
    for i in ("clvis", "marching_cubes", "numpy")
    if c == 1.0 or i == "clvis"
]


@pytest.mark.parametrize(
    "size,completion,impl", CASES, ids=[f"{s}-{round(c * 100)}%-{i}" for s, c, i in CASES]
)
def test_iso(benchmark, queue, size, completion, impl):
    d, zv, r, lo, hi = scene(queue)
    w, h = SIZES[size]
    cam = _camera(lo, hi, w, h)
    op = f"iso[turbulence {N}^3, {size}, to {round(completion * 100)}%]"
    rays = w * h
    if impl == "clvis":
        spec = _cold(r, cam, w, h, completion)
        plain = _cold(r, cam, w, h, completion, speculation=False)
        fine, _ = r.grids.active(ISO)
        st = spec.stats
        dev = sum(st["device_bytes"].values())
        run(
            benchmark,
            lambda: _cold(r, cam, w, h, completion),
            op=op,
            impl=impl,
            role="clvis",
            n=rays,
            nbytes=zv.nbytes,
            rounds=3,
            passes=st["passes"],
            passes_without_speculation=plain.stats["passes"],
            pass_reduction=plain.stats["passes"] / max(st["passes"], 1),
            blocks_decoded=st["blocks_decoded"],
            blocks_decoded_without_speculation=plain.stats["blocks_decoded"],
            isovalue_blocks=int(fine.sum()),
            blocks=zv.nblocks,
            decoded_per_isovalue_block=st["blocks_decoded"] / max(int(fine.sum()), 1),
            device_bytes=st["device_bytes"],
            device_memory_fraction=dev / d["volume"].nbytes,
            completion=spec.completion,
            hits=int(spec.hit.sum()),
        )
    elif impl == "marching_cubes":
        from skimage.measure import marching_cubes

        vol = zfp.decode(zv)
        run(
            benchmark,
            lambda: marching_cubes(vol, ISO),
            op=op,
            impl="skimage.measure.marching_cubes",
            role="peer",
            n=rays,
            nbytes=zv.nbytes,
            rounds=3,
        )
    else:
        vol = zfp.decode(zv)
        o, dd = camera_rays(ray_buffer(cam, w, h), w, h)
        m = 2048
        pick = np.linspace(0, rays - 1, m).astype(np.intp)
        run(
            benchmark,
            lambda: ref.render_rays(vol, o[pick], dd[pick], ISO, spacing=d["spacing"], origin=d["origin"]),
            op=op,
            impl="numpy dense reference (extrapolated from a ray subset)",
            role="peer",
            n=rays,
            nbytes=zv.nbytes,
            rounds=3,
            time_scale=rays / m,
            subset_rays=m,
        )


SURFACE_CASES = [(s, i) for s in SIZES for i in ("clvis", "numpy-reference")]


@pytest.mark.parametrize("size,impl", SURFACE_CASES, ids=[f"{s}-{i}" for s, i in SURFACE_CASES])
def test_iso_surface(benchmark, queue, size, impl):
    """A second field at the surface hits (sample_hits) of the 100% frame."""
    d, zv, r, lo, hi = scene(queue)
    w, h = SIZES[size]
    cam = _camera(lo, hi, w, h)
    key = ("frame", size)
    if key not in _cache:
        _cache[key] = r.render(cam, w, h, ISO)
    img = _cache[key]
    field = np.ascontiguousarray(d["volume"][::-1])  # another field on the same grid
    op = f"iso_surface[turbulence {N}^3, {size}]"
    if impl == "clvis":
        iso.sample_hits(img, cam, field, d["spacing"], d["origin"], queue=queue)  # builds the kernel
        run(
            benchmark,
            lambda: iso.sample_hits(img, cam, field, d["spacing"], d["origin"], queue=queue),
            op=op,
            impl=impl,
            role="clvis",
            n=w * h,
            nbytes=field.nbytes,
            rounds=3,
            hits=int(img.hit.sum()),
        )
    else:
        from clvis.reference.iso import surface

        run(
            benchmark,
            lambda: surface.sample_hits(field, cam, w, h, img.hit, img.t, d["spacing"], d["origin"]),
            op=op,
            impl="numpy reference",
            role="peer",
            n=w * h,
            nbytes=field.nbytes,
            rounds=3,
        )


# ZFP fixed-rate decoding of the whole volume (clvis.zfp.decode into a device
# array) against zfpy's serial decompression of the same headerless stream;
# "2 x zfpy" (zfpy's time halved) is the ideal two-thread zfp beside it.
ZFP_RATES = (8, 16)
ZFP_CASES = [(r, i) for r in ZFP_RATES for i in ("clvis", "zfpy", "zfpy2")]


def zfp_stream(rate):
    key = ("zfp", rate)
    if key not in _cache:
        v = datasets.turbulence(N)["volume"]
        _cache[key] = (v, zfp.compress(v, rate))
    return _cache[key]


@pytest.mark.parametrize("rate,impl", ZFP_CASES, ids=[f"rate{r}-{i}" for r, i in ZFP_CASES])
def test_zfp_decode(benchmark, queue, rate, impl):
    import zfpy

    v, zv = zfp_stream(rate)
    op = f"zfp_decode[turbulence {N}^3, rate {rate}]"
    common = dict(op=op, n=v.size, nbytes=zv.nbytes + v.nbytes, rounds=5)
    if impl == "clvis":
        dev = zv.to_device(queue)
        out = zfp.decode(dev, v.shape, rate, queue=queue, host=False)
        want = zfpy._decompress(zv.stream, zfpy.type_float, list(v.shape), rate=float(rate))
        assert np.array_equal(out.get().view(np.uint32), want.view(np.uint32))  # bit-exact
        run(
            benchmark,
            lambda: zfp.decode(dev, v.shape, rate, queue=queue, host=False),
            impl=impl,
            role="clvis",
            queue=queue,
            **common,
        )
    else:
        run(
            benchmark,
            lambda: zfpy._decompress(zv.stream, zfpy.type_float, list(v.shape), rate=float(rate)),
            impl="zfpy (serial)" if impl == "zfpy" else "2 x zfpy (ideal two-thread zfp: zfpy's time / 2)",
            role="peer",
            time_scale=1.0 if impl == "zfpy" else 0.5,
            **common,
        )
