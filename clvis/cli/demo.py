"""`clvis demo`: each kernel family on generated data, its figures and a
check against its reference. The primitives part is here; each rendering
family's part lives with its command (raster.demo, gauss.demo, iso.demo;
demo_post.demo: the networks' contact sheets)."""

from __future__ import annotations

import argparse
import typing

import numpy as np
import pyopencl.array as cla

from . import demo_post, gauss, iso, raster
from ._common import Parser, count, folder, size, timed
from .raster import MAX_POINTS

MAX_N = 2**32 - 1  # the primitives count in uint


def add_parser(sub: argparse._SubParsersAction[Parser]) -> Parser:
    d = sub.add_parser("demo", help="run the kernels on generated data and print the figures")
    d.add_argument(
        "--n", type=count(1, MAX_N), default=1 << 24, help="elements of the primitives (default 2^24)"
    )
    d.add_argument(
        "--points",
        type=count(1, MAX_POINTS),
        default=500_000,
        help="particles of the rendered hurricane (default 500,000)",
    )
    d.add_argument(
        "--size",
        type=size,
        default=(1920, 1080),
        metavar="WxH",
        help="image size of the render (default 1920x1080)",
    )
    d.add_argument(
        "--iso-size",
        type=size,
        default=(640, 480),
        metavar="WxH",
        help="the isosurface picture (default 640x480)",
    )
    d.add_argument(
        "--gauss-size",
        type=size,
        default=(480, 480),
        metavar="WxH",
        help="each Gaussian LOD panel (default 480x480)",
    )
    d.add_argument(
        "--post-size",
        type=size,
        default=(640, 360),
        metavar="WxH",
        help="each panel of the networks' contact sheets (default 640x360; narvis-scan's: half that)",
    )
    d.add_argument(
        "-o",
        "--out",
        type=folder,
        default="clvis-demo",
        metavar="DIR",
        help="where the PNGs go (default ./clvis-demo)",
    )
    return d


def cmd(args: argparse.Namespace) -> int:

    from .. import __version__, primitives, runtime
    from ..reference import primitives as ref

    q = runtime.default_queue()
    caps = runtime.capabilities(q)
    n = args.n
    print(
        f"clvis {__version__} on {runtime.describe(q.device)} "
        f"({caps.device_type}, {caps.compute_units} compute units, tuning {runtime.tuning_profile(q)})"
    )
    print(
        "\nprimitives on generated data, device-resident arrays; numpy on the host "
        "(best of 3 after a warm-up that builds the kernels):\n"
    )
    rng = np.random.default_rng(0)
    x = rng.integers(0, 100, n).astype(np.int32)
    mask = rng.random(n) < 0.5
    keys = rng.integers(0, 1 << 32, n, dtype=np.uint64).astype(np.uint32)
    vals = np.arange(n, dtype=np.uint32)
    bins = rng.integers(0, 256, n).astype(np.int32)
    xd, md = cla.to_device(q, x), cla.to_device(q, mask)
    kd, vd, bd = cla.to_device(q, keys), cla.to_device(q, vals), cla.to_device(q, bins)

    def np_sort():
        o = np.argsort(keys, kind="stable")
        return keys[o], vals[o]

    cases = [
        (
            "scan int32 (exclusive)",
            lambda: primitives.scan(xd),
            lambda: np.cumsum(x, dtype=np.int32),
            "np.cumsum",  # the same int32 output
            lambda: np.array_equal(primitives.scan(xd).get(), ref.scan(x)),
        ),
        (
            "compact int32, half kept",
            lambda: primitives.compact(xd, md),
            lambda: x[mask],
            "boolean mask",
            lambda: np.array_equal(primitives.compact(xd, md).get(), ref.compact(x, mask)),
        ),
        (
            "radix sort uint32 keys+values",
            lambda: primitives.radix_sort(kd, vd),
            np_sort,
            "argsort+gather",
            lambda: all(
                np.array_equal(a.get(), b)
                for a, b in zip(primitives.radix_sort(kd, vd), ref.radix_sort(keys, vals), strict=True)
            ),
        ),
        (
            "histogram, 256 bins",
            lambda: primitives.histogram(bd, 256),
            lambda: np.bincount(bins, minlength=256),
            "np.bincount",
            lambda: np.array_equal(
                typing.cast(cla.Array, primitives.histogram(bd, 256)).get(), ref.histogram(bins, 256)
            ),
        ),
    ]
    print(f"  {'op (n = ' + format(n, ',') + ')':34} {'clvis':>16} {'numpy':>26} {'speed-up':>9}  reference")
    ok_all = True
    for name, fn, npfn, npname, check in cases:
        t_cl = timed(fn, q)
        t_np = timed(npfn)
        ok = bool(check())
        ok_all &= ok
        print(
            f"  {name:34} {t_cl * 1e3:7.2f} ms {n / t_cl / 1e6:5.0f} M/s   "
            f"{npname:>14} {t_np * 1e3:7.2f} ms {t_np / t_cl:8.1f}x  {'matches' if ok else 'MISMATCH'}"
        )
    print("\nfull benchmarks with every peer: clvis bench primitives")
    ok_all &= raster.demo(args, q)
    ok_all &= gauss.demo(args.out, q, size=args.gauss_size)
    ok_all &= iso.demo(args.out, q, size=args.iso_size)
    ok_all &= demo_post.demo(args.out, q, size=args.post_size)
    return 0 if ok_all else 1
