"""NumPy references of the iso family (clvis/iso/), module for module: zfp,
macrocell, traverse, cache, raytrace, surface, render (the rules of the whole
raycaster are written out in render's module docstring)."""

from . import cache, macrocell, raytrace, surface, traverse, zfp
from .macrocell import block_ranges, cell_ranges, coarse_ranges
from .raytrace import (
    BISECTION_STEPS,
    TINY_DIR,
    IsoImage,
    Shading,
    cell_cubic,
    cubic_first_zero,
    render_rays,
    shade,
)
from .render import DEPTH_TOLERANCE, VALUE_TOLERANCE, agreement, reliable, render

__all__ = [
    "BISECTION_STEPS",
    "DEPTH_TOLERANCE",
    "TINY_DIR",
    "VALUE_TOLERANCE",
    "IsoImage",
    "Shading",
    "agreement",
    "block_ranges",
    "cache",
    "cell_cubic",
    "cell_ranges",
    "coarse_ranges",
    "cubic_first_zero",
    "macrocell",
    "raytrace",
    "reliable",
    "render",
    "render_rays",
    "shade",
    "surface",
    "traverse",
    "zfp",
]
