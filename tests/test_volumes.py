"""clvis.read_volume (clvis/io/volumes.py): raw files named like the Open SciVis datasets,
.npy and NIfTI, and a DataError naming the file for everything it cannot read."""

import gzip
import struct
import sys

import nibabel
import numpy as np
import pytest

from clvis import DataError
from clvis.io import read_points, volumes
from clvis.io.volumes import RAW_TYPES, Volume, read_volume


def _sample(shape, dtype, seed=0):
    rng = np.random.default_rng(seed)
    dt = np.dtype(dtype)
    if dt.kind == "f":
        return rng.normal(size=shape).astype(dt)
    info = np.iinfo(dt)
    return rng.integers(info.min, info.max, size=shape, endpoint=True, dtype=dt)


def _write_raw(path, a):
    a.astype(a.dtype.newbyteorder("<")).tofile(path)
    return path


@pytest.mark.parametrize("dtype", sorted(RAW_TYPES))
def test_raw_round_trip(tmp_path, dtype):
    a = _sample((3, 4, 5), dtype)  # Z, Y, X
    path = _write_raw(tmp_path / f"thing_5x4x3_{dtype}.raw", a)
    v = read_volume(path)
    assert isinstance(v, Volume)
    assert v.data.dtype == np.dtype(dtype) and v.data.dtype.isnative
    assert v.data.shape == (3, 4, 5) and v.shape == (3, 4, 5) and v.data.flags.c_contiguous
    np.testing.assert_array_equal(v.data, a)
    assert v.spacing == (1.0, 1.0, 1.0) and v.origin == (0.0, 0.0, 0.0) and v.affine is None
    assert v.path == str(path)


def test_raw_is_little_endian_with_x_fastest(tmp_path):
    # samples numbered 0.. in file order: x fastest, then y, then z
    path = tmp_path / "ramp_3x2x2_uint16.raw"
    path.write_bytes(struct.pack("<12H", *range(256, 268)))
    v = read_volume(path)
    assert v.data[0, 0, 1] == 257 and v.data[0, 1, 0] == 259 and v.data[1, 0, 0] == 262
    np.testing.assert_array_equal(v.data.ravel(), np.arange(256, 268))


def test_raw_open_scivis_names(tmp_path):
    a = _sample((2, 3, 4), np.uint8)
    for name in ("bonsai_4x3x2_uint8.raw", "a_b_c_4x3x2_UINT8.RAW", "x_1_2_4x3x2_uint8.raw"):
        np.testing.assert_array_equal(read_volume(_write_raw(tmp_path / name, a)).data, a)


def test_raw_keywords_give_or_override_the_name(tmp_path):
    a = _sample((2, 3, 4), np.float32)
    path = _write_raw(tmp_path / "plain.raw", a)
    np.testing.assert_array_equal(read_volume(path, shape=(2, 3, 4), dtype=np.float32).data, a)
    np.testing.assert_array_equal(
        read_volume(path, shape=(np.int64(4), 3, 2), dtype="float32").data, a.reshape(4, 3, 2)
    )
    # a name that says something else is overridden
    named = _write_raw(tmp_path / "x_2x2x2_uint8.raw", a)
    np.testing.assert_array_equal(read_volume(named, shape=(2, 3, 4), dtype=np.float32).data, a)
    np.testing.assert_array_equal(read_volume(named, shape=(6, 4, 4)).data.ravel(), a.view(np.uint8).ravel())


@pytest.mark.parametrize(
    "name, message",
    [
        ("plain.raw", "the name does not give the shape"),
        ("thing_4x3_uint8.raw", "the name does not give the shape"),
        ("thing_4x3x2.raw", "the name does not give the shape"),
        ("thing_4x3x2_uint12.raw", "unknown sample type 'uint12'"),
        ("thing_4x0x2_uint8.raw", "empty axis"),
    ],
)
def test_raw_bad_names(tmp_path, name, message):
    path = tmp_path / name
    path.write_bytes(bytes(24))
    with pytest.raises(DataError, match=message) as e:
        read_volume(path)
    assert str(path) in str(e.value)


@pytest.mark.parametrize(
    "size, what", [(59, "short by 1"), (61, "long by 1"), (0, "short by 60"), (120, "long by 60")]
)
def test_raw_wrong_sizes(tmp_path, size, what):
    path = tmp_path / "thing_5x3x2_uint16.raw"
    path.write_bytes(bytes(size))
    with pytest.raises(DataError, match=what) as e:
        read_volume(path)
    assert str(path) in str(e.value) and f"{size} bytes" in str(e.value)


def test_raw_bad_keywords(tmp_path):
    path = _write_raw(tmp_path / "plain.raw", np.zeros(8, np.uint8))
    with pytest.raises(TypeError, match="shape"):
        read_volume(path, shape=(2, 2.0, 2), dtype=np.uint8)
    with pytest.raises(ValueError, match="shape"):
        read_volume(path, shape=(2, 4), dtype=np.uint8)
    with pytest.raises(ValueError, match="dtype"):
        read_volume(path, shape=(2, 2, 2), dtype=np.complex64)
    with pytest.raises(DataError, match="sample type"):
        read_volume(path, shape=(2, 2, 2))
    with pytest.raises(ValueError, match="only for .raw"):
        read_volume(_npy(tmp_path, np.zeros((2, 2, 2))), dtype=np.uint8)


def _npy(tmp_path, a, name="v.npy"):
    path = tmp_path / name
    np.save(path, a)
    return path


@pytest.mark.parametrize("dtype", ["uint8", "int16", ">f4", "float64"])
def test_npy_round_trip(tmp_path, dtype):
    a = _sample((4, 3, 5), np.dtype(dtype).newbyteorder("="), seed=2).astype(dtype)
    v = read_volume(_npy(tmp_path, a))
    assert v.data.dtype.isnative and v.data.dtype == np.dtype(dtype).newbyteorder("=")
    np.testing.assert_array_equal(v.data, a)
    assert v.spacing == (1.0, 1.0, 1.0)
    f = read_volume(_npy(tmp_path, np.asfortranarray(a), "f.npy"))
    assert f.data.flags.c_contiguous
    np.testing.assert_array_equal(f.data, a)


def test_npy_mask_reads_as_zeros_and_ones(tmp_path):
    """A boolean mask (a segmentation saved as seg > t) is a 0/1 volume."""
    mask = np.zeros((4, 5, 6), bool)
    mask[1:3, 2:4, 1:5] = True
    v = read_volume(_npy(tmp_path, mask))
    assert v.data.dtype == np.uint8
    np.testing.assert_array_equal(v.data, mask.astype(np.uint8))


@pytest.mark.parametrize(
    "a, message",
    [
        (np.zeros((3, 4)), "expected a 3-D volume"),
        (np.zeros((2, 3, 4, 5)), "expected a 3-D volume"),
        (np.zeros((2, 3, 4), np.complex64), "real numbers"),
        (np.zeros((2, 0, 4)), "empty"),
    ],
)
def test_npy_bad_arrays(tmp_path, a, message):
    path = _npy(tmp_path, a)
    with pytest.raises(DataError, match=message) as e:
        read_volume(path)
    assert str(path) in str(e.value)


def test_npy_malformed_and_object_arrays(tmp_path):
    good = _npy(tmp_path, np.zeros((3, 3, 3), np.float32))
    truncated = tmp_path / "t.npy"
    truncated.write_bytes(good.read_bytes()[:-5])
    garbage = tmp_path / "g.npy"
    garbage.write_bytes(b"not an npy file at all")
    objects = tmp_path / "o.npy"
    np.save(objects, np.array([[[{}]]], dtype=object), allow_pickle=True)
    for path in (truncated, garbage, objects):
        with pytest.raises(DataError) as e:
            read_volume(path)
        assert str(path) in str(e.value)


def _nifti(path, data, zooms=(1.0, 1.0, 1.0), slope=None):
    img = nibabel.Nifti1Image(data, np.diag([*zooms, 1.0]))
    img.header.set_zooms(zooms[: data.ndim] if data.ndim < 3 else (*zooms, *([1.0] * (data.ndim - 3))))
    if slope is not None:
        img.header.set_slope_inter(slope, 0.5)
    nibabel.save(img, path)
    return path


@pytest.mark.parametrize("suffix", [".nii", ".nii.gz", ".NII.GZ"])
@pytest.mark.parametrize("dtype", [np.int16, np.float32])
def test_nifti_round_trip(tmp_path, suffix, dtype):
    ijk = _sample((5, 4, 3), dtype, seed=3)  # NIfTI order: i (x), j (y), k (z)
    path = _nifti(tmp_path / f"brain{suffix}", ijk, zooms=(0.5, 0.75, 2.0))
    v = read_volume(path)
    assert v.data.shape == (3, 4, 5) and v.data.dtype == dtype and v.data.flags.c_contiguous
    np.testing.assert_array_equal(v.data, ijk.transpose(2, 1, 0))  # [z, y, x]
    assert v.spacing == (2.0, 0.75, 0.5)  # (dz, dy, dx)
    assert v.origin == (0.0, 0.0, 0.0)
    np.testing.assert_allclose(v.affine, np.diag([0.5, 0.75, 2.0, 1.0]))


@pytest.mark.parametrize("suffix", [".nii", ".mgz"])
def test_nifti_and_mgh_come_in_ras_order_not_mirrored(tmp_path, suffix):
    """One subject stored in three voxel orders (RAS, LAS: x reversed, and
    SAR: axes permuted, as FreeSurfer's test.mgz) reads as one volume: the
    same samples [z, y, x] along superior, anterior, right, the spacing
    following the axes, and an affine that maps each returned voxel to the
    same world point."""
    ras = _sample((6, 5, 4), np.dtype(np.float32), seed=7)  # i right, j anterior, k superior
    zooms = np.array([0.5, 1.0, 2.0])
    shift = np.array([-3.0, 4.0, 5.0])

    def save(name, data, affine):
        path = tmp_path / f"{name}{suffix}"
        image = nibabel.Nifti1Image if suffix == ".nii" else nibabel.MGHImage
        nibabel.save(image(data, affine), path)
        return read_volume(path)

    a = np.diag([*zooms, 1.0])
    a[:3, 3] = shift
    las = a.copy()
    las[0, 0] = -zooms[0]
    las[0, 3] = shift[0] + zooms[0] * 5  # voxel i = 5 - i' at the same world x
    sar = np.zeros((4, 4))
    sar[3, 3] = 1
    sar[2, 0], sar[1, 1], sar[0, 2] = zooms[2], zooms[1], zooms[0]  # i superior, j anterior, k right
    sar[:3, 3] = shift
    vols = [
        save("ras", ras, a),
        save("las", np.ascontiguousarray(ras[::-1]), las),
        save("sar", np.ascontiguousarray(ras.transpose(2, 1, 0)), sar),
    ]
    for v in vols:
        np.testing.assert_array_equal(v.data, ras.transpose(2, 1, 0))
        assert v.spacing == (2.0, 1.0, 0.5)  # (dz, dy, dx)
        assert v.data.flags.c_contiguous
        # voxel (i, j, k) = (x, y, z) index of the returned data -> the world point of RAS's
        np.testing.assert_allclose(v.affine @ [5, 0, 3, 1], a @ [5, 0, 3, 1])
        assert nibabel.aff2axcodes(v.affine) == ("R", "A", "S")


def test_nifti_scaling_and_trailing_axes(tmp_path):
    ijk = np.arange(24, dtype=np.int16).reshape(4, 3, 2)
    v = read_volume(_nifti(tmp_path / "s.nii", ijk, slope=2.0))
    np.testing.assert_allclose(v.data, ijk.transpose(2, 1, 0) * 2.0 + 0.5)
    v = read_volume(_nifti(tmp_path / "four.nii", ijk[..., None]))
    np.testing.assert_array_equal(v.data, ijk.transpose(2, 1, 0))
    with pytest.raises(DataError, match="4-D NIfTI image of 2 volumes .*volume_index") as e:
        read_volume(_nifti(tmp_path / "series.nii", np.stack([ijk, ijk], axis=-1)))
    assert "series.nii" in str(e.value)
    with pytest.raises(DataError, match="3-D"):
        read_volume(_nifti(tmp_path / "flat.nii", ijk[:, :, 0]))


def test_nifti_broken_files(tmp_path):
    good = _nifti(tmp_path / "g.nii.gz", np.ones((8, 8, 8), np.float32))
    truncated = tmp_path / "t.nii.gz"
    truncated.write_bytes(good.read_bytes()[: len(good.read_bytes()) // 2])
    short = tmp_path / "short.nii"
    short.write_bytes(gzip.decompress(good.read_bytes())[:600])
    garbage = tmp_path / "x.nii"
    garbage.write_bytes(b"\0" * 400)
    for path in (truncated, short, garbage):
        with pytest.raises(DataError) as e:
            read_volume(path)
        assert str(path) in str(e.value)
    # voxel sizes: pixdim[2] (dy) of the NIfTI-1 header at byte 76 + 2 * 4. nibabel reads 0
    # as 1 and -2 as 2 (with a warning); NaN and inf are an error
    path = _nifti(tmp_path / "z.nii", np.ones((2, 2, 2), np.float32), zooms=(1.5, 1.0, 3.0))
    raw = bytearray(path.read_bytes())
    for value, spacing in ((0.0, (3.0, 1.0, 1.5)), (-2.0, (3.0, 2.0, 1.5)), (np.nan, None), (np.inf, None)):
        raw[84:88] = struct.pack("<f", value)
        path.write_bytes(bytes(raw))
        if spacing is not None:
            assert read_volume(path).spacing == spacing
        else:
            with pytest.raises(DataError, match="pixdim"):
                read_volume(path)


def test_nifti_without_nibabel(tmp_path, monkeypatch):
    path = _nifti(tmp_path / "v.nii", np.ones((2, 2, 2), np.float32))
    monkeypatch.setitem(sys.modules, "nibabel", None)
    with pytest.raises(ImportError, match=r"pip install \".\[nifti\]\" in a clvis checkout"):
        read_volume(path)


def test_missing_unknown_and_unreadable(tmp_path):
    with pytest.raises(FileNotFoundError):
        read_volume(tmp_path / "nope_2x2x2_uint8.raw")
    with pytest.raises(DataError, match=r"not a regular file \(a directory\)"):
        read_volume(tmp_path)
    other = tmp_path / "v.mha"
    other.write_bytes(b"x")
    with pytest.raises(DataError, match="unknown volume format") as e:
        read_volume(other)
    assert str(other) in str(e.value) and "triangle mesh" not in str(e.value)
    mesh = tmp_path / "part.STL"  # a mesh: what to do with it (clvis draws points and volumes)
    mesh.write_bytes(b"solid x\nendsolid x\n")
    for read in (read_volume, read_points):
        with pytest.raises(DataError, match=r"it is a triangle mesh, .*sample_points_uniformly"):
            read(mesh)
    with pytest.raises(TypeError, match="path"):
        read_volume(None)


def _nifti_header(shape, datatype=16, bitpix=32, vox_offset=352.0):
    """A NIfTI-1 header (348 bytes + 4 extension bytes) declaring shape, nothing after it."""
    h = bytearray(352)
    struct.pack_into("<i", h, 0, 348)
    struct.pack_into("<8h", h, 40, len(shape), *shape, *([1] * (7 - len(shape))))
    struct.pack_into("<hh", h, 70, datatype, bitpix)
    struct.pack_into("<8f", h, 76, 1, 1, 1, 1, 1, 1, 1, 1)
    struct.pack_into("<f", h, 108, vox_offset)
    h[344:348] = b"n+1\0"
    return bytes(h)


def test_nifti_declaring_more_than_it_holds(tmp_path):
    tiny = tmp_path / "tiny.nii"
    tiny.write_bytes(_nifti_header((700, 700, 700)) + bytes(256))  # 608 bytes
    assert tiny.stat().st_size == 608
    with pytest.raises(DataError, match="the file has 608 bytes") as e:
        read_volume(tiny)
    assert str(tiny) in str(e.value)
    gz = tmp_path / "tiny.nii.gz"
    gz.write_bytes(gzip.compress(tiny.read_bytes()))
    with pytest.raises(DataError, match="more than a gzip file") as e:
        read_volume(gz)
    assert str(gz) in str(e.value)


@pytest.mark.parametrize(
    "header, message",
    [
        (_nifti_header((2, 2, 2), datatype=999), "not a readable NIfTI"),  # unknown datatype
        (_nifti_header((2, 2, 2), datatype=32, bitpix=64), "real numbers"),  # complex64
        (_nifti_header((2, 2, 2), datatype=128, bitpix=24), "real numbers"),  # RGB24
        (_nifti_header((2, 2, 2), vox_offset=float("inf")), "NIfTI"),
        (_nifti_header((2, 2, 2), vox_offset=3e38), "NIfTI"),
        (_nifti_header((2, 2, 2), vox_offset=-1e9), "NIfTI"),
    ],
)
def test_nifti_hostile_headers(tmp_path, header, message):
    path = tmp_path / "h.nii"
    path.write_bytes(header + bytes(64))
    with pytest.raises(DataError, match=message) as e:
        read_volume(path)
    assert str(path) in str(e.value)


@pytest.mark.parametrize(
    "a",
    [np.zeros((2, 2, 2), np.complex128), np.array(["ab"] * 8).reshape(2, 2, 2), np.zeros((2, 2, 2), ">c8")],
)
def test_npy_string_and_complex_volumes(tmp_path, a):
    path = _npy(tmp_path, a)
    with pytest.raises(DataError, match="real numbers") as e:
        read_volume(path)
    assert str(path) in str(e.value)


def test_npy_volume_declaring_more_than_it_holds(tmp_path):
    path = tmp_path / "big.npy"
    header = b"{'descr': '<f4', 'fortran_order': False, 'shape': (700, 700, 700), }"
    header += b" " * (-(len(header) + 11) % 64) + b"\n"
    path.write_bytes(b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header + bytes(100))
    with pytest.raises(DataError, match=r"declares shape \(700, 700, 700\)") as e:
        read_volume(path)
    assert str(path) in str(e.value)


def test_nifti_time_series_volume_index(tmp_path):
    """A 4-D NIfTI is a series: one volume is read by index (nibabel's own
    example4d.nii.gz, and a generated one checked sample for sample)."""
    data = np.arange(4 * 5 * 6 * 3, dtype=np.int16).reshape(4, 5, 6, 3)
    path = tmp_path / "series.nii"
    nibabel.save(nibabel.Nifti1Image(data, np.diag([1.0, 2.0, 3.0, 1.0])), path)
    with pytest.raises(DataError, match="4-D NIfTI image of 3 volumes"):
        read_volume(path)
    for t in range(3):
        v = read_volume(path, volume_index=t)
        np.testing.assert_array_equal(v.data, data[..., t].transpose(2, 1, 0))
        assert v.spacing == (3.0, 2.0, 1.0)
    with pytest.raises(ValueError, match="outside 0..2"):
        read_volume(path, volume_index=3)
    with pytest.raises(ValueError, match="only for 4-D NIfTI"):
        np.save(tmp_path / "v.npy", np.zeros((2, 2, 2), np.float32))
        read_volume(tmp_path / "v.npy", volume_index=0)
    import os

    ex = os.path.join(os.path.dirname(nibabel.__file__), "tests", "data", "example4d.nii.gz")
    assert read_volume(ex, volume_index=1).data.shape == (24, 96, 128)


@pytest.mark.parametrize("suffix", [".nii", ".nii.gz"])
def test_nifti_truncated_series_says_so_before_asking_for_an_index(tmp_path, suffix, monkeypatch):
    """A 4-D file cut short (its bytes cut, as a broken download leaves a
    .gz): the error says it is truncated and which volumes are whole, not
    "choose a volume" (the index asked for would then fail); an index past
    the cut says truncated too. A whole .gz is not decompressed to say
    "choose one" (its gzip trailer gives the size)."""
    rng = np.random.default_rng(0)
    data = rng.integers(-3000, 3000, (16, 12, 10, 6), dtype=np.int16)  # hardly compressible
    whole = tmp_path / f"whole{suffix}"
    nibabel.save(nibabel.Nifti1Image(data, np.eye(4)), whole)
    raw = whole.read_bytes()
    path = tmp_path / f"cut{suffix}"
    path.write_bytes(raw[: int(len(raw) * 0.55)])  # volumes 0..2 whole (about 3.3 of 6 held)
    with pytest.raises(
        DataError, match=r"truncated NIfTI file: the header declares 6 volumes.*volumes 0..2 are whole"
    ):
        read_volume(path)
    for t in range(3):
        np.testing.assert_array_equal(read_volume(path, volume_index=t).data, data[..., t].transpose(2, 1, 0))
    with pytest.raises(DataError, match="truncated NIfTI file"):
        read_volume(path, volume_index=4)
    if suffix.endswith(".gz"):  # the reader's own zlib (nibabel's gzip keeps the real one)
        fake = type("Zlib", (), {"error": volumes.zlib.error})()
        fake.decompressobj = lambda *a, **k: pytest.fail("decompressed")
        monkeypatch.setattr(volumes, "zlib", fake)
    with pytest.raises(DataError, match="4-D NIfTI image of 6 volumes .*volume_index"):
        read_volume(whole)  # whole: the index is what is missing


@pytest.mark.parametrize("suffix", [".mgz", ".mgh"])
@pytest.mark.parametrize("dtype", [np.uint8, np.float32])
def test_mgh_round_trip(tmp_path, suffix, dtype):
    """FreeSurfer's MGH (brain.mgz, aseg.mgz) through nibabel, as NIfTI is read:
    [i, j, k] to [z, y, x], the voxel sizes reversed; nibabel's own test.mgz
    is 4-D and needs volume_index; a cut .mgh says it is truncated."""
    data = _sample((6, 5, 4), np.dtype(dtype), seed=4)
    affine = np.diag([0.5, 1.0, 2.0, 1.0])
    path = tmp_path / f"brain{suffix}"
    nibabel.save(nibabel.MGHImage(data, affine), path)
    v = read_volume(path)
    np.testing.assert_array_equal(v.data, data.transpose(2, 1, 0))
    assert v.spacing == (2.0, 1.0, 0.5)
    cut = tmp_path / f"cut{suffix}"
    cut.write_bytes(path.read_bytes()[: len(path.read_bytes()) // 2])
    with pytest.raises(DataError, match="truncated MGH file"):
        read_volume(cut)
    bad = tmp_path / f"bad{suffix}"
    bad.write_bytes(b"not an MGH file at all" * 20)
    with pytest.raises(DataError, match="not a readable MGH file"):
        read_volume(bad)
    if suffix == ".mgh":  # a zero dimension (big-endian int32 at byte 4): nibabel's MGHError
        raw = bytearray(path.read_bytes())
        raw[4:8] = (0).to_bytes(4, "big")
        bad.write_bytes(bytes(raw))
        with pytest.raises(DataError, match="not a readable MGH file: MGHError"):
            read_volume(bad)
    import os

    test = os.path.join(os.path.dirname(nibabel.__file__), "tests", "data", "test.mgz")
    with pytest.raises(DataError, match="a 4-D MGH image of 2 volumes"):
        read_volume(test)
    # stored (i, j, k) = (3, 4, 5) along S, A, R: in RAS+ order (5, 4, 3), [z, y, x] (3, 4, 5)
    assert read_volume(test, volume_index=1).data.shape == (3, 4, 5)


@pytest.mark.parametrize("image", ["AnalyzeImage", "Nifti1Pair"])
def test_analyze_pair_read_by_either_name(tmp_path, image):
    """An Analyze 7.5 header and data file (.hdr/.img; a NIfTI-1 pair alike)
    through nibabel, read as NIfTI is, by either name; the other file
    missing, or the data cut short, is named."""
    data = _sample((6, 5, 4), np.dtype(np.int16), seed=5)
    path = tmp_path / "scan.hdr"
    nibabel.save(getattr(nibabel, image)(data, np.diag([0.5, 1.0, 2.0, 1.0])), path)
    assert (tmp_path / "scan.img").is_file()
    # an Analyze header keeps no affine: nibabel's is radiological (x toward
    # the left, LAS), so the RAS+ volume is x-reversed; a NIfTI pair keeps its own
    expected = data[::-1] if image == "AnalyzeImage" else data
    for name in ("scan.hdr", "scan.img"):
        v = read_volume(tmp_path / name)
        np.testing.assert_array_equal(v.data, expected.transpose(2, 1, 0))
        assert v.spacing == (2.0, 1.0, 0.5)
    raw = (tmp_path / "scan.img").read_bytes()
    (tmp_path / "scan.img").write_bytes(raw[: len(raw) // 2])
    with pytest.raises(DataError, match=r"scan\.hdr: truncated Analyze file: .*the data file scan\.img has"):
        read_volume(path)
    (tmp_path / "scan.img").unlink()
    with pytest.raises(DataError, match=r"scan\.hdr: an Analyze header; its data file scan\.img is missing"):
        read_volume(path)
    (tmp_path / "lone.img").write_bytes(b"\0" * 64)
    with pytest.raises(DataError, match=r"lone\.img: .*its header file lone\.hdr is missing"):
        read_volume(tmp_path / "lone.img")
    (tmp_path / "lone.hdr").write_bytes(b"not an Analyze header")
    with pytest.raises(DataError, match=r"lone\.img: not a readable Analyze file"):
        read_volume(tmp_path / "lone.img")
    # a single-file NIfTI named .hdr: said so, not "its data file is missing"
    nibabel.save(nibabel.Nifti1Image(data, np.eye(4)), tmp_path / "one.nii")
    (tmp_path / "one.hdr").write_bytes((tmp_path / "one.nii").read_bytes())
    with pytest.raises(DataError, match=r"one\.hdr: a single-file NIfTI .*name it \.nii"):
        read_volume(tmp_path / "one.hdr")


def test_compressed_and_any_case_pairs_read_as_nibabel_reads_them(tmp_path):
    """A .hdr.gz/.img.gz pair (nibabel writes and reads them) is read by
    either name; suffixes in upper or mixed case are read (nibabel pairs
    scan.HDR with scan.IMG but looks for brain.nii.gz when given
    brain.Nii.gz, and for scan.hdr and scan.img when given scan.Hdr: clvis
    reads the files there are); a pair whose other half is missing, is
    compressed where this one is not, or is ambiguous, is a DataError
    naming it."""
    data = _sample((6, 5, 4), np.dtype(np.int16), seed=7)
    nibabel.save(nibabel.AnalyzeImage(data, np.diag([0.5, 1.0, 2.0, 1.0])), tmp_path / "plain.hdr")
    want = read_volume(tmp_path / "plain.hdr")
    nibabel.save(nibabel.AnalyzeImage(data, np.diag([0.5, 1.0, 2.0, 1.0])), tmp_path / "z.hdr.gz")
    assert sorted(p.name for p in tmp_path.glob("z.*")) == ["z.hdr.gz", "z.img.gz"]
    head, img = (tmp_path / "plain.hdr").read_bytes(), (tmp_path / "plain.img").read_bytes()
    cases = {
        "UP.HDR.GZ": "UP.IMG.GZ",
        "up.HDR": "up.IMG",
        "scan.Hdr": "SCAN.IMG",
        "Mixed.hDr.Gz": "mixed.IMG.gz",
    }
    for h, i in cases.items():
        (tmp_path / h).write_bytes(gzip.compress(head) if h.lower().endswith(".gz") else head)
        (tmp_path / i).write_bytes(gzip.compress(img) if i.lower().endswith(".gz") else img)
    for name in ("z.hdr.gz", "z.img.gz", *cases, *cases.values()):
        v = read_volume(tmp_path / name)
        np.testing.assert_array_equal(v.data, want.data)
        assert v.spacing == want.spacing and np.array_equal(v.affine, want.affine), name
    nii = nibabel.Nifti1Image(data, np.diag([0.5, 1.0, 2.0, 1.0]))
    for name in ("brain.Nii.Gz", "BRAIN.NII.GZ", "brain.nii.GZ", "brain.Nii"):
        nibabel.save(nii, tmp_path / "tmp.nii.gz" if name.lower().endswith(".gz") else tmp_path / "tmp.nii")
        (tmp_path / ("tmp.nii.gz" if name.lower().endswith(".gz") else "tmp.nii")).rename(tmp_path / name)
        np.testing.assert_array_equal(read_volume(tmp_path / name).data, data.transpose(2, 1, 0))
    # the other half compressed where this one is not, and the reverse: said so
    (tmp_path / "half.hdr.gz").write_bytes(gzip.compress(head))
    (tmp_path / "half.img").write_bytes(img)
    with pytest.raises(
        DataError, match=r"half\.hdr\.gz: .*its data file half\.img\.gz is missing; half\.img is there"
    ):
        read_volume(tmp_path / "half.hdr.gz")
    with pytest.raises(
        DataError, match=r"half\.img: .*its header file half\.hdr is missing; half\.hdr\.gz is there"
    ):
        read_volume(tmp_path / "half.img")
    (tmp_path / "lone.IMG.gz").write_bytes(gzip.compress(img))
    with pytest.raises(DataError, match=r"lone\.IMG\.gz: .*its header file lone\.HDR\.gz is missing \("):
        read_volume(tmp_path / "lone.IMG.gz")
    # two files that could be the data file, neither nibabel's name for it (two.img)
    (tmp_path / "two.Hdr").write_bytes(head)
    for name in ("TWO.IMG", "Two.Img"):
        (tmp_path / name).write_bytes(img)
    with pytest.raises(
        DataError, match=r"two\.Hdr: .*several files could be its data file \(TWO\.IMG, Two\.Img\)"
    ):
        read_volume(tmp_path / "two.Hdr")
    (tmp_path / "two.img").write_bytes(img)  # nibabel's own name: the pair
    np.testing.assert_array_equal(read_volume(tmp_path / "two.Hdr").data, want.data)
    # a cut .img.gz and a header that is not gzip: DataErrors naming the file
    (tmp_path / "cut.hdr.gz").write_bytes(gzip.compress(head))
    (tmp_path / "cut.img.gz").write_bytes(gzip.compress(img)[:40])
    with pytest.raises(DataError, match=r"cut\.hdr\.gz: "):
        read_volume(tmp_path / "cut.hdr.gz")
    (tmp_path / "notgz.hdr.gz").write_bytes(head)
    (tmp_path / "notgz.img.gz").write_bytes(gzip.compress(img))
    with pytest.raises(DataError, match=r"notgz\.hdr\.gz: cannot read"):
        read_volume(tmp_path / "notgz.hdr.gz")


def test_otsu_level_sits_between_the_samples_it_separates():
    from skimage.filters import threshold_otsu

    from clvis.io.volumes import otsu_level

    mask = np.zeros((20, 20, 20), np.uint8)
    mask[5:15, 5:15, 5:15] = 1
    # scikit-image's bin centre is 1/512 of the range above the background
    assert threshold_otsu(mask.astype(np.float64)) < 0.01
    assert otsu_level(mask) == 0.5
    assert otsu_level(mask * np.uint8(255)) == 127.5
    labels = np.random.default_rng(1).integers(0, 5, 100_000)
    assert otsu_level(labels) % 1 == 0.5  # halfway between two labels
    # continuous data: the same threshold, within the gap between samples
    r = np.random.default_rng(0).normal(size=100_000)
    t, s = otsu_level(r), threshold_otsu(r)
    assert abs(t - s) < 1e-3 and (r <= t).sum() == (r <= s).sum()
    assert otsu_level(np.full(8, 3.0)) == 3.0
    with pytest.raises(ValueError, match="no finite sample"):
        otsu_level(np.full(8, np.nan))
