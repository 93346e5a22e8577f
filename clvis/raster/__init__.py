"""raster family: point rasterization into multi-attribute G-buffers
(render.py: render.cl + resolve.cl; morton.py: morton.cl; inputs.py: the
input rules the Rasterizer and the distributed layer share), and the
hierarchical depth filter (depth_filter.py: depth_filter.cl), and eye-dome
lighting (edl.py: edl.cl)."""

from .depth_filter import FilteredImage, depth_filter, depth_filter_mask, filter_gbuffers, rgbda
from .edl import edl
from .inputs import MAX_ATTRIBUTES, MAX_IMAGE_SIDE, MAX_POINT_SIZE
from .morton import morton_order
from .render import (
    BATCH_SIZE,
    EMPTY,
    VIS_DTYPE,
    GBuffers,
    Rasterizer,
    rasterize,
)

__all__ = [
    "BATCH_SIZE",
    "EMPTY",
    "MAX_ATTRIBUTES",
    "MAX_IMAGE_SIDE",
    "MAX_POINT_SIZE",
    "VIS_DTYPE",
    "FilteredImage",
    "GBuffers",
    "Rasterizer",
    "depth_filter",
    "depth_filter_mask",
    "edl",
    "filter_gbuffers",
    "morton_order",
    "rasterize",
    "rgbda",
]
