"""clvis: hand-written OpenCL kernels for scientific visualization.

Arrays in, arrays out: numpy arrays come back as numpy arrays, and
``pyopencl.array.Array`` inputs stay on the device (same queue).
See ``clvis.runtime`` for device choice and options.
"""

from __future__ import annotations

import sys as _sys

from ._version import __version__

# typing.TYPE_CHECKING without importing typing (type checkers take any
# TYPE_CHECKING as true): `import clvis` imports nothing else
TYPE_CHECKING = False
if TYPE_CHECKING:  # the names for type checkers; at run time __getattr__ imports them
    from . import datasets
    from .camera import Camera, grid_cameras, hemisphere_cameras
    from .colormap import TransferFunction
    from .errors import AspectWarning, ClvisError, DataError, DeviceError, KernelBuildError
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
    from .io import PointCloud, Volume, from_open3d, from_vtk, read_points, read_volume, volumes
    from .iso import IsoImage, IsoRenderer, zfp
    from .primitives import compact, compact_indices, histogram, radix_sort, scan
    from .raster import (
        FilteredImage,
        GBuffers,
        Rasterizer,
        morton_order,
        rasterize,
    )
    from .raster.depth_filter import depth_filter  # (clvis.raster.depth_filter is a module too)
    from .runtime import capabilities, default_queue, set_default_device

# each public name -> the module that defines it
_WHERE = {
    **dict.fromkeys(["Camera", "grid_cameras", "hemisphere_cameras"], ".camera"),
    "TransferFunction": ".colormap",
    **dict.fromkeys(
        ["AspectWarning", "ClvisError", "DataError", "DeviceError", "KernelBuildError"], ".errors"
    ),
    **dict.fromkeys(
        [
            "GaussianImage",
            "GaussianRenderer",
            "Gaussians",
            "SparseVolume",
            "gaussians_from_points",
            "gaussians_from_volume",
            "read_vdb",
            "render_gaussians",
        ],
        ".gauss",
    ),
    **dict.fromkeys(
        ["PointCloud", "Volume", "from_open3d", "from_vtk", "read_points", "read_volume", "volumes"], ".io"
    ),
    **dict.fromkeys(["IsoImage", "IsoRenderer", "zfp"], ".iso"),
    **dict.fromkeys(["compact", "compact_indices", "histogram", "radix_sort", "scan"], ".primitives"),
    **dict.fromkeys(
        ["FilteredImage", "GBuffers", "Rasterizer", "depth_filter", "morton_order", "rasterize"], ".raster"
    ),
    **dict.fromkeys(["capabilities", "default_queue", "set_default_device"], ".runtime"),
}

__all__ = [
    "AspectWarning",
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
    "from_open3d",
    "from_vtk",
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
    # The public names and the subpackages load when first used: `import clvis`
    # (and so the command line's start, before it handles Ctrl-C) does not wait
    # for NumPy, PyOpenCL and the families.
    if name == "view":
        # clvis.view(obj), the browser viewer: a layer above the families (its
        # server, tornado, is the optional `view` extra)
        import clvis.view  # noqa: F401  (not `from . import view`: that would call this again)

        return _sys.modules["clvis.view"]
    import importlib.util

    where = _WHERE.get(name)
    if where is not None:
        value = getattr(importlib.import_module(where, __name__), name)
    elif not name.startswith("__") and importlib.util.find_spec(f"{__name__}.{name}") is not None:
        value = importlib.import_module(f"{__name__}.{name}")  # clvis.io, clvis.runtime, ...
    else:
        raise AttributeError(f"module 'clvis' has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
