"""NumPy references of the raster family (clvis/raster/), module for module."""

from . import depth_filter, edl, morton, render
from .morton import morton_order
from .render import depth_key, key_depth, nonfinite, rasterize, splat, visibility

__all__ = [
    "depth_filter",
    "depth_key",
    "edl",
    "key_depth",
    "morton",
    "morton_order",
    "nonfinite",
    "rasterize",
    "render",
    "splat",
    "visibility",
]
