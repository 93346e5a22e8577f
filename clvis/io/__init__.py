"""Reading and writing data files.

- :mod:`~clvis.io.points`: point clouds (:class:`PointCloud`,
  :func:`read_points`, :func:`write_ply`, :func:`save_npz`), one module per
  format whose checks are long (:mod:`~clvis.io.ply`, :mod:`~clvis.io.las`,
  :mod:`~clvis.io.pcd`, :mod:`~clvis.io.ascii` for .xyz/.txt/.csv/.pts/.xyzn/.xyzrgb,
  :mod:`~clvis.io.polydata` for VTK's .vtp, .vtu, .vts and legacy .vtk point
  sets);
- :mod:`~clvis.io.volumes`: volumes (:func:`read_volume`, :class:`Volume`):
  raw, NPY, NIfTI and VTK image data (:mod:`~clvis.io.vtk`, whose header
  checks the VTK point sets share), and :func:`otsu_level` (a scan's
  default isovalue);
- :mod:`~clvis.io.npy`: NPY and NPZ read safely (:func:`load_npy`,
  :func:`load_npz`, :func:`npy_shape`), for both;
- :mod:`~clvis.io.objects`: data other libraries hold in memory
  (:func:`from_vtk`: a VTK or pyvista point set or image; :func:`from_open3d`:
  an Open3D point cloud or triangle mesh).

:func:`~clvis.gauss.read_vdb` (OpenVDB, into the Gaussian family's sparse
layout) lives with :class:`~clvis.gauss.SparseVolume`.
"""

from .cloud import PointCloud
from .npy import load_npy, load_npz, npy_shape
from .objects import from_open3d, from_vtk
from .ply import write_ply
from .points import read_points, save_npz
from .volumes import FORMATS, RAW_TYPES, Volume, otsu_level, raw_layout, read_volume

__all__ = [
    "FORMATS",
    "RAW_TYPES",
    "PointCloud",
    "Volume",
    "from_open3d",
    "from_vtk",
    "load_npy",
    "load_npz",
    "npy_shape",
    "otsu_level",
    "raw_layout",
    "read_points",
    "read_volume",
    "save_npz",
    "write_ply",
]
