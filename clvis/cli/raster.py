"""`clvis render`: a point cloud (a file, or an embedded synthetic one)
rasterized to G-buffers, written as PNGs; and the demo's raster part."""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import re
import sys
import time
import typing
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..camera import fit_camera
from ..colormap import named_colour
from ..errors import ClvisError
from ._common import (
    POINTS_FIT,
    SIZE_RULE,
    VIEWS_HELP,
    CliError,
    Parser,
    Progress,
    add_camera_options,
    add_cluster_options,
    add_output_options,
    camera_from_args,
    check_camera_args,
    check_embedded_points,
    clear_targets,
    cluster_client,
    cluster_failed,
    colormap_name,
    count,
    describe_camera,
    distributed_run,
    frame_bulk,
    note_earlier_pngs,
    on_workers,
    plane_attribute,
    plane_names,
    progress_from_args,
    size,
    stray_note,
    timed,
    world_box,
    world_camera_args,
)
from .orbit import add_orbit_options, check_orbit_args

if TYPE_CHECKING:
    import pyopencl as cl

    from ..raster import GBuffers

# The embedded clouds: generator, default attribute, whether the depth filter
# panel is on by default (the filter is made for LiDAR scans seen through holes).
_DATASETS = {
    "hurricane": ("temperature", False),
    "terrain": ("classification", True),
}
_DEFAULT_POINTS = {"hurricane": 2_000_000, "terrain": 1_000_000}
# --post narvis-scan: the kNN radius plane's seconds are said on stderr above this
# (a big LAS takes seconds on every call; the progress display shows them anyway)
KNN_NOTE_SECONDS = 1.0
# --view fit: the point clouds' default view, clvis gauss's too
_FIT = POINTS_FIT
_SOFT_Z_FACTOR = 1.01
_OVERVIEW_WIDTH = 2880  # the overview is shrunk by an integer factor to fit this
_COORDINATES = ("x", "y", "z")  # --attribute takes these too
MAX_POINTS = 2**32 - 2  # the Rasterizer's: index 0xFFFFFFFF marks an empty pixel
# host bytes a pixel `clvis render` takes at its peak (measured: ~97 B a pixel
# for a cloud with colors and attributes)
HOST_BYTES_PER_PIXEL = 100
MAX_POINT_SIZE = 64  # the Rasterizer's point_size: 1..64 pixels a side
MAX_AUTO_POINT_SIZE = 16  # --point-size auto: larger points blot out the shape
_SPARSE_FRACTION = 1000  # a note when the points cover under 1/1000 of the image


def _soft_z(text: str) -> float | None:
    """A tolerance factor >= 1, or off."""
    if text.strip().lower() in ("off", "0", "none"):
        return None
    try:
        f = float(text)
    except ValueError:
        f = math.nan
    if not (math.isfinite(f) and f >= 1.0):
        raise argparse.ArgumentTypeError(f"expected a factor >= 1 (such as 1.01) or off, got {text!r}")
    return f


def _levels(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        n = -1
    if not 0 <= n <= 16:
        raise argparse.ArgumentTypeError(f"expected pyramid levels in 0..16 (0: off), got {text!r}")
    return n


def _point_size(text: str) -> int | str:
    """'auto' or a whole number of pixels in 1..MAX_POINT_SIZE."""
    if text.strip().lower() == "auto":
        return "auto"
    try:
        return count(1, MAX_POINT_SIZE)(text)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(
            f"expected auto or a positive integer in 1..{MAX_POINT_SIZE}, got {text!r}"
        ) from None


def _value_range(text: str) -> tuple[str, float, float]:
    """'MIN,MAX' -> ('values', MIN, MAX); 'pLO,pHI' -> ('percentile', LO, HI)."""
    parts = [t.strip().lower() for t in text.split(",")]
    pct = len(parts) == 2 and all(p.startswith("p") for p in parts)
    try:
        a, b = (float(p[1:] if pct else p) for p in parts)
    except ValueError:
        a = b = math.nan
    ok = math.isfinite(a) and math.isfinite(b) and a < b and (not pct or (0 <= a and b <= 100))
    if len(parts) != 2 or not ok:
        raise argparse.ArgumentTypeError(
            f"expected MIN,MAX (MIN < MAX) or percentiles pLO,pHI such as p2,p98, got {text!r}"
        )
    return ("percentile" if pct else "values", a, b)


_COLOUR_NAMES = {
    "black": (0, 0, 0),
    "white": (255, 255, 255),
    "grey": (128, 128, 128),
    "gray": (128, 128, 128),
    "darkgrey": (24, 24, 28),
    "darkgray": (24, 24, 28),
    "lightgrey": (211, 211, 211),
    "lightgray": (211, 211, 211),
    "navy": (0, 0, 128),
    "blue": (0, 0, 255),
    "skyblue": (135, 206, 235),
}


def _colour(text: str) -> tuple[int, int, int]:
    """A colour name (clvis's own above, else a CSS/X11 name as matplotlib
    and PyVista take them: red, tomato, ...; colormap.named_colour), #RRGGBB,
    #RGB or R,G,B (0..255 each)."""
    t = text.strip().lower()
    if t in _COLOUR_NAMES:
        return _COLOUR_NAMES[t]
    m = re.fullmatch(r"(\d{1,3}),(\d{1,3}),(\d{1,3})", t.replace(" ", ""))
    if m and all(int(v) <= 255 for v in m.groups()):
        return int(m[1]), int(m[2]), int(m[3])
    try:
        r, g, b = named_colour("colour", t)
    except ValueError:
        raise argparse.ArgumentTypeError(
            "expected a colour: a name (black, white, darkgrey: the UI's grey, red, skyblue and the other "
            f"CSS names), #RRGGBB, #RGB or R,G,B (0..255), got {text!r}"
        ) from None
    return round(255 * r), round(255 * g), round(255 * b)


def _edl_strength(text: str) -> float:
    from ..raster.edl import MAX_EDL_STRENGTH

    try:
        f = float(text)
    except ValueError:
        f = math.nan
    if not (math.isfinite(f) and 0 < f <= MAX_EDL_STRENGTH):
        raise argparse.ArgumentTypeError(
            f"expected an eye-dome lighting strength in (0, {MAX_EDL_STRENGTH:g}] such as 1, got {text!r}"
        )
    return f


def _embedded(name: str, n: int):
    """An embedded dataset (clvis.datasets) as a clvis.PointCloud."""
    from .. import datasets
    from ..io import PointCloud

    d = getattr(datasets, name)(n)
    return PointCloud(d["positions"], colors=d["colors"], attributes=d["attributes"], velocity=d["velocity"])


def _informative(a) -> bool:
    """Whether an array varies: a colour or attribute all one value shows nothing."""
    a = np.asarray(a)
    if a.size == 0:
        return False
    if a.ndim == 2:
        return bool((a != a[:1]).any())
    finite = a[np.isfinite(a)] if a.dtype.kind == "f" else a
    return finite.size > 0 and bool(finite.min() != finite.max())


def _colors_title(colors: np.ndarray | None) -> str:
    """The point-colour panel's title; it names the colour when the file gives
    every point the same one (LAS files often store RGB 0 where the scanner
    took no photograph: a black panel would look like a broken render)."""
    if colors is None or colors.shape[0] == 0 or _informative(colors[:, :3]):
        return "point colors"
    rgb = ", ".join(f"{float(v):.3g}" for v in colors[0, :3])
    return f"point colors (all ({rgb}) in the file)"


def _pick_attribute(cloud, requested: str | None, default: str | None, source: str) -> str | None:
    """The attribute to color by: the one asked for (it must exist; x, y and z
    name the coordinates unless the cloud has attributes of those names);
    else an embedded cloud's default; else None, the cloud's own colors, when
    they are not all one colour (what Open3D, PyVista, Potree and CloudCompare
    show first); else intensity, else the first attribute that varies; else z
    (height). An attribute or colour that is one value everywhere is passed
    over: it shows nothing."""
    names = list(cloud.attributes)
    if requested is not None:
        plane_attribute(cloud, requested)
        if requested not in cloud.attributes and requested not in _COORDINATES:
            names += plane_names(cloud)
            raise CliError(
                f"no attribute {requested!r} in {source}; it has "
                f"{', '.join(names) + ' and ' if names else ''}the coordinates x, y, z"
            )
        return requested
    if default in cloud.attributes:
        return default
    if cloud.colors is not None and _informative(cloud.colors[:, :3]):
        return None
    for cand in ["intensity", *names]:
        if cand in cloud.attributes and _informative(cloud.attributes[cand]):
            return cand
    return "z"


@dataclasses.dataclass
class _Panel:
    key: str  # the PNG's file name, without .png
    title: str  # its label in the overview
    image: np.ndarray  # (H, W, 4) uint8 RGBA
    bar: tuple | None = None  # (colormap, vmin, vmax) of its colour bar
    legend: list | None = None  # [(RGB, text)]: the categories' legend


@dataclasses.dataclass
class _Rendered:
    gbuffers: GBuffers  # of the main render
    panels: list
    first_s: float  # the first render (it may build the kernels)
    warm_s: float  # the same render again
    post_s: float = 0.0  # the network's frame, render + network (narvis-scan: + its depth filter)
    post_removed: int | None = None  # the pixels its depth filter emptied (narvis-scan)
    post_scale: int = 1  # the network's frame rendered this many times smaller, its picture resized up


def _safe_name(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("._") or "attribute"


def _raster_fields(cloud, attribute) -> dict:
    """Rasterizer keywords for `cloud`: only the attribute colored by travels
    to the device (a LAS file has more attributes than the G-buffers hold)."""
    attrs = {}
    if attribute in cloud.attributes:
        attrs[attribute] = cloud.attributes[attribute]
    elif attribute is not None:
        attrs[attribute] = cloud.positions[:, _COORDINATES.index(attribute)]
    return {"colors": cloud.colors, "attributes": attrs, "velocity": cloud.velocity, "radius": cloud.radius}


@dataclasses.dataclass
class _Look:
    """How the colour panels look: the attribute's value range (None: its
    min..max; in the renderer's coordinates), the offset its colour bar adds
    (the origin along a coordinate, so bars read in the file's coordinates),
    the class legend of a categorical attribute (then the points carry the
    class colours and no attribute), eye-dome lighting's strength and radius."""

    value_range: tuple[float, float] | None = None
    bar_offset: float = 0.0
    classes: list | None = None  # [(RGB, text)]
    edl: float | None = None
    edl_radius: int = 1
    class_colors: np.ndarray | None = None  # (N, 4) uint8, with classes


def _render_kw(look: _Look, attribute, colormap, point_size) -> dict:
    """Rasterizer.render's colour keywords for the look: the attribute through
    the colormap over its range, or (classes, the cloud's colours) none."""
    return {
        "color_by": None if look.classes is not None else attribute,
        "colormap": colormap,
        "point_size": point_size,
        "value_range": look.value_range,
    }


def _render_panels(
    raster,
    cloud,
    camera,
    width,
    height,
    attribute,
    colormap,
    soft_z,
    levels,
    progress,
    point_size=1,
    post=None,
    look: _Look | None = None,
    post_scale: int | None = None,
) -> _Rendered:
    """Render one view; the G-buffers and the images a person looks at.
    post_scale: the network's frame rendered that many times smaller and its
    picture resized up to the view (None: its spec's render_scale for the
    view's splat radius, 1 for a network without one)."""
    from .. import images
    from ..post import MIN_SCALED_SIDE, SCALED_SMOOTH, resized
    from ..raster import EMPTY, depth_filter, edl, filter_gbuffers

    look = look or _Look()
    color_by = None if look.classes is not None else attribute
    kw = _render_kw(look, attribute, colormap, point_size)
    with progress.stage("rendering + resolving G-buffers"):
        t0 = time.perf_counter()
        g = raster.render(camera, width, height, **kw)
        first = time.perf_counter() - t0
        t0 = time.perf_counter()
        raster.render(camera, width, height, **kw)
        warm = time.perf_counter() - t0

    def shaded(rgba):
        if look.edl is None:
            return rgba
        return edl(g.depth, rgba, look.edl, look.edl_radius, queue=raster.queue)

    panels = []
    if look.classes is not None:
        panels.append(
            _Panel(
                f"attribute-{_safe_name(attribute)}",
                f"{attribute} (ASPRS classes)",
                shaded(g.rgba),
                legend=look.classes,
            )
        )
    elif attribute is not None:
        from ..colormap import value_range  # the range render() colours over

        vr = look.value_range or value_range(_raster_fields(cloud, attribute)["attributes"][attribute])
        bar = (colormap, vr[0] + look.bar_offset, vr[1] + look.bar_offset, attribute)
        panels.append(
            _Panel(f"attribute-{_safe_name(attribute)}", f"{attribute} ({colormap})", shaded(g.rgba), bar)
        )
    if cloud.colors is not None:
        if color_by is None and look.classes is None:
            colors = g.rgba
        else:  # the winners' colors, gathered on the host: no second render
            colors = np.zeros_like(g.rgba)
            hit = g.index != EMPTY
            colors[hit] = cloud.colors[g.index[hit]]
        panels.append(_Panel("colors", _colors_title(cloud.colors), shaded(colors)))
    panels.append(_depth_panel(g.depth))
    if g.vel2d is not None:
        angle, magnitude = images.velocity_images(g.vel2d)
        speed = np.hypot(g.vel2d[..., 0], g.vel2d[..., 1])
        speed = speed[np.isfinite(speed)]
        top = float(np.percentile(speed, 99)) if speed.size else 1.0
        panels.append(
            _Panel("velocity-angle", "screen velocity: angle", angle, ("twilight", -180.0, 180.0, "degrees"))
        )
        panels.append(
            _Panel(
                "velocity-magnitude",
                "screen velocity: magnitude",
                magnitude,
                ("inferno", 0.0, top, "pixels per unit time"),
            )
        )
    if soft_z is not None:
        with progress.stage(f"soft z (factor {soft_z:g})"):
            soft = raster.render(
                camera, width, height, **kw, soft_z=soft_z, host=False
            )  # read back its rgba alone
            key = _Panel("soft-z", f"soft z (factor {soft_z:g})", soft.rgba.get())
            panels.append(_keyed(key, panels))
    if levels:
        with progress.stage(f"depth filter ({levels} levels)"):
            filtered = depth_filter(g, levels)
        kept = typing.cast(np.ndarray, filtered.rgba)  # G-buffers in: the rgba is there
        panels.append(_keyed(_Panel("depth-filtered", f"depth filter ({levels} levels)", kept), panels))
    post_s = 0.0
    removed: list[int | None] = [None]
    scale = 1
    if post is not None:
        # the splat radius as the network reads the view: narvis-scan's through its
        # depth filter (what the viewer measures too; no other network has a range)
        seen = g
        if post.spec.radius_px_trained is not None and post.spec.depth_filter is not None:
            seen = filter_gbuffers(g, *post.spec.depth_filter)
        median = post.median_radius_px(seen)
        # the network's frame keeps MIN_SCALED_SIDE pixels a side (and so the view's aspect within 1 %)
        if post_scale is None:
            scale = post.render_scale(seen)
        else:
            scale = min(post_scale, min(width, height) // MIN_SCALED_SIDE)
        scale = max(scale, 1)
        pw, ph = (width, height) if scale == 1 else (round(width / scale), round(height / scale))
        post_camera = camera if scale == 1 else camera.with_aspect(pw / ph)  # the rounded size's

        def frame() -> np.ndarray:
            """The documented pipeline: G-buffers with only the planes the
            network reads, rendered on the device (the panels above are the
            host render's); read back never, but for narvis-scan, whose
            spec's depth filter runs first and brings its planes back once.
            At a scale, the picture is resized up to the view (bilinear)."""
            gd = raster.render(post_camera, pw, ph, **kw, planes=post.attribute_planes, host=False)
            if post.name == "lidar":  # device planes in, device planes out
                picture = post(depth_filter(gd, levels))
            elif post.spec.depth_filter is not None:
                gf = filter_gbuffers(gd, *post.spec.depth_filter)
                removed[0] = gf.stats["depth_filter_removed"]
                picture = post(gf)
            else:
                picture = post(gd)
            return picture if scale == 1 else resized(picture, width, height, smooth=SCALED_SMOOTH)

        title = post.spec.title
        with progress.stage(f"{post.name} network" + (f" at {pw}x{ph}" if scale > 1 else "")):
            frame()  # the first call sizes its buffers
            t0 = time.perf_counter()
            panels.append(_Panel(f"post-{post.name}", title, frame()))
            post_s = time.perf_counter() - t0
        _say_unlike_training(post, median, scale, post_scale is not None)
    return _Rendered(g, panels, first, warm, post_s, removed[0], scale)


def _post_scale(text: str) -> int | None:
    """--post-scale: a whole number 1..64, or auto (None)."""
    t = text.strip().lower()
    if t == "auto":
        return None
    try:
        n = int(t)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number 1..64 or auto, got {text!r}") from None
    if not 1 <= n <= 64:
        raise argparse.ArgumentTypeError(f"expected a whole number 1..64 or auto, got {text!r}")
    return n


def _say_unlike_training(post, median: float, scale: int, asked: bool) -> None:
    """On stderr: the scale the network's frame was rendered at, and why
    (unless --post-scale `asked` for it); a warning when the view's splat
    radius (at that scale) still lies far outside the post network's
    training frames (its spec's unlike_training)."""
    if not np.isfinite(median):
        return
    if scale > 1 and not asked:
        print(
            f"clvis render: --post {post.name}: its frame rendered {scale}x smaller and resized up: the "
            f"points' median splat radius, {median:.2f} pixels, is over the "
            f"{post.spec.radius_px_trained[1]:g} of its training frames (--post-scale 1: full size)",
            file=sys.stderr,
        )
    why = post.spec.unlike_training(median / scale)
    if why is not None:
        print(f"clvis render: --post {post.name}: warning: {why}", file=sys.stderr)


def _narvis_sigma(cloud, source, progress) -> float:
    """GR's base sigma for a narvis model with the radius plane: the same
    number its training scenes' radius and Gaussians were made of
    (clvis.training.data.narvis_sigma: NARVIS_SIGMA x the median 4-NN
    distance), of the points drawn (one with a NaN or infinite coordinate is
    dropped by the renderer). A radius the cloud brings is not used: the
    network was trained on this one."""
    from ..training.data import narvis_sigma

    finite = np.isfinite(cloud.positions).all(axis=1)
    with progress.stage("splat radius plane (GR's sigma: median 4-NN distance)"):
        pos = cloud.positions if finite.all() else cloud.positions[finite]
        if len(pos) < 2:
            raise CliError(f"--post narvis: {source} has fewer than 2 finite points; no spacing to measure")
        return narvis_sigma(pos)


def _compare_gaussians(
    cloud, camera, width, height, attribute, colormap, r, net, progress, look, scan_radius=None, sigma=None
) -> list[str]:
    """--compare: the Gaussian renderer NARVis replaces, on the same view and
    transfer function (narvis-scan: the isotropic Gaussians of the radius
    plane, the points' colours; narvis: `sigma`, GR's base sigma when the
    command computed it for the radius plane); a panel, and lines scoring the
    network's image and the plain rasterization against it, with the time of
    each path."""
    from ..colormap import value_range
    from ..metrics import metrics
    from ..training.data import NarvisScene, ScanScene

    scene: NarvisScene | ScanScene
    if scan_radius is not None:
        from ..colormap import apply, lut
        from ..io import PointCloud

        # the Gaussians in the colours the network's points were drawn in: the
        # class colours, the attribute through the colormap over the panels'
        # range, or the cloud's own colours (a LAS file's all-black RGB is not
        # what the network saw when the command coloured by intensity)
        if look.classes is not None:
            colors = look.class_colors
        elif attribute is not None:
            values = _raster_fields(cloud, attribute)["attributes"][attribute]
            colors = apply(values, lut(colormap), *(look.value_range or value_range(values)))
        else:
            colors = cloud.colors
        # the finite points, as the rasterizer draws them
        finite = np.isfinite(cloud.positions).all(axis=1)
        keep = slice(None) if finite.all() else finite
        c = PointCloud(cloud.positions[keep], colors=colors[keep], radius=scan_radius[keep])
        scene, kind = ScanScene(c, "landscape", "the cloud"), "isotropic kNN Gaussians, 3DGS splatting"
    else:
        vr = value_range(_raster_fields(cloud, attribute)["attributes"][attribute])
        scene, kind = (
            NarvisScene(cloud, attribute, vr, colormap, "the cloud", sigma),
            "velocity-elongated Gaussians",
        )
    with progress.stage(f"Gaussian renderer ({kind})"):
        t0 = time.perf_counter()
        gr = scene.gaussian_renderer(queue=net.queue)
        setup = time.perf_counter() - t0
        gr.render(camera, width, height)  # builds the kernels
        t0 = time.perf_counter()
        img = gr.render(camera, width, height)
        gr_s = time.perf_counter() - t0
    target = np.clip(np.asarray(img.rgba)[..., :3], 0, 1).astype(np.float32)
    rgba = np.empty((height, width, 4), np.uint8)
    rgba[..., :3] = np.rint(target * 255)
    rgba[..., 3] = 255
    r.panels.append(_Panel("gaussians", "Gaussian renderer (the target)", rgba))
    g = r.gbuffers
    plain = np.where(g.covered[..., None], g.rgba[..., :3] / np.float32(255), 0).astype(np.float32)
    post_img = next(p.image for p in r.panels if p.key == f"post-{net.name}")
    m_net = metrics(post_img[..., :3] / np.float32(255), target)
    m_plain = metrics(plain, target)
    ns = net.stats
    fast = r.post_s
    ratio = f"{gr_s / fast:.1f}x faster" if fast <= gr_s else f"{fast / gr_s:.1f}x slower"
    stage = "render on the device" if net.spec.depth_filter is None else "render and depth filter"
    return [
        f"  compare   against the Gaussian renderer ({gr.n:,} Gaussians; set up in {setup:.1f} s):",
        f"            plain rasterization {m_plain['psnr']:.2f} dB, SSIM {m_plain['ssim']:.3f}",
        f"            {net.name + ' network':<20}{m_net['psnr']:.2f} dB, SSIM {m_net['ssim']:.3f}",
        f"            MACR + network {fast * 1e3:.0f} ms ({stage} "
        f"{(fast - ns['pack'] - ns['inference'] - ns['unpack']) * 1e3:.0f}, "
        f"pack {ns['pack'] * 1e3:.0f}, inference {ns['inference'] * 1e3:.0f}, "
        f"unpack {ns['unpack'] * 1e3:.0f}) against Gaussians "
        f"{gr_s * 1e3:.0f} ms: {ratio}",
    ]


def _keyed(p: _Panel, panels: list) -> _Panel:
    """A panel in the first panel's colours (soft z, the depth filter) with its
    colour bar or legend: the colours read the same there."""
    if panels and panels[0].key.startswith("attribute-"):
        p.bar, p.legend = panels[0].bar, panels[0].legend
    return p


def _depth_panel(depth) -> _Panel:
    """The depth panel, its bar from the nearest depth (bright, left) to the farthest."""
    from .. import images
    from ..colormap import lut, value_range

    near, far = value_range(depth)
    if near == far:  # one depth (one point): the colormap's middle, not its black end
        pad = max(abs(near) * 1e-3, 1e-6)
        near, far = near - pad, far + pad
    bar = (lut("magma")[::-1], near, far, "view depth")
    return _Panel("depth", "depth (near = bright)", images.depth_image(depth, near=near, far=far), bar)


def _framed(p: _Panel, transparent: bool = False, background=None) -> np.ndarray:
    """A panel's own PNG: its image under its title, over its colour bar or
    legend when it maps values to colours (the overview's tile at full size);
    the image alone otherwise."""

    image = p.image if transparent else _opaque(p.image, background)
    if p.bar is None and not p.legend:
        return image
    return _tile(p, image)


def _tile(p: _Panel, image: np.ndarray) -> np.ndarray:
    """`image` (the panel's, shrunk or not) labelled, over its bar or legend."""
    from .. import images

    tile = images.label(image, p.title)
    if p.bar is not None and tile.shape[1] >= 2:  # a bar needs two columns (--size 1xH has one)
        lut, vmin, vmax, *title = p.bar
        bar = images.colorbar(lut, vmin, vmax, tile.shape[1], title=title[0] if title else "")
        tile = np.concatenate([tile, bar], axis=0)
    if p.legend and tile.shape[1] >= 2:  # the same for a legend
        tile = np.concatenate([tile, images.legend(p.legend, tile.shape[1])], axis=0)
    return tile


def _panel_pngs(panels, args) -> list:
    """[(file name, image)] of the panels: framed (title, colour bar, legend)
    unless --no-labels asks for the images alone."""
    if args.no_labels:
        return [
            (f"{p.key}.png", p.image if args.transparent else _opaque(p.image, args.background))
            for p in panels
        ]
    return [(f"{p.key}.png", _framed(p, args.transparent, args.background)) for p in panels]


def _shrink(image: np.ndarray, f: int) -> np.ndarray:
    """An RGBA image shrunk by f in each direction, keeping the most opaque
    pixel of each f x f block (single-pixel points stay points, not a haze)."""
    h, w = image.shape[0] // f, image.shape[1] // f
    if f <= 1 or h == 0 or w == 0:
        return image
    words = np.ascontiguousarray(image).view(np.uint32)[..., 0]  # one word per pixel
    alpha_of = (lambda a: a >> 24) if sys.byteorder == "little" else (lambda a: a & 0xFF)
    out = words[0 : h * f : f, 0 : w * f : f]
    for dy in range(f):
        for dx in range(f):
            cand = words[dy : h * f : f, dx : w * f : f]
            out = np.where(alpha_of(cand) > alpha_of(out), cand, out)
    return np.ascontiguousarray(out).view(np.uint8).reshape(h, w, 4)


def _overview(panels, transparent: bool = False, background=None) -> np.ndarray:
    """The panels in a grid, up to three a row, each labelled with its title
    (and the attribute's colour bar), shrunk to at most _OVERVIEW_WIDTH pixels
    wide; empty pixels over images.BACKGROUND unless `transparent`."""
    from .. import images

    cols = min(3, len(panels))
    f = max(1, -(-cols * panels[0].image.shape[1] // _OVERVIEW_WIDTH))
    tiles = []
    for p in panels:
        tile = _shrink(p.image, f)
        tiles.append(_tile(p, tile if transparent else _opaque(tile, background)))
    return images.compose(tiles, columns=cols)


def _opaque(image, background=None):
    from .. import images

    return images.opaque(image) if background is None else images.opaque(image, background)


def _save_pngs(out: Path, named) -> list[Path]:
    """images.save_png of each (file name, image) into `out`, a few at a time
    (Pillow's PNG encoder releases the GIL)."""
    from concurrent.futures import ThreadPoolExecutor

    from .. import images

    clear_targets(out, [name for name, _ in named])
    with ThreadPoolExecutor(max_workers=max(1, min(len(named), os.cpu_count() or 1))) as pool:
        files = list(pool.map(lambda item: images.save_png(out / item[0], item[1]), named))
    note_earlier_pngs("clvis render", out, {name for name, _ in named}, _PANEL_PNG)
    return files


#: the PNGs clvis render writes (and overview.png, always)
_PANEL_PNG = re.compile(
    r"(colors|depth|soft-z|depth-filtered|velocity-angle|velocity-magnitude|gaussians|post-[a-z-]+"
    r"|attribute-.+)\.png"
)


def _not_a_volume(path: str) -> None:
    """CliError saying which commands read it when `path` names a volume
    (read_points said "unknown point cloud format '.gz'" of brain.nii.gz)."""
    from ..io.points import POINT_SUFFIXES
    from ..io.volumes import FORMATS
    from ..io.vtk import VOLUME_DATASETS, legacy_dataset

    name = path.lower()
    # a .npy may be either; a .vtk is a volume where its DATASET is STRUCTURED_POINTS or
    # RECTILINEAR_GRID, else points
    if name.endswith(FORMATS) and (
        not name.endswith(POINT_SUFFIXES)
        or (name.endswith(".vtk") and legacy_dataset(path) in VOLUME_DATASETS)
    ):
        kind = next(f for f in FORMATS if name.endswith(f))
        raise CliError(
            f"{path}: a volume file ({kind}), not a point cloud; "
            "clvis iso, clvis gauss and clvis view read volumes"
        )


def _load(args, progress):
    """(cloud, its description, default attribute, depth filter on by default)."""
    from ..io import read_points

    if args.file is not None:
        if args.dataset is not None or args.points is not None:
            raise CliError("--dataset and --points choose an embedded cloud; leave them out with a FILE")
        if len(args.file) > 1:
            # the same file twice would draw every point twice (a shell glob and a name, say)
            seen: dict[str, str] = {}
            for f in args.file:
                key = os.path.realpath(f)
                if key in seen:
                    raise CliError(
                        f"{f}: given twice (as {seen[key]} too); each file's points are drawn once"
                    )
                seen[key] = f
            return _load_tiles(args, progress)
        args.file = args.file[0]
        _not_a_volume(args.file)
        with progress.stage(f"reading {Path(args.file).name}"):
            try:
                cloud = read_points(args.file)
            except FileNotFoundError:
                raise CliError(f"{args.file}: no such file") from None
            except IsADirectoryError:
                raise CliError(f"{args.file}: is a folder, not a point cloud file") from None
        if len(cloud) == 0:
            raise CliError(f"{args.file}: the file holds no points")
        return cloud, str(args.file), None, False
    name = args.dataset or "hurricane"
    n = args.points if args.points is not None else _DEFAULT_POINTS[name]
    check_embedded_points(name, n)
    with progress.stage(f"generating {name} ({n:,} points)"):
        cloud = _embedded(name, n)
    attribute, depth_filter_on = _DATASETS[name]
    return cloud, f"the embedded {name}", attribute, depth_filter_on


def _load_tiles(args, progress):
    """Several point files as one cloud on this device (the files in order:
    one coordinate origin, the smallest of theirs; the attribute planes every
    file has, matched by name; colours, velocity and radius when every file
    has them), as clvis.distributed.concatenate makes it for the workers."""
    from .. import runtime
    from ..distributed.raster import concatenate
    from ..io import read_points

    clouds = []
    for f in args.file:
        with progress.stage(f"reading {Path(f).name}"):
            try:
                clouds.append(read_points(f))
            except FileNotFoundError:
                raise CliError(f"{f}: no such file") from None
            except IsADirectoryError:
                raise CliError(f"{f}: is a folder, not a point cloud file") from None
    if args.attribute is not None:
        for f, c in zip(args.file, clouds, strict=True):
            plane_attribute(c, args.attribute)
            if args.attribute not in c.attributes and args.attribute not in _COORDINATES:
                have = [*c.attributes, *plane_names(c)]
                raise CliError(f"{f}: no attribute {args.attribute!r}; it has {', '.join(have) or 'none'}")
    names = [k for k in clouds[0].attributes if all(k in c.attributes for c in clouds[1:])]
    for k in names:
        kinds = {str(c.attributes[k].dtype) for c in clouds}
        if len(kinds) > 1:
            raise CliError(f"attribute {k!r}: of types {sorted(kinds)} in the files; one type needed")
    partial = [f for f in ("colors", "velocity", "radius") if any(getattr(c, f) is None for c in clouds)]
    for c in clouds:
        c.attributes = {k: c.attributes[k] for k in names}
        for f in partial:  # not in every file: left out
            setattr(c, f, None)
    n = sum(len(c) for c in clouds)
    if n == 0:
        raise CliError(f"{len(clouds)} files: they hold no points")
    need = n * (12 + 4 * len(names) + 16)  # positions, attributes, colours and room to render
    q = runtime.default_queue()
    if n >= 0xFFFFFFFF or need > int(q.device.global_mem_size):
        raise CliError(
            f"{len(clouds)} files, {n:,} points: more than one device holds ({q.device.name.strip()}); "
            "render them on Dask workers (--workers N or --scheduler ADDRESS)"
        )
    with progress.stage(f"joining {len(clouds)} tiles ({n:,} points)"):
        cloud = concatenate(clouds)
    return cloud, f"{len(clouds)} tiles", None, False


def cmd(args: argparse.Namespace) -> int:
    if args.post == "infill":
        raise CliError(
            "--post infill: the in-fill network fills an isosurface's unfinished rays, not a point "
            "cloud's image: clvis iso FILE --completion 0.85 --post infill"
        )
    check_camera_args(args)
    if args.transparent and args.background is not None:
        raise CliError("--transparent and --background: empty pixels are either clear or a colour; give one")
    progress = progress_from_args(args, "clvis render")
    check_orbit_args(args)
    if distributed_run(args):
        if args.orbit is not None:
            raise CliError("--orbit: not with --workers/--scheduler (one device renders the turntable)")
        for name in ("post", "compare"):
            if getattr(args, name) not in (None, False):
                raise CliError(f"--{name}: not with --workers/--scheduler (the networks run on one device)")
        if args.range is not None and args.range[0] == "percentile":
            raise CliError(
                "--range pLO,pHI: percentiles would read every value here; on workers give MIN,MAX"
            )
        if args.point_size == "auto":
            raise CliError(
                "--point-size auto: measured on the whole cloud, not with --workers/--scheduler; give N"
            )
        args.colormap_given, args.colormap = args.colormap, args.colormap or "viridis"
        return on_workers("render", _render_distributed, args, progress)
    args.file = args.file or None
    return _render(args, progress)


def _render_distributed(args, progress) -> int:
    """`clvis render TILES... --workers N | --scheduler ADDRESS`: the tiles
    read and rendered on Dask workers, composited into one view."""
    from .._arrays import on_host
    from ..distributed import DistributedRasterizer
    from ..raster import depth_filter

    if not args.file:
        raise CliError("--workers and --scheduler render point FILEs (tiles); give at least one")
    if args.dataset is not None or args.points is not None:
        raise CliError("--dataset and --points choose an embedded cloud; leave them out with FILEs")
    for f in args.file:
        if not Path(f).is_file():
            raise CliError(f"{f}: no such file")
    client, workers = cluster_client(args)
    width, height = args.size
    t_start = time.perf_counter()
    fields = [args.attribute] if args.attribute is not None else None
    with progress.stage(f"reading {len(args.file)} tiles on the workers"):
        try:
            dr = DistributedRasterizer(
                args.file, client, workers=workers, fields=fields, connect_timeout=args.connect_timeout
            )
        except ClvisError:
            raise
        except OSError as e:
            raise cluster_failed(args, e) from None
    with dr:
        attribute = args.attribute
        names = dr.attribute_names
        if attribute is not None and attribute not in names:
            raise CliError(f"--attribute {attribute}: the tiles have {', '.join(names) or 'no attributes'}")
        if attribute is None:
            attribute = _attribute_on_workers(dr)
        if dr.bounds is None:
            raise CliError("the tiles hold no point with finite coordinates")
        # one framing rule with and without workers: the box of the bulk
        # (stray points left out, with the same note) and, for a fit view,
        # the same sample of its points as one device's
        with progress.stage("framing"):
            lo, hi, sample, bulk, finite = dr.framing()
        if bulk < finite:
            stray_note("clvis render", bulk, finite, dr.bounds, (lo, hi), dr.origin)
        camera = camera_from_args(world_camera_args(args, dr.origin), lo, hi, width, height, points=sample)
        if attribute is None and args.range is not None:
            raise CliError(
                "--range scales an attribute's colours; the tiles have none (add --attribute NAME)"
            )
        if attribute is None and args.colormap_given is not None:
            raise CliError(
                "--colormap colours an attribute; the tiles are shown in their own colours "
                "(add --attribute NAME)"
            )
        if attribute is not None and args.colormap_given is None and _class_like(attribute):
            print(
                f"clvis render: note: on workers {attribute} is coloured through {args.colormap}, "
                "not the ASPRS class colours with their legend (those need one device; "
                "--colormap NAME chooses the map and silences this)",
                file=sys.stderr,
            )
        vr = None if args.range is None else (args.range[1], args.range[2])
        kw = {"color_by": attribute, "colormap": args.colormap, "point_size": args.point_size}
        kw["value_range"] = vr
        with progress.stage("rendering + compositing"):
            g = dr.render(camera, width, height, **kw)
            t0 = time.perf_counter()
            g = dr.render(camera, width, height, **kw)
            warm = time.perf_counter() - t0

        def shaded(rgba):
            if args.edl is None:
                return rgba
            from .. import runtime
            from ..raster import edl

            radius = max(1, (args.point_size + 1) // 2)
            return edl(g.depth, rgba, args.edl, radius, queue=runtime.default_queue())

        panels = []
        if attribute is not None:
            vr = vr or dr._ranges[attribute]
            panels.append(
                _Panel(
                    f"attribute-{_safe_name(attribute)}",
                    f"{attribute} ({args.colormap})",
                    shaded(on_host(g.rgba)),
                    (args.colormap, *vr, attribute),
                )
            )
        else:
            panels.append(_Panel("colors", "point colors", shaded(on_host(g.rgba))))
        panels.append(_depth_panel(on_host(g.depth)))
        if args.depth_filter:
            with progress.stage(f"depth filter ({args.depth_filter} levels)"):
                filtered = depth_filter(g, args.depth_filter)
            kept = typing.cast(np.ndarray, filtered.rgba)  # G-buffers in: the rgba is there
            panels.append(
                _keyed(_Panel("depth-filtered", f"depth filter ({args.depth_filter} levels)", kept), panels)
            )
        out = Path(args.out)
        with progress.stage("writing PNGs"):
            named = _panel_pngs(panels, args)
            named.append(("overview.png", _overview(panels, args.transparent, args.background)))
            files = _save_pngs(out, named)
        st = g.stats
        covered = int(on_host(g.covered).sum())
        print(f"clvis render: {len(args.file)} tiles, {dr.n:,} points, on {st['workers']} Dask workers")
        if workers is not None and workers > dr.npartitions:
            print(
                f"  note      {dr.npartitions} file{'s' if dr.npartitions > 1 else ''} on {workers} workers: "
                "a file is one partition, rendered by one worker (give more tiles to use them all)"
            )
        print(f"  view      {describe_camera(args)}, {width}x{height}")
        if args.range is not None:
            print(f"  range     {attribute} {args.range[1]:.6g}..{args.range[2]:.6g}")
        if args.edl is not None:
            print(f"  edl       eye-dome lighting, strength {args.edl:g}")
        print(
            f"  covered   {covered:,} of {width * height:,} pixels ({100 * covered / (width * height):.1f} %)"
        )
        sec = st["seconds"]
        print(
            f"  frame     {warm * 1e3:.1f} ms ({st['compositing']} compositing; busiest worker: render "
            f"{sec['render'] * 1e3:.1f} ms, composite {sec['composite'] * 1e3:.1f} ms)"
        )
        print(
            "  sent      " + ", ".join(f"{w} {b / 1e6:.2f} MB" for w, b in sorted(st["bytes_sent"].items()))
        )
        print("  soft z    off (on workers it would need every tile's colours near each pixel's winner)")
        print(f"  total     {time.perf_counter() - t_start:.2f} s")
    print(f"wrote {len(files)} PNGs to {out}{os.sep}")
    for p in files:
        print(f"  {p.name}")
    return 0


def _attribute_on_workers(dr) -> str | None:
    """What the tiles are coloured by on workers without --attribute, as
    _pick_attribute picks on one device: their colours when they vary (None),
    else intensity, else the first attribute that varies; where one device
    would colour by z (nothing varies), intensity or the first attribute
    (the workers colour by attributes), else the colours."""
    if "colors" in dr.fields and dr.colors_vary:
        return None
    names = dr.attribute_names
    for cand in ["intensity", *names]:
        if dr.varies.get(cand):
            return cand
    return "intensity" if "intensity" in names else (names[0] if names else None)


def _class_like(attribute: str) -> bool:
    """Whether an attribute's name says it holds class codes."""
    return attribute.lower() in ("classification", "class", "classes", "label")


def _look(args, cloud, attribute, point_size, queue) -> _Look:
    """The colour panels' look from --range, --colormap, --edl (see _Look)."""
    from ..colormap import ASPRS_CLASSES, categorical, class_name, class_palette

    look = _Look()
    if args.edl is not None:
        look.edl, look.edl_radius = args.edl, max(1, (point_size + 1) // 2)
    if attribute is None:
        for given, what in ((args.range, "--range scales"), (args.colormap, "--colormap colours")):
            if given is not None:
                raise CliError(
                    f"{what} an attribute; the cloud is shown in its own colours (add --attribute NAME)"
                )
        return look
    coordinate = attribute not in cloud.attributes
    values = cloud.positions[:, _COORDINATES.index(attribute)] if coordinate else cloud.attributes[attribute]
    offset = float(cloud.origin[_COORDINATES.index(attribute)]) if coordinate else 0.0
    if args.colormap is None and not coordinate and _class_like(attribute) and categorical(values):
        if args.range is not None:
            raise CliError(
                f"--range: {attribute} is shown by class (ASPRS colours); --colormap NAME scales it"
            )
        codes, counts = np.unique(np.asarray(values).astype(np.int64), return_counts=True)
        table = class_palette()
        look.classes = [
            (
                tuple(int(c) for c in table[k, :3]),
                f"{k} {class_name(int(k))}" + ("" if k in ASPRS_CLASSES else ""),
            )
            for k in codes
        ]
        look.class_colors = table[np.asarray(values).astype(np.int64)]
        return look
    look.bar_offset = offset
    if args.range is not None:
        kind, a, b = args.range
        if kind == "percentile":
            v = np.asarray(values, np.float64)
            v = v[np.isfinite(v)]
            if v.size == 0:
                raise CliError(f"--range: {attribute} has no finite value")
            lo, hi = (float(x) for x in np.percentile(v, [a, b]))
        else:
            lo, hi = a - offset, b - offset
        look.value_range = (lo, hi)
    else:
        from ..colormap import value_range

        lo, hi = value_range(values)
        if lo == hi:  # one value (one point, a level plane by z): the colormap's middle, not its dark end
            look.value_range = (lo - 1.0, hi + 1.0)
    return look


def _render(args, progress) -> int:
    from .. import runtime
    from .._arrays import on_host
    from ..raster import Rasterizer
    from ..raster.depth_filter import LEVELS

    width, height = args.size
    t_start = time.perf_counter()
    cloud, source, default_attribute, filter_on = _load(args, progress)
    attribute = _pick_attribute(cloud, args.attribute, default_attribute, source)
    # --post lidar takes the depth-filtered image: the filter is on (its default levels) unless given
    on = filter_on or args.post == "lidar"
    levels = args.depth_filter if args.depth_filter is not None else (LEVELS if on else 0)
    lo, hi, framed, _ = frame_bulk(cloud, source, "clvis render")
    camera = camera_from_args(world_camera_args(args, cloud.origin), lo, hi, width, height, points=framed)
    point_size, spacing = args.point_size, None
    if point_size == "auto":
        from ..camera import point_spacing

        spacing = point_spacing(camera, framed, width, height)
        point_size = int(min(max(round(spacing), 1), MAX_AUTO_POINT_SIZE))
    colormap = args.colormap or "viridis"
    q = runtime.default_queue()
    # the whole command's host memory a pixel (G-buffers read back, the depth
    # filter, the panels, the overview and their PNGs), refused up front
    # rather than met by the OOM killer
    runtime.check_memory(
        q, f"clvis render --size {width}x{height}", host_bytes=width * height * HOST_BYTES_PER_PIXEL
    )
    net = None
    if args.compare and args.post not in ("narvis", "narvis-scan"):
        raise CliError(
            "--compare: it scores the narvis network against the Gaussian renderer; add --post narvis"
        )
    post_name = args.post
    if args.post == "narvis":  # the NARVis model the cloud's planes allow
        post_name = "narvis" if cloud.velocity is not None else "narvis-scan"
        why = (
            "it has a velocity: velocity-elongated Gaussians"
            if post_name == "narvis"
            else "no velocity: isotropic Gaussians of its kNN splat radius"
        )
        print(f"clvis render: --post narvis: {source}: model {post_name} ({why})", file=sys.stderr)
    if post_name == "narvis":
        from ..io.cloud import check_finite

        # the network reads the velocity of every point drawn (one with a NaN or
        # infinite coordinate is not): a NaN there is the file's, said as such
        drawn = np.isfinite(cloud.positions).all(axis=1)
        check_finite(f"{source}: velocity", np.where(drawn[:, None], cloud.velocity, 0))
    scan_radius = None
    flow_sigma = None
    if args.post_scale is not None and args.post is None:
        raise CliError("--post-scale scales a post network's frame: add --post")
    if args.post_guard is not None and args.post is None:
        raise CliError("--post-guard guards a post network: add --post lidar")
    if args.model_dir is not None and args.post is None:
        raise CliError("--model-dir: where a post network's model is: add --post lidar|narvis|narvis-scan")
    if args.post is not None:
        from .. import post

        if args.post == "lidar" and not levels:
            raise CliError(
                f"--post {args.post}: the network takes the depth-filtered image; --depth-filter 0 turns "
                f"the filter off (leave it out for {LEVELS} levels)"
            )
        if post_name == "narvis":
            if attribute is None:
                raise CliError(
                    "--post narvis: the network takes points coloured by an attribute; add --attribute"
                )
        if post_name == "narvis-scan":
            if cloud.colors is None and attribute is None:
                raise CliError(
                    f"--post {args.post}: {source} has no colours; add --attribute to colour it by one"
                )
            import scipy.spatial  # noqa: F401  (imported here, not inside the time said below)

            from ..gauss.points import knn_sigma
            from ..training.data import SCAN_K

            # the radius plane the network was trained on: each point's mean
            # 4-NN distance (clamped), projected to pixels by the resolve
            t0 = time.perf_counter()
            with progress.stage(f"splat radius plane (mean {SCAN_K}-NN distance)"):
                # of the points drawn: one with a NaN or infinite coordinate is
                # dropped by the renderer (and said so), its radius unused
                finite = np.isfinite(cloud.positions).all(axis=1)
                if finite.all():
                    scan_radius = knn_sigma(cloud.positions, SCAN_K)
                else:
                    scan_radius = np.zeros(len(cloud), np.float32)
                    scan_radius[finite] = knn_sigma(cloud.positions[finite], SCAN_K)
            took = time.perf_counter() - t0
            if took > KNN_NOTE_SECONDS and not progress.enabled:
                # the progress display shows it already; else say where the seconds went
                print(
                    f"clvis render: --post {args.post}: the splat radius plane (mean {SCAN_K}-NN "
                    f"distance of {len(cloud):,} points) took {took:.1f} s; it is computed on every call",
                    file=sys.stderr,
                )
        if args.post_guard and post_name == "narvis":
            raise CliError(
                f"--post-guard: the {post_name} network has no guard (the in-fill, LiDAR and narvis-scan "
                "ones have)"
            )
        net = post.load(post_name, queue=q, directory=args.model_dir)
        if args.transparent or args.background is not None:
            # the network predicts colour alone (no coverage): what is empty cannot be told apart
            print(
                f"clvis render: note: post-{post_name}.png is the {post_name} network's opaque frame over "
                f"black (it predicts no coverage); --{'transparent' if args.transparent else 'background'} "
                "applies to the other pictures",
                file=sys.stderr,
            )
        if args.post_guard is not None:
            net.guard = args.post_guard
        if post_name == "narvis" and "radius" in net.planes:
            flow_sigma = _narvis_sigma(cloud, source, progress)
    look = _look(args, cloud, attribute, point_size, q)
    fields = _raster_fields(cloud, attribute)
    if look.classes is not None:  # the class colours travel as the points' colours
        fields = {**fields, "colors": look.class_colors, "attributes": {}}
    if scan_radius is not None:
        fields = {**fields, "radius": scan_radius}
    if flow_sigma is not None:  # the radius plane this narvis model reads: GR's sigma, every point
        from ..training.data import narvis_radius

        fields = {**fields, "radius": narvis_radius(cloud.positions, flow_sigma)}
    with progress.stage("uploading + Morton order"):
        raster = Rasterizer(cloud.positions, **fields, queue=q)
        q.finish()
    r = _render_panels(
        raster,
        cloud,
        camera,
        width,
        height,
        attribute,
        colormap,
        args.soft_z,
        levels,
        progress,
        point_size,
        net,
        look,
        args.post_scale,
    )
    compared = []
    if args.compare:
        compared = _compare_gaussians(
            cloud, camera, width, height, attribute, colormap, r, net, progress, look, scan_radius, flow_sigma
        )
    out = Path(args.out)
    with progress.stage("writing PNGs"):
        named = _panel_pngs(r.panels, args)
        named.append(("overview.png", _overview(r.panels, args.transparent, args.background)))
        files = _save_pngs(out, named)
    orbit: tuple = ([], None)
    if args.orbit is not None:
        from ..raster import edl
        from .orbit import render_orbit

        first = r.panels[0]  # the colour panel: the attribute's, the classes' or the cloud's colours

        def draw(cam) -> np.ndarray:
            g = raster.render(cam, width, height, **_render_kw(look, attribute, colormap, point_size))
            rgba = g.rgba if look.edl is None else edl(g.depth, g.rgba, look.edl, look.edl_radius, queue=q)
            p = dataclasses.replace(first, image=rgba)
            if args.no_labels:
                return p.image if args.transparent else _opaque(p.image, args.background)
            return _framed(p, args.transparent, args.background)

        orbit = render_orbit(args, camera, lo, hi, draw, out, progress)
    total = time.perf_counter() - t_start

    g, n = r.gbuffers, len(cloud)
    covered = int(on_host(g.covered).sum())
    stats = g.stats
    if look.classes is not None:
        colored = f"colored by {attribute} (ASPRS classes: {len(look.classes)})"
    elif attribute:
        colored = f"colored by {attribute} ({colormap})"
    else:
        colored = "its colors"
    print(f"clvis render: {source}, {n:,} point{'s' if n != 1 else ''}, {colored}")
    print(f"  device    {runtime.describe(q.device)}")
    sized = ""
    if spacing is not None:
        sized = f", points {point_size}x{point_size} pixels (auto: {spacing:.1f} pixels apart)"
    elif point_size > 1:
        sized = f", points {point_size}x{point_size} pixels"
    print(f"  view      {describe_camera(args)}, {width}x{height}{sized}")
    o = cloud.origin
    print(f"  bounds    {world_box(lo, hi, o)}" + (" (the file's coordinates)" if o.any() else ""))
    if look.value_range is not None:
        a, b = (v + look.bar_offset for v in look.value_range)
        print(f"  range     {attribute} {a:.6g}..{b:.6g}")
    if look.edl is not None:
        print(f"  edl       eye-dome lighting, strength {look.edl:g}, radius {look.edl_radius}")
    dropped = stats.get("points_nonfinite", 0)
    if dropped:
        print(
            f"  dropped   {dropped:,} point{'s' if dropped != 1 else ''} with a NaN or infinite coordinate "
            "(never drawn)"
        )
    print(f"  covered   {covered:,} of {width * height:,} pixels ({100 * covered / (width * height):.1f} %)")
    print(
        f"  batches   {stats['batches_drawn']:,} drawn, {stats['batches'] - stats['batches_drawn']:,} "
        f"culled of {stats['batches']:,} ({stats['points_read']:,} points read)"
    )
    print(
        f"  render    {r.warm_s * 1e3:.1f} ms ({n / r.warm_s / 1e6:.1f} M points/s): render, resolve, "
        f"read back; the first call, which may build kernels: {r.first_s * 1e3:.0f} ms"
    )
    if net is not None:
        ns = net.stats
        where = "G-buffers on the device"
        if net.spec.depth_filter is not None:
            lv, st = net.spec.depth_filter
            where = (
                f"the G-buffers through its depth filter ({lv} levels, strength {st:g}; "
                f"{r.post_removed:,} far-side points removed) on the host"
            )
        scaled = ""
        if r.post_scale > 1:
            pw, ph = round(width / r.post_scale), round(height / r.post_scale)
            scaled = f"at {pw}x{ph} ({r.post_scale}x smaller, resized up), "
        print(
            f"  post      {net!r}: {r.post_s * 1e3:.1f} ms a frame from render to picture, {scaled}"
            f"{where} (pack {ns['pack'] * 1e3:.1f} ms, inference "
            f"{ns['inference'] * 1e3:.1f} ms, unpack {ns['unpack'] * 1e3:.1f} ms)"
        )
    for line in compared:
        print(line)
    if covered == 0 and (args.eye is not None or args.target is not None):
        print(
            "clvis render: note: no point is in view of this camera; --eye and --target are in "
            f"the file's coordinates (the points span {world_box(lo, hi, cloud.origin)})",
            file=sys.stderr,
        )
    elif covered * _SPARSE_FRACTION < width * height and covered < n:
        print(
            f"clvis render: note: the points cover {covered:,} of {width * height:,} pixels "
            f"({100 * covered / (width * height):.2g} %)"
            + ("; --point-size auto draws them large enough to see" if args.point_size == 1 else ""),
            file=sys.stderr,
        )
    if args.orbit is not None:
        from .orbit import report

        report(*orbit)
    print(f"  total     {total:.2f} s")
    print(
        f"wrote {len(files)} PNGs to {out}{os.sep}"
        + (f" and {len(orbit[0])} orbit frames" if orbit[0] else "")
    )
    for p in files:
        print(f"  {p.name}")
    return 0


def demo(args: argparse.Namespace, q: cl.CommandQueue) -> bool:
    """The demo's raster part: throughput, the reference check, the overview PNG."""
    from .. import images
    from .._arrays import on_host
    from ..raster import Rasterizer
    from ..reference import raster as ref

    W, H = args.size
    n, attribute = args.points, "temperature"
    print(
        f"\nraster: the embedded hurricane, {n:,} particles at {W}x{H}, colored by {attribute} "
        "(best of 3 after a warm-up):\n"
    )
    check_embedded_points("hurricane", n)
    cloud = _embedded("hurricane", n)
    lo, hi = cloud.bounds()
    cam = fit_camera(cloud.positions, lo, hi, direction=_FIT.direction, fov_y=_FIT.fov_y, aspect=W / H)
    raster = Rasterizer(cloud.positions, **_raster_fields(cloud, attribute), queue=q)
    t_vis = timed(lambda: raster.visibility(cam, W, H), q)
    t_all = timed(lambda: raster.render(cam, W, H, color_by=attribute), q)
    for name, t in (
        ("render pass (visibility buffer)", t_vis),
        ("render + resolve, G-buffers on the host", t_all),
    ):
        print(f"  {name:40} {t * 1e3:8.2f} ms {n / t / 1e6:8.1f} M points/s")

    m, w, h = min(n, 100_000), 320, 180
    sub = cloud.positions[:m]  # the generator's order is random: a uniform subsample
    sub_cam = fit_camera(sub, lo, hi, direction=_FIT.direction, fov_y=_FIT.fov_y, aspect=w / h)
    got = Rasterizer(sub, queue=q).render(sub_cam, w, h)
    want = ref.rasterize(sub, sub_cam, w, h)
    ok = np.array_equal(on_host(got.index), on_host(want.index)) and np.array_equal(
        on_host(got.depth), on_host(want.depth)
    )
    print(
        f"  G-buffers vs clvis.reference.raster ({m:,} points at {w}x{h}, index and depth): "
        f"{'matches' if ok else 'MISMATCH'}"
    )

    r = _render_panels(raster, cloud, cam, W, H, attribute, "viridis", _SOFT_Z_FACTOR, 0, Progress(False))
    path = images.save_png(Path(args.out) / "overview.png", _overview(r.panels))
    print(f"  overview of the G-buffers: {path}")
    print("\nmore: clvis render --help, clvis bench raster")
    return ok


_RENDER_HELP = (
    """\
Render a point cloud and write PNGs of its G-buffers: the color by an
attribute, the point colors, depth, the screen-space velocity's angle and
magnitude, the soft z-buffer, the depth-filtered image (each when the cloud
has what it needs), and overview.png with all of them side by side.

Without a FILE it renders an embedded synthetic cloud: a hurricane of 2M
particles (velocity, pressure, temperature, speed) or a 1M-point LiDAR-like
terrain (intensity, classification). The fit view frames the points
themselves, not only their bounding box.

"""
    + VIEWS_HELP
)


def add_parser(sub: argparse._SubParsersAction[Parser]) -> Parser:
    r = sub.add_parser(
        "render",
        help="render a point cloud (default: a synthetic hurricane) to PNGs",
        description=_RENDER_HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    r.add_argument(
        "file",
        nargs="*",
        help="a PLY, LAS, LAZ, E57, PCD, XYZ/TXT/CSV, NPY, NPZ or VTK (.vtp/.vtu/.vts; legacy .vtk POLYDATA, "
        "UNSTRUCTURED_GRID or STRUCTURED_GRID) "
        "point cloud (several: tiles joined into one cloud here, or rendered on Dask workers with "
        "--workers/--scheduler)",
    )
    r.add_argument(
        "--dataset",
        choices=sorted(_DATASETS),
        help="the embedded cloud when no FILE is given (default hurricane)",
    )
    r.add_argument(
        "--points",
        type=count(1, MAX_POINTS),
        metavar="N",
        help="points of the embedded cloud (default 2,000,000 hurricane, 1,000,000 terrain)",
    )
    r.add_argument(
        "--attribute",
        metavar="NAME",
        help="color by this attribute, by a coordinate: x, y, z, or by the points' radius or speed "
        "(|velocity|) where the file has them (default: temperature "
        "for the hurricane, classification for the terrain; for a file its colors "
        "when they vary, else intensity, else the first attribute that varies, else z)",
    )
    r.add_argument(
        "--colormap",
        type=colormap_name,
        default=None,
        metavar="NAME",
        help="a matplotlib colormap for the attribute (default viridis; a classification "
        "attribute of class codes is shown in the ASPRS class colours with a legend unless "
        "a colormap is given)",
    )
    r.add_argument(
        "--range",
        type=_value_range,
        metavar="MIN,MAX|pLO,pHI",
        help="the attribute values the colormap spans: two values (in the file's coordinates "
        "for x, y, z), or two percentiles such as p2,p98 (default: the attribute's min..max)",
    )
    r.add_argument(
        "--background",
        type=_colour,
        metavar="COLOR",
        help="the colour behind the points: a name (black, white, red and the CSS names; darkgrey is "
        "the UI's), #RRGGBB, #RGB or R,G,B "
        "(default a dark grey)",
    )
    r.add_argument(
        "--size",
        type=size,
        default=(1920, 1080),
        metavar="WxH",
        help=f"image size in pixels, {SIZE_RULE} (default 1920x1080)",
    )
    add_camera_options(r, _FIT)
    r.add_argument(
        "--point-size",
        type=_point_size,
        default=1,
        metavar="N|auto",
        help=f"draw each point as N x N pixels around its own, depth-tested per pixel "
        f"(even N: one more pixel right and down), 1..{MAX_POINT_SIZE}; auto: the points' "
        f"spacing on screen, up to {MAX_AUTO_POINT_SIZE} (default 1)",
    )
    r.add_argument(
        "--edl",
        type=_edl_strength,
        nargs="?",
        const=1.0,
        default=None,
        metavar="STRENGTH",
        help="eye-dome lighting: shade the colour panels by depth so the shape reads "
        "without normals (strength default 1; Potree's and CloudCompare's shading)",
    )
    r.add_argument(
        "--soft-z",
        type=_soft_z,
        nargs="?",
        const=_SOFT_Z_FACTOR,
        default=_SOFT_Z_FACTOR,
        metavar="FACTOR",
        help="the soft z-buffer's depth tolerance factor, or off (default 1.01)",
    )
    r.add_argument(
        "--depth-filter",
        type=_levels,
        metavar="LEVELS",
        help="apply the depth filter with this many pyramid levels, 0: off (default: off, 4 for the terrain)",
    )
    r.add_argument(
        "--post",
        choices=("lidar", "narvis", "narvis-scan", "infill"),
        help="also write post-NAME.png: lidar, the depth-filtered image reconstructed by the LiDAR "
        "RGBDA U-Net (turns the depth filter on, 4 levels, unless --depth-filter says otherwise); "
        "narvis, the G-buffers turned into the Gaussian renderer's image by a NARVis U-Net, the model "
        "the cloud's planes allow (said on stderr): narvis with a velocity (and an attribute to colour "
        "by), else narvis-scan (the points' colours and their kNN splat radius); narvis-scan: that one "
        "(infill is clvis iso's: it says so)",
    )
    r.add_argument(
        "--model-dir",
        default=None,
        metavar="DIR",
        help="with --post: the network's model card and files from DIR (a `clvis train --out` folder; "
        "default: the shipped models)",
    )
    r.add_argument(
        "--post-guard",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="with --post lidar: check the network against push-pull on this frame (some scan points "
        "withheld) and keep, tile by tile, the better (narvis-scan: against the classical splat; "
        "clvis.post.guard; default: the network's own, PostNetwork.guard)",
    )
    r.add_argument(
        "--post-scale",
        type=_post_scale,
        default=None,
        metavar="N|auto",
        help="with --post: render the network's frame N times smaller and resize its picture up to the "
        "view; auto (the default): narvis-scan's frame is made smaller where the points' median splat "
        "radius is over its training frames' (a sparse cloud: the network draws wide Gaussians as "
        "squares), said on stderr; 1 everywhere else",
    )
    r.add_argument(
        "--compare",
        action="store_true",
        help="with --post narvis: also render the Gaussian renderer's image of the view (gaussians.png) "
        "and score the network and the plain rasterization against it (PSNR, SSIM, time)",
    )
    add_output_options(r, "clvis-render", "empty pixels")
    add_orbit_options(r)
    add_cluster_options(r)
    return r
