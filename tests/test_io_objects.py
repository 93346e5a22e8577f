"""clvis.from_vtk: VTK datasets made in memory (what pyvista's meshes, point
sets and images are) as clvis data, read as the file readers read the same
data written by VTK; its refusals; and clvis.view taking them."""

import numpy as np
import pytest

import clvis
from clvis.errors import DataError

vtk = pytest.importorskip("vtk", reason="vtk is in the test extra")
from test_points_vtk import N, _check, _polydata  # noqa: E402
from vtk.util import numpy_support  # noqa: E402


def _image(values, spacing=(0.5, 2.0, 1.0), origin=(10.0, -3.0, 7.5), cells=False, name="density"):
    """vtkImageData of `values` [z, y, x] (x fastest, as VTK orders points);
    as cell data with `cells` (then one more point a side)."""
    img = vtk.vtkImageData()
    nz, ny, nx = values.shape
    img.SetDimensions(*((nx + 1, ny + 1, nz + 1) if cells else (nx, ny, nz)))
    img.SetSpacing(*spacing)
    img.SetOrigin(*origin)
    a = numpy_support.numpy_to_vtk(np.ascontiguousarray(values).ravel(), deep=True)
    a.SetName(name)
    (img.GetCellData() if cells else img.GetPointData()).SetScalars(a)
    return img


def test_a_point_set_is_read_as_its_file_is(tmp_path):
    """A vtkPolyData (a pyvista PolyData) as the .vtp reader reads it
    written: far-from-zero doubles relative to their minimum, RGB as colours,
    velocity, the other point arrays as attributes; the arrays copied."""
    pd = _polydata()
    cloud = clvis.from_vtk(pd)
    _check(cloud)
    w = vtk.vtkXMLPolyDataWriter()
    w.SetFileName(str(tmp_path / "p.vtp"))
    w.SetInputData(pd)
    assert w.Write() == 1
    written = clvis.read_points(tmp_path / "p.vtp")
    np.testing.assert_array_equal(cloud.positions, written.positions)
    np.testing.assert_array_equal(cloud.origin, written.origin)
    assert sorted(cloud.attributes) == sorted(written.attributes)
    numpy_support.vtk_to_numpy(pd.GetPointData().GetArray("temperature"))[:] = -1  # the dataset changes
    assert (cloud.attributes["temperature"] >= 0).all()  # the cloud does not
    ug = vtk.vtkUnstructuredGrid()  # a point set of another kind, no arrays
    ug.SetPoints(pd.GetPoints())
    assert len(clvis.from_vtk(ug)) == N and clvis.from_vtk(ug).colors is None


def test_image_data_is_a_volume():
    """vtkImageData (a pyvista ImageData) as a Volume [z, y, x] with its
    spacing (dz, dy, dx) and origin: its active point scalars, an array by
    name, or its cell data (one sample a cell, at the cell's centre)."""
    rng = np.random.default_rng(3)
    values = rng.random((4, 5, 6)).astype(np.float32)
    v = clvis.from_vtk(_image(values))
    np.testing.assert_array_equal(v.data, values)
    assert v.spacing == (1.0, 2.0, 0.5) and v.origin == (10.0, -3.0, 7.5) and v.array == "density"
    img = _image(values)
    other = numpy_support.numpy_to_vtk((values * 2).ravel(), deep=True)
    other.SetName("twice")
    img.GetPointData().AddArray(other)
    np.testing.assert_array_equal(clvis.from_vtk(img, array="twice").data, values * 2)
    cells = clvis.from_vtk(_image(values, cells=True))
    np.testing.assert_array_equal(cells.data, values)
    assert cells.origin == (10.25, -2.0, 8.0)  # half a step in along each axis
    scene = clvis.view.scene_for(_image(values))  # clvis.view takes it as the volume it is
    assert type(scene).__name__ == "VolumeScene" and scene.spacing == (1.0, 2.0, 0.5)
    assert type(clvis.view.scene_for(_polydata())).__name__ == "PointScene"


def test_image_data_of_negative_or_flat_spacing_gets_forward_steps():
    """An image whose spacing is negative along an axis (VTK puts sample i at
    origin + i * spacing: the axis runs backward) or 0 along a flat axis (a
    2-D image) was a Volume that every renderer refused; now the backward
    axis is flipped, its origin at its last sample, and the flat axis gets a
    step of 1, as read_volume reads such a file."""
    values = np.arange(2 * 3 * 4, dtype=np.float32).reshape(2, 3, 4)
    v = clvis.from_vtk(_image(values, spacing=(-0.5, 2.0, 1.0), origin=(10.0, 0.0, 0.0)))
    np.testing.assert_array_equal(v.data, values[:, :, ::-1])
    assert v.spacing == (1.0, 2.0, 0.5) and v.origin == (8.5, 0.0, 0.0)
    flat = clvis.from_vtk(_image(values[:1], spacing=(1.0, 1.0, 0.0)))
    assert flat.spacing == (1.0, 1.0, 1.0)
    clvis.gaussians_from_volume(flat)  # a renderer takes it
    with pytest.raises(DataError, match="vtkImageData: spacing 0 along x: its 4 samples at one place"):
        clvis.from_vtk(_image(values, spacing=(0.0, 1.0, 1.0)))


def test_image_data_whose_direction_permutes_and_flips_axes():
    """A Direction that only swaps and flips axes (x and y swapped, one of
    them reversed: a quarter turn) was refused as a rotation; it is applied
    now, each sample where VTK puts it (origin + Direction @ (ijk * spacing)),
    the samples transposed and flipped, never resampled."""
    values = np.arange(2 * 3 * 4, dtype=np.float32).reshape(2, 3, 4)  # [k, j, i]
    img = _image(values, spacing=(0.5, 2.0, 1.0), origin=(10.0, 0.0, 0.0))
    img.SetDirectionMatrix(0, -1, 0, 1, 0, 0, 0, 0, 1)  # i along +y, j along -x
    v = clvis.from_vtk(img)
    assert v.shape == (2, 4, 3) and v.spacing == (1.0, 0.5, 2.0) and v.origin == (6.0, 0.0, 0.0)
    for k in range(2):
        for j in range(3):
            for i in range(4):  # VTK's point of sample (i, j, k), and the Volume's sample there
                point = img.GetPoint(i + 4 * j + 12 * k)
                steps = zip(point, v.origin, v.spacing[::-1], strict=True)
                ix, iy, iz = (round((p - o) / st) for p, o, st in steps)
                assert v.data[iz, iy, ix] == values[k, j, i]


def test_what_from_vtk_refuses():
    values = np.zeros((3, 3, 3), np.float32)
    with pytest.raises(TypeError, match="expected a VTK dataset .* got ndarray"):
        clvis.from_vtk(values)
    with pytest.raises(TypeError, match="a vtkRectilinearGrid: resample it to image data"):
        clvis.from_vtk(vtk.vtkRectilinearGrid())
    with pytest.raises(ValueError, match="array: picks an image's scalar array; vtkPolyData is a point set"):
        clvis.from_vtk(_polydata(), array="temperature")
    with pytest.raises(DataError, match=r"no array named 'nope' \(arrays: density \(1 components\)\)"):
        clvis.from_vtk(_image(values), array="nope")
    img = _image(values)
    img.GetPointData().RemoveArray("density")
    with pytest.raises(DataError, match=r"vtkImageData 3x3x3: no one-component scalar array \(arrays: none"):
        clvis.from_vtk(img)
    img = _image(values)
    c, s = np.cos(0.3), np.sin(0.3)
    img.SetDirectionMatrix(c, -s, 0, s, c, 0, 0, 0, 1)  # turned 0.3 rad about z: a rotated image
    with pytest.raises(DataError, match="its axes are rotated"):
        clvis.from_vtk(img)


def test_pyvista_objects_as_a_pyvista_user_holds_them():
    """pyvista's own objects (they are VTK datasets): a mesh with a point
    array, a point cloud with 8-bit RGB, an ImageData, and one of the files
    pyvista's wheel carries read by pyvista; clvis.view takes them."""
    pv = pytest.importorskip("pyvista", reason="pyvista is in the test extra")
    from pyvista import examples

    mesh = pv.Sphere(radius=2.0)
    mesh["elev"] = mesh.points[:, 2]
    c = clvis.from_vtk(mesh)
    assert len(c) == mesh.n_points and "elev" in c.attributes
    np.testing.assert_allclose(np.linalg.norm(c.positions, axis=1), 2.0, rtol=1e-5)
    rgb = np.random.default_rng(0).integers(0, 256, (500, 3)).astype(np.uint8)
    cloud = pv.PolyData(np.random.default_rng(1).random((500, 3)).astype(np.float32))
    cloud["RGB"] = rgb
    np.testing.assert_array_equal(clvis.from_vtk(cloud).colors[:, :3], rgb)
    img = pv.ImageData(dimensions=(10, 12, 14), spacing=(0.5, 1.0, 2.0), origin=(1.0, 2.0, 3.0))
    img["v"] = np.arange(img.n_points, dtype=np.float32)
    v = clvis.from_vtk(img)
    assert v.data.shape == (14, 12, 10) and v.spacing == (2.0, 1.0, 0.5) and v.origin == (1.0, 2.0, 3.0)
    np.testing.assert_array_equal(v.data.ravel(), img["v"])
    channels = clvis.from_vtk(pv.read(examples.__file__.replace("__init__.py", "channels.vti")))
    assert channels.data.ndim == 3 and np.isfinite(channels.data).all()
    assert type(clvis.view.scene_for(mesh)).__name__ == "PointScene"
    assert type(clvis.view.scene_for(img)).__name__ == "VolumeScene"


def test_a_renderer_given_a_vtk_dataset_names_from_vtk():
    """A pyvista user's first try, clvis.rasterize(mesh, ...) or
    clvis.IsoRenderer(image): numpy made an object array of the dataset and
    the TypeError said "expected numbers, got an object array (dtype
    object)"; it names the dataset and clvis.from_vtk now (clvis.view takes
    the dataset itself)."""
    pd, img = _polydata(), _image(np.zeros((4, 5, 6), np.float32))
    cam = clvis.Camera.fit((0, 0, 0), (1, 1, 1), aspect=1.0)
    cloud_calls = (
        lambda: clvis.rasterize(pd, cam, 16, 16),
        lambda: clvis.Rasterizer(pd),
        lambda: clvis.gaussians_from_points(pd),
    )
    for call in cloud_calls:
        with pytest.raises(
            TypeError, match=r"a VTK dataset \(vtkPolyData.*clvis.from_vtk\(it\) gives the PointCloud"
        ):
            call()
    volume_calls = (
        lambda: clvis.IsoRenderer(img),
        lambda: clvis.gaussians_from_volume(img),
        lambda: clvis.SparseVolume.from_dense(img),
        lambda: clvis.zfp.compress(img, 8),
    )
    for call in volume_calls:
        with pytest.raises(
            TypeError, match=r"a VTK dataset \(vtkImageData.*clvis.from_vtk\(it\) gives the Volume"
        ):
            call()
