"""clvis: hand-written OpenCL kernels for scientific visualization.

Arrays in, arrays out: numpy arrays come back as numpy arrays, and
``pyopencl.array.Array`` inputs stay on the device (same queue).
See ``clvis.runtime`` for device choice and options.
"""

from ._version import __version__
from .camera import Camera, grid_cameras, hemisphere_cameras
from .errors import ClvisError, DataError, DeviceError, KernelBuildError
from .io import PointCloud, read_points
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
    "__version__", "ClvisError", "DataError", "DeviceError", "KernelBuildError",
    "Camera", "FilteredImage", "GBuffers", "PointCloud", "Rasterizer",
    "capabilities", "compact", "compact_indices", "default_queue", "depth_filter",
    "grid_cameras", "histogram", "hemisphere_cameras", "morton_order", "radix_sort",
    "rasterize", "read_points", "scan", "set_default_device",
]
