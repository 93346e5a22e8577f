"""`clvis iso`: progressive isosurface raycasting of a ZFP-compressed volume
(Dyken, Usher, Kumar 2024): the image (rays still active marked) and the
figures of each pass."""

from __future__ import annotations

import argparse
import dataclasses
import os
import re
import sys
import time
import typing
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .._arrays import to_host
from ..errors import ClvisError, DataError
from ..io.volumes import otsu_level
from ..iso.zfp import MAX_RATE, MIN_RATE
from ._common import (
    SIZE_RULE,
    VIEWS_HELP,
    CliError,
    FitView,
    Parser,
    Progress,
    add_camera_options,
    add_cluster_options,
    add_output_options,
    add_volume_index,
    add_volume_options,
    camera_from_args,
    check_camera_args,
    check_iso_volume,
    clear_targets,
    cluster_client,
    cluster_failed,
    colormap_name,
    count,
    distributed_run,
    face_the_scan,
    finite_range,
    fit_box,
    grid_arg,
    note_earlier_pngs,
    on_workers,
    progress_from_args,
    read_volume_of,
    real,
    size,
)
from .orbit import add_orbit_options, check_orbit_args
from .raster import _colour
from .raster import _value_range as value_range_arg

if TYPE_CHECKING:
    import pyopencl as cl

    from ..camera import Camera
    from ..iso import IsoImage, IsoRenderer, ZfpVolume

_HELP = (
    """\
Compress a volume with ZFP (fixed rate), then ray march its isosurface in
passes: each pass traverses the macrocell grids, decodes only the blocks its
rays need into an LRU cache, and intersects them. Writes iso.png (rays still
running at the stop shown in magenta; the isovalue and completion in a band
above) and prints the figures of each pass.

Without a FILE it renders an embedded volume: marschner-lobb (64^3, iso 0.5)
or turbulence (128^3, iso 0.5). FILE: a raw volume named like the Open SciVis
datasets (<name>_<X>x<Y>x<Z>_<type>.raw, or any .raw with --shape and --dtype),
a .npy volume [z, y, x], a NIfTI file (.nii, .nii.gz; a 4-D series with
--volume-index), FreeSurfer's MGH (.mgz, .mgh), Analyze (.hdr with its .img, or
.hdr.gz with its .img.gz), or VTK
image data (.vti, legacy .vtk structured points, or an evenly spaced rectilinear
grid: .vtr or legacy .vtk; a .vtp, .vtu, .vts or a legacy .vtk POLYDATA,
UNSTRUCTURED_GRID or STRUCTURED_GRID is a point cloud: clvis render, clvis gauss,
clvis view), or an OpenVDB float grid (.vdb, --grid; the vdb extra) made dense.
The default isovalue of a file is Otsu's threshold of its samples
(scikit-image), which separates a scan's tissue from its background, moved
to the middle of the gap between the sample values on either side of it (a
0/1 mask: 0.5).

Several isovalues (--isovalue 0.3,0.6) are rendered one after the other and
composited, the nearest surface in each pixel, each in its own colour
(--surface-color, once per isovalue; default the renderer's sand, then
matplotlib's tab10). --color-by FIELD colours the surfaces by a second volume
(a file as above: two NIfTI, MGH or Analyze scans placed by their affines in
the scanner's world, whatever their grids, two VTK images by their spacing and
origin; else on the same grid, or any grid stretched over the same box),
sampled on the device where each ray hit, through --colormap over --range,
with a colour bar under the image. A constant volume has no isosurface: it
is reported and no surface is drawn. The fit view frames the voxels the
isosurfaces pass, not the whole volume (on Dask workers: the volume's box,
since the workers read a file brick by brick).

"""
    + VIEWS_HELP
)
_DATASETS = ("marschner-lobb", "turbulence")
_ACTIVE_COLOUR = (1.0, 0.0, 1.0)
# --view fit: from the front left, a little above, a narrow lens
_FIT = FitView(direction=(-0.6, 1.0, -0.45), fov_y=35.0)


# picture() shades this many pixels at a time
_PICTURE_BAND_PIXELS = 1 << 20
# host bytes a pixel `clvis iso` takes at its peak (19.7 GB was measured at 16000x16000: ~77 B)
HOST_BYTES_PER_PIXEL = 80


def add_parser(sub: argparse._SubParsersAction[Parser]) -> Parser:
    p = sub.add_parser(
        "iso",
        help="progressive isosurface raycasting of a ZFP-compressed volume",
        description=_HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "file",
        nargs="?",
        help="a volume: .raw (Open SciVis naming), .npy, NIfTI (.nii, .nii.gz), MGH (.mgz, .mgh), "
        "Analyze .hdr/.img (.hdr.gz/.img.gz), VTK .vti, .vtr or legacy .vtk, or an OpenVDB .vdb "
        "float grid (--grid; made dense)",
    )
    p.add_argument("--dataset", choices=_DATASETS, help="an embedded volume (default marschner-lobb)")
    p.add_argument(
        "--isovalue",
        type=_isovalues,
        default=None,
        metavar="VALUE[,VALUE...]",
        help="one or more isovalues, comma-separated (several: composited, nearest surface "
        "first); default: 0.5 for the embedded volumes, else Otsu's threshold of the samples",
    )
    p.add_argument(
        "--surface-color",
        type=_colour,
        action="append",
        default=None,
        metavar="COLOR",
        help="the surface's colour: a CSS name (red, skyblue, ...), #RRGGBB, #RGB or R,G,B (0..255); "
        "give it once per "
        "isovalue (default the renderer's sand, then matplotlib's tab10)",
    )
    p.add_argument(
        "--color-by",
        default=None,
        metavar="FIELD",
        help="colour the surface by a second volume file (read as FILE is; two scans placed by "
        "their affines in the scanner's world, two VTK images by their spacing and origin, else the "
        "same grid, or stretched over the same box), "
        "sampled where each ray hit, with a colour bar",
    )
    add_volume_index(
        p, "--color-by-volume-index", "the volume of a 4-D --color-by file (--volume-index: FILE's)"
    )
    p.add_argument(
        "--colormap",
        type=colormap_name,
        default=None,
        metavar="NAME",
        help="with --color-by: a matplotlib colormap (default viridis)",
    )
    p.add_argument(
        "--range",
        type=value_range_arg,
        default=None,
        metavar="MIN,MAX|pLO,pHI",
        help="with --color-by: the values the colormap spans, or percentiles of the values on "
        "the surface such as p2,p98 (default their min..max)",
    )
    p.add_argument(
        "--rate", type=count(MIN_RATE, MAX_RATE), default=8, help="ZFP bits per value, 1..32 (default 8)"
    )
    p.add_argument(
        "--completion",
        type=real(0.0, 1.0, open_lo=True, what="a fraction"),
        default=1.0,
        help="stop once this fraction of the rays is finished (default 1.0); passes finish rays "
        "in large steps, speculation most of them in the first, so the stop may come well past "
        "it: --no-speculation stops closer",
    )
    p.add_argument(
        "--infill",
        action="store_true",
        help="also write iso-infill.png: the rays still running filled in by the in-fill network "
        "(clvis.post; use with --completion below 1)",
    )
    p.add_argument(
        "--post",
        choices=("infill",),
        default=None,
        help="--post infill: the same as --infill (clvis render's spelling of its networks; "
        "without it --post was read as --post-guard)",
    )
    p.add_argument(
        "--model-dir",
        default=None,
        metavar="DIR",
        help="with --infill: the in-fill network's model card and files from DIR (a `clvis train "
        "--out` folder; default: the shipped model)",
    )
    p.add_argument(
        "--post-guard",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="with --infill: check the network against push-pull and the partial image on this frame "
        "(the finished rays beside the running ones withheld) and keep, tile by tile, the better "
        "(clvis.post.guard; default: the network's own, PostNetwork.guard)",
    )
    p.add_argument(
        "--compare",
        action="store_true",
        help="with --infill: also render the view to completion (iso-complete.png) and score the "
        "network's picture, push-pull's and the partial image against it (PSNR, SSIM)",
    )
    p.add_argument("--no-speculation", action="store_true", help="one candidate block per ray and pass")
    p.add_argument(
        "--size", type=size, default=(1280, 720), metavar="WxH", help=f"{SIZE_RULE} (default 1280x720)"
    )
    add_output_options(p, "clvis-iso", "pixels without surface")
    add_orbit_options(p)
    add_camera_options(p, _FIT)
    add_volume_options(p)
    p.add_argument(
        "--grid",
        type=grid_arg,
        default=None,
        metavar="NAME|INDEX",
        help="the float grid of a .vdb file: its name, or its index (0 first) (default: the first float "
        "grid); made dense, its inactive voxels the grid's background (a level set's outside; its "
        "default isovalue 0)",
    )
    add_cluster_options(p)
    p.add_argument(
        "--brick",
        type=count(4, 4096),
        default=None,
        metavar="N",
        help="with --workers/--scheduler: cells per brick edge, a multiple of 4 (default 64)",
    )
    return p


def _isovalues(text: str) -> list[float]:
    """The --isovalue argument type: '0.3,0.6' -> [0.3, 0.6] (finite, distinct)."""
    parse = real()
    out = [parse(t.strip()) for t in text.split(",")]
    if len(set(out)) != len(out):
        raise argparse.ArgumentTypeError(f"expected distinct values, got {text!r}")
    return out


#: the PNGs clvis iso writes beside iso.png: an earlier run's that this one did not write are named
_EARLIER_PNG = re.compile(r"iso-(infill|complete)\.png")


def _load(args):
    """(volume, spacing, origin, default isovalue, (min, max), description,
    its world (_world: a NIfTI, MGH or Analyze file's voxel to scanner world,
    a VTK image's to its own), else None)."""
    from .. import datasets

    if args.file is not None:
        if args.dataset is not None:
            raise CliError("--dataset chooses an embedded volume; leave it out with a FILE")
        path = Path(args.file)
        if not path.exists():
            raise CliError(f"{path}: no such file")
        if path.name.lower().endswith(".vdb"):
            return _load_vdb(args, path)
        v = read_volume_of(args, path)
        data = np.asarray(v.data, np.float32)
        value_range = finite_range(data, str(path))
        level = otsu_level(data)  # of the finite samples, before any NaN is set
        data = check_iso_volume(data, str(path), "clvis iso")
        source = str(path) if v.array is None else f"{path} (array {v.array})"
        return data, v.spacing, v.origin, level, value_range, source, _world(v)
    if any(getattr(args, k) is not None for k in ("shape", "dtype", "volume_index", "array")):
        raise CliError("--shape, --dtype, --volume-index and --array are for a volume FILE")
    name = args.dataset or "marschner-lobb"
    d = datasets.marschner_lobb(64) if name == "marschner-lobb" else datasets.turbulence(128)
    spacing = d["spacing"] if args.spacing is None else tuple(reversed(args.spacing))
    return (
        d["volume"],
        spacing,
        d["origin"],
        0.5,
        finite_range(d["volume"], name),
        f"the embedded {name} ({d['volume'].shape[0]}^3)",
        None,
    )


def _load_vdb(args, path: Path):
    """_load's tuple for a .vdb's float grid made dense (read_vdb_volume): a
    level set's default isovalue 0 (its surface), another grid's Otsu's."""
    from ..gauss import default_isovalue, read_vdb_volume

    given = [
        f
        for f, v in (
            ("--shape", args.shape),
            ("--dtype", args.dtype),
            ("--volume-index", args.volume_index),
            ("--array", getattr(args, "array", None)),
        )
        if v is not None
    ]
    if given:
        raise CliError(f"{' and '.join(given)}: not for a .vdb (--grid picks its grid)")
    grid = args.grid
    v, grid_class = read_vdb_volume(path, grid)
    data = np.asarray(v.data, np.float32)
    if data.size == 0:
        raise CliError(f"{path}: grid {v.array!r} has no active voxel")
    spacing = v.spacing if args.spacing is None else tuple(float(s) for s in reversed(args.spacing))
    data = check_iso_volume(data, str(path), "clvis iso")
    kind = f", a {grid_class}" if grid_class else ""
    return (
        data,
        spacing,
        v.origin,
        default_isovalue(data, grid_class),
        finite_range(data, str(path)),
        f"{path} (grid {v.array!r}{kind})",
        None,
    )


def picture(img: IsoImage, transparent: bool = False) -> np.ndarray:
    """(H, W, 4) uint8: the shaded surface, rays still running in magenta,
    over images.BACKGROUND (or transparent where neither)."""
    from .. import images

    h, w = img.hit.shape
    out = np.empty((h, w, 4), np.uint8)
    # in bands of rows: the float temporaries (~70 bytes a pixel) stay those
    # of a band, not of the whole image (HOST_BYTES_PER_PIXEL)
    step = max(1, _PICTURE_BAND_PIXELS // max(w, 1))
    for y0 in range(0, h, step):
        rows = slice(y0, y0 + step)
        hit, active = img.hit[rows], img.active[rows]
        rgb = np.where(hit[..., None], img.rgba[rows, :, :3], np.float32(0.0))
        rgb = np.where(active[..., None], np.asarray(_ACTIVE_COLOUR, np.float32), rgb)
        alpha = (hit | active)[..., None].astype(np.float32)
        rgba = np.clip(np.rint(np.concatenate([rgb, alpha], axis=2) * 255), 0, 255).astype(np.uint8)
        out[rows] = rgba if transparent else images.opaque(rgba)
    return out


def labelled(
    img: IsoImage, isovalue: float | Sequence[float], transparent: bool = False, bare: bool = False
) -> np.ndarray:
    """picture() under a band naming the isovalue(s) and the completion (bare:
    the picture alone, --no-labels)."""
    from .. import images

    if bare:
        return picture(img, transparent)
    isos = [isovalue] if isinstance(isovalue, (int, float, np.floating)) else list(isovalue)
    values = ", ".join(f"{v:g}" for v in isos)
    text = f"isovalue{'s' if len(isos) > 1 else ''} {values}, completion {img.completion:.3f}"
    if img.completion < 1:
        text += " (magenta: rays still running)"
    return images.label(picture(img, transparent), text)


class _Status:
    """The passes stage's name, formatted when Progress redraws its line: the
    tile, passes and rays done so far (IsoRenderer.render's progress)."""

    def __init__(self) -> None:
        self.text = "passes"

    def __call__(self, p: dict) -> None:
        self.text = (
            f"passes {p['passes']}, tile {p['tile']}/{p['tiles']}, "
            f"rays {p['rays_done']:,}/{p['rays_total']:,}"
        )

    def __format__(self, spec: str) -> str:
        return format(self.text, spec)


def render(
    volume: ZfpVolume | Any,
    spacing: Sequence[float],
    origin: Sequence[float],
    isovalue: float,
    width: int,
    height: int,
    *,
    rate: int = 8,
    completion: float = 1.0,
    speculation: bool = True,
    camera: Callable[[np.ndarray, np.ndarray], Camera] | None = None,
    queue: cl.CommandQueue | None = None,
    progress: Progress | None = None,
    host: bool = True,
) -> tuple[IsoRenderer, Camera, IsoImage]:
    """(renderer, camera, IsoImage), seen by camera(lo, hi) of the volume's
    bounds (default: the fit view); progress: a clvis.cli._common.Progress
    (default: none); host=False: the image stays on the device."""
    from ..iso import IsoRenderer

    progress = progress if progress is not None else Progress(False)
    with progress.stage("compress, build kernels"):
        r = IsoRenderer(volume, rate=rate, spacing=spacing, origin=origin, queue=queue)
    lo = np.asarray(origin, np.float64)
    hi = lo + (np.array(r.shape[::-1]) - 1) * np.asarray(spacing, np.float64)[::-1]
    cam = camera(lo, hi) if camera is not None else fit_box(lo, hi, width, height, _FIT)
    status = _Status()
    with progress.stage(status):
        img = r.render(
            cam,
            width,
            height,
            isovalue,
            completion=completion,
            speculation=speculation,
            progress=status,
            host=host,
        )
    return r, cam, img


def cmd(args: argparse.Namespace) -> int:
    if getattr(args, "post", None) == "infill":  # clvis render's spelling
        args.infill = True
    check_camera_args(args)
    check_orbit_args(args)
    if args.grid is not None and not str(args.file or "").lower().endswith(".vdb"):
        raise CliError("--grid picks a grid of a .vdb FILE")
    if distributed_run(args):
        if str(args.file or "").lower().endswith(".vdb"):
            raise CliError(
                "--workers/--scheduler: a .vdb is read and made dense on one device; leave them out"
            )
        if args.orbit is not None:
            raise CliError("--orbit: not with --workers/--scheduler (one device renders the turntable)")
        args.brick = 64 if args.brick is None else args.brick
        return on_workers("iso", _run_distributed, args)
    if args.brick is not None:
        raise CliError(
            "--brick cuts the volume for Dask workers; add --workers N (or --scheduler) or leave it out"
        )
    return _run(args)


def _run_distributed(args) -> int:
    """`clvis iso FILE --workers N | --scheduler ADDRESS`: the volume cut into
    bricks, read (a FILE: memory-mapped slices) and rendered on Dask workers."""
    from .. import datasets, images
    from ..distributed.iso import DistributedIsoRenderer

    if args.brick % 4:
        raise CliError(f"--brick: {args.brick} is not a multiple of 4 (ZFP's block edge)")
    if args.completion != 1.0:
        raise CliError("--completion: on workers every ray finishes (leave it out)")
    if args.isovalue is not None and len(args.isovalue) > 1:
        raise CliError("--isovalue: one value on workers (several are composited on one device)")
    for name in ("surface_color", "color_by", "color_by_volume_index", "colormap", "range"):
        if getattr(args, name) is not None:
            raise CliError(f"--{name.replace('_', '-')}: not on workers (leave out --workers/--scheduler)")
    # the in-fill network's options (they were ignored: only iso.png was written)
    for name in ("infill", "compare", "model_dir", "post_guard"):
        if getattr(args, name) not in (None, False):
            raise CliError(
                f"--{name.replace('_', '-')}: the in-fill network fills the rays a one-device render "
                "leaves running; on workers every ray finishes (leave out --workers/--scheduler)"
            )
    client, workers = cluster_client(args)
    w, h = args.size
    t0 = time.perf_counter()
    if args.file is not None:
        if args.dataset is not None:
            raise CliError("--dataset chooses an embedded volume; leave it out with a FILE")
        if not Path(args.file).exists():
            raise CliError(f"{args.file}: no such file")
        if args.isovalue is None:
            raise CliError(
                "--isovalue: needed with a FILE on workers (Otsu's default reads every sample here)"
            )
        source, iso, spacing, origin, what = (
            args.file,
            args.isovalue[0],
            None,
            (0.0, 0.0, 0.0),
            str(args.file),
        )
        if args.spacing is not None:
            spacing = tuple(reversed(args.spacing))
        from ..io.volumes import NIBABEL_FORMATS

        if str(args.file).lower().endswith(NIBABEL_FORMATS):  # read in RAS+ order on the workers too
            face_the_scan(args)
        kw = {"shape": args.shape, "dtype": args.dtype, "volume_index": args.volume_index}
        if not str(args.file).lower().endswith(".raw"):
            kw = {"volume_index": args.volume_index} if args.volume_index is not None else {}
    else:
        name = args.dataset or "marschner-lobb"
        d = datasets.marschner_lobb(64) if name == "marschner-lobb" else datasets.turbulence(128)
        source, spacing, origin = d["volume"], d["spacing"], d["origin"]
        if args.spacing is not None:
            spacing = tuple(reversed(args.spacing))
        iso = 0.5 if args.isovalue is None else args.isovalue[0]
        what, kw = f"the embedded {name} ({d['volume'].shape[0]}^3)", {}
    try:
        dr = DistributedIsoRenderer(
            source,
            client,
            rate=args.rate,
            spacing=spacing,
            origin=origin,
            brick=args.brick,
            workers=workers,
            connect_timeout=args.connect_timeout,
            **kw,
        )
    except ClvisError:
        raise
    except OSError as e:
        raise cluster_failed(args, e) from None
    with dr:
        lo = np.asarray(dr.origin, np.float64)
        hi = lo + (np.array(dr.volume_shape[::-1]) - 1) * np.asarray(dr.spacing, np.float64)[::-1]
        cam = camera_from_args(args, lo, hi, w, h)
        img = dr.render(cam, w, h, iso, speculation=not args.no_speculation)
    total = time.perf_counter() - t0
    path = images.save_png(
        Path(args.out) / "iso.png", labelled(img, iso, args.transparent, bare=args.no_labels)
    )
    st = img.stats
    sec = st["seconds"]
    print(f"clvis iso: {what}, isovalue {iso:g}, ZFP rate {args.rate}, {w}x{h}")
    print(f"  bricks      {len(dr.bricks)} of {args.brick}^3 cells on {st['workers']} Dask workers")
    print(
        f"  frame       {sec['frame'] * 1e3:.1f} ms ({st['compositing']} compositing; busiest worker: "
        f"render {sec['render'] * 1e3:.1f} ms, composite {sec['composite'] * 1e3:.1f} ms)"
    )
    print("  sent        " + ", ".join(f"{a} {b / 1e6:.2f} MB" for a, b in sorted(st["bytes_sent"].items())))
    print(f"  time        {total:.2f} s with reading, compression and setup")
    print(f"wrote {path}{os.sep if path.is_dir() else ''}")
    return 0


def _run(args) -> int:
    from .. import images, runtime

    if args.infill and args.completion >= 1.0:
        raise CliError(
            "--infill fills the rays still running when the render stops; with --completion 1 every "
            "ray finishes and there is nothing to fill (add --completion 0.85)"
        )
    if args.post_guard is not None and not args.infill:
        raise CliError("--post-guard guards the in-fill network: add --infill")
    if args.model_dir is not None and not args.infill:
        raise CliError("--model-dir: where the in-fill network's model is: add --infill")
    if args.compare and not args.infill:
        raise CliError("--compare scores the in-fill network against the complete render: add --infill")
    if args.compare and args.orbit is not None:
        raise CliError("--compare scores one view: leave out --orbit")
    if args.color_by is None:
        for name in ("colormap", "range", "color_by_volume_index"):
            if getattr(args, name) is not None:
                flag = "--" + name.replace("_", "-")
                what = "picks a volume of" if name == "color_by_volume_index" else "colours the surface by"
                raise CliError(f"{flag} {what} a field: add --color-by FIELD")
    volume, spacing, origin, default_iso, (vmin, vmax), source, affine = _load(args)
    isos = args.isovalue if args.isovalue is not None else [default_iso]
    if args.infill and (len(isos) > 1 or args.color_by is not None or args.surface_color is not None):
        given = (
            f"{len(isos)} isovalues"
            if len(isos) > 1
            else "--color-by"
            if args.color_by is not None
            else "--surface-color"
        )
        raise CliError(
            f"--infill: not with {given}: the network in-fills one isovalue's surface in the "
            "renderer's colours (one --isovalue, no --color-by or --surface-color)"
        )
    if args.orbit is not None and (
        len(isos) > 1 or args.color_by is not None or args.surface_color is not None
    ):
        raise CliError(
            "--orbit: turns one isovalue in the renderer's colours (no several isovalues, --color-by or "
            "--surface-color)"
        )
    if args.surface_color is not None and len(args.surface_color) != len(isos):
        raise CliError(
            f"--surface-color: given {len(args.surface_color)} times for {len(isos)} isovalue(s); "
            "give it once per isovalue"
        )
    constant = vmin == vmax
    for iso in isos:
        _warn_isovalue(iso, vmin, vmax)
    _warn_scale(vmin, vmax)
    w, h = args.size
    q = runtime.default_queue()
    # the command's host memory a pixel at its peak (the renderer's host image,
    # the labelled copy, the infill and the PNGs) and the renderer's device
    # tile (its rays and pass items, at most TILE_BYTES; host memory too on a
    # CPU device), refused up front
    from ..iso.render import ITEM_BYTES, PIXEL_BYTES, TILE_BYTES

    runtime.check_memory(
        q,
        f"clvis iso --size {w}x{h}",
        device_bytes=min(TILE_BYTES, w * h * (PIXEL_BYTES + 2 * ITEM_BYTES)),
        host_bytes=w * h * HOST_BYTES_PER_PIXEL * (1 + (len(isos) > 1) + bool(args.compare)),
    )
    field = _field(args) if args.color_by is not None else None
    t0 = time.perf_counter()
    progress = progress_from_args(args, "clvis iso")
    r = cam = None
    shots = []
    for iso in isos:
        if constant:  # no isosurface: no render, no arbitrary hits
            shots.append(_empty(w, h))
            continue
        if r is None or cam is None:
            r, cam, img = render(
                volume,
                spacing,
                origin,
                iso,
                w,
                h,
                rate=args.rate,
                completion=args.completion,
                speculation=not args.no_speculation,
                queue=q,
                # only the fit view frames points (the scan is a few passes over the volume)
                camera=lambda lo, hi: camera_from_args(
                    args,
                    lo,
                    hi,
                    w,
                    h,
                    points=_surface_points(volume, isos, spacing, origin) if args.view[0] == "fit" else None,
                ),
                progress=progress,
                host=not args.infill,  # the in-fill network takes the image where it is
            )
        else:  # the next isovalue: the same compressed volume, grids and cache
            status = _Status()
            with progress.stage(status):
                img = r.render(
                    cam,
                    w,
                    h,
                    iso,
                    completion=args.completion,
                    speculation=not args.no_speculation,
                    progress=status,
                )
        shots.append(img)
    total = time.perf_counter() - t0
    out = Path(args.out)
    if args.completion < 1.0 and not args.no_speculation and not constant:
        past = max(float(i.completion) for i in shots)
        if past > args.completion + 0.05:
            print(
                f"clvis iso: note: the render stopped at completion {past:.3f}, well past "
                f"--completion {args.completion:g}: speculation finishes most rays in the first pass "
                "(--no-speculation stops closer)",
                file=sys.stderr,
            )
    img, bar, crange = shots[0], None, None
    if field is not None or args.surface_color is not None or len(shots) > 1:
        img, bar, crange = _coloured(args, shots, cam, field, (volume.shape, spacing, origin, affine))
    infilled = None
    targets = ["iso-infill.png", "iso.png"] if args.infill else ["iso.png"]
    clear_targets(out, targets + (["iso-complete.png"] if args.compare else []))
    scores = None
    if args.infill:
        from .. import post

        net = post.load("infill", queue=q, directory=args.model_dir)
        filled = net(img, guard=args.post_guard)
        # iso.png shows the colour, hit and active planes: only these come back
        # (device planes from render(host=False); a volume with no surface
        # gets a host image without rendering)
        img = dataclasses.replace(
            img, rgba=to_host(img.rgba), hit=to_host(img.hit), active=to_host(img.active)
        )
        if args.compare and r is not None and cam is not None:
            scores = _compare(args, r, cam, isos[0], img, filled, out)
        filled = filled if args.transparent else images.opaque(filled)
        text = f"isovalue {isos[0]:g}, completion {img.completion:.3f}, in-filled by the network"
        infilled = images.save_png(
            out / "iso-infill.png", filled if args.no_labels else images.label(filled, text)
        )
    picture_ = labelled(img, isos, args.transparent, bare=args.no_labels)
    if bar is not None and not args.no_labels:
        picture_ = np.concatenate([picture_, bar], axis=0)
    path = images.save_png(out / "iso.png", picture_)
    written = ["iso.png"] + ["iso-infill.png"] * args.infill + ["iso-complete.png"] * bool(scores)
    note_earlier_pngs("clvis iso", out, set(written), _EARLIER_PNG)
    orbit = None
    if args.orbit is not None and r is not None:  # the turntable (clvis.cli.orbit)
        from .orbit import iso_orbit

        surface = _surface_box(volume, isos[:1], spacing, origin)
        orbit = iso_orbit(args, r, isos[0], out, progress_from_args(args, "clvis iso"), cam, surface)
    values = ", ".join(f"{v:g}" for v in isos)
    print(
        f"clvis iso: {source}, isovalue{'s' if len(isos) > 1 else ''} {values}, ZFP rate {args.rate}, {w}x{h}"
    )
    print(f"  device      {runtime.describe(q.device)}")
    if r is None:
        print(f"  volume      {volume.shape}, constant ({vmin:g}): no isosurface, nothing rendered")
        print(f"wrote {path}{os.sep if path.is_dir() else ''}" + (f" and {infilled}" if infilled else ""))
        return 0
    print(
        f"  volume      {r.shape} = {volume.nbytes / 1e6:.1f} MB decoded, {r.volume.nbytes / 1e6:.1f} MB "
        f"compressed, {r.volume.nblocks:,} blocks, spacing (z, y, x) {', '.join(f'{v:g}' for v in spacing)}"
    )
    seconds = 0.0
    for iso, shot in zip(isos, shots, strict=True):
        st = shot.stats
        seconds += st["seconds"]
        if len(isos) > 1:
            print(f"  isovalue    {iso:g}")
        print(
            f"  passes      {st['passes']} (speculation {'on' if st['speculation'] else 'off'}), "
            f"completion {shot.completion:.3f}, {st['rays_entering']:,} rays enter the volume"
        )
        if st["tiles"] > 1:
            print(
                f"  tiles       {st['tiles']} of {st['tile_pixels']:,} pixels, passes per tile "
                f"{st['passes_per_tile']}"
            )
        print(f"  per pass    active rays {_short(st['active_per_pass'])}")
        print(f"              candidates per ray {_short(st['n_spec_per_pass'])}")
        print(f"  blocks      {st['blocks_decoded']:,} decoded, cache of {st['cache_slots']:,} slots")
        dev = st.get("device_bytes", {})
        if dev:
            print("  device MB   " + ", ".join(f"{k} {v / 1e6:.1f}" for k, v in dev.items()))
    if crange is not None:
        print(
            f"  colour      {args.color_by} at the hits through {args.colormap or 'viridis'}, "
            f"range {crange[0]:.6g}..{crange[1]:.6g}"
        )
        print(f"              the field {_placed(field, affine, volume.shape)}")
    print(
        f"  time        build {r.build_seconds:.2f} s, passes {seconds * 1e3:.1f} ms; "
        f"{total:.2f} s with compression and setup"
    )
    if orbit is not None:
        from .orbit import report

        report(*orbit)
    if infilled is not None:
        ns = net.stats
        print(
            f"  in-fill     {net!r}: pack {ns['pack'] * 1e3:.1f} ms, "
            f"inference {ns['inference'] * 1e3:.1f} ms, unpack {ns['unpack'] * 1e3:.1f} ms"
        )
        if scores is not None:
            (done, seconds_full, complete), table = scores
            print(
                f"  compare     against the complete render (completion {done:.3f}, "
                f"{seconds_full * 1e3:.1f} ms of passes), PSNR dB / SSIM:"
            )
            for name, m in table.items():
                print(f"              {name:9s} {m['psnr']:6.2f} / {m['ssim']:.3f}")
            print(f"wrote {path}, {infilled} and {complete}")
            return 0
        print(f"wrote {path} and {infilled}")
        return 0
    print(f"wrote {path}{os.sep if path.is_dir() else ''}")
    return 0


def _compare(args, r, cam, iso: float, img, filled: np.ndarray, out: Path):
    """--compare: the view rendered to completion (the renderer's cache is
    warm), written as iso-complete.png, and the in-fill network's picture
    (`filled`, uint8 RGBA), push-pull's and the partial image (running rays
    black) scored against it, each as an 8-bit picture premultiplied over
    black, as ``clvis eval infill`` scores them. Returns ((completion,
    seconds, path), {name: {psnr, ssim}})."""
    from .. import images
    from ..metrics import as_picture, metrics
    from ..post.pushpull import pushpull

    w, h = args.size
    full = r.render(cam, w, h, iso, completion=1.0, speculation=not args.no_speculation)
    target = np.where(full.hit[..., None], full.rgba[..., :3], np.float32(0)).astype(np.float32)
    kept = img.hit & ~img.active
    partial = np.concatenate(
        [np.where(kept[..., None], img.rgba[..., :3], np.float32(0)), kept[..., None]], axis=2
    ).astype(np.float32)
    filled_pp = pushpull(partial, ~img.active)[..., :3]

    table = {
        "network": metrics(filled[..., :3] / np.float32(255), target),
        "push-pull": metrics(as_picture(filled_pp), target),
        "partial": metrics(as_picture(partial[..., :3]), target),
    }
    picture_ = labelled(full, [iso], args.transparent, bare=args.no_labels)
    path = images.save_png(out / "iso-complete.png", picture_)
    return (float(full.completion), float(full.stats["seconds"]), path), table


def _surface_points(volume, isos, spacing, origin, most: int = 65536) -> np.ndarray | None:
    """Up to `most` world positions of voxels the isosurfaces pass beside (a
    sign change to a neighbour), for the fit view to frame the surface, not
    the whole volume (a small surface in a corner of its volume would fill a
    corner of the picture); None when the volume is no NumPy array or no cell
    holds an isovalue."""
    near = _beside_surface(volume, isos)
    if near is None:
        return None
    idx = np.flatnonzero(near)
    idx = idx[:: -(-idx.size // most)]
    zyx = np.stack(np.unravel_index(idx, volume.shape), axis=1).astype(np.float64)
    return np.asarray(origin, np.float64) + (zyx * np.asarray(spacing, np.float64))[:, ::-1]


def _beside_surface(volume, isos) -> np.ndarray | None:
    """The voxels the isosurfaces pass beside (a sign change to the next one
    along an axis), (Z, Y, X) bool; None when the volume is no NumPy array or
    no cell holds an isovalue."""
    if not isinstance(volume, np.ndarray) or volume.ndim != 3 or min(volume.shape) < 2:
        return None
    near = np.zeros(volume.shape, bool)
    for iso in isos:
        above = volume >= iso
        for axis in range(3):
            head = [slice(None)] * 3
            tail = [slice(None)] * 3
            head[axis], tail[axis] = slice(None, -1), slice(1, None)
            near[tuple(head)] |= above[tuple(head)] != above[tuple(tail)]
    return near if near.any() else None


def _surface_box(volume, isos, spacing, origin) -> tuple[np.ndarray, np.ndarray] | None:
    """(lo, hi), world x, y, z: a box holding the isosurfaces (the cells
    beside the voxels they pass), for --orbit to keep in every frame; None as
    _beside_surface."""
    near = _beside_surface(volume, isos)
    if near is None:
        return None
    first, last = [], []
    for axis in range(3):
        idx = np.flatnonzero(near.any(axis=tuple(a for a in range(3) if a != axis)))
        first.append(idx[0])
        last.append(min(idx[-1] + 1, near.shape[axis] - 1))
    step = np.asarray(spacing, np.float64)[::-1]
    o = np.asarray(origin, np.float64)
    return o + np.array(first[::-1], np.float64) * step, o + np.array(last[::-1], np.float64) * step


#: the data's magnitudes past which the renderer's float32 gradients (its
#: shading normals) overflow or underflow: the same sphere's distance field
#: scaled by 1e-20..1e20 renders the same picture, by 1e22 (or 1e-22) an unlit one
SCALE_LIMITS = (1e-20, 1e20)


def _warn_scale(vmin: float, vmax: float) -> None:
    """A warning on stderr for data whose values are too large, or whose
    range is too small, for the shading's float32 arithmetic."""
    big = max(abs(vmin), abs(vmax))
    if big > SCALE_LIMITS[1]:
        why = f"the data reach {big:.3g}"
    elif vmin != vmax and vmax - vmin < SCALE_LIMITS[0]:
        why = f"the data span only {vmax - vmin:.3g}"
    else:
        return
    print(
        f"clvis iso: warning: {why}: the shading's float32 gradients overflow or underflow past "
        f"{SCALE_LIMITS[0]:g}..{SCALE_LIMITS[1]:g}, and the surface comes out unlit or missing; scale the "
        "values (e.g. numpy: v / abs(v).max()) and the isovalue with them",
        file=sys.stderr,
    )


def _warn_isovalue(iso: float, vmin: float, vmax: float) -> None:
    """A warning on stderr for an isovalue that shows no surface, or flat
    regions instead of one."""
    if vmin == vmax:
        why = f"the volume is constant ({vmin:g}): it has no isosurface, and none is drawn"
    elif not vmin <= iso <= vmax:
        why = (
            f"isovalue {iso:g} is outside the data range [{vmin:g}, {vmax:g}]: the data has no surface "
            "there; what shows, if anything, is ZFP's compression error (less at a higher --rate)"
        )
    elif iso in (vmin, vmax):
        end = "minimum" if iso == vmin else "maximum"
        why = (
            f"isovalue {iso:g} is the data's {end}: regions at exactly that value show as surface "
            f"(choose a value inside ({vmin:g}, {vmax:g}))"
        )
    else:
        return
    print(f"clvis iso: warning: {why}", file=sys.stderr)


def _empty(w: int, h: int) -> IsoImage:
    """An image with no surface (a constant volume: nothing rendered)."""
    from ..iso import IsoImage

    return IsoImage(
        np.zeros((h, w, 4), np.float32),
        np.full((h, w), np.inf, np.float32),
        np.zeros((h, w), bool),
        np.full((h, w), np.inf, np.float32),
        np.zeros((h, w), bool),
        1.0,
        {},
        np.zeros((h, w), np.uint8),
        np.full((h, w), np.inf, np.float32),
    )


def _field(args) -> tuple[np.ndarray, tuple[str, np.ndarray] | None]:
    """--color-by's volume, [z, y, x] float32, and its world (_world: a
    NIfTI, MGH or Analyze file's voxel to scanner world, a VTK image's to
    its own, else None)."""
    path = Path(args.color_by)
    if not path.exists():
        raise CliError(f"--color-by: {path}: no such file")
    # FILE's --volume-index is not the field's
    field_args = argparse.Namespace(**{**vars(args), "volume_index": args.color_by_volume_index})
    try:
        v = read_volume_of(field_args, path)
        data = np.asarray(v.data, np.float32)
    except (DataError, ValueError) as e:  # read_volume's words for the field's option
        text = (
            str(e)
            .replace(
                "--volume-index T (clvis iso, gauss and view), volume_index=T in Python",
                "--color-by-volume-index T",
            )
            .replace("volume_index:", "--color-by-volume-index:")
            .replace("; clvis iso/gauss/view: --volume-index T)", ")")
        )
        raise CliError(f"--color-by: {text}") from e
    if data.ndim != 3 or min(data.shape) < 2:
        raise CliError(
            f"--color-by: {path}: expected a 3-D volume with 2 samples per axis or more, got {data.shape}"
        )
    return np.ascontiguousarray(data, np.float32), _world(v)


def _world(v) -> tuple[str, np.ndarray] | None:
    """(its world, (4, 4) voxel (i, j, k, 1) -> that world) of a volume read
    from a file: "scanner" and a NIfTI, MGH or Analyze file's affine; "vtk"
    and a VTK image's (its `array` named) own spacing and origin
    (axis-aligned); None for a file that places its samples nowhere (.npy,
    .raw: spacing 1 and origin 0 unless told). Two files are placed by their
    worlds only where it is the same one (a scanner's RAS and a VTK image's
    own frame are not)."""
    if v.affine is not None:
        return "scanner", v.affine
    if v.array is None:
        return None
    m = np.eye(4)
    m[:3, :3] = np.diag(np.asarray(v.spacing, np.float64)[::-1])
    m[:3, 3] = np.asarray(v.origin, np.float64)
    return "vtk", m


def _voxel_to_voxel(
    world: tuple[str, np.ndarray] | None, fworld: tuple[str, np.ndarray] | None
) -> np.ndarray | None:
    """(4, 4): the rendered volume's voxel (i, j, k, 1) to the field's, through
    their world (_world); None where either has none, they are not the same
    world (a scan and a VTK image), or a matrix is singular or not finite (a
    broken header: the field is then laid as a file without one is)."""
    if world is None or fworld is None or world[0] != fworld[0]:
        return None
    a, f = np.asarray(world[1], np.float64), np.asarray(fworld[1], np.float64)
    if a.shape != (4, 4) or f.shape != (4, 4) or not (np.isfinite(a).all() and np.isfinite(f).all()):
        return None
    try:
        m = np.linalg.solve(f, a)
    except np.linalg.LinAlgError:
        return None
    return m if np.isfinite(m).all() and abs(np.linalg.det(m[:3, :3])) > 1e-12 else None


def _placed(field, affine, shape) -> str:
    """How --color-by's field is laid over the rendered volume, in words
    (the colour line of the summary): see _field_grid."""
    if field is not None and _voxel_to_voxel(affine, field[1]) is not None:
        return "placed by the files' affines (a VTK image's spacing and origin), in the world"
    if field is not None and field[0].shape == tuple(shape):
        return "on the same grid"
    return "stretched over the volume's box"


def _field_grid(
    field: tuple[np.ndarray, tuple[str, np.ndarray] | None],
    grid: tuple[tuple[int, ...], Sequence[float], Sequence[float], tuple[str, np.ndarray] | None],
) -> tuple[np.ndarray, tuple[float, ...], tuple[float, ...]]:
    """(samples, spacing (dz, dy, dx), origin (x, y, z)) of --color-by's
    field in the rendered volume's frame. Both files with an affine (NIfTI,
    MGH, Analyze: voxel to scanner world): each field sample where the
    scanner's world puts it (two scans of a subject rarely share a grid or a
    box: stretching one over the other's box coloured the surface by the
    wrong places), by its own spacing and origin where the two grids'
    axes are parallel, else resampled (trilinear) onto the volume's grid,
    NaN outside the field; else the volume's grid where the shapes agree,
    and any other grid stretched over the volume's box."""
    data, faffine = field
    shape, spacing, origin, affine = grid
    sp = np.asarray(spacing, np.float64)
    m = _voxel_to_voxel(affine, faffine)
    if m is not None:
        lin, shift = m[:3, :3], m[:3, 3]  # volume voxel (i, j, k) -> field voxel
        diag = np.diag(lin).copy()
        if (diag > 0).all() and np.abs(lin - np.diag(diag)).max() <= 1e-6 * diag.max():
            # field index f = diag * i + shift along each axis: index i = (f - shift) / diag
            step = sp[::-1] / diag  # (x, y, z)
            start = np.asarray(origin, np.float64) - step * shift
            return data, tuple(float(v) for v in step[::-1]), tuple(float(v) for v in start)
        from scipy import ndimage

        flip = np.eye(3)[::-1]  # (x, y, z) <-> [z, y, x]
        out = ndimage.affine_transform(
            data, flip @ lin @ flip, offset=flip @ shift, output_shape=tuple(shape), order=1, cval=np.nan
        ).astype(np.float32)
        return out, tuple(float(v) for v in spacing), tuple(float(v) for v in origin)
    if data.shape == tuple(shape):
        return data, tuple(float(v) for v in spacing), tuple(float(v) for v in origin)
    extent = (np.asarray(shape, np.float64) - 1) * sp  # stretched over the rendered volume's box
    fspacing = tuple(float(v) for v in extent / (np.asarray(data.shape, np.float64) - 1))
    return data, fspacing, tuple(float(v) for v in origin)


def _coloured(
    args: argparse.Namespace,
    shots: list[IsoImage],
    cam: Camera | None,
    field: tuple[np.ndarray, tuple[str, np.ndarray] | None] | None,
    grid: tuple[tuple[int, ...], Sequence[float], Sequence[float], tuple[str, np.ndarray] | None],
) -> tuple[IsoImage, np.ndarray | None, tuple[float, float] | None]:
    """(the shots composited, each surface in its colour or --color-by's,
    the colour bar or None, the colormap's range or None). grid: the
    rendered volume's (shape [z, y, x], spacing (dz, dy, dx), origin, world
    (_world) or None); field: _field's."""
    from .. import images, iso
    from ..colormap import value_range

    colours = (
        [tuple(c / 255 for c in rgb) for rgb in args.surface_color]
        if args.surface_color is not None
        else iso.surface_colors(len(shots))
    )
    w = int(shots[0].hit.shape[1])
    if field is None or cam is None:
        key = None
        if len(shots) > 1 and w >= 2:  # which colour is which isovalue
            entries = [
                (tuple(round(c * 255) for c in rgb), f"isovalue {v:g}")
                for rgb, v in zip(colours, args.isovalue, strict=True)
            ]
            key = images.legend(entries, w)
        return iso.composite(shots, colours), key, None
    fdata, fspacing, forigin = _field_grid(field, grid)
    vals = [iso.sample_hits(s, cam, fdata, fspacing, forigin) for s in shots]
    on = np.concatenate([np.asarray(v)[np.asarray(s.hit)] for v, s in zip(vals, shots, strict=True)])
    on = on[np.isfinite(on)]
    if not on.size:
        print(f"clvis iso: warning: --color-by {args.color_by}: no value on the surface", file=sys.stderr)
    if args.range is None:
        lo, hi = value_range(on)
    elif args.range[0] == "percentile":
        lo, hi = (float(v) for v in np.percentile(on, args.range[1:])) if on.size else (0.0, 1.0)
    else:
        lo, hi = float(args.range[1]), float(args.range[2])
    cmap = args.colormap or "viridis"
    planes = [
        iso.color_surface(s, values=v, colormap_name=cmap, value_range=(lo, hi), nan_color=c)
        for s, v, c in zip(shots, vals, colours, strict=True)
    ]
    bar = images.colorbar(cmap, lo, hi, w, title=Path(args.color_by).name) if w >= 2 else None
    return iso.composite(shots, planes=planes), bar, (lo, hi)


def _short(values, most=12) -> str:
    """A list, its first `most` entries when longer (one per pass of every tile)."""
    if len(values) <= most:
        return str(values)
    return "[" + ", ".join(str(v) for v in values[:most]) + f", ... {len(values) - most} more]"


def demo(out_dir: str | Path, q: cl.CommandQueue, size: tuple[int, int] = (640, 480)) -> bool:
    """The demo's iso part: Marschner-Lobb, progressive, checked against the reference."""
    from .. import datasets, images, zfp
    from .._arrays import on_host
    from ..reference import iso as ref

    w, h = size
    d = datasets.marschner_lobb(64)
    print(
        f"\niso: Marschner-Lobb 64^3 at iso 0.5, ZFP rate 8, {w}x{h}, progressive passes with speculation:\n"
    )
    r, cam, _ = render(d["volume"], d["spacing"], d["origin"], 0.5, w, h, queue=q)
    r.reset_cache()  # a cold cache for the timed run
    t = time.perf_counter()
    img = r.render(cam, w, h, 0.5)
    dt = time.perf_counter() - t
    st = img.stats
    print(
        f"  {st['passes']} passes in {dt * 1e3:.1f} ms; active rays per pass {st['active_per_pass']}; "
        f"{st['blocks_decoded']:,} of {r.volume.nblocks:,} blocks decoded"
    )
    cw, ch = 64, 48
    small = r.render(cam, cw, ch, 0.5)
    want = ref.render(
        typing.cast(np.ndarray, zfp.decode(r.volume)),
        cam,
        cw,
        ch,
        0.5,
        spacing=d["spacing"],
        origin=d["origin"],
    )
    a = ref.agreement(want, on_host(small.hit), on_host(small.depth))
    print(
        f"  image vs clvis.reference.iso ({cw}x{ch}, hit mask and depth on reliable pixels): "
        f"{'matches' if a['ok'] else 'MISMATCH'} (depth error {a['depth_error']:.1e} of the diagonal)"
    )
    path = images.save_png(Path(out_dir) / "iso.png", labelled(img, 0.5))
    print(f"  the surface: {path}")
    print("\nmore: clvis iso --help")
    return bool(a["ok"])
