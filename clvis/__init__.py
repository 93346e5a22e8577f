"""clvis: hand-written OpenCL kernels for scientific visualization.

Arrays in, arrays out: numpy arrays come back as numpy arrays, and
``pyopencl.array.Array`` inputs stay on the device (same queue).
See ``clvis.runtime`` for device choice and options.
"""

import sys as _sys

from . import datasets
from ._version import __version__
from .camera import Camera, grid_cameras, hemisphere_cameras
from .colormap import TransferFunction
from .errors import ClvisError, DataError, DeviceError, KernelBuildError
from .gauss import (
    GaussianImage,
    GaussianRenderer,
    Gaussians,
    SparseVolume,
    gaussians_from_points,
    gaussians_from_volume,
    read_vdb,
    render_gaussians,
)
from .io import PointCloud, Volume, read_points, read_volume, volumes
from .iso import IsoImage, IsoRenderer, zfp
from .primitives import compact, compact_indices, histogram, radix_sort, scan
from .raster import (
    FilteredImage,
    GBuffers,
    Rasterizer,
    depth_filter,
    morton_order,
    rasterize,
)
from .runtime import capabilities, default_queue, set_default_device

__all__ = [
    "Camera",
    "ClvisError",
    "DataError",
    "DeviceError",
    "FilteredImage",
    "GBuffers",
    "GaussianImage",
    "GaussianRenderer",
    "Gaussians",
    "IsoImage",
    "IsoRenderer",
    "KernelBuildError",
    "PointCloud",
    "Rasterizer",
    "SparseVolume",
    "TransferFunction",
    "Volume",
    "__version__",
    "capabilities",
    "compact",
    "compact_indices",
    "datasets",
    "default_queue",
    "depth_filter",
    "gaussians_from_points",
    "gaussians_from_volume",
    "grid_cameras",
    "hemisphere_cameras",
    "histogram",
    "morton_order",
    "radix_sort",
    "rasterize",
    "read_points",
    "read_vdb",
    "read_volume",
    "render_gaussians",
    "scan",
    "set_default_device",
    "volumes",
    "zfp",
]


def __getattr__(name: str) -> object:
    # clvis.view(obj), the browser viewer: a layer above the families, imported
    # when first used (its server, tornado, is the optional `view` extra)
    if name == "view":
        import clvis.view  # noqa: F401  (not `from . import view`: that would call this again)

        return _sys.modules["clvis.view"]
    raise AttributeError(f"module 'clvis' has no attribute {name!r}")
