"""distributed: sort-last rendering of partitioned point clouds and bricked
volumes on Dask workers (``pip install 'clvis[distributed]'``).

A layer above the families, like the command line: it uses the raster and iso
renderers on every worker and composites their frames by the smallest 64-bit
depth|id key per pixel (:mod:`clvis.distributed.composite`; the module, not
its function, is ``clvis.distributed.composite``)."""

from . import composite
from .composite import EMPTY_KEY, Partial, depth_keys
from .iso import DistributedIsoRenderer
from .raster import DistributedRasterizer, concatenate

__all__ = [
    "EMPTY_KEY",
    "DistributedIsoRenderer",
    "DistributedRasterizer",
    "Partial",
    "composite",
    "concatenate",
    "depth_keys",
]
