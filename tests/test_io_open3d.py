"""Open3D's data as Open3D users hold it: clouds and meshes in memory
(clvis.from_open3d, read as the .ply reader reads the file Open3D writes of
them) and the text files Open3D writes (.pts, .xyzn, .xyzrgb, and its .pcd
of each encoding), against the same cloud through Open3D's PLY."""

import numpy as np
import pytest

import clvis
from clvis.errors import DataError

o3d = pytest.importorskip("open3d", reason="open3d-cpu is in the test extra")


def _cloud(n=200, offset=(0.0, 0.0, 0.0)):
    rng = np.random.default_rng(3)
    p = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(rng.random((n, 3)) * 10 + offset))
    p.colors = o3d.utility.Vector3dVector(rng.random((n, 3)))
    p.estimate_normals()
    return p


def _world(c):
    return c.positions.astype(np.float64) + (0 if c.origin is None else np.asarray(c.origin))


def test_a_legacy_cloud_is_read_as_its_ply_file_is(tmp_path):
    p = _cloud()
    assert o3d.io.write_point_cloud(str(tmp_path / "p.ply"), p)
    c, f = clvis.from_open3d(p), clvis.read_points(tmp_path / "p.ply")
    np.testing.assert_array_equal(c.positions, f.positions)
    np.testing.assert_array_equal(c.colors, f.colors)
    assert list(c.attributes) == list(f.attributes) == ["nx", "ny", "nz"]
    for k in c.attributes:
        np.testing.assert_array_equal(c.attributes[k], f.attributes[k])
    np.asarray(p.points)[:] = 0  # copied: changing the cloud later changes nothing
    assert c.positions.max() > 1


def test_tensor_clouds_and_meshes(tmp_path):
    p = _cloud()
    ref = clvis.from_open3d(p)
    t = o3d.t.geometry.PointCloud.from_legacy(p)
    t.point.intensity = o3d.core.Tensor(np.arange(200, dtype=np.float32).reshape(200, 1))
    c = clvis.from_open3d(t)
    np.testing.assert_array_equal(c.positions, ref.positions)
    np.testing.assert_array_equal(c.colors, ref.colors)
    assert list(c.attributes) == ["nx", "ny", "nz", "intensity"]
    np.testing.assert_array_equal(c.attributes["intensity"], np.arange(200))
    t.point.colors = o3d.core.Tensor(np.full((200, 3), 7, np.uint8))  # 8-bit colours as they are
    assert (clvis.from_open3d(t).colors[:, :3] == 7).all()
    mesh = o3d.geometry.TriangleMesh.create_sphere(radius=2.0)
    mesh.paint_uniform_color([1.0, 0.0, 0.0])
    m = clvis.from_open3d(mesh)
    assert len(m) == len(mesh.vertices) and (m.colors[:, :3] == [255, 0, 0]).all()
    np.testing.assert_allclose(np.linalg.norm(m.positions, axis=1), 2.0, rtol=1e-6)
    tm = clvis.from_open3d(o3d.t.geometry.TriangleMesh.from_legacy(mesh))
    np.testing.assert_array_equal(tm.positions, m.positions)


def test_far_from_zero_kept_relative_to_its_minimum():
    """Open3D's float64 points at map coordinates: float32 of 4e6 + [0, 10)
    would fall onto a grid of 0.25; kept relative to their minimum, as LAS."""
    p = _cloud(offset=(5e5, 4e6, 100.0))
    c = clvis.from_open3d(p)
    assert c.origin is not None
    np.testing.assert_allclose(_world(c), np.asarray(p.points), atol=1e-6)


def test_what_it_refuses():
    with pytest.raises(TypeError, match="expected an Open3D PointCloud or TriangleMesh, got ndarray"):
        clvis.from_open3d(np.zeros((3, 3)))
    with pytest.raises(TypeError, match="an Open3D VoxelGrid: .*get_voxel_center_coordinate"):
        clvis.from_open3d(o3d.geometry.VoxelGrid())
    with pytest.raises(TypeError, match="an Open3D LineSet: .*line_set.points"):
        clvis.from_open3d(o3d.geometry.LineSet())
    p = _cloud()
    p.colors = o3d.utility.Vector3dVector(np.full((200, 3), 2.0))
    with pytest.raises(DataError, match=r"Open3D PointCloud: colors must be finite numbers in 0..1"):
        clvis.from_open3d(p)
    assert len(clvis.from_open3d(o3d.geometry.PointCloud())) == 0
    assert len(clvis.from_open3d(o3d.t.geometry.PointCloud())) == 0  # was "no (N, 3) positions"
    t = o3d.t.geometry.PointCloud(o3d.core.Tensor(np.zeros((2, 3), np.float32)))
    t.point.colors = o3d.core.Tensor(np.array([[65535, 0, 257], [514, 65535, 0]], np.uint16))
    np.testing.assert_array_equal(clvis.from_open3d(t).colors[:, :3], [[255, 0, 1], [2, 255, 0]])  # 16-bit


@pytest.mark.parametrize(
    "name, kw",
    [
        ("a.pts", {}),
        ("a.xyzrgb", {}),
        ("a.xyzn", {}),
        ("a.pcd", {"write_ascii": True}),
        ("b.pcd", {}),
        ("c.pcd", {"compressed": True}),
    ],
)
def test_the_files_open3d_writes(tmp_path, name, kw):
    """Each point cloud format Open3D writes (o3d.io.write_point_cloud), read
    as the same cloud through Open3D's .ply: .pts, .xyzn and .xyzrgb were
    unknown formats."""
    p = _cloud()
    assert o3d.io.write_point_cloud(str(tmp_path / "p.ply"), p)
    assert o3d.io.write_point_cloud(str(tmp_path / name), p, **kw)
    ref, c = clvis.read_points(tmp_path / "p.ply"), clvis.read_points(tmp_path / name)
    np.testing.assert_allclose(_world(c), _world(ref), atol=1e-6)
    if name.endswith((".pts", ".xyzrgb", ".pcd")):
        np.testing.assert_array_equal(c.colors[:, :3], ref.colors[:, :3])
    if name.endswith(".xyzn"):
        for k in ("nx", "ny", "nz"):
            np.testing.assert_allclose(c.attributes[k], ref.attributes[k], atol=1e-6)


def test_clvis_view_takes_open3d_geometry():
    """clvis.view(pcd), as Open3D's draw_geometries([pcd]): the cloud a
    PointScene of from_open3d's cloud (it was a TypeError: not an (N, 3)
    array); a geometry from_open3d refuses is refused there too."""
    p = _cloud()
    scene = clvis.view.scene_for(p)
    assert type(scene).__name__ == "PointScene"
    np.testing.assert_array_equal(scene.cloud.positions, clvis.from_open3d(p).positions)
    np.testing.assert_array_equal(scene.cloud.colors, clvis.from_open3d(p).colors)
    mesh = clvis.view.scene_for(o3d.geometry.TriangleMesh.create_sphere())
    assert len(mesh.cloud.positions) == 762
    with pytest.raises(TypeError, match="an Open3D VoxelGrid"):
        clvis.view.scene_for(o3d.geometry.VoxelGrid())


def test_a_renderer_given_an_open3d_cloud_names_from_open3d():
    """clvis.rasterize(o3d_cloud, ...): the TypeError said "expected numbers,
    got an object array"; it names the geometry and clvis.from_open3d now."""
    cam = clvis.Camera.fit((0, 0, 0), (10, 10, 10), aspect=1.0)
    for call in (
        lambda: clvis.rasterize(_cloud(), cam, 16, 16),
        lambda: clvis.gaussians_from_points(_cloud()),
    ):
        with pytest.raises(
            TypeError, match=r"an Open3D PointCloud: clvis.from_open3d\(it\) gives the PointCloud"
        ):
            call()


def test_pure_colours_open3d_writes_as_xyzrgb(tmp_path):
    """A cloud painted one pure colour (segmentation labels, paint_uniform_color):
    Open3D writes '1.0000000000 0.0000000000 0.0000000000', which read as
    8-bit (1, 0, 0), near black; it is red, as from_open3d and the .ply say."""
    p = _cloud(50)
    p.paint_uniform_color([1.0, 0.0, 0.0])
    assert o3d.io.write_point_cloud(str(tmp_path / "red.xyzrgb"), p)
    got = clvis.read_points(tmp_path / "red.xyzrgb").colors[:, :3]
    np.testing.assert_array_equal(got, clvis.from_open3d(p).colors[:, :3])
    assert (got == [255, 0, 0]).all()
