"""Data other libraries hold in memory, as clvis data: VTK datasets, and so
pyvista's meshes, point sets and images (they are VTK objects).

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
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import DataError
from .cloud import PointCloud
from .volumes import Volume

__all__ = ["from_vtk", "is_vtk_dataset"]


def is_vtk_dataset(obj: Any) -> bool:
    """Whether `obj` is a VTK object (anything with VTK's IsA: pyvista's too)."""
    return callable(getattr(obj, "IsA", None)) and callable(getattr(obj, "GetClassName", None))


def from_vtk(dataset: Any, array: str | None = None) -> PointCloud | Volume:
    """A VTK dataset (a pyvista mesh, point set or image) as clvis data: a
    point set as a PointCloud, image data as a Volume (module docstring).

    array: image data only, the scalar array to take by name. A dataset of
    another kind (a rectilinear grid, a multiblock) is a TypeError naming it
    and what to do; an image with a rotated axis (a direction matrix that is
    not the identity) or no one-component array, or a point set VTK cannot
    give as numbers, a DataError."""
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
    direction = img.GetDirectionMatrix() if hasattr(img, "GetDirectionMatrix") else None
    if direction is not None and not all(
        direction.GetElement(i, j) == (1.0 if i == j else 0.0) for i in range(3) for j in range(3)
    ):
        raise DataError(f"{kind}: its axes are rotated (a direction matrix); clvis volumes are axis-aligned")
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
        sx, sy, sz = img.GetSpacing()
        origin = list(img.GetOrigin())
        if cells:  # the cell centres: half a step in along each axis that has cells
            origin = [
                o + (s / 2 if d > 1 else 0.0) for o, s, d in zip(origin, (sx, sy, sz), dims, strict=True)
            ]
        spacing = (float(sz), float(sy), float(sx))
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
