"""`clvis gauss`: Gaussians at the three levels of detail of a sparse volume
(or from a point cloud, or a saved .npz), ray marched, one PNG each and the
panels side by side."""

from __future__ import annotations

import argparse
import math
import os
import re
import shlex
import sys
import time
import typing
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..errors import DataError
from ..gauss.render import FOG_OPACITY, MAX_K
from ..io.points import POINT_SUFFIXES
from ..io.volumes import FORMATS as VOLUME_FORMATS
from ._common import (
    POINTS_FIT,
    SIZE_RULE,
    VIEWS_HELP,
    CliError,
    FitView,
    Parser,
    Progress,
    add_camera_options,
    add_output_options,
    add_volume_options,
    camera_from_args,
    check_camera_args,
    clear_targets,
    colormap_name,
    count,
    fit_box,
    frame_bulk,
    grid_arg,
    note_earlier_pngs,
    plane_attribute,
    plane_names,
    progress_from_args,
    read_volume_file,
    real,
    size,
    world_camera_args,
)
from .orbit import add_orbit_options, check_orbit_args
from .raster import _value_range as value_range_arg

if TYPE_CHECKING:
    import pyopencl as cl

    from ..camera import Camera
    from ..gauss import Gaussians, SparseVolume
    from ..gauss.render import GaussianImage

LODS = ("low", "medium", "high")
# the transfer function's opacity points (x along the value range, alpha): the
# default keeps low values faint; for a volume FILE (a scan: a dense, noisy
# background) the range starts at Otsu's background level and opacity is 0 up
# to 5 % above it (the table's first entries too: values below the range take
# entry 0, and a haze of them along a ray adds up)
OPACITY_DEFAULT = ((0.0, 0.05), (0.35, 0.35), (1.0, 1.0))
OPACITY_VOLUME_FILE = ((0.0, 0.0), (0.05, 0.0), (0.4, 0.25), (1.0, 1.0))
# the absorption model's default extinction scale, over the diagonal of the
# Gaussians' 1-sigma boxes
DENSITY_DEFAULT = 240.0
# what the note on a mostly dark picture suggests (a fog: a haze of low values
# in front of the rest): a quarter of the extinction and opacity that stays
# low over the bottom of the range (fog balls, smoke and the explosion come out
# glowing; kept as options, not defaults, but for the explosion and a .vdb grid
# of class "fog volume": a scan's faint tissue and a level set's surface lose
# detail under them); FOG_OPACITY is clvis.gauss.render's (the viewer's too)
DARK_SHARE = 0.5
FOG_DENSITY_FACTOR = 0.25
FOG_OPACITY_VOLUME_FILE = ((0.0, 0.0), (0.05, 0.0), (0.4, 0.05), (0.7, 0.35), (1.0, 1.0))
# a volume FILE's default range ends at this percentile of its samples (a
# scan's few hot voxels do not squeeze every colour to the bottom of the bar)
TOP_PERCENTILE = 99.5
_POINT_FORMATS = POINT_SUFFIXES  # what clvis render reads
#: the panels' PNGs (and gauss.png, always): an earlier run's that this one did not write are named
_PANEL_PNG = re.compile(r"(low|medium|high|points|file)\.png")
#: how far past its centre each Gaussian of the finest LOD the view frames, in sigmas
FRAME_SIGMAS = 3.0
# --view fit of a volume or of Gaussians: from the front left, a little above,
# a narrow lens (a point cloud gets clvis render's view, POINTS_FIT)
_FIT = FitView(direction=(-0.55, 1.0, -0.35), fov_y=40.0)
_HELP = (
    """\
Turn a volume into Gaussians at the levels of detail of Sharma & Schmalstieg
(low: one per 8^3 leaf; medium: 4^3 / 2^3 blocks; high: 2^3 blocks / voxels),
ray march each through the device BVH, compositing every Gaussian in depth
order, and write one PNG per LOD plus gauss.png with the panels side by side,
each labelled with its LOD and Gaussian count over the colormap's value range.

Without a FILE it uses an embedded explosion density (96^3, closed form), drawn as a
fog (a quarter of the default --density, an --opacity low over the bottom of the range),
as is a .vdb grid whose class is "fog volume".
FILE may be a volume as `clvis iso` reads them (.raw, .npy [z, y, x], .nii,
.nii.gz, .mgz, .mgh, Analyze .hdr/.img, .vti, an evenly spaced .vtr, a legacy .vtk of
STRUCTURED_POINTS or an evenly spaced RECTILINEAR_GRID; see --shape,
--volume-index)
or a .vdb (a float grid, --grid; needs the `vdb` extra: tinyvdb, blosc); a .npz of Gaussians
(clvis.Gaussians.save); or a point cloud (.ply, .las, .laz, .e57, .pcd,
.xyz/.txt/.csv/.pts/.xyzn/.xyzrgb, .vtp/.vtu/.vts, a legacy .vtk of POLYDATA,
UNSTRUCTURED_GRID or STRUCTURED_GRID, or an (N, 3) .npy/.npz as
`clvis render` reads them: one Gaussian per point; with a velocity, as wide
as the points' median 4-nearest-neighbour distance and 4 times that along
the velocity (NARVis's), else sized by the 4 nearest neighbours, clamped
to their 95th percentile). A cloud's
points keep their own colours when it has them; --attribute NAME colours them
by an attribute (e.g. intensity) or z instead; without colours or --attribute,
by the speed when there is a velocity, else by the elevation z.

The kernel build (once per process) is timed apart from the renders; a large
--size is rendered in bands of rows, so device memory stays bounded, with
the rays done shown on stderr when it is a terminal (--progress: always).

"""
    + VIEWS_HELP
)


def add_parser(sub: argparse._SubParsersAction[Parser]) -> Parser:
    g = sub.add_parser(
        "gauss",
        help="Gaussians from a volume at three LODs, ray marched to PNGs",
        description=_HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    g.add_argument(
        "file",
        nargs="?",
        help=f"a volume ({', '.join(('.vdb', *VOLUME_FORMATS))}), a .npz of Gaussians "
        f"(clvis.Gaussians.save) or a point cloud ({', '.join(_POINT_FORMATS)}); "
        "see the description above (default: the embedded explosion)",
    )
    g.add_argument(
        "--lod",
        type=_lods,
        default=None,
        metavar="LIST",
        help="comma-separated levels of detail of a volume (default low,medium,high)",
    )
    g.add_argument(
        "--attribute",
        default=None,
        metavar="NAME",
        help="point clouds: colour by this attribute (or z, or the points' radius or speed where "
        "the file has them) instead of the cloud's rgb",
    )
    g.add_argument(
        "--threshold",
        type=real(),
        default=None,
        help="volumes: voxels above this are active (default: > 0 for dense volumes; a .vdb "
        "grid: its active voxels, of which this keeps those above it)",
    )
    g.add_argument(
        "--model",
        choices=["max_response", "absorption", "splat"],
        default="absorption",
        help="compositing model (default absorption); splat: 3D Gaussian Splatting's "
        "rasterizer (NARVis's GR; the tile renderer)",
    )
    g.add_argument(
        "--method",
        choices=["tiles", "bvh"],
        default=None,
        help="tiles: Gaussians binned to screen tiles and sorted per tile; bvh: rays "
        "marched through an LBVH; the same image (default: the device profile's, tiles)",
    )
    g.add_argument(
        "--density",
        type=real(0.0, open_lo=True),
        default=None,
        help="extinction scale of the absorption model, > 0 (default "
        f"{DENSITY_DEFAULT:g} / the diagonal of the Gaussians' 1-sigma boxes; lower: a thinner haze)",
    )
    g.add_argument(
        "--colormap",
        type=colormap_name,
        metavar="NAME",
        help="a matplotlib colormap (default inferno)",
    )
    g.add_argument(
        "--range",
        type=value_range_arg,
        default=None,
        metavar="MIN,MAX|pLO,pHI",
        help="the values the transfer function spans (colours and opacity): two values, or two "
        "percentiles of the samples such as p2,p98 (default: a volume FILE's Otsu background "
        "level to its 99.5th percentile, so that a scan's background stays clear; else the "
        "Gaussians' min..max)",
    )
    g.add_argument(
        "--opacity",
        type=_opacity,
        default=None,
        metavar="X:A,...",
        help="the transfer function's opacity: points X:A along the range (X 0 at its start, 1 at "
        "its end; A the opacity 0..1), linear between and constant beyond, e.g. 0:0,1:0.5 "
        f"(default {_points_text(OPACITY_VOLUME_FILE)} for a volume FILE, "
        f"{_points_text(OPACITY_DEFAULT)} otherwise)",
    )
    g.add_argument(
        "--size",
        type=size,
        default=(640, 640),
        metavar="WxH",
        help=f"each panel, {SIZE_RULE} (default 640x640)",
    )
    g.add_argument(
        "--k",
        type=count(1, MAX_K),
        default=None,
        help=f"k-buffer size of the ray models, 1..{MAX_K}: hits a round of the BVH march, the tile "
        "renderer's pending hits (default: the device profile's; not --model splat, which blends "
        "each tile's splats in depth order)",
    )
    add_output_options(g, "clvis-gauss", "empty pixels")
    add_orbit_options(g)
    add_camera_options(g, _FIT, f"; {POINTS_FIT.fov_y:g} for a point cloud, as in clvis render")
    add_volume_options(g)
    g.add_argument(
        "--grid",
        type=grid_arg,
        default=None,
        metavar="NAME|INDEX",
        help="the grid of a .vdb file to read: its name, or its index (0 first) (default: the "
        "first float grid; an error lists the file's grids)",
    )
    return g


def _points_text(points: Sequence[tuple[float, float]]) -> str:
    return ",".join(f"{x:g}:{a:g}" for x, a in points)


def _opacity(text: str) -> list[tuple[float, float]]:
    """The --opacity argument type: '0:0,0.5:0.2,1:1' -> [(0, 0), (0.5, 0.2), (1, 1)]."""
    pts = []
    for part in text.split(","):
        x, sep, a = part.partition(":")
        try:
            xa = (float(x), float(a)) if sep else None
        except ValueError:
            xa = None
        if xa is None or not (0 <= xa[0] <= 1 and 0 <= xa[1] <= 1):
            raise argparse.ArgumentTypeError(
                f"expected points X:A (X and A in 0..1, X ascending) such as 0:0,1:0.5, got {text!r}"
            )
        pts.append(xa)
    if any(b[0] < a[0] for a, b in zip(pts, pts[1:], strict=False)):
        raise argparse.ArgumentTypeError(f"the points' X must ascend, got {text!r}")
    return pts


def _lods(text: str) -> list[str]:
    """The --lod argument type: 'low,high' -> ['low', 'high']."""
    out = [t.strip() for t in text.split(",") if t.strip()]
    bad = [t for t in out if t not in LODS]
    if bad or not out:
        raise argparse.ArgumentTypeError(f"expected some of {', '.join(LODS)}, got {text!r}")
    twice = sorted({t for t in out if out.count(t) > 1}, key=LODS.index)
    if twice:  # each would be rendered and listed again, written over its own PNG
        raise argparse.ArgumentTypeError(f"{', '.join(twice)} given more than once in {text!r}")
    return out


def _sources(args):
    """(panel names, sparse volume or None, Gaussians or None, description,
    the dense samples of a volume FILE or None)."""
    from .. import datasets
    from ..gauss import Gaussians, SparseVolume, read_vdb
    from ..io import read_points
    from ..io.files import mesh_hint, regular_file

    lods = args.lod or list(LODS)
    if args.attribute is not None and not (args.file and args.file.lower().endswith(_POINT_FORMATS)):
        raise CliError(f"--attribute is for point clouds ({', '.join(_POINT_FORMATS)} of points)")
    if args.array is not None and not (args.file and args.file.lower().endswith((".vti", ".vtr", ".vtk"))):
        raise CliError("--array picks a data array of a VTK volume FILE (.vti, .vtr, .vtk)")
    if args.grid is not None and not (args.file and args.file.lower().endswith(".vdb")):
        raise CliError("--grid picks a grid of a .vdb FILE")
    if args.file is None:
        # a fog: drawn as the note on dark pictures suggests (a thinner haze,
        # opacity low over the bottom of the range: _transfer), its glowing
        # inside shown; under the defaults 81 % of it was the darkest colours
        args.density_scale, args.fog = FOG_DENSITY_FACTOR, "the embedded explosion"
        e = datasets.explosion()
        sv = SparseVolume.from_dense(
            e["volume"],
            threshold=0.0 if args.threshold is None else args.threshold,
            spacing=e["spacing"],
            origin=e["origin"],
        )
        return lods, sv, None, "the embedded explosion (96^3)", e["volume"]
    path = Path(args.file)
    if not path.exists():
        raise CliError(f"{path}: no such file")
    regular_file(path)  # a directory, a FIFO: named as clvis render and clvis view name them
    from ..io import load_npz, npy_shape
    from ..io.vtk import POINT_DATASETS, legacy_dataset

    name = path.name.lower()
    if name.endswith(".vdb"):
        if any(getattr(args, k) is not None for k in ("shape", "dtype", "volume_index")):
            raise CliError("--shape, --dtype and --volume-index are for .raw and NIfTI volumes, not .vdb")
        sv = read_vdb(path, grid=args.grid)
        if sv.grid_class == "fog volume":
            # the file says it is a fog (OpenVDB's class for densities, 0
            # outside): drawn as the embedded explosion is, its glowing
            # inside shown (under the volume defaults a shell of low values
            # hides it)
            args.density_scale, args.fog = FOG_DENSITY_FACTOR, "a fog volume (the grid's class)"
        args.level_set = sv.grid_class == "level set"
        if args.threshold is not None or args.spacing is not None:
            # leaf by leaf: a sparse grid is never made dense (10^4 voxels an axis: 4 TB),
            # and --spacing alone keeps every active voxel (a level set's negative values)
            sv = sv.restricted(
                args.threshold, None if args.spacing is None else tuple(reversed(args.spacing))
            )
        source = str(path) if args.grid is None else f"{path}, grid {args.grid!r}"
        _some_active(sv, source, args.threshold, "its grid has no active voxel")
        return lods, _local(sv, args), None, source, None
    volume = name.endswith(VOLUME_FORMATS)
    if name.endswith(".vtk"):  # a legacy VTK volume (STRUCTURED_POINTS, RECTILINEAR_GRID) or point set
        volume = legacy_dataset(path) not in POINT_DATASETS
    if name.endswith(".npy"):
        shape = npy_shape(path)
        volume = len(shape) == 3
        if not volume and not (len(shape) == 1 or (len(shape) == 2 and shape[1] == 3)):
            raise CliError(
                f"{path}: expected a 3-D volume [z, y, x] or an (N, 3) point array, got shape {shape}"
            )
    if args.array is not None and not volume:
        raise CliError(f"--array picks a data array of a VTK volume file; {path} is a point set")
    if args.attribute is not None and volume:  # a 3-D .npy, a legacy .vtk volume: it was ignored
        raise CliError(
            f"--attribute colours a point cloud's Gaussians; {path} is a volume, coloured by its values "
            "(--range, --colormap)"
        )
    if volume:
        data, spacing, origin = read_volume_file(args, path)
        sv = SparseVolume.from_dense(
            data, threshold=0.0 if args.threshold is None else args.threshold, spacing=spacing, origin=origin
        )
        if np.isfinite(data).any():  # else the transfer function's 'no finite value'
            _some_active(sv, str(path), args.threshold, "no sample above 0 (the default --threshold)")
        return lods, _local(sv, args), None, str(path), data
    if name.endswith(".npz") and "means" in load_npz(path):
        _no_lod(args, path, "a file of Gaussians, drawn as they are")
        if args.attribute is not None:
            raise CliError(
                f"--attribute colours a point cloud's Gaussians; {path} holds Gaussians, drawn as saved"
            )
        return ["file"], None, Gaussians.load(path), str(path), None
    if name.endswith(_POINT_FORMATS):
        from ..gauss import gaussians_from_points

        _no_lod(args, path, "a point cloud, one Gaussian a point")
        cloud = _finite_points(read_points(path), args)
        if len(cloud) == 0:
            raise CliError(f"{path}: the file holds no points")
        plane_attribute(cloud, args.attribute)  # --attribute radius / speed: the cloud's planes
        if args.attribute not in (None, "rgb", "z") and args.attribute not in cloud.attributes:
            have = ["rgb"] * (cloud.colors is not None) + ["z", *cloud.attributes, *plane_names(cloud)]
            raise CliError(
                f"--attribute: no attribute {args.attribute!r} in {path}; it has {', '.join(have)}"
            )
        try:
            g = gaussians_from_points(
                cloud, velocity="cloud" if cloud.velocity is not None else None, color_by=args.attribute
            )
        except DataError as e:  # what the file holds (a NaN velocity, an infinite attribute)
            raise CliError(f"{path}: {e}") from None
        except ValueError as e:
            raise CliError(f"{path}: {e}" if args.attribute is None else f"--attribute: {e}") from None
        # the view frames the bulk of the cloud, as clvis render's does (stray
        # points far outside it left out, with the same note)
        _, _, _, inside = frame_bulk(cloud, str(path), "clvis gauss")
        args.frame = None if inside is None else g.subset(np.flatnonzero(inside))
        # --view fit from clvis render's direction, through its lens (framing
        # the Gaussians' box, as for a volume: fitted to the points, the
        # splats at the edges were cut)
        args.fit_view = POINTS_FIT
        # what the colour bar names: the attribute, else what gaussians_from_points
        # coloured by: the speed with a velocity, else the elevation z. The
        # Gaussians' z is relative to the cloud's origin (a LAS file's lowest
        # point): --range takes and the bar and summary show the file's z (as
        # clvis render's), the origin added back
        by_z = args.attribute == "z" or (args.attribute is None and cloud.velocity is None)
        args.value_offset = float(cloud.origin[2]) if by_z and cloud.origin is not None else 0.0
        # --eye/--target are in the file's coordinates (as clvis render and clvis view's text)
        args.camera_origin = cloud.origin
        args.value_name = args.attribute or ("speed" if cloud.velocity is not None else "z")
        return ["points"], None, g, str(path), None
    raise CliError(
        f"{path}: unknown format (expected a volume: .vdb, {', '.join(VOLUME_FORMATS)}; "
        f"Gaussians: .npz of clvis.Gaussians.save; or points: {', '.join(_POINT_FORMATS)}){mesh_hint(path)}"
    )


def _some_active(sv: SparseVolume, source: str, threshold: float | None, empty: str) -> None:
    """A volume FILE without an active voxel: an error naming the file and the
    threshold (it was 'no Gaussians: the volume has no active voxel', neither)."""
    if sv.n_leaves == 0:
        why = empty if threshold is None else f"no active voxel above --threshold {threshold:g}"
        raise CliError(f"{source}: {why}; nothing to draw")


def _local(sv: SparseVolume, args) -> SparseVolume:
    """The volume moved to start at the world origin, its origin kept in
    args.camera_origin (--eye and --target stay in the file's coordinates, as
    for a point cloud): the Gaussians are float32, so a grid placed at map
    coordinates (a translation of 4,000,000) lost its detail, and the view,
    framing a box that large numbers round, showed it as a dot."""
    from ..gauss import SparseVolume

    if not any(sv.origin):
        return sv
    args.camera_origin = np.asarray(sv.origin, np.float64)
    return SparseVolume(
        sv.shape, sv.spacing, (0.0, 0.0, 0.0), sv.coords, sv.masks, sv.tiles, sv.tile_values, sv.values
    )


def _no_lod(args, path, what: str) -> None:
    """--lod makes levels of detail from a volume and --threshold picks its
    active voxels: an error for other files."""
    if args.lod is not None:
        raise CliError(f"--lod: levels of detail are made from a volume; {path} is {what} (leave --lod out)")
    if args.threshold is not None:
        raise CliError(
            f"--threshold: a volume's voxels above it are active; {path} is {what} (leave --threshold out)"
        )
    given = [  # a volume file's options: they were ignored without a word
        flag
        for flag, key in (
            ("--spacing", "spacing"),
            ("--shape", "shape"),
            ("--dtype", "dtype"),
            ("--volume-index", "volume_index"),
        )
        if getattr(args, key, None) is not None
    ]
    if given:
        raise CliError(f"{' and '.join(given)}: for a volume file; {path} is {what} (leave them out)")


def _finite_points(cloud, args):
    """The cloud without its points that have a NaN or infinite coordinate
    (counted in args.dropped for the summary): `clvis render`'s rule, they
    are never drawn and the summary says how many."""
    keep = np.isfinite(cloud.positions).all(axis=1)
    args.dropped = int(len(keep) - keep.sum())
    return cloud.subset(np.flatnonzero(keep)) if args.dropped else cloud


def cmd(args: argparse.Namespace) -> int:
    check_camera_args(args)
    check_orbit_args(args)
    args.colormap_given, args.colormap = args.colormap, args.colormap or "inferno"
    if args.model == "splat" and args.method == "bvh":  # the library's own words are its API's
        raise CliError(
            "--model splat (3D Gaussian Splatting's rasterizer) draws on tiles; leave --method bvh out"
        )
    if args.density is not None and args.model != "absorption":
        raise CliError(
            f"--density: the absorption model's extinction scale; --model {args.model} does not use it "
            "(leave --density out)"
        )
    if args.k is not None and args.model == "splat":
        raise CliError(
            "--k: the k-buffer of the ray models (max_response, absorption); --model splat blends each "
            "tile's splats in depth order (leave --k out)"
        )
    return _run(args)


class _Label:
    """A progress stage's name that changes while it runs: Progress formats
    the name each time it redraws the line, so the rays done show as they grow."""

    def __init__(self, text: str):
        self.text = text

    def __format__(self, spec: str) -> str:
        return format(self.text, spec)

    def __str__(self) -> str:
        return self.text


def render_panels(
    lods: Sequence[str],
    sv: SparseVolume | None,
    gaussians: Gaussians | None,
    width: int,
    height: int,
    *,
    model: str = "absorption",
    density: float | None = None,
    colormap: str = "inferno",
    k: int | None = None,
    method: str | None = None,
    camera: Callable[[np.ndarray, np.ndarray], Camera] | None = None,
    queue: cl.CommandQueue | None = None,
    opacity: Sequence[tuple[float, float]] | None = None,
    value_range: tuple[float, float] | None = None,
    progress: Progress | None = None,
    timings: dict[str, float] | None = None,
    frame: Gaussians | None = None,
    density_scale: float = 1.0,
) -> list[tuple[str, Gaussians, GaussianImage]]:
    """[(name, Gaussians, GaussianImage)] for each LOD of `sv` (or the given
    Gaussians), seen by camera(lo, hi) of their bounds (default: the fit view).

    k: the ray models' k-buffer (the march's hits a round, the tile renderer's
    pending hits; None: the device profile's);
    opacity: the transfer function's opacity points (default OPACITY_DEFAULT, a
    ramp that keeps low densities faint); value_range: the values it spans
    (default the Gaussians' min..max); progress: a Progress showing each panel's rays done;
    timings: a dict given "build_s", the wall time of the kernel build (the
    first renderer and frame, on a tiny scene), and "density", the absorption
    model's extinction scale used; frame: the Gaussians the view
    frames and the default density scales with (default: all; a point cloud's
    bulk, its stray points left out, as clvis render frames it)."""
    from ..camera import aspect_checked
    from ..colormap import TransferFunction
    from ..gauss import GaussianRenderer, gaussians_from_volume

    items = []
    for name in lods:
        g = gaussians if gaussians is not None else gaussians_from_volume(sv, lod=name, queue=queue)
        items.append((name, g))
    allg = [g for _, g in items if g.n]
    if not allg:
        raise CliError("no Gaussians: the volume has no active voxel")
    framed = [frame] if frame is not None and frame.n else allg
    # the default density scales with the diagonal of every LOD's 1-sigma boxes
    boxes = np.array([g.bounds(1.0) for g in framed])  # (LODs, lo / hi, xyz)
    diag = float(np.linalg.norm(boxes[:, 1].max(axis=0) - boxes[:, 0].min(axis=0))) or 1.0
    # the view frames the finest LOD's Gaussians out to FRAME_SIGMAS (what they
    # draw): every LOD's 1-sigma box, as before, cut the splats at the panel's
    # edges (a volume's corner, an L-shaped mask seen from the front); the
    # coarser LODs' few wide Gaussians would leave the data small
    lo, hi = max(framed, key=lambda g: g.n).bounds(FRAME_SIGMAS)
    cam = camera(lo, hi) if camera is not None else fit_box(lo, hi, width, height, _FIT)
    if value_range is None:
        vals = np.concatenate([g.values for g in allg])
        value_range = (float(vals.min()), float(vals.max()))
    vr = value_range
    if opacity is None:
        opacity = OPACITY_DEFAULT
    tf = TransferFunction(colormap, opacity=opacity, value_range=vr)
    dens = density if density is not None else density_scale * DENSITY_DEFAULT / diag
    progress = progress or Progress(False)
    # warm-up: build the kernels on a tiny scene (the build is timed apart
    # from the renders), so the figures below are the work itself
    t0 = time.perf_counter()
    with progress.stage("building kernels"), aspect_checked():  # a throwaway 8 x 8 of the panels' camera
        GaussianRenderer(
            allg[0].subset(slice(0, 2)), tf, model=model, density=dens, k=k, kp=k, queue=queue, method=method
        ).render(cam, 8, 8)
    if timings is not None:
        timings["build_s"] = time.perf_counter() - t0
        timings["density"] = dens
    out = []
    for name, g in items:
        label = _Label(f"{name}: {g.n:,} Gaussians")
        with progress.stage(label):
            r = GaussianRenderer(g, tf, model=model, density=dens, k=k, kp=k, queue=queue, method=method)
            label.text = f"{name}: rendering"

            def done(rays, total, label=label, name=name):
                label.text = f"{name}: {rays:,} / {total:,} rays"

            img = r.render(cam, width, height, progress=done)
        out.append((name, g, img))
    return out


def _transfer(args, lods, sv, gaussians, samples):
    """(value range or None, opacity points or None, a line saying what was
    chosen or None) of the transfer function, from --range and --opacity and
    the defaults (see their help)."""
    from ..io.volumes import otsu_level

    points = lods == ["points"]
    given = [o for o, v in (("--range", args.range), ("--opacity", args.opacity)) if v is not None]
    given += ["--colormap"] if getattr(args, "colormap_given", None) is not None else []
    if points and given and gaussians is not None and gaussians.colors is not None:
        raise CliError(
            f"{' and '.join(given)}: the transfer function's; the points are drawn in their own "
            "colours (add --attribute NAME to colour them by a value)"
        )
    opacity = args.opacity
    if opacity is None and points:
        opacity = [(0.0, 1.0), (1.0, 1.0)]  # points are surfaces: fully opaque, whatever the value
    # a point cloud coloured by z: --range is in the file's coordinates, the
    # Gaussians' values relative to its origin (0 otherwise)
    off = getattr(args, "value_offset", 0.0)
    if args.range is not None:
        kind, a, b = args.range
        if kind == "values":
            return (a - off, b - off), opacity, f"range {a:.15g}..{b:.15g}"
        # percentiles of the volume's samples, else of the Gaussians' values
        if samples is not None:
            values = np.asarray(samples)
        elif sv is not None:
            values = sv.to_dense()
        else:
            values = np.asarray(gaussians.values)
        values = values[np.isfinite(values)]
        if not values.size:
            raise CliError("--range: the data has no finite value")
        lo, hi = (float(v) for v in np.percentile(values, [a, b]))
        return (lo, hi), opacity, f"range p{a:g}..p{b:g} of the samples: {lo + off:.6g}..{hi + off:.6g}"
    if args.file is not None and samples is not None:
        # a scan: its background (the lower of Otsu's two classes) stays clear
        if not np.isfinite(samples).any():
            raise CliError(f"{args.file}: no finite value (every sample is NaN or infinite)")
        level = otsu_level(samples)
        top = float(np.nanpercentile(samples, TOP_PERCENTILE))
        if top > level:
            return (
                (level, top),
                opacity if opacity is not None else list(OPACITY_VOLUME_FILE),
                f"range {level:.6g} (Otsu's background level)..{top:.6g} (p{TOP_PERCENTILE:g}); "
                "--range and --opacity change it",
            )
    fog = getattr(args, "fog", None)
    if fog is not None and opacity is None and not points:  # the embedded explosion, a fog volume
        return None, list(FOG_OPACITY), f"{fog} drawn as a fog: --opacity and --density change it"
    if getattr(args, "level_set", False):
        # Gaussians of its narrow band (signed distances), the band's outside
        # in front: what to run for the surface itself
        iso = shlex.join(
            ["clvis", "iso", args.file] + ([] if args.grid is None else ["--grid", str(args.grid)])
        )
        return None, opacity, f"a level set's narrow band (its distances); {iso} draws its surface"
    return None, opacity, None


def _one_value(sv, gaussians, lods) -> tuple[tuple[float, float], str] | None:
    """A value range putting data of one value at the top of the colours
    (an occupancy or mask grid, all 1; an attribute that is 0 everywhere),
    with the line saying so; None for data of several values (or none, or in
    their own colours). Its own min..max put it at the bottom: the darkest
    colour, and under the volumes' opacity ramp almost transparent (a 160^3
    grid of 0.5 drew as a near-black box)."""
    if gaussians is not None:
        if gaussians.colors is not None:
            return None
        values = np.asarray(gaussians.values)
    elif sv is not None and sv.n_active:
        values = sv.leaf_values()[sv.active_masks()]
    else:
        return None
    values = values[np.isfinite(values)]
    if not values.size or values.min() != values.max():
        return None
    v = float(values[0])
    span = max(abs(v), 1.0)
    what = "every point's value" if lods == ["points"] else "every active voxel"
    return (v - span, v), f"{what} is {v:.6g}: drawn in the top colour (range {v - span:.6g}..{v:.6g})"


def _picture(img, transparent: bool = False) -> np.ndarray:
    """(H, W, 4) uint8 of a GaussianImage, over images.BACKGROUND unless
    `transparent` (composited a band of rows at a time: no full-size float
    temporaries for large images)."""
    from .. import images

    return img.to_uint8(None if transparent else images.BACKGROUND)


def strip(
    panels: Sequence[tuple[str, Gaussians, GaussianImage]],
    colormap: str,
    transparent: bool = False,
    value_name: str = "value",
    value_range: tuple[float, float] | None = None,
    value_offset: float = 0.0,
) -> np.ndarray:
    """render_panels' images side by side, each labelled with its LOD and
    Gaussian count, over a colour bar of the transfer function's range
    (`value_range`, default the values' min..max; none for Gaussians drawn in
    their own colours), `value_offset` added to the bar's ends (a point
    cloud's origin along z: the bar reads the file's coordinates)."""
    from .. import images
    from ..colormap import value_range as finite_range

    if value_range is None:
        vmin, vmax = finite_range(np.concatenate([g.values for _, g, _ in panels]))
    else:
        vmin, vmax = value_range
    tiles = []
    for name, g, img in panels:
        title = f"{name} LOD" if name in LODS else name
        tile = images.label(_picture(img, transparent), f"{title}: {g.n:,} Gaussians")
        if getattr(g, "colors", None) is None and tile.shape[1] >= 2:  # --size 1xH: no room for a bar
            bar = images.colorbar(
                colormap, vmin + value_offset, vmax + value_offset, tile.shape[1], title=value_name
            )
            tile = np.concatenate([tile, bar], axis=0)
        tiles.append(tile)
    return images.compose(tiles)


def bar_title(args: argparse.Namespace) -> str:
    """What the colour bar names: --attribute, else what a point cloud is
    coloured by (speed or z), else "value"."""
    return args.attribute or getattr(args, "value_name", None) or "value"


def _run(args) -> int:
    from .. import images, runtime

    t0 = time.perf_counter()
    progress = progress_from_args(args, "clvis gauss")
    lods, sv, gaussians, source, samples = _sources(args)
    width, height = args.size
    q = runtime.default_queue()
    timings: dict = {}
    vr, opacity, why = _transfer(args, lods, sv, gaussians, samples)
    if vr is None:
        vr, why = _one_value(sv, gaussians, lods) or (vr, why)
    panels = render_panels(
        lods,
        sv,
        gaussians,
        width,
        height,
        model=args.model,
        density=args.density,
        colormap=args.colormap,
        k=args.k,
        method=args.method,
        queue=q,
        opacity=opacity,
        value_range=vr,
        progress=progress,
        timings=timings,
        frame=getattr(args, "frame", None),
        density_scale=getattr(args, "density_scale", 1.0),
        camera=lambda lo, hi: camera_from_args(
            world_camera_args(args, getattr(args, "camera_origin", None)),
            lo,
            hi,
            width,
            height,
        ),
    )
    if not _say_if_empty(panels, width, height):
        _say_if_dark(panels, args, opacity, timings["density"])
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    files = []
    clear_targets(out, [f"{panel[0]}.png" for panel in panels] + ["gauss.png"])
    with progress.stage("writing PNGs"):
        value_name = bar_title(args)
        off = getattr(args, "value_offset", 0.0)
        for panel in panels:  # each labelled over its colour bar, as in gauss.png (--no-labels: bare)
            one = _picture(panel[2], args.transparent) if args.no_labels else None
            if one is None:
                one = strip([panel], args.colormap, args.transparent, value_name, vr, off)
            files.append(images.save_png(out / f"{panel[0]}.png", one))
        files.append(
            images.save_png(
                out / "gauss.png",
                strip(panels, args.colormap, args.transparent, value_name, vr, off),
            )
        )
    note_earlier_pngs("clvis gauss", out, {p.name for p in files}, _PANEL_PNG)
    if args.orbit is not None:  # the turntable (clvis.cli.orbit)
        from .orbit import gauss_orbit, report

        orbit = gauss_orbit(args, lods, sv, gaussians, q, opacity, out, progress, vr)
    print(f"clvis gauss: {source}, {args.model} model, {width}x{height}")
    print(f"  device    {runtime.describe(q.device)}")
    if sv is not None:
        print(f"  volume    {sv.shape}, {sv.n_leaves:,} leaves")
    if gaussians is not None and gaussians.colors is not None:
        print("  colour    the points' own rgb")
    elif lods == ["points"]:
        print(f"  colour    {value_name} through {args.colormap}")
    if why:
        print(f"  transfer  {why}")
    if getattr(args, "dropped", 0):
        print(
            f"  dropped   {args.dropped:,} point{'s' if args.dropped != 1 else ''} with a NaN or infinite "
            "coordinate (never drawn)"
        )
    print(f"  build     {timings['build_s']:.2f} s (kernels, once per process; not in the render times)")
    method = panels[0][2].stats.get("method", "bvh")
    print(
        f"  method    {method}"
        + (
            " (setup: count, scan, keys, sort; keys per Gaussian)"
            if method == "tiles"
            else " (setup: BVH build)"
        )
    )
    print(
        f"  {'LOD':8} {'Gaussians':>10} {'MB':>8} {'setup ms':>8} {'render ms':>10} {'bands':>6} "
        f"{'hits/ray':>9}" + (f" {'keys/G':>7}" if method == "tiles" else "")
    )
    for name, g, img in panels:
        s = img.stats
        setup = s["bvh_build_s"] if method == "bvh" else s["bin_s"] + s["sort_s"]
        print(
            f"  {name:8} {g.n:10,} {g.nbytes / 1e6:8.2f} {setup * 1e3:8.1f} "
            f"{s['render_s'] * 1e3:10.1f} {s['bands']:6} {s['hits_per_ray_mean']:9.1f}"
            + (f" {s['keys_per_gaussian']:7.2f}" if method == "tiles" else "")
        )
    if args.orbit is not None:
        report(*orbit)
    print(f"  total     {time.perf_counter() - t0:.2f} s")
    frames = f" and {len(orbit[0])} orbit frames" if args.orbit is not None and orbit[0] else ""
    print(f"wrote {len(files)} PNGs to {out}{os.sep}{frames}")
    for p in files:
        print(f"  {p.name}")
    return 0


def _say_if_empty(panels, width: int, height: int) -> bool:
    """A note on stderr when every panel came out (nearly) empty, under one
    pixel in 1000 drawn (no ray met a Gaussian but a few: they are smaller
    than a pixel at this size, or out of view), so that a blank PNG does not
    look like a broken render (clvis render says the same of sparse points).
    Whether it said so."""
    from .._arrays import to_host

    drawn = max(int((to_host(img.rgba)[..., 3] >= 0.5 / 255).sum()) for _, _, img in panels)
    if drawn * 1000 >= width * height:
        return False
    # --lod is a volume's (a point cloud's or a saved .npz's Gaussians refuse it)
    lod = " or --lod low (fewer, larger Gaussians)" if any(name in LODS for name, _, _ in panels) else ""
    print(
        f"clvis gauss: note: the picture is {'empty' if drawn == 0 else 'nearly empty'}: "
        f"{drawn:,} of {width * height:,} pixels drawn at {width}x{height} (the Gaussians are few, "
        "smaller than a pixel here, or out of view); a larger --size, a closer view (--eye/--target, "
        f"--fov){lod} draws more of them",
        file=sys.stderr,
    )
    return True


def _say_if_dark(panels, args, opacity, density: float) -> None:
    """A note on stderr when the default transfer function drew a picture
    that is mostly the bottom of the colours (over DARK_SHARE of the drawn
    pixels darker than a quarter of the way up the colormap): a fog, a smoke
    or a density ball, most of it low values, hides its bright inside
    behind a shell of them. It names the options that show the inside
    (a fainter haze); nothing is said when --range, --opacity or --density
    was given (the user's choice)."""
    if any(getattr(args, k, None) is not None for k in ("range", "opacity", "density")):
        return
    if panels[0][0] == "points":  # opaque surfaces coloured by an attribute: dark is what they are
        return
    share = _dark_share(panels, args.colormap)
    if share is None or share <= DARK_SHARE:
        return
    file_default = opacity is not None and [tuple(p) for p in opacity] == list(OPACITY_VOLUME_FILE)
    fog = _points_text(FOG_OPACITY_VOLUME_FILE if file_default else FOG_OPACITY)
    thinner = f"--density {density * FOG_DENSITY_FACTOR:.3g} " if args.model == "absorption" else ""
    print(
        f"clvis gauss: note: the picture is mostly dark: {share:.0%} of the pixels drawn show the "
        "lowest quarter of the colours (low values in front hide the rest, as in a fog or a "
        f"density ball); a fainter haze shows the inside: {thinner}--opacity {fog} (or --range "
        "to start the colours higher)",
        file=sys.stderr,
    )


def _dark_share(panels, colormap: str) -> float | None:
    """The share of the drawn pixels (alpha at least 1/2, over every panel)
    whose colour is darker than the colormap a quarter of the way up its
    range: near 1 when the picture shows little but the bottom of the
    colours. None for Gaussians in their own colours, a colormap that does
    not run from dark to bright (its luminance rising by under 0.3), or
    fewer than 100 pixels drawn. Measured on every k-th row and column, up
    to about 10^6 pixels a panel (no full-size float64 copy of a large one)."""
    from .._arrays import to_host
    from ..colormap import lut

    if any(getattr(g, "colors", None) is not None for _, g, _ in panels):
        return None
    weights = np.array([0.2126, 0.7152, 0.0722])
    table = lut(colormap).astype(np.float64)[:, :3] / 255 @ weights
    if table[-1] - table[0] < 0.3:
        return None
    dark = float(table[len(table) // 4])
    drawn = below = 0
    for _, _, img in panels:
        rgba = to_host(img.rgba)
        step = max(1, math.ceil(math.sqrt(rgba.shape[0] * rgba.shape[1] / 1e6)))
        rgba = np.asarray(rgba[::step, ::step], np.float64)
        a = rgba[..., 3]
        keep = a >= 0.5
        lum = (rgba[..., :3][keep] / a[keep][:, None]) @ weights
        drawn += int(keep.sum())
        below += int((lum < dark).sum())
    return below / drawn if drawn >= 100 else None


def demo(out_dir: str | Path, q: cl.CommandQueue, size: tuple[int, int] = (480, 480)) -> bool:
    """The demo's gauss part: the explosion at three LODs (figures, PNG) and a
    small frame checked against the brute-force reference."""
    from .. import Camera, datasets, images
    from ..camera import ray_buffer
    from ..colormap import TransferFunction
    from ..gauss import GaussianRenderer, SparseVolume, lod_table
    from ..reference.gauss import render as ref

    w, h = size
    e = datasets.explosion()
    sv = SparseVolume.from_dense(e["volume"], threshold=0.0, spacing=e["spacing"], origin=e["origin"])
    print(
        f"\ngauss: the embedded explosion (96^3, {sv.n_active:,} active voxels in {sv.n_leaves:,} leaves) "
        f"as Gaussians, ray marched at {w}x{h} (absorption model, every Gaussian in depth order):\n"
    )
    table = lod_table(sv, queue=q)
    panels = render_panels(
        LODS, sv, None, w, h, queue=q, opacity=FOG_OPACITY, density_scale=FOG_DENSITY_FACTOR
    )
    print(
        f"  sparse volume: {table.sparse_bytes / 1e6:.2f} MB ({table.tiles} tiles); "
        f"dense: {e['volume'].nbytes / 1e6:.2f} MB"
    )
    print(
        f"  {'LOD':8} {'Gaussians':>10} {'MB':>7} {'MB axis-aligned':>16} {'setup':>10} {'frame':>10} "
        f"{'hits/ray':>9}   (setup: the BVH build, or the tiles' bin and sort)"
    )
    for name, g, img in panels:
        s, row = img.stats, table[name]
        assert row.gaussians == g.n
        setup = s["bvh_build_s"] if s.get("method", "bvh") == "bvh" else s["bin_s"] + s["sort_s"]
        print(
            f"  {name:8} {g.n:10,} {row.bytes / 1e6:7.2f} {row.axis_aligned_bytes / 1e6:16.2f} "
            f"{setup * 1e3:8.1f}ms {s['render_s'] * 1e3:8.1f}ms {s['hits_per_ray_mean']:9.1f}"
        )
    # the check: a small frame of the medium LOD against every-ray-against-every-Gaussian
    g = panels[1][1]
    lo, hi = g.bounds(1.0)
    cw, ch = 24, 24
    cam = Camera.fit(lo, hi, direction=_FIT.direction, aspect=1.0, fov_y=_FIT.fov_y)
    tf = TransferFunction("inferno")
    img = GaussianRenderer(g, tf, model="max_response", queue=q).render(cam, cw, ch)
    vmin, scale = tf.limits(g.values)
    want, _, _ = ref.render(
        g.means,
        g.scales,
        g.rotations,
        g.values,
        g.opacities,
        ray_buffer(cam, cw, ch),
        cw,
        ch,
        tf.table(),
        float(vmin),
        float(scale),
    )
    err = float(np.abs(typing.cast(np.ndarray, img.rgba) - want).max())  # a host render
    ok = err <= 1e-3
    print(
        f"  frame vs clvis.reference.gauss ({g.n:,} Gaussians at {cw}x{ch}, max |difference| {err:.1e}): "
        f"{'matches' if ok else 'MISMATCH'}"
    )
    path = images.save_png(Path(out_dir) / "gauss.png", strip(panels, "inferno"))
    print(f"  the three LODs side by side: {path}")
    print("\nmore: clvis gauss --help, clvis bench gauss")
    return ok
