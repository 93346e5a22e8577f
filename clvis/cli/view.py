"""`clvis view`: an interactive, progressive viewer in the browser."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..errors import ClvisError, DeviceError
from ..io.points import POINT_SUFFIXES
from ..io.volumes import otsu_level
from ._common import (
    CliError,
    Parser,
    add_cluster_options,
    add_volume_options,
    check_embedded_points,
    check_iso_volume,
    cluster_client,
    cluster_failed,
    count,
    distributed_run,
    grid_arg,
    on_workers,
    read_volume_file,
    real,
    size,
)

if TYPE_CHECKING:
    from ..view import Scene

_HELP = """\
Serve an interactive view of a point cloud or a volume and print its URL
(and open a browser where there is one). The frames are rendered here, on the
OpenCL device, and streamed to the page as JPEG over a WebSocket; the page
sends the mouse, touch and key events back. Drag to orbit, right- or
shift-drag to pan, wheel or pinch to zoom; keys: arrows, + and -, f (fit),
c (the camera as --eye/--target/--up/--fov options for the other commands;
edit them and press Enter to go to a typed camera).
While the pointer drags, frames are half the page's size; when it stops,
full size. The status line shows each frame's milliseconds per stage
(render / post / encode / send), the frames per second and the latency from
an event to the frame that shows it.

Points (.ply, .las, .laz, .e57, .pcd, .xyz/.txt/.csv/.pts/.xyzn/.xyzrgb, .npz, an (N, 3) .npy,
.vtp/.vtu/.vts, a legacy .vtk of POLYDATA, UNSTRUCTURED_GRID or STRUCTURED_GRID, or --dataset
hurricane|terrain):
modes points (colour by an attribute or RGB, colormap, point size), lidar
(depth filter + LiDAR U-Net), narvis (clouds with a velocity) or narvis-scan
(clouds without one, LAS/LAZ/PLY scans: the radius plane from the points'
kNN distances, computed when the mode is first chosen), gaussians,
narvis|gaussians or narvis-scan|gaussians (split: MACR + the network beside
the Gaussian renderer it was trained on, the PSNR).
Volumes (.raw, a 3-D .npy, NIfTI, MGH (.mgz, .mgh), Analyze .hdr/.img, .vti, .vtr, a legacy .vtk of
STRUCTURED_POINTS or RECTILINEAR_GRID, or --dataset marschner-lobb|turbulence|explosion): modes
iso (progressive:
each pass is shown as it completes, and a camera move restarts the passes),
iso+infill (the in-fill network on the partial passes), gaussians, infill|iso
(split: 85 % of the rays + in-fill beside the complete render, the PSNR).
Sparse volumes (a .vdb float grid, --grid; the `vdb` extra): mode gaussians
(Sharma & Schmalstieg: the active voxels' Gaussians at a level of detail,
never made dense), and a threshold: the active voxels above it are drawn;
mode iso (clvis iso FILE.vdb's isosurface: the grid made dense when the mode
is first chosen, its inactive voxels the grid's background; --isovalue,
default 0 for a level set, else Otsu's; refused in the page, gaussians still
shown, where the dense volume would not fit in host memory), and the in-fill
network on it as on a volume (iso+infill, infill|iso; --model-dir).

Dask (--workers N: a LocalCluster of N one-thread processes started here and
stopped with the viewer; --scheduler ADDRESS: a running cluster): the frames
are rendered on the workers and composited (clvis.distributed), the newest
view still wins. Points: mode points only (a FILE is one partition, read on
a worker; an embedded cloud is cut into one block per worker), the single
device's frame bit for bit. Volumes: mode iso only, one complete frame per
view (bricks of --brick cells; a FILE needs --isovalue), the single device's
up to float32 rounding. The other modes run on one device (leave out
--workers/--scheduler). A lost worker's data is rebuilt elsewhere; a frame
that fails shows its error in the page and the next view tries again.

The server listens on 127.0.0.1; --host 0.0.0.0 (or another address) makes
it reachable from other machines, with a token in the printed URL that the
page must present. Only the FILE given here is ever read.
"""
_POINT_SETS = ("hurricane", "terrain")
_VOLUME_SETS = ("marschner-lobb", "turbulence", "explosion")
# what read_points reads, but .npy (an (N, 3) array is points, a 3-D one a volume) and
# .vtk (a volume where its DATASET is STRUCTURED_POINTS or RECTILINEAR_GRID, else points)
_POINT_SUFFIXES = tuple(s for s in POINT_SUFFIXES if s not in (".npy", ".vtk"))


def add_parser(sub: argparse._SubParsersAction[Parser]) -> Parser:
    p = sub.add_parser(
        "view",
        help="an interactive viewer in the browser (points, progressive isosurfaces, Gaussians)",
        description=_HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("file", nargs="?", help="a point cloud or a volume file")
    p.add_argument("--dataset", choices=_POINT_SETS + _VOLUME_SETS, help="an embedded dataset")
    p.add_argument(
        "--points",
        type=count(1, 2**31),
        default=None,
        metavar="N",
        help=f"points of an embedded cloud (default {POINTS:,})",
    )
    p.add_argument(
        "--isovalue",
        type=real(),
        default=None,
        help="default: 0.5 embedded, 0 for a .vdb level set (mode iso), else Otsu's",
    )
    p.add_argument("--rate", type=count(1, 32), default=None, help=f"ZFP bits per value (default {RATE})")
    p.add_argument("--host", default="127.0.0.1", help="the address to listen on (default 127.0.0.1)")
    p.add_argument("--port", type=count(0, 65535), default=0, help="default 0: a free port")
    p.add_argument("--no-browser", action="store_true", help="print the URL only")
    p.add_argument(
        "--measure",
        nargs="?",
        const="all",
        default=None,
        metavar="MODES",
        help="serve nothing: print the frame budget of the modes named (comma-separated; default "
        "all): render, post, JPEG encode; interaction frames at half --size, then still frames; "
        "iso: the first frame after a camera stop (its first pass at half size), the first at "
        "full size and the last",
    )
    p.add_argument(
        "--size",
        type=size,
        default=(1280, 720),
        metavar="WxH",
        help="--measure's page size (default 1280x720)",
    )
    p.add_argument(
        "--brick",
        type=count(4, 4096),
        default=64,
        help="with --workers/--scheduler, a volume: cells per brick edge, a multiple of 4 (default 64)",
    )
    p.add_argument(
        "--model-dir",
        metavar="DIR",
        help="where the networks' models are (clvis train --out writes them; default: the ones "
        "clvis ships), for the network modes",
    )
    p.add_argument(
        "--grid",
        type=grid_arg,
        default=None,
        metavar="NAME|INDEX",
        help="the grid of a .vdb file: its name, or its index (0 first) (default: the first float grid)",
    )
    add_volume_options(p)
    add_cluster_options(p)
    return p


#: --points' and --rate's defaults
POINTS = 2_000_000
RATE = 8


def _fits(args: argparse.Namespace, volume: bool, what: str) -> None:
    """A CliError for the options the scene would ignore: --points beside a
    volume or a point file, --isovalue and --rate beside a point cloud."""
    if args.points is not None and (volume or args.file is not None):
        kind = "a volume" if volume else "read whole"
        raise CliError(f"--points: the size of an embedded point cloud; {what} is {kind}")
    given = [f for f, v in (("--isovalue", args.isovalue), ("--rate", args.rate)) if v is not None]
    if given and not volume:
        raise CliError(f"{' and '.join(given)}: for a volume's isosurface; {what} is a point cloud")


def _is_volume(path: Path) -> bool:
    name = path.name.lower()
    if name.endswith(_POINT_SUFFIXES):
        return False
    if name.endswith(".npy"):  # its header alone, checked (np.load's errors named no file)
        from ..io import npy_shape

        return len(npy_shape(path)) == 3
    if name.endswith(".vtk"):
        from ..io.vtk import POINT_DATASETS, legacy_dataset

        return legacy_dataset(path) not in POINT_DATASETS
    return True


def load_scene(args: argparse.Namespace) -> Scene:
    """The scene of the FILE or --dataset (the only data the server reads)."""
    from .. import datasets
    from ..view import PointScene, VolumeScene

    if args.file is not None:
        if args.dataset is not None:
            raise CliError("--dataset chooses an embedded dataset; leave it out with a FILE")
        path = Path(args.file)
        if not path.exists():
            raise CliError(f"{path}: no such file")
        if path.name.lower().endswith(".vdb"):
            return _vdb_scene(args, path)
        if args.grid is not None:
            raise CliError(f"--grid picks a grid of a .vdb file; {path} is not one")
        from ..io.files import mesh_hint
        from ..io.volumes import FORMATS

        if not path.name.lower().endswith((*FORMATS, *_POINT_SUFFIXES)):  # it was "unknown volume format"
            raise CliError(
                f"{path}: unknown format (expected a volume: .vdb, {', '.join(FORMATS)}; or points: "
                f"{', '.join(_POINT_SUFFIXES)}){mesh_hint(path)}"
            )
        volume = _is_volume(path)
        _fits(args, volume, str(path))
        if volume:
            data, spacing, origin = read_volume_file(args, path)
            iso = args.isovalue if args.isovalue is not None else otsu_level(data)  # of the finite ones
            data = check_iso_volume(data, str(path), "clvis view")
            return VolumeScene(
                data,
                spacing,
                origin,
                iso,
                args.rate or RATE,
                description=str(path),
                model_dir=args.model_dir,
                anatomical=getattr(args, "anatomical", False),  # read_volume_file: a scan, its face first
            )
        from .. import read_points

        if args.array is not None:
            raise CliError(f"--array picks a data array of a VTK volume file; {path} is a point cloud")

        return PointScene(read_points(path), description=str(path), model_dir=args.model_dir)
    if args.grid is not None:
        raise CliError("--grid picks a grid of a .vdb FILE")
    if args.array is not None:
        raise CliError("--array picks a data array of a VTK volume FILE (.vti, .vtr, .vtk)")
    name = args.dataset or "hurricane"
    _fits(args, name not in _POINT_SETS, f"the embedded {name}")
    if name in _POINT_SETS:
        from .. import PointCloud

        check_embedded_points(name, args.points or POINTS)
        d = getattr(datasets, name)(args.points or POINTS)
        cloud = PointCloud(
            d["positions"], colors=d["colors"], attributes=d["attributes"], velocity=d["velocity"]
        )
        return PointScene(cloud, description=f"the embedded {name}", model_dir=args.model_dir)
    if name == "explosion":
        d = datasets.explosion()
        iso = 0.2
    else:
        d = datasets.marschner_lobb(64) if name == "marschner-lobb" else datasets.turbulence(128)
        iso = 0.5
    iso = args.isovalue if args.isovalue is not None else iso
    return VolumeScene(
        d["volume"],
        d["spacing"],
        d["origin"],
        iso,
        args.rate or RATE,
        description=f"the embedded {name}",
        model_dir=args.model_dir,
    )


def _vdb_scene(args: argparse.Namespace, path: Path) -> Scene:
    """A .vdb's float grid as a SparseScene (its Gaussians; its isosurface,
    --isovalue and --rate, when the iso mode is chosen)."""
    from ..gauss import read_vdb
    from ..view import SparseScene

    given = [
        f
        for f, v in (
            ("--points", args.points),
            ("--spacing", args.spacing),
            ("--shape", args.shape),
            ("--dtype", args.dtype),
            ("--volume-index", args.volume_index),
            ("--array", args.array),
        )
        if v is not None
    ]
    if given:
        raise CliError(
            f"{' and '.join(given)}: not for a .vdb (its grid is drawn as Gaussians, mode gaussians, "
            "or as its isosurface, modes iso, iso+infill, infill|iso: --isovalue, --rate, --model-dir; "
            "the threshold is set in the page)"
        )
    grid = args.grid
    return SparseScene(
        read_vdb(path, grid=grid),
        description=str(path),
        isovalue=args.isovalue,
        rate=args.rate or RATE,
        model_dir=args.model_dir,
    )


def load_dask_scene(args: argparse.Namespace) -> Scene:
    """The FILE or --dataset on Dask workers (--workers/--scheduler):
    points mode or iso mode, the data read on the workers where it is a FILE."""
    from .. import datasets
    from ..view import DaskPointScene, DaskVolumeScene

    if args.file is not None and str(args.file).lower().endswith(".vdb"):
        raise CliError(
            "--workers/--scheduler: a .vdb is drawn on one device (its Gaussians and isosurface modes); "
            "leave them out"
        )
    if args.array is not None:
        raise CliError("--array: not on workers (they read .npy, .raw and NIfTI volumes)")
    if args.model_dir is not None:
        raise CliError("--model-dir: on workers the viewer runs no network (points and iso modes)")
    client, workers = cluster_client(args)
    if args.brick % 4:
        raise CliError(f"--brick: {args.brick} is not a multiple of 4 (ZFP's block edge)")
    common = {"workers": workers, "connect_timeout": args.connect_timeout}
    if args.file is not None:
        if args.dataset is not None:
            raise CliError("--dataset chooses an embedded dataset; leave it out with a FILE")
        path = Path(args.file)
        if not path.exists():
            raise CliError(f"{path}: no such file")
        volume = _is_volume(path)
        _fits(args, volume, str(path))
        if not volume:
            try:
                return DaskPointScene([str(path)], client, description=str(path), **common)
            except ClvisError:
                raise
            except OSError as e:
                raise cluster_failed(args, e) from None
        if args.isovalue is None:
            raise CliError(
                "--isovalue: needed with a volume FILE on workers (Otsu's reads every sample here)"
            )
        kw: dict = {"volume_index": args.volume_index} if args.volume_index is not None else {}
        if path.name.lower().endswith(".raw"):
            kw = {"shape": args.shape, "dtype": args.dtype, "volume_index": args.volume_index}
        spacing = tuple(reversed(args.spacing)) if args.spacing is not None else None
        source: object = str(path)
        what, iso, vrange, origin = str(path), args.isovalue, None, (0.0, 0.0, 0.0)
    else:
        name = args.dataset or "hurricane"
        _fits(args, name not in _POINT_SETS, f"the embedded {name}")
        if name in _POINT_SETS:
            import dask.array as da

            check_embedded_points(name, args.points or POINTS)  # made here, then split over the workers
            d = getattr(datasets, name)(args.points or POINTS)
            parts = max(1, workers)
            chunk = -(-len(d["positions"]) // parts)

            def arr(a):
                return None if a is None else da.from_array(a, chunks=(chunk,) + a.shape[1:])

            try:
                return DaskPointScene(
                    arr(d["positions"]),
                    client,
                    colors=arr(d["colors"]),
                    attributes={k: arr(v) for k, v in d["attributes"].items()},
                    velocity=arr(d["velocity"]),
                    description=f"the embedded {name}",
                    **common,
                )
            except ClvisError:
                raise
            except OSError as e:
                raise cluster_failed(args, e) from None
        if name == "explosion":
            d, iso = datasets.explosion(), 0.2
        else:
            d = datasets.marschner_lobb(64) if name == "marschner-lobb" else datasets.turbulence(128)
            iso = 0.5
        iso = args.isovalue if args.isovalue is not None else iso
        source, spacing, origin = d["volume"], d["spacing"], d["origin"]
        what, kw = f"the embedded {name}", {}
        vrange = (float(np.nanmin(d["volume"])), float(np.nanmax(d["volume"])))
    try:
        scene = DaskVolumeScene(
            source,
            client,
            isovalue=iso,
            vrange=vrange,
            description=what,
            rate=args.rate or RATE,
            spacing=spacing,
            origin=origin,
            brick=args.brick,
            **common,
            **kw,
        )
        from ..io.volumes import NIBABEL_FORMATS

        if isinstance(source, str) and source.lower().endswith(NIBABEL_FORMATS):
            scene.home_azimuth = 115.0  # a scan, read in RAS+ order on the workers too: its face first
        return scene
    except ClvisError:
        raise
    except OSError as e:
        raise cluster_failed(args, e) from None


def _measure(scene, args) -> int:
    from ..view.measure import measure

    w, h = args.size
    load = " / ".join(f"{x:.2f}" for x in os.getloadavg()) if hasattr(os, "getloadavg") else "?"
    print(f"clvis view --measure: {scene.description} on {scene.device}, page {w}x{h}, load average {load}")
    modes = scene.modes if args.measure == "all" else args.measure.split(",")
    unknown = [m for m in modes if m not in scene.modes]
    if unknown and scene.device.startswith("Dask workers"):
        raise CliError(
            f"--measure: mode {unknown[0]!r} is not rendered on Dask workers (they render "
            f"{', '.join(scene.modes)}); leave out --workers/--scheduler for it"
        )
    if unknown:
        raise CliError(f"--measure: no mode {unknown[0]!r} for this data; it has {', '.join(scene.modes)}")
    mw = max([13] + [len(m) for m in modes])  # narvis-scan|gaussians: 21
    print(
        f"{'mode':{mw}} frame       first ms  full ms  last ms  frames  fps    CPU ms  "
        "stages of the first frame (ms)"
    )
    for mode in modes:
        for interactive in (True, False):
            try:
                r = measure(scene, w, h, mode, interactive=interactive)
            except DeviceError as e:
                if args.measure != "all":
                    raise
                # every mode measured: one the data is too large for (a .vdb grid's
                # isosurface, made dense) is said, the others measured (it stopped them)
                print(f"{mode:{mw}} refused: {e}", flush=True)
                break
            stages = " / ".join(f"{k} {v:.1f}" for k, v in r["stages_ms"].items())
            if "inference ms" in r["info"]:
                stages += f" (inference {r['info']['inference ms']:.1f})"
            kind = "interaction" if interactive else "still"
            print(
                f"{mode:{mw}} {kind:11} {r['first_ms']:8.1f} {r['first_full_ms']:8.1f} {r['last_ms']:8.1f} "
                f"{r['frames']:6g} {r['fps']:6.1f} {r['cpu_ms']:7.1f}  {r['size']}: {stages}",
                flush=True,
            )
    return 0


def _has_display() -> bool:
    """Whether a graphical browser can open here: on Linux and the BSDs only
    with an X or Wayland display (webbrowser would start a text browser in
    this terminal on a server)."""
    if sys.platform in ("darwin", "win32"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def cmd(args: argparse.Namespace) -> int:
    if distributed_run(args):
        return on_workers("view", _serve, args)
    return _serve(args)


def _serve(args: argparse.Namespace) -> int:
    from ..view import Viewer, ViewServer

    scene = load_dask_scene(args) if distributed_run(args) else load_scene(args)
    if args.measure is not None:
        try:
            return _measure(scene, args)
        finally:
            scene.close()
    try:
        server = ViewServer(scene, args.host, args.port)
    except OSError as e:  # an address that does not resolve, a port in use: name them
        scene.close()
        raise CliError(
            f"--host {args.host} --port {args.port}: cannot listen there ({e.strerror or e})"
        ) from None
    except BaseException:
        scene.close()
        raise
    viewer = Viewer(server)
    try:  # a Ctrl-C from the line that says it stops the viewer on (wait() takes one itself)
        print(f"clvis view: {scene.description} on {scene.device}")
        print(f"clvis view: open {viewer.url}   (Ctrl-C stops)", flush=True)
        if not args.no_browser and _has_display():
            viewer.show()
        viewer.wait()
    except KeyboardInterrupt:
        viewer.close()
    from . import _ctrl_c_handled

    _ctrl_c_handled()  # Ctrl-C is how a viewer stops: one line, status 0
    print("clvis view: stopped", file=sys.stderr)
    return 0
