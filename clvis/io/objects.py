"""Data other libraries hold in memory, as clvis data: VTK datasets, and so
pyvista's meshes, point sets and images (they are VTK objects), and Open3D's
point clouds and triangle meshes.

:func:`from_vtk` takes a point set (vtkPolyData, vtkUnstructuredGrid,
vtkStructuredGrid, vtkPointSet: a pyvista ``PolyData``, ``UnstructuredGrid``,
``StructuredGrid``, ``PointSet``) as a :class:`~clvis.io.PointCloud`, read as
the ``.vtp``/``.vtu``/``.vts`` reader reads a file's (clvis.io.polydata: the
points, unsigned-char RGB(A) as colours, a velocity, a radius, the other
point arrays as attributes), and image data (vtkImageData: a pyvista
``ImageData`` / ``UniformGrid``) as a :class:`~clvis.io.Volume` of one
scalar array, as the ``.vti`` reader reads a file's: the named array, else
the active point scalars, else the one 1-component point array, else the same
of the cell data (one sample a cell, at its centre). The arrays are copied:
changing the dataset later changes nothing here. ``clvis.view(dataset)``
takes them too.

:func:`from_open3d` takes an Open3D point cloud or triangle mesh (the legacy
``open3d.geometry.PointCloud`` / ``TriangleMesh`` and the tensor
``open3d.t.geometry`` ones) as a :class:`~clvis.io.PointCloud`, as the
``.ply`` reader reads the file Open3D writes of it: the points (a mesh's
vertices), colours (Open3D's 0..1 floats) as 8-bit RGB, normals as the
attributes nx, ny, nz, a tensor cloud's other attributes by name. Positions
are float64 in Open3D: far from zero they are kept relative to their
minimum (``cloud.origin``), as for LAS. clvis does not import Open3D.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import DataError
from .cloud import PointCloud, _cloud, component_columns, relative_positions
from .volumes import Volume

__all__ = ["from_open3d", "from_vtk", "is_open3d_geometry", "is_vtk_dataset"]


def is_vtk_dataset(obj: Any) -> bool:
    """Whether `obj` is a VTK object (anything with VTK's IsA: pyvista's too)."""
    return callable(getattr(obj, "IsA", None)) and callable(getattr(obj, "GetClassName", None))


def from_vtk(dataset: Any, array: str | None = None) -> PointCloud | Volume:
    """A VTK dataset (a pyvista mesh, point set or image) as clvis data: a
    point set as a PointCloud, image data as a Volume (module docstring).

    array: image data only, the scalar array to take by name. A dataset of
    another kind (a rectilinear grid, a multiblock) is a TypeError naming it
    and what to do; an image whose direction matrix rotates its axes (one
    that only permutes and flips them is applied: the samples transposed and
    flipped) or with no one-component array, or a point set VTK cannot give
    as numbers, a DataError."""
    if not is_vtk_dataset(dataset):
        raise TypeError(
            "dataset: expected a VTK dataset (a pyvista mesh, point set or image), "
            f"got {type(dataset).__name__}"
        )
    from .vtk import _vtk

    ns = _vtk()[3]
    kind = dataset.GetClassName()
    if dataset.IsA("vtkImageData"):
        return _volume(dataset, kind, array, ns)
    if array is not None:
        raise ValueError(
            f"array: picks an image's scalar array; {kind} is a point set (its arrays are attributes)"
        )
    if dataset.IsA("vtkPointSet"):
        from .polydata import cloud_of

        return cloud_of(dataset, kind, ns)
    hint = {
        "vtkRectilinearGrid": "resample it to image data (pyvista: grid.cast_to_structured_grid() for its "
        "points, or sample it onto an ImageData)",
        "vtkMultiBlockDataSet": "take one block (pyvista: blocks[i]) or combine them (blocks.combine())",
        "vtkPartitionedDataSet": "take one partition, or combine them",
    }.get(kind, "clvis takes point sets (PolyData, UnstructuredGrid, StructuredGrid) and image data")
    raise TypeError(f"dataset: a {kind}: {hint}")


def _volume(img: Any, kind: str, array: str | None, ns: Any) -> Volume:
    dims = img.GetDimensions()
    for cells, data in ((False, img.GetPointData()), (True, img.GetCellData())):
        nx, ny, nz = (max(d - 1, 1) for d in dims) if cells else dims
        arr = _scalar_array(data, array, nx * ny * nz)
        if arr is None:
            continue
        try:
            values = np.array(ns.vtk_to_numpy(arr), copy=True).reshape(nz, ny, nx)
        except (TypeError, ValueError, AssertionError, KeyError) as e:  # a type numpy has not (bits)
            raise DataError(f"{kind}: its array {arr.GetName()!r} is not numbers numpy takes ({e})") from None
        from .vtk import image_axes  # the world's axes (a flipped or permuted Direction), steps > 0

        values, spacing, origin = image_axes(kind, img, values, cells)
        return Volume(values, spacing, tuple(float(o) for o in origin), array=arr.GetName())
    names = [
        f"{d.GetArrayName(i)} ({d.GetArray(i).GetNumberOfComponents() if d.GetArray(i) else '?'} components)"
        for d in (img.GetPointData(), img.GetCellData())
        for i in range(d.GetNumberOfArrays())
    ]
    what = f"no array named {array!r}" if array is not None else "no one-component scalar array"
    raise DataError(f"{kind} {'x'.join(map(str, dims))}: {what} (arrays: {', '.join(names) or 'none'})")


def _scalar_array(data: Any, name: str | None, n: int) -> Any:
    """The one-component array of `n` tuples to take from point or cell data:
    the named one, else the active scalars, else the only one-component one."""
    if name is not None:
        arr = data.GetArray(name)
    else:
        arr = data.GetScalars()
        if arr is None:
            ones = [
                data.GetArray(i)
                for i in range(data.GetNumberOfArrays())
                if data.GetArray(i) is not None and data.GetArray(i).GetNumberOfComponents() == 1
            ]
            arr = ones[0] if len(ones) == 1 else None
    if arr is None or arr.GetNumberOfComponents() != 1 or arr.GetNumberOfTuples() != n:
        return None
    return arr


def refuse_foreign(obj: Any, what: str, expected: str) -> None:
    """A renderer's argument check: where it was given another library's
    object (a pyvista/VTK dataset, an Open3D geometry) for `what`
    ("PointCloud" or "Volume"), a TypeError "`expected`, got" the words naming
    it and the call that converts it (numpy made an object array of it:
    "expected numbers, got dtype object"); nothing for anything else."""
    if is_vtk_dataset(obj):
        kind = obj.GetClassName()
        hint = f"a VTK dataset ({kind}: a pyvista mesh or image): clvis.from_vtk(it) gives the {what}"
    elif is_open3d_geometry(obj):
        hint = f"an Open3D {type(obj).__name__}: clvis.from_open3d(it) gives the PointCloud"
    else:
        return
    raise TypeError(f"{expected}, got {hint}")


def is_open3d_geometry(obj: Any) -> bool:
    """Whether `obj` is an Open3D object (its class defined in the open3d
    package: ``open3d.pybind...`` or ``open3d.cpu.pybind...``)."""
    return (getattr(type(obj), "__module__", "") or "").split(".")[0] == "open3d"


def from_open3d(geometry: Any) -> PointCloud:
    """An Open3D point cloud or triangle mesh (legacy or tensor) as a
    PointCloud: its points or vertices, colours, normals and (tensor
    geometry) other per-point attributes (module docstring). Another Open3D
    geometry (a voxel grid, a line set, an image) is a TypeError naming it;
    colours outside 0..1 or not finite, or attributes that are not one row
    per point, a DataError."""
    if not is_open3d_geometry(geometry):
        raise TypeError(
            f"geometry: expected an Open3D PointCloud or TriangleMesh, got {type(geometry).__name__}"
        )
    kind = type(geometry).__name__
    what: Any = f"Open3D {kind}"  # names it in errors, as a file's path would
    tensor = ".t." in type(geometry).__module__ or type(geometry).__module__.startswith("open3d.t")
    columns: dict[str, np.ndarray] = {}
    if tensor and kind in ("PointCloud", "TriangleMesh"):
        tmap = geometry.point if kind == "PointCloud" else geometry.vertex
        for name in tmap:
            t = tmap[name]
            columns[str(name)] = np.array((t.cpu() if hasattr(t, "cpu") else t).numpy(), copy=True)
    elif not tensor and kind in ("PointCloud", "TriangleMesh"):
        legacy = {
            "PointCloud": ("points", "colors", "normals"),
            "TriangleMesh": ("vertices", "vertex_colors", "vertex_normals"),
        }
        for key, attr in zip(("positions", "colors", "normals"), legacy[kind], strict=True):
            a = np.array(np.asarray(getattr(geometry, attr)), copy=True)
            if key == "positions" or len(a):
                columns[key] = a
    else:
        hint = {
            "VoxelGrid": "; its voxels' centres as points: "
            "[grid.get_voxel_center_coordinate(v.grid_index) for v in grid.get_voxels()]",
            "LineSet": "; its points: line_set.points",
        }.get(kind, "")
        raise TypeError(
            f"geometry: an {what}: clvis takes Open3D point clouds and triangle meshes "
            f"(their points or vertices){hint}"
        )
    xyz = columns.pop("positions", None)
    if xyz is None and tensor and not columns:  # an empty tensor cloud holds no positions at all
        xyz = np.zeros((0, 3), np.float32)
    if xyz is None or xyz.ndim != 2 or xyz.shape[1] != 3:
        raise DataError(f"{what}: no (N, 3) positions")
    n = len(xyz)
    for name, a in columns.items():
        if len(a) != n:
            raise DataError(f"{what}: its {name} hold {len(a)} rows for {n} points")
    positions, origin = relative_positions(xyz)
    fields: dict[str, Any] = {"positions": positions, "origin": origin, "attributes": {}}
    colors = columns.pop("colors", None)
    if colors is not None:
        fields["colors"] = _open3d_colors(colors, what)
    normals = columns.pop("normals", None)
    if normals is not None:
        fields["attributes"].update(
            {c: normals[:, k].astype(np.float32) for k, c in enumerate(("nx", "ny", "nz"))}
        )
    for name, a in columns.items():
        a = a.reshape(n, -1)
        if a.dtype.kind not in "biuf":
            raise DataError(f"{what}: its attribute {name!r} is not numbers ({a.dtype})")
        if a.shape[1] == 1:
            fields["attributes"][name] = a[:, 0]
        else:
            fields["attributes"].update(component_columns(name, a))
    return _cloud(what, **fields)


def _open3d_colors(colors: np.ndarray, what: str) -> np.ndarray:
    """Open3D's colours as (N, 3) uint8: floats in 0..1 (its convention),
    or 8-bit already (a tensor cloud's uint8 colours)."""
    if colors.ndim != 2 or colors.shape[1] not in (3, 4):
        raise DataError(f"{what}: colors of shape {colors.shape}; expected (N, 3)")
    if colors.dtype == np.uint8:
        return colors[:, :3].copy()
    if colors.dtype == np.uint16:  # 16-bit colours (a tensor cloud's, from a 16-bit source)
        return (colors[:, :3] // 257).astype(np.uint8)
    c = colors[:, :3].astype(np.float64)
    if c.size and not (np.isfinite(c).all() and c.min() >= 0 and c.max() <= 1):
        lo, hi = np.nanmin(c), np.nanmax(c)
        raise DataError(f"{what}: colors must be finite numbers in 0..1 (Open3D's), got {lo:.6g}..{hi:.6g}")
    return np.rint(c * 255).astype(np.uint8)
