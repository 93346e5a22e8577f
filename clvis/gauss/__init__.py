"""gauss family: Gaussian particles from sparse volumes and point clouds, a
device LBVH, and ray marching that composites every Gaussian a ray meets in
depth order (Sharma & Schmalstieg; 3D Gaussian Ray Tracing)."""

from .bvh import BVH, BVH_NODE_DTYPE, build_bvh
from .gaussians import Gaussians
from .lod import LODS, LodRow, LodTable, gaussians_from_volume, lod_table
from .sparse import SparseVolume, read_vdb

__all__ = ["BVH", "BVH_NODE_DTYPE", "Gaussians", "LODS", "LodRow", "LodTable", "SparseVolume", "build_bvh",
           "gaussians_from_volume", "lod_table", "read_vdb"]
