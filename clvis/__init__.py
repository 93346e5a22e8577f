"""clvis: hand-written OpenCL kernels for scientific visualization.

Arrays in, arrays out: numpy arrays come back as numpy arrays, and
``pyopencl.array.Array`` inputs stay on the device (same queue).
See ``clvis.runtime`` for device choice and options.
"""

from ._version import __version__
from .errors import ClvisError, DataError, DeviceError, KernelBuildError
from .primitives import compact, compact_indices, histogram, radix_sort, scan
from .runtime import capabilities, default_queue, set_default_device

__all__ = [
    "__version__", "ClvisError", "DataError", "DeviceError", "KernelBuildError",
    "capabilities", "compact", "compact_indices", "default_queue", "histogram",
    "radix_sort", "scan", "set_default_device",
]
