"""gauss family: Gaussian particles from sparse volumes and point clouds, a
device LBVH, and ray marching that composites every Gaussian a ray meets in
depth order (Sharma & Schmalstieg; 3D Gaussian Ray Tracing)."""

from .gaussians import Gaussians
from .lod import LODS, LodRow, LodTable, gaussians_from_volume, lod_table
from .sparse import SparseVolume, read_vdb

__all__ = ["Gaussians", "LODS", "LodRow", "LodTable", "SparseVolume", "gaussians_from_volume", "lod_table",
           "read_vdb"]
