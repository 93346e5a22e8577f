"""gauss family: Gaussian particles from sparse volumes and point clouds, a
device LBVH, and ray marching that composites every Gaussian a ray meets in
depth order (Sharma & Schmalstieg; 3D Gaussian Ray Tracing)."""

from .bvh import BVH, BVH_NODE_DTYPE, build_bvh
from .gaussians import GAUSSIAN_DTYPE, Gaussians
from .lod import LODS, LodRow, LodTable, gaussians_from_volume, lod_table
from .points import gaussians_from_points, knn_mean_distance
from .render import (
    GaussianImage,
    GaussianRenderer,
    render_gaussians,
)
from .sparse import SparseVolume, default_isovalue, dense_volume, read_vdb, read_vdb_volume

__all__ = [
    "BVH",
    "BVH_NODE_DTYPE",
    "GAUSSIAN_DTYPE",
    "LODS",
    "GaussianImage",
    "GaussianRenderer",
    "Gaussians",
    "LodRow",
    "LodTable",
    "SparseVolume",
    "build_bvh",
    "default_isovalue",
    "dense_volume",
    "gaussians_from_points",
    "gaussians_from_volume",
    "knn_mean_distance",
    "lod_table",
    "read_vdb",
    "read_vdb_volume",
    "render_gaussians",
]
