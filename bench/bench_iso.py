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
  surface, once); VTK's vtkFlyingEdges3D of the same volume on 2 threads
  (vtkSMPTools, STDThread backend: the PyPI wheel has no TBB/OpenMP), alone
  (the lower bound: no image) and followed by rendering its mesh to the same
  image size from the same viewpoint (offscreen through EGL, Mesa's llvmpipe
  software rasterizer on a machine without a GPU, pixels read back; skipped
  with VTK's reason where the wheel cannot draw offscreen); and the
  dense NumPy reference raycaster
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
    for i in ("clvis", "marching_cubes", "flying_edges", "flying_edges+render", "numpy")
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
    elif impl.startswith("flying_edges"):
        if impl.endswith("+render") and (why := _vtk_offscreen()) is not None:
            pytest.skip(f"VTK cannot render offscreen here: {why}")
        fe, render, info = flying_edges(zfp.decode(zv), d, cam, w, h, impl.endswith("+render"))
        run(benchmark, render, op=op, role="peer", n=rays, nbytes=zv.nbytes, rounds=3, **info)
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


VTK_THREADS = 2
_PROBE = """
import vtk
w = vtk.vtkRenderWindow(); w.SetOffScreenRendering(1); w.SetSize(8, 8)
r = vtk.vtkRenderer(); w.AddRenderer(r); w.Render()
print(w.GetClassName())
"""


def _vtk_offscreen():
    """None when VTK's wheel can draw offscreen in this machine (EGL or OSMesa),
    else why not: probed once in a child process, since a failed OpenGL
    context can abort the process."""
    if "vtk_offscreen" not in _cache:
        import re
        import subprocess
        import sys

        p = subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, text=True, timeout=120)
        ok = p.returncode == 0 and "RenderWindow" in p.stdout
        # VTK's log lines carry ANSI colour codes: strip them from the skip reason
        lines = re.sub(r"\x1b\[[0-9;]*m", "", p.stderr).strip().splitlines()
        _cache["vtk_offscreen"] = None if ok else (lines or [f"exit {p.returncode}"])[-1]
    return _cache["vtk_offscreen"]


def flying_edges(vol, d, cam, w, h, draw):
    """VTK's peer: (filter, fn, extra_info). fn re-runs vtkFlyingEdges3D on
    `vol` (Modified forces it) and, with `draw`, renders the mesh offscreen to
    w x h and reads the pixels back."""
    import vtk
    from vtkmodules.util.numpy_support import numpy_to_vtk
    from vtkmodules.vtkCommonCore import vtkSMPTools

    vtkSMPTools.SetBackend("STDThread")
    vtkSMPTools.Initialize(VTK_THREADS)
    img = vtk.vtkImageData()
    img.SetDimensions(*vol.shape[::-1])
    img.SetSpacing(*d["spacing"][::-1])
    img.SetOrigin(*d["origin"])
    img.GetPointData().SetScalars(numpy_to_vtk(np.ascontiguousarray(vol).ravel(), deep=True))
    fe = vtk.vtkFlyingEdges3D()
    fe.SetInputData(img)
    fe.SetValue(0, ISO)
    fe.ComputeNormalsOn()
    threads = f"vtkSMPTools {vtkSMPTools.GetBackend()}, {vtkSMPTools.GetEstimatedNumberOfThreads()} threads"
    info = {"impl": f"vtkFlyingEdges3D (VTK {vtk.vtkVersion.GetVTKVersion()}, {threads})"}
    if not draw:

        def fn():
            fe.Modified()
            fe.Update()
            return fe.GetOutput().GetNumberOfCells()

        fn()
        info["triangles"] = int(fe.GetOutput().GetNumberOfCells())
        return fe, fn, info
    win = vtk.vtkRenderWindow()
    win.SetOffScreenRendering(1)
    win.SetSize(w, h)
    ren = vtk.vtkRenderer()
    win.AddRenderer(ren)
    mapper = vtk.vtkPolyDataMapper()
    mapper.SetInputConnection(fe.GetOutputPort())
    mapper.ScalarVisibilityOff()
    actor = vtk.vtkActor()
    actor.SetMapper(mapper)
    ren.AddActor(actor)
    vc = ren.GetActiveCamera()
    vc.SetPosition(*cam.eye)
    vc.SetFocalPoint(*(cam.eye + cam.forward))
    vc.SetViewUp(*cam.view[1, :3])
    vc.SetViewAngle(35)
    vc.SetClippingRange(cam.near, cam.far)
    grab = vtk.vtkUnsignedCharArray()

    def fn():
        fe.Modified()
        win.Render()
        win.GetRGBACharPixelData(0, 0, w - 1, h - 1, 0, grab)  # the image back on the host
        return grab

    fn()
    gl = win.ReportCapabilities()
    renderer = next((ln.split(":", 1)[1].strip() for ln in gl.splitlines() if "renderer" in ln), "?")
    info["impl"] += f" + render {w}x{h} ({win.GetClassName()}, {renderer}, pixels read back)"
    info["triangles"] = int(fe.GetOutput().GetNumberOfCells())
    return fe, fn, info


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
            cpu_scale=1.0,  # two ideal threads halve the time, not the CPU time
            **common,
        )
