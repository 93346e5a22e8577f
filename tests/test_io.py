"""PointCloud validation, file round trips, and malformed files raising DataError."""

import numpy as np
import pytest

from clvis.errors import DataError
from clvis.io import PointCloud, read_points, save_npz, write_ply

plyfile = pytest.importorskip("plyfile")
laspy = pytest.importorskip("laspy")


def _cloud(n=50, seed=0, **extra):
    rng = np.random.default_rng(seed)
    return PointCloud(rng.normal(0, 10, (n, 3)), **extra)


def _full_cloud(n=50, seed=0):
    rng = np.random.default_rng(seed)
    return PointCloud(
        rng.normal(0, 10, (n, 3)),
        colors=rng.integers(0, 256, (n, 4), dtype=np.uint8),
        attributes={
            "intensity": rng.random(n).astype(np.float32),
            "label": rng.integers(0, 9, n).astype(np.uint8),
        },
        velocity=rng.normal(0, 1, (n, 3)),
        radius=rng.random(n),
        origin=(1e6, -2.5, 0.125),
    )


def _assert_same(a: PointCloud, b: PointCloud):
    assert len(a) == len(b)
    np.testing.assert_array_equal(a.positions, b.positions)
    for name in ("colors", "velocity", "radius"):
        x, y = getattr(a, name), getattr(b, name)
        assert (x is None) == (y is None), name
        if x is not None:
            assert x.dtype == y.dtype
            np.testing.assert_array_equal(x, y)
    assert a.attribute_names == b.attribute_names
    for k in a.attributes:
        assert a.attributes[k].dtype == b.attributes[k].dtype
        np.testing.assert_array_equal(a.attributes[k], b.attributes[k])
    np.testing.assert_array_equal(a.origin, b.origin)


# ---------------------------------------------------------------- PointCloud


def test_pointcloud_conversions():
    n = 4
    pc = PointCloud(
        np.arange(12, dtype=np.int64).reshape(n, 3),
        colors=np.array([[0, 0.5, 1]] * n),
        attributes={
            "f64": np.arange(n, dtype=np.float64),
            "i32": np.arange(n, dtype=np.int32),
            "u8": np.arange(n, dtype=np.uint8),
            "flag": np.array([True, False] * 2),
        },
        radius=[1, 2, 3, 4],
    )
    assert pc.positions.dtype == np.float32 and pc.positions.flags.c_contiguous
    np.testing.assert_array_equal(pc.colors, [[0, 128, 255, 255]] * n)
    assert pc.attributes["f64"].dtype == np.float32
    assert pc.attributes["i32"].dtype == np.float32
    assert pc.attributes["u8"].dtype == np.uint8
    assert pc.attributes["flag"].dtype == np.uint8
    np.testing.assert_array_equal(pc.attributes["flag"], [1, 0, 1, 0])
    assert pc.radius.dtype == np.float32 and pc.velocity is None
    np.testing.assert_array_equal(pc.origin, 0)
    assert len(pc) == n and pc.attribute_names == ("f64", "i32", "u8", "flag")


def test_pointcloud_colors():
    p = np.zeros((2, 3))
    u16 = PointCloud(p, colors=np.array([[65535, 256, 255], [0, 511, 32768]], dtype=np.uint16))
    np.testing.assert_array_equal(u16.colors, [[255, 1, 0, 255], [0, 1, 128, 255]])
    big = PointCloud(p, colors=np.array([[65535, 256, 255], [0, 511, 32768]], dtype=">u2"))  # big-endian
    np.testing.assert_array_equal(big.colors, u16.colors)
    # 8-bit colours in 16-bit fields (laspy's simple.las, autzen): as is, as read_points
    # takes them from a LAS file; >> 8 made the cloud black
    low = np.array([[249, 0, 10], [1, 2, 255]], dtype=np.uint16)
    np.testing.assert_array_equal(PointCloud(p, colors=low).colors, [[249, 0, 10, 255], [1, 2, 255, 255]])
    rgba = PointCloud(p, colors=np.array([[1, 2, 3, 4], [5, 6, 7, 8]], dtype=np.uint8))
    np.testing.assert_array_equal(rgba.colors, [[1, 2, 3, 4], [5, 6, 7, 8]])
    ints = PointCloud(p, colors=[[255, 0, 10], [1, 2, 3]])  # int64 within 0..255
    np.testing.assert_array_equal(ints.colors, [[255, 0, 10, 255], [1, 2, 3, 255]])
    assert ints.colors.dtype == np.uint8


def test_a_laspy_users_colours_match_read_points():
    """PointCloud(xyz, colors=np.c_[las.red, las.green, las.blue]) of laspy's
    simple.laz (8-bit colours in 16-bit fields) was black; read_points drew it
    in colour."""
    from pathlib import Path

    laspy = pytest.importorskip("laspy")
    path = Path(__file__).parent / "data" / "laspy_simple.laz"
    las = laspy.read(str(path))
    rgb = np.stack([np.asarray(las.red), np.asarray(las.green), np.asarray(las.blue)], axis=1)
    assert rgb.dtype == np.uint16 and 0 < rgb.max() <= 255
    pc = PointCloud(
        np.stack([las.x, las.y, las.z], axis=1) - [las.x.min(), las.y.min(), las.z.min()], colors=rgb
    )
    np.testing.assert_array_equal(pc.colors, read_points(path).colors)


def test_bounds_and_subset():
    p = np.array([[0, 1, 2], [np.nan, 100, 100], [-1, 5, 3], [4, -2, np.inf]])
    pc = PointCloud(
        p,
        colors=np.zeros((4, 3), np.uint8),
        attributes={"a": np.arange(4.0)},
        velocity=np.ones((4, 3)),
        radius=np.arange(4.0),
        origin=(1, 2, 3),
    )
    lo, hi = pc.bounds()
    assert lo.dtype == np.float64
    np.testing.assert_array_equal(lo, [-1, 1, 2])
    np.testing.assert_array_equal(hi, [0, 5, 3])
    sub = pc.subset(np.array([True, False, True, False]))
    assert len(sub) == 2
    np.testing.assert_array_equal(sub.attributes["a"], [0, 2])
    np.testing.assert_array_equal(sub.radius, [0, 2])
    np.testing.assert_array_equal(sub.origin, [1, 2, 3])
    np.testing.assert_array_equal(pc.subset([3, 0]).positions[1], [0, 1, 2])
    assert len(pc.subset(slice(1, None))) == 3
    with pytest.raises(ValueError, match="no finite points"):
        PointCloud([[np.nan, 0, 0]]).bounds()
    with pytest.raises(ValueError, match="index"):
        pc.subset(np.array([True, False]))
    with pytest.raises(TypeError, match="index"):
        pc.subset(np.array([0.5]))


@pytest.mark.parametrize(
    "kwargs,exc,name",
    [
        ({"positions": np.zeros((3, 2))}, ValueError, "positions"),
        ({"positions": np.zeros(3)}, ValueError, "positions"),
        ({"positions": np.array([["a", "b", "c"]])}, TypeError, "positions"),
        ({"positions": np.zeros((3, 3), bool)}, TypeError, "positions"),
        ({"positions": None}, TypeError, "positions"),
        ({"positions": np.zeros((3, 3)), "colors": np.zeros((2, 3), np.uint8)}, ValueError, "colors"),
        ({"positions": np.zeros((3, 3)), "colors": np.zeros((3, 2), np.uint8)}, ValueError, "colors"),
        ({"positions": np.zeros((3, 3)), "colors": np.full((3, 3), 1.5)}, ValueError, "colors"),
        ({"positions": np.zeros((3, 3)), "colors": np.full((3, 3), np.nan)}, ValueError, "colors"),
        ({"positions": np.zeros((3, 3)), "colors": np.full((3, 3), 300)}, ValueError, "colors"),
        ({"positions": np.zeros((3, 3)), "velocity": np.zeros((4, 3))}, ValueError, "velocity"),
        ({"positions": np.zeros((3, 3)), "radius": np.zeros(2)}, ValueError, "radius"),
        ({"positions": np.zeros((3, 3)), "radius": np.zeros((3, 1))}, ValueError, "radius"),
        ({"positions": np.zeros((3, 3)), "attributes": {"t": np.zeros(4)}}, ValueError, "'t'"),
        ({"positions": np.zeros((3, 3)), "attributes": {"t": np.zeros((3, 2))}}, ValueError, "'t'"),
        ({"positions": np.zeros((3, 3)), "attributes": {"t": np.array(["a"] * 3)}}, TypeError, "'t'"),
        ({"positions": np.zeros((3, 3)), "attributes": {1: np.zeros(3)}}, TypeError, "attributes"),
        ({"positions": np.zeros((3, 3)), "attributes": [np.zeros(3)]}, TypeError, "attributes"),
        ({"positions": np.zeros((3, 3)), "origin": (0, 0)}, ValueError, "origin"),
        ({"positions": np.zeros((3, 3)), "origin": (0, 0, np.nan)}, ValueError, "origin"),
    ],
)
def test_pointcloud_bad_input(kwargs, exc, name):
    with pytest.raises(exc, match=name):
        PointCloud(**kwargs)


def test_empty_cloud_round_trips(tmp_path):
    pc = PointCloud(np.zeros((0, 3)), colors=np.zeros((0, 3), np.uint8))
    for name in ("e.ply", "e.npz"):
        (write_ply if name.endswith("ply") else save_npz)(tmp_path / name, pc)
        _assert_same(read_points(tmp_path / name), pc)


# ---------------------------------------------------------------- PLY


@pytest.mark.parametrize("text", [False, True])
@pytest.mark.parametrize("full", [False, True])
def test_ply_round_trip(tmp_path, text, full):
    pc = _full_cloud() if full else _cloud()
    path = tmp_path / "c.ply"
    write_ply(path, pc, text=text)
    assert path.read_bytes().startswith(b"ply\nformat " + (b"ascii" if text else b"binary_little_endian"))
    _assert_same(read_points(path), pc)


def test_ply_foreign_properties(tmp_path):
    """A PLY written by someone else: r/g/b naming, velocity_*, doubles, extra elements."""
    n = 6
    v = np.zeros(
        n,
        dtype=[
            ("x", ">f8"),
            ("y", ">f8"),
            ("z", ">f8"),
            ("r", "u1"),
            ("g", "u1"),
            ("b", "u1"),
            ("velocity_x", "f4"),
            ("velocity_y", "f4"),
            ("velocity_z", "f4"),
            ("nx", "f4"),
            ("scalar_temp", "i2"),
            ("red", "u1"),
        ],
    )
    v["x"] = np.arange(n) + 0.25
    v["r"], v["g"], v["b"], v["red"] = 10, 20, 30, 99
    v["velocity_y"] = 2
    v["scalar_temp"] = -7
    faces = np.array([([0, 1, 2],)], dtype=[("vertex_indices", "i4", (3,))])
    path = tmp_path / "FOREIGN.PLY"
    plyfile.PlyData(
        [plyfile.PlyElement.describe(v, "vertex"), plyfile.PlyElement.describe(faces, "face")], byte_order=">"
    ).write(str(path))
    pc = read_points(path)
    np.testing.assert_array_equal(pc.positions[:, 0] + pc.origin[0], np.arange(n) + 0.25)  # doubles
    np.testing.assert_array_equal(pc.colors, [[10, 20, 30, 255]] * n)
    np.testing.assert_array_equal(pc.velocity, [[0, 2, 0]] * n)
    assert pc.attribute_names == ("nx", "scalar_temp", "red")  # a lone "red" stays an attribute
    assert pc.attributes["scalar_temp"].dtype == np.float32
    np.testing.assert_array_equal(pc.attributes["scalar_temp"], -7)


def test_names_in_another_case_and_diffuse_colours(tmp_path):
    """X, Y, Z (a pandas DataFrame's records, np.save(df.to_records()); some
    PLY writers) were refused ("no x, y, z column (found X, Y, Z)"), and the
    PLY spec's diffuse_red/green/blue (VTK's PLY reader takes them as
    colours) were attributes. A lower-case name still wins over another case
    (a second 'X' beside 'x' stays an attribute)."""
    n = 4
    rec = np.zeros(n, dtype=[("X", "f8"), ("Y", "f8"), ("Z", "f8"), ("Intensity", "f4")])
    rec["X"], rec["Z"], rec["Intensity"] = np.arange(n), 5.0, 7.0
    np.save(tmp_path / "records.npy", rec)
    c = read_points(tmp_path / "records.npy")
    np.testing.assert_array_equal(c.positions[:, 0] + c.origin[0], np.arange(n))
    np.testing.assert_array_equal(c.positions[:, 2] + c.origin[2], 5.0)
    assert c.attribute_names == ("Intensity",)
    v = np.zeros(
        n,
        dtype=[(k, "f4") for k in ("X", "Y", "Z")]
        + [(k, "u1") for k in ("diffuse_red", "diffuse_green", "diffuse_blue")],
    )
    v["Y"], v["diffuse_red"], v["diffuse_green"], v["diffuse_blue"] = 3.0, 200, 10, 30
    plyfile.PlyData([plyfile.PlyElement.describe(v, "vertex")]).write(str(tmp_path / "upper.ply"))
    c = read_points(tmp_path / "upper.ply")
    np.testing.assert_array_equal(c.positions[:, 1] + c.origin[1], 3.0)
    np.testing.assert_array_equal(c.colors, [[200, 10, 30, 255]] * n)
    assert c.attribute_names == ()
    both = np.zeros(n, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"), ("X", "f4")])
    plyfile.PlyData([plyfile.PlyElement.describe(both, "vertex")]).write(str(tmp_path / "both.ply"))
    assert read_points(tmp_path / "both.ply").attribute_names == ("X",)
    # a lone name in another case is an attribute as it was (an amplitude "A" beside r, g, b
    # became the alpha: float colours refused; "R" alone was renamed "r")
    amp = np.zeros(n, dtype=[(k, "f4") for k in ("x", "y", "z", "r", "g", "b", "A")])
    amp["A"] = 7.5
    np.save(tmp_path / "amp.npy", amp)
    c = read_points(tmp_path / "amp.npy")
    assert c.attribute_names == ("A",) and (c.colors[:, 3] == 255).all()
    lone = np.zeros(n, dtype=[(k, "f4") for k in ("X", "Y", "Z", "R", "Radius")])
    np.save(tmp_path / "lone.npy", lone)
    c = read_points(tmp_path / "lone.npy")
    assert c.attribute_names == ("R", "Radius") and c.colors is None and c.radius is None


def test_ply_double_coordinates_keep_an_origin(tmp_path):
    """Double x, y, z (Open3D's, PDAL's, georeferenced scans): positions relative
    to their finite minimum, the origin kept in float64, as LAS files are (as
    float32 the 5000 points of a unit cube at 1e9 fell onto one point, and
    clvis render drew one pixel); a NaN point stays NaN; clvis's own origin
    comment wins; float32 files keep their coordinates."""
    rng = np.random.default_rng(2)
    xyz = 1e9 + rng.random((5000, 3))
    xyz[10, 1] = np.nan
    v = np.zeros(len(xyz), [("x", "<f8"), ("y", "<f8"), ("z", "<f8")])
    v["x"], v["y"], v["z"] = xyz.T
    path = tmp_path / "geo.ply"
    plyfile.PlyData([plyfile.PlyElement.describe(v, "vertex")]).write(str(path))
    pc = read_points(path)
    finite = np.isfinite(xyz).all(axis=1)
    np.testing.assert_array_equal(pc.origin, xyz[finite].min(axis=0))
    assert np.isnan(pc.positions[10, 1]) and np.isfinite(pc.positions[finite]).all()
    np.testing.assert_allclose(pc.positions[finite] + pc.origin, xyz[finite], rtol=0, atol=1e-6)
    assert len(np.unique(pc.positions[finite], axis=0)) == finite.sum()
    again = tmp_path / "again.ply"
    write_ply(again, pc)
    back = read_points(again)
    np.testing.assert_array_equal(back.origin, pc.origin)
    np.testing.assert_array_equal(back.positions, pc.positions)
    v32 = np.zeros(3, [("x", "<f4"), ("y", "<f4"), ("z", "<f4")])
    v32["x"] = [1e6, 2e6, 3e6]
    plyfile.PlyData([plyfile.PlyElement.describe(v32, "vertex")]).write(str(tmp_path / "f32.ply"))
    pc32 = read_points(tmp_path / "f32.ply")
    assert not pc32.origin.any() and pc32.positions[:, 0].tolist() == [1e6, 2e6, 3e6]


def test_npy_and_npz_double_positions_keep_an_origin(tmp_path):
    """As for PLY: (N, 3) float64 NPY, a structured NPY with double x, y, z
    and an NPZ of float64 positions without an origin key are read relative
    to their finite minimum (as float32 a unit cube at 1e9 fell onto one
    point); an NPZ that carries its origin (clvis's own) and float32 arrays
    keep their positions."""
    rng = np.random.default_rng(3)
    xyz = 1e9 + rng.random((4000, 3))
    xyz[7, 2] = np.inf
    finite = np.isfinite(xyz).all(axis=1)
    s = np.zeros(len(xyz), [("x", "<f8"), ("y", "<f8"), ("z", "<f8"), ("t", "<f4")])
    s["x"], s["y"], s["z"] = xyz.T
    np.save(tmp_path / "plain.npy", xyz)
    np.save(tmp_path / "fields.npy", s)
    np.savez(tmp_path / "geo.npz", positions=xyz)
    for name in ("plain.npy", "fields.npy", "geo.npz"):
        pc = read_points(tmp_path / name)
        np.testing.assert_array_equal(pc.origin, xyz[finite].min(axis=0), err_msg=name)
        np.testing.assert_allclose(pc.positions[finite] + pc.origin, xyz[finite], rtol=0, atol=1e-6)
        assert len(np.unique(pc.positions[finite], axis=0)) == finite.sum(), name
        assert np.isinf(pc.positions[7, 2]), name
    np.savez(tmp_path / "own.npz", positions=xyz[finite] - 1e9, origin=np.full(3, 1e9))
    own = read_points(tmp_path / "own.npz")
    assert own.origin.tolist() == [1e9] * 3
    np.testing.assert_array_equal(own.positions, (xyz[finite] - 1e9).astype(np.float32))
    np.save(tmp_path / "f32.npy", np.array([[1e6, 0, 0], [2e6, 0, 0]], np.float32))
    f32 = read_points(tmp_path / "f32.npy")
    assert not f32.origin.any() and f32.positions[:, 0].tolist() == [1e6, 2e6]


def test_ply_list_property_in_vertex_is_skipped(tmp_path):
    v = np.empty(2, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"), ("nbrs", object)])
    v["x"], v["y"], v["z"] = 1, 2, 3
    v["nbrs"] = [np.array([1], np.int32), np.array([0, 1], np.int32)]
    path = tmp_path / "l.ply"
    plyfile.PlyData([plyfile.PlyElement.describe(v, "vertex")]).write(str(path))
    pc = read_points(path)
    assert len(pc) == 2 and pc.attribute_names == ()


def test_write_ply_rejects_bad_attribute_names(tmp_path):
    with pytest.raises(ValueError, match="'red'"):
        write_ply(tmp_path / "a.ply", _cloud(attributes={"red": np.zeros(50)}))
    with pytest.raises(ValueError, match="'two words'"):
        write_ply(tmp_path / "a.ply", _cloud(attributes={"two words": np.zeros(50)}))
    with pytest.raises(TypeError, match="cloud"):
        write_ply(tmp_path / "a.ply", np.zeros((3, 3)))
    assert not (tmp_path / "a.ply").exists()


def _binary_ply(tmp_path):
    path = tmp_path / "good.ply"
    write_ply(path, _full_cloud(n=40))
    return path.read_bytes()


def _expect_data_error(path, match=None):
    with pytest.raises(DataError) as info:
        read_points(path)
    assert str(path) in str(info.value)
    if match:
        assert match in str(info.value)
    return info.value


def test_ply_truncated(tmp_path):
    data = _binary_ply(tmp_path)
    header_end = data.index(b"end_header\n") + len(b"end_header\n")
    row = (len(data) - header_end) // 40
    cuts = [
        0,
        3,
        20,
        header_end - 5,
        header_end,
        header_end + 1,
        header_end + row,
        header_end + row + 7,
        len(data) - row,
        len(data) - 1,
    ]
    for cut in cuts:
        path = tmp_path / f"cut{cut}.ply"
        path.write_bytes(data[:cut])
        _expect_data_error(path)


def test_ply_ascii_truncated(tmp_path):
    path = tmp_path / "t.ply"
    write_ply(path, _cloud(n=10), text=True)
    lines = path.read_bytes().splitlines(keepends=True)
    path.write_bytes(b"".join(lines[:-3]) + lines[-3][:5])  # two rows missing, one cut short
    _expect_data_error(path)


@pytest.mark.parametrize(
    "content",
    [
        b"hello, this is not a point cloud\n",
        b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nend_header\n",
        (
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
            b"end_header\n1 2 banana\n"
        ),
        b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n1 2\n",
        b"ply\nformat ascii 1.0\nelement face 1\nproperty float x\nend_header\n1\n",
        bytes(range(256)) * 4,
    ],
)
def test_ply_malformed(tmp_path, content):
    path = tmp_path / "bad.ply"
    path.write_bytes(content)
    _expect_data_error(path)


def test_ply_bad_colors_become_data_error(tmp_path):
    v = np.zeros(
        2, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"), ("red", "f4"), ("green", "f4"), ("blue", "f4")]
    )
    v["red"] = 200.0  # float colors must be in [0, 1]
    path = tmp_path / "c.ply"
    plyfile.PlyData([plyfile.PlyElement.describe(v, "vertex")]).write(str(path))
    _expect_data_error(path, "colors")


# ---------------------------------------------------------------- LAS / LAZ


def _write_las(path, n=300, point_format=3, big_colors=True, seed=0):
    rng = np.random.default_rng(seed)
    header = laspy.LasHeader(point_format=point_format, version="1.2" if point_format < 6 else "1.4")
    header.scales = [0.001, 0.001, 0.001]
    header.offsets = [600000.0, 5200000.0, 100.0]
    las = laspy.LasData(header)
    x = 600000 + np.round(rng.random(n) * 50000) / 1000 + 123.0
    y = 5200000 + np.round(rng.random(n) * 80000) / 1000 + 456.0
    z = 100 + np.round(rng.random(n) * 30000) / 1000
    las.x, las.y, las.z = x, y, z
    top = 65536 if big_colors else 256
    rgb = rng.integers(0, top, (3, n)).astype(np.uint16)
    las.red, las.green, las.blue = rgb
    las.intensity = rng.integers(0, 65536, n)
    las.classification = rng.integers(0, 20, n)
    las.return_number = rng.integers(1, 4, n)
    las.gps_time = 3.5e8 + np.arange(n) * 0.25
    las.write(str(path))
    return np.stack([x, y, z], axis=1), rgb.T


@pytest.mark.parametrize("ext", ["las", "laz", "LAZ"])
@pytest.mark.parametrize("point_format", [3, 7])
def test_las_round_trip(tmp_path, ext, point_format):
    path = tmp_path / f"c.{ext}"
    xyz, rgb = _write_las(path, point_format=point_format)
    pc = read_points(path)
    assert len(pc) == len(xyz)
    np.testing.assert_array_equal(pc.origin, xyz.min(axis=0))
    assert pc.positions.min() == 0
    # float32 relative coordinates keep millimetres where absolute ones would not
    np.testing.assert_allclose(pc.origin + pc.positions.astype(np.float64), xyz, rtol=0, atol=2e-4)
    assert np.abs(xyz.astype(np.float32).astype(np.float64) - xyz).max() > 0.01
    np.testing.assert_array_equal(pc.colors[:, :3], rgb >> 8)
    np.testing.assert_array_equal(pc.colors[:, 3], 255)
    for name in ("intensity", "classification", "return_number", "gps_time"):
        assert name in pc.attributes
    assert pc.attributes["classification"].dtype == np.uint8
    assert pc.attributes["intensity"].dtype == np.float32
    np.testing.assert_array_equal(pc.attributes["gps_time"], np.arange(len(xyz)) * np.float32(0.25))
    assert not {"X", "Y", "Z", "red", "green", "blue"} & set(pc.attribute_names)


def test_few_finite_points_among_many_nan_rows_keep_their_origin(tmp_path):
    """Two finite points among 2,000,000 NaN rows: the sample the bulk is
    found on (every k-th row) held no finite one, and read_points escaped
    with numpy-side 'ValueError: bounds: the cloud has no finite points';
    the origin is the finite points' minimum, as before the bulk."""
    q = np.full((2_000_002, 3), np.nan)
    q[1], q[3] = [6e6, 1.0, 1.0], [6e6 + 5, 2.0, 2.0]
    np.save(tmp_path / "few.npy", q)
    pc = read_points(tmp_path / "few.npy")
    np.testing.assert_array_equal(pc.origin, [6e6, 1.0, 1.0])
    assert len(pc) == 2_000_002


def test_stray_records_far_away_do_not_cost_the_bulk_its_precision(tmp_path):
    """A georeferenced scan with a few stray records at (0, 0, 0) (laspy's
    test file append-bug-cpy.laz: 2 of 37,807): the positions were kept
    relative to the minimum of all points, (0, 0, 0), so float32 held the
    scan, 6.26e6 m from it, to 0.5 m (a close view drew its points in rows).
    The origin is the bulk's minimum now: the scan keeps its 0.1 mm, and
    the strays are still where they are, to float32 at their distance. So
    for LAS, text and double-precision PLY files."""
    rng = np.random.default_rng(5)
    xyz = np.round(rng.random((300, 3)) * [50, 80, 30] * 1000) / 1000 + [698000.0, 6259000.0, 12.0]
    xyz[:2] = 0.0
    header = laspy.LasHeader(point_format=1, version="1.2")
    header.scales, header.offsets = [0.001, 0.01, 0.001], [0.0, 0.0, 0.0]
    xyz[:, 1] = np.round(xyz[:, 1], 2)
    las = laspy.LasData(header)
    las.x, las.y, las.z = xyz.T
    path = tmp_path / "stray.las"
    las.write(str(path))
    pc = read_points(path)
    np.testing.assert_array_equal(pc.origin, xyz[2:].min(axis=0))
    world = pc.origin + pc.positions.astype(np.float64)
    np.testing.assert_allclose(world[2:], xyz[2:], rtol=0, atol=2e-4)  # it was off by up to 0.25 m
    np.testing.assert_allclose(world[:2], 0.0, rtol=0, atol=1.0)
    text = tmp_path / "stray.xyz"
    np.savetxt(text, xyz, fmt="%.3f")
    np.testing.assert_allclose(read_points(text).origin, xyz[2:].min(axis=0), atol=1e-3)
    v = np.zeros(len(xyz), dtype=[("x", "f8"), ("y", "f8"), ("z", "f8")])
    v["x"], v["y"], v["z"] = xyz.T
    plyfile.PlyData([plyfile.PlyElement.describe(v, "vertex")]).write(str(tmp_path / "stray.ply"))
    pc = read_points(tmp_path / "stray.ply")
    np.testing.assert_allclose(pc.origin + pc.positions[2:].astype(np.float64), xyz[2:], rtol=0, atol=2e-4)
    _write_las(path)  # no stray point: the minimum, as before
    np.testing.assert_array_equal(read_points(path).origin, laspy.read(str(path)).xyz.min(axis=0))


def test_las_8bit_colors_kept(tmp_path):
    path = tmp_path / "c.las"
    _, rgb = _write_las(path, big_colors=False)
    np.testing.assert_array_equal(read_points(path).colors[:, :3], rgb)


def test_las_without_colors(tmp_path):
    path = tmp_path / "c.las"
    header = laspy.LasHeader(point_format=1, version="1.2")
    las = laspy.LasData(header)
    las.x, las.y, las.z = [1.0, 2.0], [3.0, 4.0], [5.0, 6.0]
    las.write(str(path))
    pc = read_points(path)
    assert pc.colors is None and len(pc) == 2
    np.testing.assert_array_equal(pc.origin, [1, 3, 5])


def test_las_extra_bytes_of_several_values_are_attributes(tmp_path):
    """An extra-bytes field of 3 (or 2) values a point (laspy's extrabytes.las:
    "Colors", "Flags") was dropped without a word: one attribute a value now,
    named as a VTK array's components (_x, _y, _z; _0, _1)."""
    path = tmp_path / "e.las"
    header = laspy.LasHeader(point_format=1, version="1.4")
    header.add_extra_dims(
        [laspy.ExtraBytesParams(name="Colors", type="3u2"), laspy.ExtraBytesParams(name="Flags", type="2f4")]
    )
    las = laspy.LasData(header)
    las.x, las.y, las.z = [1.0, 2.0], [3.0, 4.0], [5.0, 6.0]
    las.Colors = np.array([[1, 2, 3], [4, 5, 6]], np.uint16)
    las.Flags = np.array([[0.5, 1.5], [2.5, 3.5]], np.float32)
    las.write(str(path))
    pc = read_points(path)
    for k, col in zip("xyz", ([1, 4], [2, 5], [3, 6]), strict=True):
        np.testing.assert_array_equal(pc.attributes[f"Colors_{k}"], col)
    np.testing.assert_array_equal(pc.attributes["Flags_1"], [1.5, 3.5])
    assert "Colors" not in pc.attributes


@pytest.mark.parametrize("ext", ["las", "laz"])
def test_las_truncated(tmp_path, ext):
    path = tmp_path / f"good.{ext}"
    _write_las(path, point_format=7)
    data = path.read_bytes()
    start = laspy.read(str(path)).header.offset_to_point_data
    for cut in sorted(
        {
            0,
            4,
            100,
            226,
            300,
            start - 1,
            start,
            start + 1,
            start + 36,
            start + 36 * 5,
            (start + len(data)) // 2,
            len(data) - 36,
            len(data) - 1,
        }
    ):
        bad = tmp_path / f"cut{cut}.{ext}"
        bad.write_bytes(data[:cut])
        _expect_data_error(bad)


def test_las_garbage(tmp_path):
    rng = np.random.default_rng(3)
    path = tmp_path / "garbage.las"
    path.write_bytes(rng.integers(0, 256, 5000, dtype=np.uint8).tobytes())
    _expect_data_error(path)
    path.write_bytes(b"LASF" + rng.integers(0, 256, 5000, dtype=np.uint8).tobytes())
    _expect_data_error(path)
    path.write_bytes(b"x,y,z\n1,2,3\n")
    _expect_data_error(path)


@pytest.mark.parametrize("ext", ["las", "laz"])
@pytest.mark.parametrize(
    "offset,fmt,value",
    [
        (100, "<I", 0xFFFFFFF0),  # number of VLRs (laspy would loop over them for hours)
        (96, "<I", 0xFFFFFFF0),  # offset to point data past the end
        (94, "<H", 10),  # header size
        (243, "<I", 0xFFFFFFF0),  # number of extended VLRs (LAS 1.4)
        (247, "<Q", 1 << 40),  # point count (LAS 1.4)
        (247, "<Q", (1 << 64) - 1),
    ],
)
def test_las_corrupt_header_fields(tmp_path, ext, offset, fmt, value):
    import struct

    path = tmp_path / f"c.{ext}"
    _write_las(path, n=50, point_format=7)
    data = bytearray(path.read_bytes())
    struct.pack_into(fmt, data, offset, value)
    path.write_bytes(bytes(data))
    _expect_data_error(path)


# ---------------------------------------------------------------- NPY / NPZ


def test_npy_plain(tmp_path):
    p = np.random.default_rng(1).normal(size=(20, 3))
    np.save(tmp_path / "p.npy", p)
    pc = read_points(tmp_path / "p.npy")
    np.testing.assert_array_equal(pc.positions, p.astype(np.float32))
    assert pc.colors is None and pc.attribute_names == ()


def test_npy_structured(tmp_path):
    n = 5
    a = np.zeros(
        n,
        dtype=[
            ("x", "f8"),
            ("y", "f4"),
            ("z", "i4"),
            ("red", "u1"),
            ("green", "u1"),
            ("blue", "u1"),
            ("temperature", "f8"),
            ("valid", "?"),
            ("rgb3", "u1", (3,)),
        ],
    )
    a["x"], a["z"], a["red"], a["temperature"], a["valid"] = np.arange(n), 7, 200, 1.5, True
    np.save(tmp_path / "s.npy", a)
    pc = read_points(tmp_path / "s.npy")
    np.testing.assert_array_equal(pc.positions[:, 0], np.arange(n))
    np.testing.assert_array_equal(pc.positions[:, 2], 7)
    np.testing.assert_array_equal(pc.colors[:, 0], 200)
    assert pc.attribute_names == ("temperature", "valid")  # the sub-array field is skipped
    assert pc.attributes["valid"].dtype == np.uint8


@pytest.mark.parametrize("full", [False, True])
def test_npz_round_trip(tmp_path, full):
    pc = _full_cloud() if full else _cloud()
    save_npz(tmp_path / "c.npz", pc)
    _assert_same(read_points(tmp_path / "c.npz"), pc)


def test_npz_attribute_named_like_savez_keywords(tmp_path):
    pc = _cloud(n=3, attributes={"file": np.ones(3), "allow_pickle": np.zeros(3)})
    save_npz(tmp_path / "c.npz", pc)
    _assert_same(read_points(tmp_path / "c.npz"), pc)
    with pytest.raises(ValueError, match="origin"):
        save_npz(tmp_path / "d.npz", _cloud(n=3, attributes={"origin": np.ones(3)}))
    assert not (tmp_path / "d.npz").exists()


def test_npz_of_one_unnamed_array_reads_as_a_npy(tmp_path):
    """np.savez(path, xyz) keeps the array as arr_0: an archive of one array
    is read as a .npy of it is ((N, 3), or x, y, z fields)."""
    xyz = np.random.default_rng(1).random((5, 3))
    np.savez(tmp_path / "one.npz", xyz)
    np.testing.assert_allclose(read_points(tmp_path / "one.npz").positions, xyz, rtol=1e-6)
    rec = np.zeros(4, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"), ("intensity", "f4")])
    rec["intensity"] = [1, 2, 3, 4]
    np.savez(tmp_path / "rec.npz", points=rec)
    np.testing.assert_array_equal(read_points(tmp_path / "rec.npz").attributes["intensity"], [1, 2, 3, 4])


@pytest.mark.parametrize(
    "arrays,match",
    [
        ({"points": np.zeros((3, 3)), "rgb": np.zeros((3, 3))}, "np.savez(path, positions=xyz"),
        ({"points": np.zeros((3, 2))}, "(N, 3) array"),  # one array: read as a .npy is
        ({"positions": np.zeros((3, 2))}, "positions"),
        ({"positions": np.zeros((3, 3)), "colors": np.zeros((4, 3), np.uint8)}, "colors"),
        ({"positions": np.zeros((3, 3)), "extra": np.zeros((3, 2))}, "extra"),
        ({"positions": np.zeros((3, 3)), "origin": np.zeros(2)}, "origin"),
    ],
)
def test_npz_malformed(tmp_path, arrays, match):
    path = tmp_path / "bad.npz"
    np.savez(path, **arrays)
    _expect_data_error(path, match)


@pytest.mark.parametrize(
    "make",
    [
        lambda p: np.save(p, np.zeros((4, 2))),
        lambda p: np.save(p, np.zeros((4, 3, 1))),
        lambda p: np.save(p, np.array(["a", "b", "c"] * 2).reshape(2, 3)),
        lambda p: np.save(p, np.array([None, 1], dtype=object)),  # needs pickle
        lambda p: np.save(p, np.zeros(3, dtype=[("x", "f4"), ("y", "f4")])),
        lambda p: p.write_bytes(b"\x93NUMPY\x01\x00garbage"),
        lambda p: p.write_bytes(b"not numpy at all"),
    ],
)
def test_npy_malformed(tmp_path, make):
    path = tmp_path / "bad.npy"
    make(path)
    _expect_data_error(path)


@pytest.mark.parametrize("ext", ["npy", "npz"])
def test_npy_npz_truncated(tmp_path, ext):
    path = tmp_path / f"good.{ext}"
    if ext == "npy":
        np.save(path, np.zeros((100, 3)))
    else:
        save_npz(path, _full_cloud())
    data = path.read_bytes()
    for cut in [0, 5, 60, len(data) // 2, len(data) - 30, len(data) - 1]:
        bad = tmp_path / f"cut{cut}.{ext}"
        bad.write_bytes(data[:cut])
        _expect_data_error(bad)


def test_npz_named_npy_and_back(tmp_path):
    path = tmp_path / "archive.npy"
    save_npz(path, _cloud())
    _expect_data_error(path, "NPZ")
    path = tmp_path / "array.npz"
    with open(path, "wb") as f:
        np.save(f, np.zeros((3, 3)))
    assert "malformed" not in str(_expect_data_error(path, "found an NPY array"))


# ---------------------------------------------------------------- dispatch


def test_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError):
        read_points(tmp_path / "nope.ply")


@pytest.mark.parametrize("name", ["points.e58", "points", "points.ply.gz"])
def test_unknown_extension(tmp_path, name):
    path = tmp_path / name
    path.write_bytes(b"1 2 3\n")
    _expect_data_error(path, "unknown")


def test_text_file_named_ply(tmp_path):
    path = tmp_path / "notes.ply"
    path.write_text("x y z\n1 2 3\n")
    _expect_data_error(path)


def test_str_paths(tmp_path):
    pc = _full_cloud()
    write_ply(str(tmp_path / "a.ply"), pc)
    save_npz(str(tmp_path / "a.npz"), pc)
    _assert_same(read_points(str(tmp_path / "a.ply")), read_points(str(tmp_path / "a.npz")))


# ---------------------------------------------------------------- hostile files


def _npy_with_header(path, header: bytes, data=b""):
    header += b" " * (-(len(header) + 11) % 64) + b"\n"
    path.write_bytes(b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header + data)
    return path


@pytest.mark.parametrize(
    "header,match",
    [
        (b"{'descr': '<f4', 'fortran_order': False, 'shape': (1000000000, 3)}", "declares shape"),
        (
            b"{'descr': '<f8', 'fortran_order': False, "
            b"'shape': (4611686018427387904, 4611686018427387904, 3)}",
            "declares shape",
        ),
        (b"{'descr': '<f8', 'fortran_order': False, 'shape': (9223372036854775807, 3)}", "declares shape"),
        (b"{b'descr': '<f8', 'fortran_order': False, 'shape': (4, 3)}", "malformed NPY"),
        (b"{'descr': '<f8', 'fortran_order': False, 'shape': (4, 3)", "malformed NPY"),  # unterminated
        (b"{'descr': '''<f8", "malformed NPY"),  # TokenError
        (b"{'descr': 'nonsense', 'fortran_order': False, 'shape': (4, 3)}", "bad dtype"),
        (b"{'descr': '<f8', 'fortran_order': False, 'shape': (4, -3)}", "malformed NPY"),
        (b"{'descr': '|O', 'fortran_order': False, 'shape': (4, 3)}", "pickle"),
    ],
)
def test_npy_hostile_headers(tmp_path, header, match):
    _expect_data_error(_npy_with_header(tmp_path / "h.npy", header, bytes(96)), match)


def test_text_file_named_npy(tmp_path):
    path = tmp_path / "notes.npy"
    path.write_text("x y z\n1 2 3\n")
    err = _expect_data_error(path, "not a NumPy file")
    assert "pickle" not in str(err)


def test_npz_truncated_and_lying(tmp_path):
    path = tmp_path / "c.npz"
    save_npz(path, _cloud(n=200))
    data = path.read_bytes()
    for cut in range(0, len(data), 97):
        bad = tmp_path / f"cut{cut}.npz"
        bad.write_bytes(data[:cut])
        _expect_data_error(bad)
    # a stored member whose NPY header declares 10^9 rows
    import zipfile

    with zipfile.ZipFile(tmp_path / "lie.npz", "w") as z:
        z.writestr(
            "positions.npy",
            _npy_with_header(
                tmp_path / "x.npy",
                b"{'descr': '<f4', 'fortran_order': False, 'shape': (1000000000, 3)}",
                bytes(36),
            ).read_bytes(),
        )
    _expect_data_error(tmp_path / "lie.npz", "declares shape (1000000000, 3)")


def test_subset_out_of_range_is_a_clvis_error():
    pc = _cloud(n=5)
    for index in ([5], [-6], np.array([0, 1, 99])):
        with pytest.raises(DataError, match="index"):
            pc.subset(index)
    assert len(pc.subset([-5, 4])) == 2


def _laz_with_header_count(tmp_path, count):
    import struct

    path = tmp_path / "lie.laz"
    _write_las(path, n=20, point_format=3)
    data = bytearray(path.read_bytes())
    struct.pack_into("<I", data, 107, count)  # legacy point count (LAS 1.2)
    path.write_bytes(bytes(data))
    return path


def test_laz_declaring_more_points_than_it_can_hold(tmp_path):
    path = _laz_with_header_count(tmp_path, 50_000_000)
    err = _expect_data_error(path, "declares 50000000 points of 34 bytes")
    assert "points per byte" in str(err)


def test_laz_corrupt_chunk_table(tmp_path):
    import struct

    path = tmp_path / "c.laz"
    _write_las(path, n=60, point_format=7)
    data = bytearray(path.read_bytes())
    start = laspy.read(str(path)).header.offset_to_point_data
    table = struct.unpack_from("<q", data, start)[0]
    for value in (0xFFFF0001, 0x7FFFFFFF, 1000):  # the number of chunks (lazrs aborted on these)
        bad = bytearray(data)
        struct.pack_into("<I", bad, table + 4, value)
        path.write_bytes(bytes(bad))
        _expect_data_error(path, "chunk")
    for value in (-5, len(data) + 100, start):  # the chunk table's offset
        bad = bytearray(data)
        struct.pack_into("<q", bad, start, value)
        path.write_bytes(bytes(bad))
        _expect_data_error(path, "chunk table")


# Mutates a LAZ file at many positions and reads each in a child process under
# an address-space limit, printing one JSON line per case: a lazrs abort
# (SIGABRT, uncatchable) fails the test instead of killing pytest.
_LAZ_FUZZ_CHILD = r"""
import json, resource, sys
import numpy as np
import laspy, lazrs
import clvis.io
from clvis.errors import ClvisError
limit = 1536 << 20
resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
src, out = sys.argv[1], sys.argv[2]
data = open(src, "rb").read()
rng = np.random.default_rng(600)
for i in range(int(sys.argv[3])):
    b = bytearray(data)
    for _ in range(rng.integers(1, 4)):
        b[rng.integers(0, len(b))] = rng.integers(0, 256)
    open(out, "wb").write(bytes(b))
    print(json.dumps({"i": i, "start": True}), flush=True)
    try:
        clvis.io.read_points(out)
        r = "ok"
    except ClvisError as e:
        r = "clvis" if out in str(e) else "unnamed"
    except BaseException as e:
        r = f"{type(e).__name__}: {e}"[:200]
    print(json.dumps({"i": i, "r": r}), flush=True)
"""


@pytest.mark.parametrize("point_format", [3, 7])
def test_laz_mutations_never_abort(tmp_path, point_format):
    import json
    import os
    import subprocess
    import sys
    from pathlib import Path

    src = tmp_path / "good.laz"
    _write_las(src, n=80, point_format=point_format)
    root = str(Path(__file__).resolve().parents[1])
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([root, os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.run(
        [sys.executable, "-c", _LAZ_FUZZ_CHILD, str(src), str(tmp_path / "m.laz"), "300"],
        capture_output=True,
        text=True,
        env=env,
        timeout=240,
    )
    lines = [json.loads(line) for line in proc.stdout.splitlines()]
    results = [r["r"] for r in lines if "r" in r]
    assert proc.returncode == 0, (
        f"the child died (rc {proc.returncode}) at case {lines[-1]['i'] if lines else '?'}: "
        f"{proc.stderr[-1500:]}"
    )
    assert len(results) == 300
    bad = [r for r in results if r not in ("ok", "clvis")]
    assert not bad, bad[:10]
    assert results.count("clvis") > 10  # the mutations do break files


@pytest.mark.parametrize("order", ["<", ">"])
def test_binary_ply_memory_mapped_columns_copied(tmp_path, order):
    """Binary PLY is memory-mapped (a 2 M-vertex file: a minute row by row,
    milliseconds mapped); what the cloud holds are copies in native order,
    so the file is not held."""
    import plyfile

    v = np.zeros(5, [("x", order + "f4"), ("y", order + "f4"), ("z", order + "f4"), ("value", order + "f8")])
    v["x"], v["value"] = np.arange(5), np.linspace(0, 1, 5)
    path = tmp_path / "m.ply"
    plyfile.PlyData([plyfile.PlyElement.describe(v, "vertex")], byte_order=order).write(str(path))
    c = read_points(path)
    np.testing.assert_array_equal(c.positions[:, 0], np.arange(5))
    np.testing.assert_allclose(c.attributes["value"], np.linspace(0, 1, 5))
    for a in (c.positions, c.attributes["value"]):
        assert a.dtype.isnative and not isinstance(a, np.memmap) and not isinstance(a.base, np.memmap)
    path.unlink()  # nothing maps it any more
    assert c.attributes["value"].sum() == pytest.approx(2.5)


def test_point_suffixes_are_the_readers():
    # clvis gauss and clvis view choose points or a volume by POINT_SUFFIXES
    from clvis.io import points

    assert points.POINT_SUFFIXES == tuple(points._readers())


def test_las_truncated_before_its_extended_vlrs_says_so(tmp_path):
    from laspy.vlrs.vlrlist import VLRList

    path = tmp_path / "e.las"
    las = laspy.LasData(laspy.LasHeader(point_format=6, version="1.4"))
    las.x, las.y, las.z = np.arange(50.0), np.arange(50.0), np.arange(50.0)
    las.evlrs = VLRList([laspy.VLR(user_id="clvis", record_id=7, record_data=b"x" * 20)])
    las.write(str(path))
    data = path.read_bytes()
    start = laspy.read(str(path)).header.start_of_first_evlr
    assert len(read_points(path)) == 50
    for cut, words in ((start - 100, "should start at byte"), (start + 10, "do not fit")):
        short = tmp_path / f"cut{cut}.las"
        short.write_bytes(data[:cut])
        with pytest.raises(DataError, match=f"truncated LAS/LAZ file.*{words}"):
            read_points(short)
