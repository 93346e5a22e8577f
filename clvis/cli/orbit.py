"""--orbit N [--movie FILE]: a turntable of the data, shared by `clvis render`,
`clvis iso` and `clvis gauss`. The command's own view (--view, --eye, ...)
is the first frame; each next one turns the camera by 360/N degrees about the
vertical axis (z, or --up) through the centre of the data's bounds. The whole
turn is fitted, not its first view: the camera steps back along its line of
sight (an orthographic one widens) as far as every frame needs to hold the
data's box, the same distance in all of them (unless --eye placed it). The frames
are PNGs written as they are made (each file complete or absent, a Ctrl-C
leaves the ones done; once all are, the frames past N an earlier, longer
turntable left in the folder are removed, and that said), the progress shown
as for other long work; with
--movie they are also encoded into a video by imageio's ffmpeg plugin (the
`movie` extra: imageio, imageio-ffmpeg)."""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import re
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from ..camera import AXIS_VIEWS, FIT_MARGIN, Camera, box_corners
from ._common import CliError, Progress, _replaced, camera_from_args, count, unwritable, world_camera_args

MAX_FRAMES = 3600
MOVIE_FORMATS = (".mp4", ".mkv", ".mov", ".webm")
MOVIE_EXTRA = "pip install '.[movie]' (imageio and imageio-ffmpeg)"


def add_orbit_options(parser: argparse.ArgumentParser) -> None:
    """--orbit N, --movie FILE and --fps: the turntable options."""
    g = parser.add_argument_group("turntable")
    g.add_argument(
        "--orbit",
        type=count(2, MAX_FRAMES),
        default=None,
        metavar="N",
        help="also render N frames around the data (360/N degrees apart about the vertical "
        "axis through its centre, the view given being the first, from as far back as keeps the "
        "data in every frame unless --eye is given) as orbit-0000.png ... in --out",
    )
    g.add_argument(
        "--movie",
        default=None,
        metavar="FILE",
        help=f"with --orbit: also encode the frames as a video ({', '.join(MOVIE_FORMATS)}; "
        f"needs the movie extra: {MOVIE_EXTRA})",
    )
    g.add_argument("--fps", type=count(1, 240), default=30, help="with --movie: frames a second (default 30)")


def check_orbit_args(args: argparse.Namespace) -> None:
    """The turntable options that cannot work, before any rendering: --movie
    without --orbit, an unknown video format, a folder it cannot be written
    in, an encoder not installed."""
    if getattr(args, "orbit", None) is None:
        if args.movie is not None:
            raise CliError("--movie encodes the --orbit frames; add --orbit N")
        if args.fps != 30:
            raise CliError("--fps is the --movie's frame rate; add --orbit N --movie FILE")
        return
    if args.movie is None:
        if args.fps != 30:
            raise CliError("--fps is the --movie's frame rate; add --movie FILE")
        return
    movie = Path(args.movie)
    if movie.suffix.lower() not in MOVIE_FORMATS:
        raise CliError(f"--movie {args.movie}: expected a video file name ending {', '.join(MOVIE_FORMATS)}")
    if movie.is_dir():
        raise CliError(f"--movie {args.movie}: is a folder, not a video file name")
    why = unwritable(movie.parent)  # found now, not after every frame is rendered
    if why is not None:
        raise CliError(f"--movie {args.movie}: {why}")
    encoder()


def encoder() -> Any:
    """imageio (its v2 API) with the ffmpeg plugin's binary; CliError naming
    the extra when either is missing."""
    try:
        import imageio.v2 as iio
        import imageio_ffmpeg
    except ImportError as e:
        raise CliError(f"--movie needs the movie extra ({e.name or e} is missing): {MOVIE_EXTRA}") from None
    try:
        imageio_ffmpeg.get_ffmpeg_exe()
    except RuntimeError as e:
        raise CliError(f"--movie: imageio-ffmpeg finds no ffmpeg binary ({e}): {MOVIE_EXTRA}") from None
    return iio


def turn(camera: Any, lo: npt.ArrayLike, hi: npt.ArrayLike, degrees: float, args: argparse.Namespace) -> Any:
    """`camera` turned by `degrees` about the vertical axis (z, or --up)
    through the centre of the box [lo, hi]; its projection kept, near and far
    enclosing the box again (clvis.cli._common's rule for --eye); a turn by a
    whole number of circles is the camera itself."""
    return _turn(camera, lo, hi, degrees, args)


def _turn(camera: Any, lo: npt.ArrayLike, hi: npt.ArrayLike, degrees: float, args: argparse.Namespace) -> Any:
    """turn(), which the frames call (and tests watch), for whole_turn to try the frames with."""
    if degrees % 360.0 == 0.0:
        return camera
    lo_, hi_ = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    centre = 0.5 * (lo_ + hi_)
    axis = np.asarray(args.up if getattr(args, "up", None) is not None else (0.0, 0.0, 1.0), np.float64)
    axis /= np.linalg.norm(axis)
    kind = args.view[0]
    up0 = args.up if args.up is not None else (AXIS_VIEWS[kind][1] if kind in AXIS_VIEWS else (0, 0, 1))
    eye = np.asarray(camera.eye, np.float64)
    target = eye + camera.forward * max(float(np.linalg.norm(centre - eye)), 1e-12)
    rot = _rotation(axis, math.radians(degrees))
    turned = argparse.Namespace(
        eye=tuple(centre + rot @ (eye - centre)),
        target=tuple(centre + rot @ (target - centre)),
        up=tuple(rot @ np.asarray(up0, np.float64)),
    )
    p = camera.projection
    return _replaced(camera, kind, turned, lo_, hi_, float(p[1, 1] / p[0, 0]))


def whole_turn(
    camera: Any, lo: npt.ArrayLike, hi: npt.ArrayLike, n: int, args: argparse.Namespace, box: Any = None
) -> Any:
    """`camera` framing the whole turntable of `n` frames (turn() by 360 k / n
    degrees) rather than its first view: a perspective camera moved back along
    its line of sight, an orthographic one widened, as little as puts the
    corners of `box` (lo, hi; default [lo, hi], the box turned about) inside
    every frame, with Camera.fit's margin. The camera itself when every frame
    holds them already, or when --eye placed it (the user's position kept)."""
    if getattr(args, "eye", None) is not None:
        return camera
    corners = box_corners(*(box if box is not None else (lo, hi)))
    p = camera.projection
    tan_x, tan_y = 1.0 / float(p[0, 0]), 1.0 / float(p[1, 1])  # half extents at depth 1 (or in world)
    back, half = 0.0, 0.0
    for k in range(n):
        c = _turn(camera, lo, hi, 360.0 * k / n, args)
        o = corners - c.eye
        x, y, z = o @ c.view[0, :3], o @ c.view[1, :3], o @ c.forward
        if camera.orthographic:
            half = max(half, float(np.max(np.maximum(np.abs(x) * tan_y / tan_x, np.abs(y)))))
        else:  # in frame at depth z + back when |x| <= tan_x (z + back), |y| likewise
            need = FIT_MARGIN * np.maximum(np.abs(x) / tan_x, np.abs(y) / tan_y) - z
            back = max(back, float(np.max(need)), float(np.max(-z)) * (1 + 1e-6))
    up = camera.view[1, :3]
    if camera.orthographic:
        height = 2.0 * FIT_MARGIN * half
        if height <= 2.0 * tan_y:
            return camera
        target = camera.eye + camera.forward
        aspect = tan_x / tan_y
        return Camera.ortho(camera.eye, target, up, height, aspect, near=camera.near, far=camera.far)
    if back <= 0.0:
        return camera
    eye = camera.eye - back * camera.forward
    moved = argparse.Namespace(eye=tuple(eye), target=tuple(eye + camera.forward), up=tuple(up))
    return _replaced(camera, args.view[0], moved, lo, hi, tan_x / tan_y)


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues: the 3x3 rotation by `angle` radians about the unit `axis`."""
    x, y, z = axis
    k = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]], np.float64)
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * (k @ k)


class _Frames:
    """The orbit stage's name, formatted when Progress redraws its line."""

    def __init__(self, n: int) -> None:
        self.n, self.done = n, 0

    def __format__(self, spec: str) -> str:
        return format(f"orbit: frame {self.done}/{self.n}", spec)


def write_orbit(
    out: str | os.PathLike[str],
    n: int,
    frame: Callable[[int, float], np.ndarray],
    progress: Progress,
    movie: str | None = None,
    fps: int = 30,
) -> tuple[list[Path], Path | None]:
    """frame(k, degrees) for k in 0..n-1 (degrees = 360 k / n), each written as
    out/orbit-KKKK.png when made (atomically: complete or absent), then the
    movie when asked. Returns (the PNGs, the movie or None)."""
    from .. import images

    out = Path(out)
    files: list[Path] = []
    label = _Frames(n)
    try:
        with progress.stage(label):
            for k in range(n):
                files.append(images.save_png(out / f"orbit-{k:04d}.png", frame(k, 360.0 * k / n)))
                label.done = k + 1
    except BaseException as e:
        if isinstance(e, KeyboardInterrupt):
            done = f"orbit-0000.png .. {files[-1].name}" if files else "none"
            print(
                f"clvis: interrupted after {len(files)} of {n} orbit frames ({done}) in {out}",
                file=sys.stderr,
            )
        _stale_note(out, _stale_frames(out, n), "stay")  # a turntable cut short takes nothing away
        raise
    _remove_stale(out, n)
    if movie is None:
        return files, None
    with progress.stage(f"encoding {Path(movie).name}"):
        return files, encode(files, movie, fps)


def _remove_stale(out: Path, n: int) -> None:
    """The frames numbered past a turntable of `n` (an earlier, longer one's
    in the same folder, which orbit-%04d.png would take into a movie)
    removed, and said on stderr; those that cannot be removed are named."""
    stale = _stale_frames(out, n)
    kept = []
    for p in stale:
        try:
            p.unlink()
        except FileNotFoundError:
            pass
        except OSError:
            kept.append(p)
    removed = len(stale) - len(kept)
    if removed:
        s = "s" if removed != 1 else ""
        print(f"clvis: removed {removed} stale orbit frame{s} from an earlier run in {out}", file=sys.stderr)
    _stale_note(out, kept, "could not be removed and stay")


def _stale_note(out: Path, stale: Sequence[Path], what: str) -> None:
    """The warning naming the frames of an earlier, longer turntable left in `out`."""
    if stale:
        s = "s" if len(stale) != 1 else ""
        print(
            f"clvis: warning: {len(stale)} orbit frame{s} of an earlier, longer turntable {what} in "
            f"{out} ({stale[0].name} .. {stale[-1].name}); a movie of orbit-%04d.png would take them too",
            file=sys.stderr,
        )


def _stale_frames(out: Path, n: int) -> list[Path]:
    """The files out/orbit-KKKK.png with K >= n, in order (none when out is not a folder)."""
    try:
        # only the names write_orbit gives (MAX_FRAMES < 10,000: four digits), and files
        names = [
            p for p in out.glob("orbit-*.png") if re.fullmatch(r"orbit-\d{4}\.png", p.name) and p.is_file()
        ]
    except OSError:
        return []
    return sorted((p for p in names if int(p.name[6:-4]) >= n), key=lambda p: int(p.name[6:-4]))


def encode(frames: Sequence[Path], movie: str | os.PathLike[str], fps: int) -> Path:
    """The PNGs `frames` as the video `movie` (H.264 where the container takes
    it, VP9 for .webm), written to a temporary file beside it and renamed:
    the video is complete or absent. Odd sides are padded by one pixel (the
    encoders' 4:2:0 chroma needs even ones)."""
    from PIL import Image

    iio = encoder()
    path = Path(movie)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.partial{path.suffix}")
    codec = "libvpx-vp9" if path.suffix.lower() == ".webm" else "libx264"
    try:
        with iio.get_writer(
            str(tmp),
            format="FFMPEG",
            mode="I",
            fps=fps,
            codec=codec,
            macro_block_size=1,
            pixelformat="yuv420p",
        ) as w:
            for f in frames:
                with Image.open(f) as im:
                    a = np.asarray(im.convert("RGB"))
                h, wd = a.shape[:2]
                if h % 2 or wd % 2:
                    a = np.pad(a, ((0, h % 2), (0, wd % 2), (0, 0)), mode="edge")
                w.append_data(a)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
    return path


# ---------------------------------------------------------------- the commands' frames


def report(files: Sequence[Path], movie: Path | None) -> None:
    """The summary's lines on the turntable."""
    if files:
        print(f"  orbit     {len(files)} frames, {files[0].name} .. {files[-1].name}")
    if movie is not None:
        print(f"  movie     {movie}")


def iso_orbit(
    args: argparse.Namespace,
    renderer: Any,
    isovalue: float,
    out: Path,
    progress: Progress,
    base: Any = None,
    surface: tuple[npt.ArrayLike, npt.ArrayLike] | None = None,
) -> tuple[list[Path], Path | None]:
    """`clvis iso --orbit N`: the isosurface from N cameras around the volume,
    each frame as iso.png shows it (its band unless --no-labels); the first
    looks as `base`, iso.png's camera (default: the options' camera of the
    volume), from as far back as the whole turn needs to hold the box
    `surface` (lo, hi: the isosurface's; default the volume's)."""
    from .iso import labelled

    w, h = args.size
    origin = np.asarray(renderer.origin, np.float64)
    lo = origin
    hi = origin + (np.array(renderer.shape[::-1]) - 1) * np.asarray(renderer.spacing, np.float64)[::-1]
    if base is None:
        base = camera_from_args(args, lo, hi, w, h)
    base = whole_turn(base, lo, hi, args.orbit, args, surface)

    def frame(k: int, degrees: float) -> np.ndarray:
        img = renderer.render(
            turn(base, lo, hi, degrees, args),
            w,
            h,
            isovalue,
            completion=args.completion,
            speculation=not args.no_speculation,
        )
        return labelled(img, isovalue, args.transparent, bare=args.no_labels)

    return write_orbit(out, args.orbit, frame, progress, args.movie, args.fps)


def gauss_orbit(
    args: argparse.Namespace,
    lods: Sequence[str],
    sv: Any,
    gaussians: Any,
    queue: Any,
    opacity: Any,
    out: Path,
    progress: Progress,
    value_range: tuple[float, float] | None = None,
) -> tuple[list[Path], Path | None]:
    """`clvis gauss --orbit N`: the LOD panels side by side (gauss.png's
    layout) from N cameras around the Gaussians (each holding their whole
    box: whole_turn), through the transfer function gauss.png used (its
    opacity points and value range)."""
    from .. import images
    from .gauss import _picture, bar_title, render_panels, strip

    w, h = args.size
    cameras: dict[bytes, Any] = {}  # a LOD's bounds -> its whole turn's camera, fitted once

    def fitted(lo: npt.ArrayLike, hi: npt.ArrayLike) -> Any:
        key = np.asarray([lo, hi], np.float64).tobytes()
        if key not in cameras:
            local = world_camera_args(args, getattr(args, "camera_origin", None))
            cam = camera_from_args(local, lo, hi, w, h)
            cameras[key] = whole_turn(cam, lo, hi, args.orbit, args)
        return cameras[key]

    def frame(k: int, degrees: float) -> np.ndarray:
        panels = render_panels(
            lods,
            sv,
            gaussians,
            w,
            h,
            model=args.model,
            density=args.density,
            colormap=args.colormap,
            k=args.k,
            method=args.method,
            queue=queue,
            opacity=opacity,
            value_range=value_range,
            frame=getattr(args, "frame", None),
            density_scale=getattr(args, "density_scale", 1.0),
            camera=lambda lo, hi: turn(fitted(lo, hi), lo, hi, degrees, args),
        )
        if args.no_labels:
            return images.compose([_picture(img, args.transparent) for _, _, img in panels])
        return strip(
            panels,
            args.colormap,
            args.transparent,
            bar_title(args),
            value_range,
            getattr(args, "value_offset", 0.0),
        )

    return write_orbit(out, args.orbit, frame, progress, args.movie, args.fps)


def render_orbit(
    args: argparse.Namespace,
    camera: Any,
    lo: npt.ArrayLike,
    hi: npt.ArrayLike,
    draw: Callable[[Any], np.ndarray],
    out: Path,
    progress: Progress,
) -> tuple[list[Path], Path | None]:
    """`clvis render --orbit N`: draw(camera) (the first panel as its PNG
    shows it) from N cameras around the cloud's bounds [lo, hi], each
    holding the whole box (whole_turn)."""
    camera = whole_turn(camera, lo, hi, args.orbit, args)

    def frame(k: int, degrees: float) -> np.ndarray:
        return draw(turn(camera, lo, hi, degrees, args))

    return write_orbit(out, args.orbit, frame, progress, args.movie, args.fps)
