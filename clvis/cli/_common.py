"""What every clvis command shares: the argument types (image size, counts),
the one error class a command reports, the wrapper that turns errors into
one line on stderr and exit status 2, and the progress display."""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import itertools
import math
import os
import re
import shutil
import sys
import threading
import time
from collections.abc import Iterator

import numpy as np

from ..camera import (
    AXIS_VIEWS,
    Camera,
    axis_camera,
    box_corners,
    fit_camera,
    grid_cameras,
    hemisphere_cameras,
    min_extent,
)
from ..errors import ClvisError
from ..limits import RASTER

# The one image-size rule of every command: each side in 1..MAX_SIDE, the
# rasterizer's limit (the smallest any renderer has). W * H then stays below
# 2^31, so the kernels' 32-bit pixel indices never overflow.
MAX_SIDE = RASTER.max_side
MAX_PIXELS = RASTER.max_pixels
SIZE_RULE = f"each side 1..{MAX_SIDE}, so W*H < 2^31"


class CliError(Exception):
    """A problem a command reports as one line on stderr, with exit status 2."""


class Parser(argparse.ArgumentParser):
    """A sub-command's parser: a bad argument is one line, without the usage text."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def glue_values(parser: argparse.ArgumentParser, argv: list[str]) -> list[str]:
    """argv with `--opt VALUE` written `--opt=VALUE` where VALUE starts with a
    dash: argparse takes `-5x5` or `-1,2,3` for an option of its own, not for
    the value of the option before it."""
    takes_value = {
        s for a in parser._actions if a.option_strings and a.nargs is None for s in a.option_strings
    }
    known = set(parser._option_string_actions)
    out, i = [], 0
    while i < len(argv):
        tok = argv[i]
        if tok == "--":
            out += argv[i:]
            break
        nxt = argv[i + 1] if i + 1 < len(argv) else None
        if (
            tok in takes_value
            and nxt is not None
            and nxt.startswith("-")
            and nxt != "--"
            and nxt.split("=", 1)[0] not in known
        ):
            out.append(f"{tok}={nxt}")
            i += 2
            continue
        out.append(tok)
        i += 1
    return out


# ---------------------------------------------------------------- argument types


def size(text: str) -> tuple[int, int]:
    """'WxH' -> (W, H), each side in 1..MAX_SIDE (so W * H <= MAX_PIXELS)."""
    m = re.fullmatch(r"\s*([+-]?\d+)\s*[xX×]\s*([+-]?\d+)\s*", text)
    if not m:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT such as 1920x1080, got {text!r}")
    w, h = int(m.group(1)), int(m.group(2))
    if not (1 <= w <= MAX_SIDE and 1 <= h <= MAX_SIDE) or w * h > MAX_PIXELS:
        raise argparse.ArgumentTypeError(f"width and height must lie in 1..{MAX_SIDE}, got {text!r}")
    return w, h


def _integer(text: str) -> int | None:
    """'2000000', '2_000_000', '2,000,000' or '2e6' -> 2000000; None if not a whole number."""
    t = text.strip().replace("_", "").replace(",", "")
    try:
        return int(t)
    except ValueError:
        pass
    try:
        f = float(t)
    except ValueError:
        return None
    return int(f) if math.isfinite(f) and f == int(f) else None


def positive_int(text: str) -> int:
    n = _integer(text)
    if n is None or n < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return n


def count(lo: int, hi: int):
    """An argument type: a whole number in lo..hi."""

    def parse(text: str) -> int:
        n = _integer(text)
        if n is None or not lo <= n <= hi:
            what = "a positive integer" if lo == 1 else "an integer"
            raise argparse.ArgumentTypeError(f"expected {what} in {lo:,}..{hi:,}, got {text!r}")
        return n

    parse.__name__ = "count"  # argparse names the type in some messages
    return parse


def real(lo: float = -math.inf, hi: float = math.inf, *, open_lo: bool = False, what: str = "a number"):
    """An argument type: a finite float in [lo, hi] (or (lo, hi] with open_lo)."""

    def parse(text: str) -> float:
        try:
            f = float(text)
        except ValueError:
            f = math.nan
        if not (math.isfinite(f) and (f > lo if open_lo else f >= lo) and f <= hi):
            rng = (
                ""
                if lo == -math.inf and hi == math.inf
                else f" > {lo:g}"
                if hi == math.inf and open_lo
                else f" >= {lo:g}"
                if hi == math.inf
                else f" in {'(' if open_lo else '['}{lo:g}, {hi:g}]"
            )
            raise argparse.ArgumentTypeError(f"expected {what}{rng} (finite), got {text!r}")
        return f

    parse.__name__ = "real"
    return parse


def colormap_name(text: str) -> str:
    """A matplotlib colormap name; an unknown one gets the closest names."""
    import difflib

    from .. import colormap

    known = colormap.names()
    if text in known:
        return text
    close = difflib.get_close_matches(text, known, n=5) or difflib.get_close_matches(
        text.lower(), [k.lower() for k in known], n=5, cutoff=0.5
    )
    common = [k for k in ("viridis", "magma", "inferno", "plasma", "cividis", "gray") if k in known]
    hint = f"closest: {', '.join(close)}" if close else f"some valid names: {', '.join(common)}"

    raise argparse.ArgumentTypeError(
        f"unknown colormap {text!r}; {hint} ({len(known)} names in all: matplotlib's colormaps, _r reversed)"
    )


# ---------------------------------------------------------------- running a command


def run(name: str, fn, args) -> int:
    """fn(args), with the errors a user can cause as one line on stderr and
    exit status 2: CliError, clvis's own errors (a file clvis cannot read, a
    device too small), a bad value a library call rejects (ValueError,
    TypeError), OSError (an unreadable file, an unwritable folder), a
    missing optional package and running out of memory. CLVIS_DEBUG=1 lets
    them through, traceback and all."""
    try:
        return fn(args)
    except BrokenPipeError:
        raise  # main's: the reader went away, not an error of ours
    except (CliError, ClvisError, ValueError, TypeError, ImportError, OSError, MemoryError) as e:
        if os.environ.get("CLVIS_DEBUG", "") not in ("", "0"):
            raise
        msg = _one_line(e)
    print(f"clvis {name}: error: {msg}", file=sys.stderr)
    return 2


def _one_line(e: BaseException) -> str:
    if isinstance(e, MemoryError):
        return f"out of host memory{': ' + str(e) if str(e) else ''}"
    if isinstance(e, OSError) and e.filename and e.strerror:
        return f"{e.filename}: {e.strerror}"
    lines = str(e).strip().splitlines() or [type(e).__name__]
    more = " [more with CLVIS_DEBUG=1]" if len(lines) > 1 else ""
    return lines[0] + more


def timed(fn, queue=None, repeat=3) -> float:
    """Best of `repeat` timed runs after one warm-up (which builds the
    kernels); a single timed run when that one takes over half a second."""

    def once():
        t0 = time.perf_counter()
        fn()
        if queue is not None:
            queue.finish()
        return time.perf_counter() - t0

    once()
    best = once()
    if best > 0.5:
        return best
    for _ in range(repeat - 1):
        best = min(best, once())
    return best


# ---------------------------------------------------------------- progress


def add_output_options(parser: argparse.ArgumentParser, out: str, empty: str) -> None:
    """--out, --transparent, --progress and --quiet: where the PNGs go and what is
    shown on the way, alike for every command that renders. `empty` names
    what --transparent leaves clear."""
    parser.add_argument(
        "-o", "--out", type=out_dir, default=out, metavar="DIR", help=f"folder for the PNGs (default ./{out})"
    )
    parser.add_argument(
        "--transparent",
        action="store_true",
        help=f"leave {empty} transparent (default: over a dark grey; label bands stay opaque)",
    )
    parser.add_argument(
        "--progress",
        action="store_true",
        help="show the progress on stderr even when it is not a terminal",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress display")
    parser.add_argument(
        "--no-labels",
        action="store_true",
        help="write each image alone, exactly --size, without its title, colour bar or legend "
        "(the side-by-side PNG keeps them)",
    )


def unwritable(folder: os.PathLike[str] | str) -> str | None:
    """Why no file can be made in `folder` (or, where it does not exist yet,
    in the nearest folder above it that does, where it would be made), or
    None: a temporary file is made there and removed, so a read-only folder
    is found before the work, not when its first output is written."""
    import tempfile
    from pathlib import Path

    p = Path(folder)
    q = next((q for q in (p, *p.parents) if q.exists()), Path("."))
    try:
        fd, name = tempfile.mkstemp(prefix=".clvis-probe-", dir=q)
    except OSError as e:
        return f"no file can be made in {q} ({e.strerror or e})"
    os.close(fd)
    with contextlib.suppress(OSError):
        os.unlink(name)
    return None


def clear_targets(out: os.PathLike[str] | str, names) -> None:
    """CliError when something other than a file (a folder, say) sits where
    one of the files `names` would be written in `out`: checked for all of
    them before the first is written, so the outputs appear all or none."""
    from pathlib import Path

    for name in names:
        p = Path(out) / name
        if p.exists() and not p.is_file():
            raise CliError(f"{p}: not a file (a folder is in the way); move it or choose another --out")


def note_earlier_pngs(prog: str, out: os.PathLike[str] | str, written, pattern) -> None:
    """A note naming the PNGs an earlier run of the command left in `out`
    (file names `pattern`, a compiled regex, fully matches) that this one did
    not write (`written`: names): beside the fresh ones they read as this
    run's (clvis render's post-lidar.png, clvis gauss's high.png after
    --lod low). They are kept: the user's to remove."""
    from pathlib import Path

    try:
        earlier = sorted(
            p.name
            for p in Path(out).iterdir()
            if pattern.fullmatch(p.name) and p.name not in written and p.is_file()
        )
    except OSError:
        return
    if earlier:
        print(
            f"{prog}: note: {out} also holds {', '.join(earlier)} from an earlier run, not this one's",
            file=sys.stderr,
        )


def folder(text: str) -> str:
    """A folder option's value, refused when empty (an unset $OUTDIR would
    otherwise put the outputs in the current folder unnoticed)."""
    if not text.strip():
        raise argparse.ArgumentTypeError(
            f"expected a folder, got {text!r} (an unset variable?); give . for the current folder"
        )
    return text


def out_dir(text: str) -> str:
    """--out: a folder (made when missing); an empty name, a file of that
    name, or below one, or a folder no file can be made in, is an error
    before any work starts."""
    from pathlib import Path

    p = Path(folder(text))
    for q in (p, *p.parents):
        if q.exists():
            if not q.is_dir():
                what = "is a file" if q == p else f"lies below the file {q}"
                raise argparse.ArgumentTypeError(
                    f"{text} {what}, not a folder (--out names the folder for the PNGs)"
                )
            break
    why = unwritable(p)
    if why is not None:
        raise argparse.ArgumentTypeError(f"{text}: {why}")
    if p.suffix.lower() in (".png", ".jpg", ".jpeg", ".tif", ".tiff") and not p.is_dir():
        raise argparse.ArgumentTypeError(
            f"{text} names an image, but --out/-o is the folder for the PNGs (a command writes "
            f"several, and overview.png): give a folder, e.g. -o {p.parent / p.stem}"
        )
    return text


def progress_from_args(args: argparse.Namespace, prefix: str) -> Progress:
    """The progress display --progress / --quiet ask for (by default: on a terminal only)."""
    return Progress(not args.quiet and (args.progress or isatty(sys.stderr)), prefix)


class Progress:
    """Stage names and their elapsed times on stderr.

    On a terminal the running stage's line is rewritten in place a few times
    a second; elsewhere (a log, --progress into a pipe) each stage prints one
    line when it ends. Disabled, it prints nothing.
    """

    def __init__(self, enabled: bool, prefix: str = "clvis render"):
        self.enabled = enabled
        self.stream = sys.stderr
        self.tty = enabled and isatty(self.stream)
        self.prefix = prefix
        self.start = time.perf_counter()

    def _line(self, name: object, since: float, failed: bool = False) -> str:
        now = time.perf_counter()
        tail = "failed" if failed else f"(total {now - self.start:6.2f} s)"
        line = f"{self.prefix}: {name:<36} {now - since:6.2f} s  {tail}"
        if self.tty:  # one terminal row, or \r cannot rewrite it
            line = line[: shutil.get_terminal_size().columns - 1]
        return line

    def _write(self, text: str):
        self.stream.write(text)
        self.stream.flush()

    @contextlib.contextmanager
    def stage(self, name: object) -> Iterator[None]:
        """Time the block as a stage called `name` (formatted at each redraw:
        an object whose __format__ changes shows progress within the stage)."""
        if not self.enabled:
            yield
            return
        t0 = time.perf_counter()
        stop = threading.Event()
        ticker = None
        if self.tty:

            def tick():
                while not stop.wait(0.2):
                    self._write("\r\x1b[K" + self._line(name, t0))

            self._write("\r\x1b[K" + self._line(name, t0))
            ticker = threading.Thread(target=tick, daemon=True)
            ticker.start()
        failed = True
        try:
            yield
            failed = False
        finally:
            stop.set()
            if ticker is not None:
                ticker.join()
            self._write(("\r\x1b[K" if self.tty else "") + self._line(name, t0, failed) + "\n")


def isatty(stream) -> bool:
    try:
        return stream.isatty()
    except (AttributeError, ValueError):
        return False


# ---------------------------------------------------------------- camera options


@dataclasses.dataclass(frozen=True)
class FitView:
    """A command's default view: --view fit looks along `direction` (from the
    eye towards the centre, z up) with a vertical field of view of `fov_y`."""

    direction: tuple[float, float, float]
    fov_y: float


# --view fit of a point cloud, in clvis render and clvis gauss alike (one file,
# one default view): from the south-south-west, about 40 degrees above the
# horizon, z up; fit then moves the eye until the points fill the frame
POINTS_FIT = FitView(direction=(0.45, 1.0, -0.9), fov_y=60.0)

SAMPLER_CAMERAS = {"hemisphere": 128, "grid": 384}  # grid_cameras with count=4

VIEWS_HELP = """\
views (--view):
  fit           the whole scene from an oblique direction, perspective (default)
  top           orthographic, looking down, north (+y) up
  front, side   orthographic, looking along +y / along -x, z up
                (a NIfTI, MGH or Analyze scan, RAS+: front looks along -y,
                at the face, and fit from the front too)
  hemisphere:K  the K-th of the 128 NARVis hemisphere cameras (K = 0..127)
  grid:K        the K-th of the 384 NARVis grid cameras, a 4 x 4 grid (K = 0..383)
--eye, --target and --up replace that part of the view's camera (the target
then defaults to the centre of the scene's bounds when --eye is given, and up
to +z, +y for top or a view straight down); --fov sets the field of view of a
perspective view.
"""


def view(text: str) -> tuple[str, int]:
    """'fit' | 'top' | 'front' | 'side' | 'hemisphere:K' | 'grid:K' -> (kind, K)."""
    kind, sep, k = text.strip().lower().partition(":")
    if not sep and kind in ("fit", *AXIS_VIEWS):
        return kind, 0
    if sep and kind in SAMPLER_CAMERAS:
        count = SAMPLER_CAMERAS[kind]
        if k.strip().isdigit() and int(k) < count:
            return kind, int(k)
        raise argparse.ArgumentTypeError(f"{kind}:K needs K in 0..{count - 1}, got {text!r}")
    raise argparse.ArgumentTypeError(f"expected fit, top, front, side, hemisphere:K or grid:K, got {text!r}")


def vec3(text: str) -> tuple[float, float, float]:
    """'X,Y,Z' -> three finite floats."""
    parts = text.replace(" ", "").split(",")
    try:
        v = tuple(float(p) for p in parts)
    except ValueError:
        v = ()
    if len(v) != 3 or not all(math.isfinite(x) for x in v):
        raise argparse.ArgumentTypeError(
            f"expected three finite numbers X,Y,Z such as 1,-2.5,3, got {text!r}"
        )
    return v


def direction(text: str) -> tuple[float, float, float]:
    v = vec3(text)
    if not any(v):
        raise argparse.ArgumentTypeError(f"expected a non-zero direction, got {text!r}")
    return v


def fov(text: str) -> float:
    try:
        f = float(text)
    except ValueError:
        f = math.nan
    if not (math.isfinite(f) and 0 < f < 180):
        raise argparse.ArgumentTypeError(
            f"expected a field of view in degrees, between 0 and 180, got {text!r}"
        )
    return f


def add_camera_options(parser: argparse.ArgumentParser, fit: FitView, fov_note: str = ""):
    """--view, --eye, --target, --up and --fov; `fit` is the command's default
    view (`fov_note`: what --fov's help adds to its default)."""
    g = parser.add_argument_group("camera", "the view (see above), and parts of it replaced")
    g.add_argument(
        "--view",
        type=view,
        default=("fit", 0),
        help="fit, top, front, side, hemisphere:K or grid:K (default fit)",
    )
    g.add_argument("--eye", type=vec3, metavar="X,Y,Z", help="the camera position, in world units")
    g.add_argument(
        "--target",
        type=vec3,
        metavar="X,Y,Z",
        help="the point looked at (default: the view's; the centre with --eye)",
    )
    g.add_argument("--up", type=direction, metavar="X,Y,Z", help="the up direction (default: the view's)")
    g.add_argument(
        "--fov",
        type=fov,
        metavar="DEG",
        help=f"vertical field of view of a perspective view (default {fit.fov_y:g}{fov_note})",
    )
    parser.set_defaults(fit_view=fit)


def check_camera_args(args):
    """The camera options that contradict each other, before any work."""
    kind, _ = args.view
    if args.fov is not None and kind in AXIS_VIEWS:
        raise CliError(f"--fov: the {kind} view is orthographic; leave --fov out or use a perspective view")
    if args.eye is not None and args.target is not None and args.eye == args.target:
        raise CliError("--eye and --target are the same point")


def describe_camera(args) -> str:
    """The view as given on the command line: 'fit', 'grid:7', 'fit, eye 1,2,3'."""
    kind, k = args.view
    text = f"{kind}:{k}" if kind in SAMPLER_CAMERAS else kind
    for name in ("eye", "target", "up"):
        v = getattr(args, name)
        if v is not None:
            text += f", {name} {','.join(f'{x:g}' for x in v)}"
    if args.fov is not None:
        text += f", fov {args.fov:g}"
    return text


def fit_box(lo, hi, width: int, height: int, fit: FitView):
    """The default view (--view fit, no overrides) of the box [lo, hi]: what the
    commands use when no options are given, and the demo too."""
    return fit_camera(
        box_corners(lo, hi), lo, hi, direction=fit.direction, fov_y=fit.fov_y, aspect=width / height
    )


def world_camera_args(args, origin):
    """args with --eye and --target (given in the file's coordinates) moved
    into a point cloud's local ones (`origin`: a clvis.PointCloud's origin): the
    origin is an internal detail that keeps float32 positions precise, never
    something a user types (clvis view's camera text is in the file's)."""
    if origin is None or not np.asarray(origin).any() or (args.eye is None and args.target is None):
        return args
    local = argparse.Namespace(**vars(args))
    for name in ("eye", "target"):
        v = getattr(args, name)
        if v is not None:
            setattr(local, name, tuple(float(a - b) for a, b in zip(v, origin, strict=True)))
    return local


def camera_from_args(args, lo, hi, width: int, height: int, points=None):
    """The camera the options ask for, framing the box [lo, hi] (for --view
    fit, the `points` themselves when given, else the box's corners)."""
    kind, k = args.view
    aspect = width / height
    fit = args.fit_view
    fov_y = args.fov if args.fov is not None else fit.fov_y
    try:
        if kind == "fit":
            if points is None:  # the box's corners: framed tighter than its bounding sphere
                points = box_corners(lo, hi)
            cam = fit_camera(points, lo, hi, direction=fit.direction, fov_y=fov_y, aspect=aspect)
        elif kind in AXIS_VIEWS:
            cam = axis_camera(kind, lo, hi, aspect, anatomical=getattr(args, "anatomical", False))
        else:
            sampler = hemisphere_cameras if kind == "hemisphere" else grid_cameras
            sampled = next(itertools.islice(sampler(lo, hi, fov_y=fov_y, aspect=aspect), k, None), None)
            if sampled is None:
                raise CliError(f"--view {kind}:{k}: the sampler has fewer than {k + 1} cameras")
            cam = sampled
        if args.eye is None and args.target is None and args.up is None:
            return cam
        return _replaced(cam, kind, args, lo, hi, aspect)
    except ValueError as e:  # Camera's own checks: an up along the view, ...
        raise CliError(camera_error(e)) from None


def camera_error(e: BaseException) -> str:
    """A camera check's message for a command line user: one 'camera:' prefix
    (the library's own message may carry one already) and the options to change,
    not the library calls that make a camera (those are the API's advice)."""
    text = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
    while text.lower().startswith("camera:"):
        text = text[len("camera:") :].strip()
    text = text.split("; make cameras with", 1)[0]
    return f"camera: {text} (check --eye, --target, --up and --fov)"


def _replaced(cam, kind, args, lo, hi, aspect: float):
    """`cam` with the eye, target and up of the options, near and far
    enclosing the box, the projection (and field of view) kept."""
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    centre = 0.5 * (lo + hi)
    eye = np.asarray(args.eye if args.eye is not None else cam.eye, np.float64)
    if args.target is not None:
        target = np.asarray(args.target, np.float64)
    elif args.eye is not None:
        target = centre
    else:  # the view's own line of sight
        target = cam.eye + cam.forward * max(float(np.linalg.norm(centre - cam.eye)), 1.0)
    up = args.up if args.up is not None else (AXIS_VIEWS[kind][1] if kind in AXIS_VIEWS else (0, 0, 1))
    if np.array_equal(eye, target):
        raise CliError("--eye: the camera would sit on its target; give a --target too")
    forward = (target - eye) / np.linalg.norm(target - eye)
    if args.up is None and np.linalg.norm(np.cross(forward, np.asarray(up, np.float64))) < 1e-3:
        # straight down (or up) the default up: north (+y) up, as --view top (it was an error
        # naming --up, which the user had not given)
        up = (0.0, 1.0, 0.0)
    corners = box_corners(lo, hi)
    depths = (corners - eye) @ forward
    scale = max(
        float(np.linalg.norm(hi - lo)), min_extent(lo, hi), float(np.linalg.norm(target - eye)) * 1e-3
    )
    if cam.orthographic:
        return Camera.ortho(
            eye,
            target,
            up,
            height=2.0 / cam.projection[1, 1],
            aspect=aspect,
            near=float(depths.min()) - 0.1 * scale,
            far=float(depths.max()) + 0.1 * scale,
        )
    fov_y = math.degrees(2 * math.atan(1.0 / cam.projection[1, 1]))
    far = max(1.01 * float(depths.max()), 0.0) + 1e-3 * scale
    near = max(0.5 * float(depths.min()), 1e-4 * scale, 1e-6 * far)
    return Camera.look_at(eye, target, up, fov_y, aspect, near=near, far=max(far, 2 * near))


# --------------------------------------------------------------------------
# volumes: the same file options for iso and gauss


def spacing_xyz(text: str) -> tuple[float, float, float]:
    """'DX,DY,DZ' -> three finite positive floats (x, y, z order)."""
    v = vec3(text)
    if not all(x > 0 for x in v):
        raise argparse.ArgumentTypeError(f"expected three positive sample spacings DX,DY,DZ, got {text!r}")
    return v


def raw_shape(text: str) -> tuple[int, int, int]:
    """'XxYxZ' (the Open SciVis order) -> (Z, Y, X)."""
    parts = text.lower().replace(",", "x").split("x")
    try:
        xyz = tuple(int(p) for p in parts)
    except ValueError:
        xyz = ()
    if len(xyz) != 3 or not all(0 < n <= 2**31 for n in xyz):
        raise argparse.ArgumentTypeError(
            f"expected XxYxZ with positive sides, such as 256x256x128, got {text!r}"
        )
    return xyz[2], xyz[1], xyz[0]


def add_volume_index(parser, flag: str, what: str) -> None:
    """A volume-index option `flag` (T: 0 first) on `parser` (or a group)."""
    parser.add_argument(flag, type=count(0, 2**31 - 1), default=None, metavar="T", help=f"{what} (0 first)")


def add_volume_options(parser: argparse.ArgumentParser) -> None:
    """--spacing, --shape, --dtype, --volume-index and --array: how to read a volume FILE."""
    from ..io.volumes import RAW_TYPES

    g = parser.add_argument_group("volume files")
    g.add_argument(
        "--spacing",
        type=spacing_xyz,
        default=None,
        metavar="DX,DY,DZ",
        help="sample spacing along x, y, z (default: the file's: NIfTI and VDB carry "
        "their own, raw and .npy files 1,1,1)",
    )
    g.add_argument(
        "--shape",
        type=raw_shape,
        default=None,
        metavar="XxYxZ",
        help="samples along x, y, z of a .raw file whose name does not say",
    )
    g.add_argument(
        "--dtype",
        choices=sorted(RAW_TYPES),
        default=None,
        help="sample type of a .raw file whose name does not say",
    )
    add_volume_index(g, "--volume-index", "the volume of a 4-D NIfTI, MGH or Analyze time series to read")
    g.add_argument(
        "--array",
        default=None,
        metavar="NAME",
        help="the data array of a .vti, .vtr or legacy .vtk file to read (default: its point "
        "scalars, else its first point array, else its first cell array; the summary names it)",
    )


def grid_arg(text: str) -> str | int:
    """The --grid argument type (a .vdb's grid): its name, or digits for its index."""
    if not text:
        raise argparse.ArgumentTypeError("expected a grid name or index, got ''")
    return int(text) if text.isdigit() else text


def read_volume_file(args, path):
    """(samples as float32, spacing, origin) of `path` with the volume
    options applied (spacing replaced); see :func:`read_volume_of`."""
    v = read_volume_of(args, path)
    return np.asarray(v.data, np.float32), v.spacing, v.origin


def read_volume_of(args, path):
    """The Volume of `path` with the volume options applied (--spacing
    replaces the file's; --array picks a VTK file's array). CliError for
    options that do not fit the file."""
    import dataclasses

    from ..io.volumes import read_volume

    name = str(path).lower()
    raw = name.endswith(".raw")
    if not raw and (args.shape is not None or args.dtype is not None):
        raise CliError(f"--shape and --dtype are for .raw files, not {path}")
    array = getattr(args, "array", None)
    if array is not None and not name.endswith((".vti", ".vtr", ".vtk")):
        raise CliError(f"--array picks a data array of a VTK file (.vti, .vtr, .vtk), not {path}")
    v = read_volume(
        path,
        shape=args.shape if raw else None,
        dtype=args.dtype if raw else None,
        volume_index=args.volume_index,
        array=array,
    )
    spacing = v.spacing if args.spacing is None else tuple(reversed(args.spacing))
    if v.affine is not None:
        face_the_scan(args)
    return dataclasses.replace(v, spacing=tuple(float(s) for s in spacing))


def face_the_scan(args) -> None:
    """Views of a scan read in RAS+ order (a NIfTI, MGH or Analyze file: +y
    anterior): the default view's direction with its y reversed, and --view
    front along -y, so both look at the face (they saw the back of the head);
    set on `args` (args.fit_view, args.anatomical) once the file is read."""
    fit = getattr(args, "fit_view", None)
    if not getattr(args, "anatomical", False):
        if fit is not None:  # (clvis view has no --view: its Orbit turns, VolumeScene's anatomical)
            d = fit.direction
            args.fit_view = FitView(direction=(d[0], -d[1], d[2]), fov_y=fit.fov_y)
        args.anatomical = True


def check_iso_volume(data: np.ndarray, source: str, prog: str) -> np.ndarray:
    """The volume the isosurface renderer is given; what was changed in it
    is said on stderr (`prog`: the command's name, `source` the file). A
    CliError naming `source`, the count and the first sample when the
    volume holds an infinite sample: the renderer compresses it with ZFP's
    fixed-rate mode, which cannot keep them (the library's message named
    no file); and when an axis has a single
    sample (a slice: no surface to find between samples). NaN samples (a
    masked scan's outside: SPM and nilearn write them) are drawn as empty:
    set, in a copy, to a value below every finite sample, so that every
    isovalue of the data's range finds them outside and the surface closes
    where the mask cuts it (they were refused: such a scan could not be
    drawn); `data` itself is returned where it holds no NaN."""
    if data.ndim == 3 and min(data.shape) < 2:
        raise CliError(
            f"{source}: shape {tuple(data.shape)} (z, y, x): an isosurface lies between samples, so it "
            "needs 2 or more along every axis (clvis gauss draws a single slice)"
        )
    bad = ~np.isfinite(data)
    if not bad.any():
        return data
    nan = np.isnan(data)
    if not (bad & ~nan).any():  # NaN only: a mask's outside
        lo, hi = finite_range(data, source)
        # just below the lowest sample, by a thousandth of the range: ZFP's fixed-rate
        # blocks along the mask's edge keep the data's own range (a whole range below,
        # they held twice it and drew the surface there in blocks)
        fill = np.float32(lo - 1e-3 * (hi - lo))
        if not fill < np.float32(lo):  # a range of 0, or too small for float32 to step by
            fill = np.nextafter(np.float32(lo), np.float32(-np.inf))
        if np.isfinite(fill):  # (-inf: the lowest float32, nothing below it: refused as before)
            print(
                f"{prog}: {source}: {int(nan.sum()):,} NaN samples (a mask's outside) drawn as empty: "
                f"set to {float(fill):.6g}, below every sample",
                file=sys.stderr,
            )
            return np.where(nan, fill, data).astype(np.float32, copy=False)
    first = np.unravel_index(int(np.argmax(bad)), data.shape)  # no list of every bad sample
    where = ", ".join(str(int(i)) for i in first)
    raise CliError(
        f"{source}: {int(bad.sum()):,} NaN or infinite samples, the first at [z, y, x] = ({where}): "
        f"{data[first]} (isosurfaces are rendered from ZFP's fixed-rate compression, which cannot "
        "keep them)"
    )


# host bytes a point of an embedded cloud takes at the peak of making it
# (clvis.datasets' temporaries; peak RSS over 0.25M-2M points, rounded up:
# ~190 hurricane, ~120 terrain), what clvis render then adds is less
EMBEDDED_BYTES_PER_POINT = {"hurricane": 200, "terrain": 130}


def check_embedded_points(name: str, n: int) -> None:
    """DeviceError before an embedded cloud of `n` points is made when it
    would not fit in the host memory available (--points 4000000000 ran into
    the OOM killer after minutes of swapping)."""
    from .. import runtime

    runtime.check_memory(
        runtime.default_queue(),
        f"--points {n:,} (the embedded {name})",
        host_bytes=n * EMBEDDED_BYTES_PER_POINT[name],
    )


def finite_range(data: np.ndarray, source: str) -> tuple[float, float]:
    """(min, max) of the finite samples; ClvisError naming `source` when there
    is none (no numpy RuntimeWarning on an all-NaN volume)."""
    finite = np.isfinite(data)
    if not finite.any():
        raise CliError(f"{source}: the volume has no finite sample")
    vals = data if finite.all() else data[finite]
    return float(vals.min()), float(vals.max())


#: what --attribute may name beside a cloud's attributes: its per-point size
#: (PointCloud.radius: a file's "radius" array) and its velocity's magnitude
PLANE_ATTRIBUTES = ("radius", "speed")


def plane_attribute(cloud, name: str | None) -> None:
    """Make --attribute `name` colour by the cloud's radius or speed: the
    readers keep a file's "radius" array (and "velocity") as the cloud's
    planes, not as attributes, so --attribute radius found nothing. Adds
    it to cloud.attributes when the cloud has the plane and no attribute of
    that name."""
    if name not in PLANE_ATTRIBUTES or name in cloud.attributes:
        return
    if name == "radius" and cloud.radius is not None:
        cloud.attributes["radius"] = np.asarray(cloud.radius, np.float32)
    elif name == "speed" and cloud.velocity is not None:
        cloud.attributes["speed"] = np.linalg.norm(np.asarray(cloud.velocity, np.float32), axis=1)


def plane_names(cloud) -> list[str]:
    """The names plane_attribute makes for this cloud (it has the plane)."""
    have = {"radius": cloud.radius is not None, "speed": cloud.velocity is not None}
    return [k for k in PLANE_ATTRIBUTES if have[k] and k not in cloud.attributes]


def frame_bulk(cloud, source: str, prog: str):
    """(lo, hi, the points to frame, the mask of the points kept or None when
    all are): the bounds of the bulk of a point cloud (clvis.camera.robust_bounds),
    with a note on stderr, prefixed with the command `prog`, when stray points far
    outside it are left out of the frame (clvis render and clvis gauss frame alike)."""
    from ..camera import robust_bounds

    try:
        rb = robust_bounds(cloud.positions)
    except ValueError:
        raise CliError(f"{source}: no point has finite coordinates") from None
    if rb.kept == rb.total:
        return rb.lo, rb.hi, cloud.positions, None
    stray_note(prog, rb.kept, rb.total, cloud.bounds(), (rb.lo, rb.hi), cloud.origin)
    return rb.lo, rb.hi, cloud.positions[rb.inside], rb.inside


def stray_note(prog: str, kept: int, total: int, full, bulk, o) -> None:
    """The note on stderr when stray points are left out of the frame
    (full, bulk: (lo, hi) relative to the origin `o`)."""
    print(
        f"{prog}: note: {total - kept:,} of {total:,} points lie far outside the rest "
        f"(the cloud spans {world_box(full[0], full[1], o)}, its bulk {world_box(bulk[0], bulk[1], o)}); "
        "the view frames the bulk (--eye/--target to look elsewhere)",
        file=sys.stderr,
    )


def world_box(lo, hi, origin) -> str:
    """Local (float32) bounds in the file's coordinates: each value at the
    float32 precision it has (its shortest decimal) plus the origin, so
    586.38 reads 586.38, not 586.3799933; the sum rounded to the decimals
    that precision holds (a stray point 6e5 from the origin, float32's step
    there 0.06, read -0.05000000005)."""

    def world(v, o):
        f = np.float32(v)
        w = float(np.format_float_positional(f, unique=True)) + float(o)
        step = float(np.spacing(np.abs(f)))
        return round(w, max(0, -math.floor(math.log10(step)))) if f and step > 0 else w

    return " x ".join(
        f"{world(a, o):.10g}..{world(b, o):.10g}" for a, b, o in zip(lo, hi, origin, strict=True)
    )


#: --connect-timeout's default (seconds)
CONNECT_TIMEOUT = 10.0


def add_cluster_options(parser: argparse.ArgumentParser) -> None:
    """--workers N / --scheduler ADDRESS: render on Dask workers (clvis.distributed)."""
    g = parser.add_mutually_exclusive_group()
    g.add_argument(
        "--workers",
        type=count(1, 4096),
        metavar="N",
        help="render on N local Dask worker processes of one thread each (a LocalCluster started "
        "here; needs the distributed extra)",
    )
    g.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="render on the workers of a running Dask scheduler (tcp://host:port)",
    )
    parser.add_argument(
        "--connect-timeout",
        type=real(0, open_lo=True, what="seconds"),
        default=None,
        metavar="SECONDS",
        help="with --scheduler: seconds to reach it (a refused connection fails at once; default 10)",
    )


def cluster_client(args) -> tuple[object, int]:
    """(client argument, workers) for clvis.distributed from --workers/--scheduler."""
    try:
        import distributed  # noqa: F401
    except ImportError:
        raise CliError(
            "--workers and --scheduler need dask.distributed: pip install 'clvis[distributed]'"
        ) from None
    if args.connect_timeout is None:
        args.connect_timeout = CONNECT_TIMEOUT
    if args.scheduler is not None:
        return args.scheduler, 1
    from ..distributed.cluster import WORKERS_PER_CORE, local_workers_max

    most = local_workers_max()
    if args.workers > most:
        raise CliError(
            f"--workers {args.workers}: at most {most} on this machine ({WORKERS_PER_CORE} per CPU core: "
            "more worker processes only compete for the cores and memory); for more, start a Dask "
            "cluster on several machines and give --scheduler ADDRESS"
        )
    return None, args.workers


def cluster_failed(args, e: OSError) -> CliError:
    """The one-line error of an OSError out of starting or reaching the Dask
    cluster (clvis's own errors, ClusterTimeout among them, say what they
    waited for themselves and go through as they are)."""
    if args.scheduler is not None:
        return CliError(f"--scheduler {args.scheduler}: cannot reach it ({e})")
    return CliError(f"--workers {args.workers}: the local Dask cluster did not start ({e})")


def on_workers(name: str, fn, *args) -> int:
    """fn(*args), a Ctrl-C as one line on stderr and exit status 130: the
    renderer's close (unwinding) stops the Dask workers started here, which
    never see the signal themselves (clvis.distributed.cluster.start_cluster)."""
    import signal

    def interrupt(signum, frame):  # the first Ctrl-C stops; more would cut the stopping short
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        raise KeyboardInterrupt

    main = threading.current_thread() is threading.main_thread()
    old = signal.signal(signal.SIGINT, interrupt) if main else None
    try:
        status = fn(*args)
    except KeyboardInterrupt:  # SIGINT stays ignored: this process is on its way out
        from . import _ignore_on_exit

        # main() puts its caller's SIGINT handler back on return; noted here,
        # entry() ignores the signal again while the interpreter joins Dask's
        # threads (a second Ctrl-C then would end `python -m clvis` by SIGINT)
        _ignore_on_exit.append(signal.SIGINT)
        print(f"clvis {name}: interrupted; the Dask workers started here were stopped", file=sys.stderr)
        return 130
    if main:
        signal.signal(signal.SIGINT, old)
    return status


def distributed_run(args) -> bool:
    """True when --workers or --scheduler asks for Dask workers; a CliError
    for --connect-timeout without --scheduler (it would be ignored)."""
    if getattr(args, "connect_timeout", None) is not None and getattr(args, "scheduler", None) is None:
        raise CliError(
            "--connect-timeout: the wait for a --scheduler; add --scheduler ADDRESS or leave it out"
        )
    return getattr(args, "workers", None) is not None or getattr(args, "scheduler", None) is not None
