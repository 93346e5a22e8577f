"""The clvis command line.

    clvis info                   OpenCL platforms and devices, the one clvis uses, its capabilities
    clvis demo                   runs the kernel families on generated data and prints the figures
    clvis render [FILE]          renders a point cloud (default: an embedded synthetic hurricane)
                                 and writes PNGs of its G-buffers
    clvis iso [FILE]             progressive isosurface raycasting of a ZFP-compressed volume
                                 (default: an embedded Marschner-Lobb volume)
    clvis gauss [FILE]           Gaussians from a volume at three levels of detail, ray marched
                                 (default: an embedded explosion), PNGs side by side
    clvis bench primitives|raster|gauss|iso
                                 a benchmark suite with its peers, as a table (and JSON)
"""

from __future__ import annotations

import argparse

from . import bench, demo, gauss, info, iso, raster
from ._common import Parser, run

_COMMANDS = {"info": info, "demo": demo, "render": raster, "iso": iso, "gauss": gauss, "bench": bench}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="clvis", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True, parser_class=Parser)
    for module in (info, demo, raster, gauss, iso, bench):
        module.add_parser(sub)
    args = p.parse_args(argv)
    return run(args.cmd, _COMMANDS[args.cmd].cmd, args)
