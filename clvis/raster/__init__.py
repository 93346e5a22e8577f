"""raster family: point rasterization into multi-attribute G-buffers
(render.py: render.cl + resolve.cl; Morton order: morton.cl), and the
hierarchical depth filter (depth_filter.py: depth_filter.cl)."""

from ..camera import CAMERA_DTYPE, camera_buffer
from .depth_filter import FilteredImage, depth_filter, depth_filter_mask, rgbda
from .render import (
    BATCH_SIZE,
    EMPTY,
    MAX_ATTRIBUTES,
    MAX_IMAGE_SIDE,
    MAX_POINT_SIZE,
    VIS_DTYPE,
    GBuffers,
    Rasterizer,
    morton_order,
    rasterize,
)

__all__ = [
    "BATCH_SIZE",
    "CAMERA_DTYPE",
    "EMPTY",
    "MAX_ATTRIBUTES",
    "MAX_IMAGE_SIDE",
    "MAX_POINT_SIZE",
    "VIS_DTYPE",
    "FilteredImage",
    "GBuffers",
    "Rasterizer",
    "camera_buffer",
    "depth_filter",
    "depth_filter_mask",
    "morton_order",
    "rasterize",
    "rgbda",
]
