"""Each file that once crashed a reader, took gigabytes or escaped as a foreign
exception, made again from its recipe and read in a forked child under an
address-space limit (harness.run_limited): it must end in a clvis error naming
the file, within the limit, or read as the unchanged file does."""

import os
import stat
import struct
from pathlib import Path

import numpy as np
import pytest
from fuzz.harness import run_limited

import clvis.io as io

laspy = pytest.importorskip("laspy")
pytest.importorskip("lazrs")
nibabel = pytest.importorskip("nibabel")

DATA = Path(__file__).resolve().parents[1] / "data"
SIMPLE_LAZ = DATA / "laspy_simple.laz"  # point format 3, pointwise chunked, one chunk
SIMPLE_COPC = DATA / "laspy_simple.copc.laz"  # point format 7, layered, variable chunks
MiB = 1 << 20


def _vlr(data: bytes, key: tuple[bytes, int]) -> int:
    """Where the data of the VLR (user id, record id) starts."""
    header_size, _, n_vlr = struct.unpack_from("<HII", data, 94)
    pos = header_size
    for _ in range(n_vlr):
        uid = bytes(data[pos + 2 : pos + 18]).rstrip(b"\0")
        rid, length = struct.unpack_from("<HH", data, pos + 18)
        if (uid, rid) == key:
            return pos + 54
        pos += 54 + length
    raise AssertionError(f"no VLR {key}")


LASZIP = (b"laszip encoded", 22204)


def _edited(tmp_path, src: Path, name: str, edit) -> str:
    data = bytearray(src.read_bytes())
    edit(data)
    out = tmp_path / name
    out.write_bytes(bytes(data))
    return str(out)


def _refused(path: str, fn=io.read_points, limit=4 << 30, **kw):
    r = run_limited(fn, path, name=path, limit_bytes=limit, **kw)
    assert r.kind == "clvis", r
    return r


def test_unchanged_laspy_files_read_within_limits():
    for path in (SIMPLE_LAZ, SIMPLE_COPC):
        r = run_limited(io.read_points, str(path), limit_bytes=1 << 30)
        assert r.kind == "ok", r
        assert r.peak_rss < 256 * MiB


def test_laz_case_after_a_laz_read_in_this_process_does_not_hang():
    # a LAZ read here starts lazrs's rayon pool; a child forked from this process
    # got the pool without its threads and waited for them until the timeout (a LAZ
    # case after tests/test_io.py in one session); the harness's server forks instead
    io.read_points(str(SIMPLE_COPC))  # copc: lazrs's parallel decoder
    r = run_limited(io.read_points, str(SIMPLE_COPC), name=str(SIMPLE_COPC), timeout=10)
    assert r.kind == "ok", r


@pytest.mark.parametrize("src", [SIMPLE_COPC, SIMPLE_LAZ], ids=["copc", "simple"])
def test_laz_item_type_of_another_format_is_refused(tmp_path, src):
    # item 0's type + 1 (copc: POINT14 10 -> RGB14 11), sizes still summing to the record:
    # lazrs aborted ("memory allocation of 4229463041 bytes failed") on the copc file and
    # read re-interpreted points from simple.laz
    def edit(d):
        d[_vlr(d, LASZIP) + 34] += 1

    r = _refused(_edited(tmp_path, src, "type.laz", edit))
    assert "items (type, size, version)" in r.detail


@pytest.mark.parametrize("field,value", [(4, 1), (2, 7)], ids=["version", "size"])
def test_laz_item_version_or_size_not_canonical_is_refused(tmp_path, field, value):
    # item 1 of simple.laz (GPSTIME11, 8 bytes, version 2): another version; or RGB12's
    # size moved onto it (sizes no longer those of the format)
    def edit(d):
        at = _vlr(d, LASZIP) + 34 + 6 + field
        struct.pack_into("<H", d, at, value if field == 4 else 7)
        if field == 2:  # keep the sum: RGB12 takes the byte
            struct.pack_into("<H", d, at + 6, 7)

    _refused(_edited(tmp_path, SIMPLE_LAZ, f"{field}.laz", edit))


@pytest.mark.parametrize("chunk", [200_000_000, 50_000_000, 17_000_000])
def test_laz_chunk_size_beyond_the_point_count_is_refused(tmp_path, chunk):
    # lazrs allocates chunk size x record length up front: 200 M aborted, 17 M (within the
    # old bound of 1000 points per chunk byte) read at ~600 MB
    def edit(d):
        struct.pack_into("<I", d, _vlr(d, LASZIP) + 12, chunk)

    r = _refused(_edited(tmp_path, SIMPLE_LAZ, "chunk.laz", edit))
    assert "chunk size" in r.detail


@pytest.mark.parametrize("point_format", [6, 8])
def test_laz_of_point_formats_6_and_8_with_swapped_items_are_refused(tmp_path, point_format):
    rng = np.random.default_rng(point_format)
    las = laspy.LasData(laspy.LasHeader(point_format=point_format, version="1.4"))
    n = 200
    las.x, las.y, las.z = rng.random((3, n)) * 100
    las.intensity = rng.integers(0, 65536, n)
    src = tmp_path / f"pf{point_format}.laz"
    las.write(str(src))
    ok = run_limited(io.read_points, str(src), limit_bytes=1 << 30)
    assert ok.kind == "ok" and ok.peak_rss < 256 * MiB, ok
    for t in (11, 12, 13, 14, 6):

        def edit(d, t=t):
            struct.pack_into("<H", d, _vlr(d, LASZIP) + 34, t)

        _refused(_edited(tmp_path, src, f"pf{point_format}-{t}.laz", edit))


def test_one_chunk_laz_with_a_huge_chunk_size_is_refused(tmp_path):
    # a valid one-chunk LAZ (~300 kB) whose chunk size says 200 M points
    rng = np.random.default_rng(0)
    las = laspy.LasData(laspy.LasHeader(point_format=3, version="1.2"))
    n = 40_000
    las.x, las.y, las.z = rng.random((3, n)) * 1000
    las.red, las.green, las.blue = rng.integers(0, 65536, (3, n)).astype(np.uint16)
    src = tmp_path / "one.laz"
    las.write(str(src))
    assert run_limited(io.read_points, str(src), limit_bytes=1 << 30).kind == "ok"

    def edit(d):
        struct.pack_into("<I", d, _vlr(d, LASZIP) + 12, 200_000_000)

    _refused(_edited(tmp_path, src, "huge.laz", edit))


def test_laz_chunk_table_that_makes_lazrs_panic_is_refused(tmp_path):
    # ./dev.sh fuzz --cases 10000 --seed 27, case 8620: the 4 bytes after the chunk
    # table's version and count set to 0xFF; lazrs.read_chunk_table panicked ("index out
    # of bounds: the len is 18 but the index is 39"), and pyo3's PanicException, a
    # BaseException, escaped clvis
    def edit(d):
        (table,) = struct.unpack_from("<q", d, struct.unpack_from("<I", d, 96)[0])
        d[table + 8 : table + 12] = b"\xff" * 4

    r = _refused(_edited(tmp_path, SIMPLE_COPC, "table.laz", edit))
    assert "chunk table" in r.detail and "lazrs" in r.detail, r


@pytest.mark.parametrize("field,options", [(0, None), (1, 0), (2, None)])
def test_extra_bytes_of_data_type_0_without_bytes_are_refused(tmp_path, field, options):
    # laspy divided by the element size: ZeroDivisionError
    las = laspy.LasData(laspy.LasHeader(point_format=3, version="1.4"))
    las.add_extra_dims(
        [
            laspy.ExtraBytesParams("a", "f4"),
            laspy.ExtraBytesParams("b", "u1"),
            laspy.ExtraBytesParams("c", "i2"),
        ]
    )
    n = 20
    las.x, las.y, las.z = np.arange(3 * n, dtype=float).reshape(3, n)
    src = tmp_path / "eb.las"
    las.write(str(src))
    assert run_limited(io.read_points, str(src)).kind == "ok"

    def edit(d):
        at = _vlr(d, (b"LASF_Spec", 4)) + 192 * field
        d[at + 2] = 0
        if options is not None:
            d[at + 3] = options

    r = _refused(_edited(tmp_path, src, "eb0.las", edit))
    assert "extra bytes" in r.detail


def test_extra_bytes_field_without_a_name_is_refused(tmp_path):
    # laspy listed the field "" among the dimensions and then could not give
    # it: a bare ValueError "no field of name " (fuzz seed 334, splice+las_fields)
    las = laspy.LasData(laspy.LasHeader(point_format=3, version="1.4"))
    las.add_extra_dims([laspy.ExtraBytesParams("a", "f4"), laspy.ExtraBytesParams("b", "u1")])
    n = 20
    las.x, las.y, las.z = np.arange(3 * n, dtype=float).reshape(3, n)
    src = tmp_path / "eb.las"
    las.write(str(src))

    def edit(d):
        at = _vlr(d, (b"LASF_Spec", 4)) + 192
        d[at + 4 : at + 36] = bytes(32)  # the second field's name: empty

    r = _refused(_edited(tmp_path, src, "noname.las", edit))
    assert "extra bytes field 1 has no name" in r.detail, r


def _nifti_with_extension(tmp_path, name, esize, vox_offset=368.0):
    img = nibabel.Nifti1Image(np.random.default_rng(0).random((4, 3, 2)).astype(np.float32), np.eye(4))
    nibabel.save(img, tmp_path / "v.nii")
    b = bytearray((tmp_path / "v.nii").read_bytes())
    b[348] = 1
    struct.pack_into("<f", b, 108, vox_offset)
    b = b[:352] + struct.pack("<ii", esize, 0) + bytes(8) + b[352:]  # 16 bytes to vox_offset
    return b


@pytest.mark.parametrize("limit_gib", [4, 2, 1])
def test_nifti_extension_larger_than_the_file_is_refused(tmp_path, limit_gib):
    # a ~450-byte file with extension size 0x7FFFFFF0: nibabel reserved 2.2 GB first, and
    # under a 2 GiB limit a bare MemoryError escaped
    import gzip

    b = _nifti_with_extension(tmp_path, "ext.nii", 0x7FFFFFF0)
    (tmp_path / "ext.nii").write_bytes(b)
    (tmp_path / "ext.nii.gz").write_bytes(gzip.compress(bytes(b)))
    for name in ("ext.nii", "ext.nii.gz"):
        r = _refused(str(tmp_path / name), io.read_volume, limit=limit_gib << 30)
        assert "extension" in r.detail and r.peak_rss < 256 * MiB


def test_nifti_with_a_valid_extension_reads(tmp_path):
    b = _nifti_with_extension(tmp_path, "ok.nii", 16)
    (tmp_path / "ok.nii").write_bytes(b)
    r = run_limited(io.read_volume, str(tmp_path / "ok.nii"))
    assert r.kind == "ok", r


def test_cifti_file_is_refused_saying_what_it_is():
    path = Path(nibabel.__file__).parent / "tests" / "data" / "row_major.dconn.nii"
    if not path.is_file():
        pytest.skip("nibabel's test data is not installed")
    r = _refused(str(path), io.read_volume)
    assert "CIFTI-2" in r.detail


def _special(tmp_path, kind, suffix):
    if kind == "fifo":
        path = tmp_path / f"pipe{suffix}"
        os.mkfifo(path)
        return str(path)
    if kind == "dir":
        path = tmp_path / f"folder{suffix}"
        path.mkdir()
        return str(path)
    link = tmp_path / f"zero{suffix}"  # /dev/zero under a reader's name
    link.symlink_to("/dev/zero")
    return str(link)


@pytest.mark.parametrize("suffix", [".las", ".laz", ".ply", ".npy", ".npz"])
@pytest.mark.parametrize("kind", ["fifo", "dir", "zero"])
def test_read_points_refuses_special_files(tmp_path, kind, suffix):
    # a FIFO hung the reader, /dev/zero as .npz read to 3.7 GB, a directory gave IsADirectoryError
    path = _special(tmp_path, kind, suffix)
    r = run_limited(io.read_points, path, name=path, timeout=10)
    assert r.kind == "clvis" and "not a regular file" in r.detail, r
    assert stat.S_ISFIFO(os.stat(path).st_mode) == (kind == "fifo")


@pytest.mark.parametrize("kind", ["fifo", "dir", "zero"])
def test_other_readers_refuse_special_files(tmp_path, kind):
    pytest.importorskip("tinyvdb")
    from clvis.gauss import Gaussians, read_vdb

    readers = ((read_vdb, ".vdb"), (io.read_volume, ".npy"), (io.load_npz, ".npz"), (Gaussians.load, ".npz"))
    for fn, suffix in readers:
        (tmp_path / fn.__name__).mkdir()
        path = _special(tmp_path / fn.__name__, kind, suffix)
        r = run_limited(fn, path, name=path, timeout=10)
        # read_vdb said "no such file" of a directory
        assert r.kind == "clvis" and "not a regular file" in r.detail, (fn.__name__, r)


@pytest.mark.parametrize("field,value", [("tiles", 50_000_000), ("tiles", 10_000_000), ("children", 10**6)])
def test_vdb_root_counts_beyond_the_file_are_refused_before_tinyvdb(tmp_path, field, value):
    # the root node's tile count of a 1.5 MB file set to 5e7: tinyvdb reserved 1.7 GB first
    pytest.importorskip("tinyvdb")
    from fuzz.seeds import _vdb

    from clvis.gauss import read_vdb

    src = tmp_path / "big.vdb"
    _vdb(tmp_path, src, n=300_000, seed=3)
    ok = run_limited(read_vdb, str(src))
    assert ok.kind == "ok" and ok.peak_rss < 256 * MiB, ok
    data = bytearray(src.read_bytes())
    # after the transform's name and 18 doubles: buffer count, background, tiles, children
    at = (
        data.index(b"ScaleTranslateMap") + len("ScaleTranslateMap") + 144 + 8 + (0 if field == "tiles" else 4)
    )
    struct.pack_into("<I", data, at, value)
    path = tmp_path / "root.vdb"
    path.write_bytes(bytes(data))
    r = _refused(str(path), read_vdb)
    assert "root node" in r.detail and r.peak_rss < 256 * MiB


def _tree_fields(data: bytes) -> dict[str, int]:
    """Where fields of the first nodes of a _vdb_tree grid (zip, active mask)
    are: the grid's compression flags; the first 32^3 node's child mask, value
    mask, values' metadata byte and compressed size; the same of its first
    16^3 node; that node's first leaf value mask (topology)."""
    at = data.index(b"Tree_float_5_4_3") + 16 + 4  # then the instance parent, empty
    (grid,) = struct.unpack_from("<q", data, at)
    # after the transform's name and 18 doubles: buffer count, background, tiles, children
    root = data.index(b"ScaleTranslateMap") + len("ScaleTranslateMap") + 144
    assert struct.unpack_from("<I", data, root + 8)[0] == 0  # no root tiles
    out = {"compression": grid}
    pos = root + 16 + 12  # the first child's origin
    for level, nbytes in ((5, 4096), (4, 512)):
        out[f"child mask {level}"], out[f"value mask {level}"] = pos, pos + nbytes
        out[f"metadata {level}"] = meta = pos + 2 * nbytes
        assert data[meta] in (0, 1, 6)  # no inactive values, no selection mask
        out[f"size {level}"] = meta + 1
        pos = meta + 9 + abs(struct.unpack_from("<q", data, meta + 1)[0])
    out["leaf mask"] = pos
    return out


@pytest.fixture(scope="module")
def vdb_tree(tmp_path_factory):
    """A 1 MB grid of ~40 32^3 nodes, ~160 16^3 nodes and ~2400 leaves (zip,
    active mask) that read_vdb reads whole within 256 MB (tinyvdb 0.9's own
    voxel list returns 9,287 of its 9,439 voxels; read_vdb places the leaves
    by its walk of the file)."""
    tinyvdb = pytest.importorskip("tinyvdb")
    from fuzz.seeds import _vdb_tree

    from clvis.gauss import read_vdb
    from clvis.io.vdb import check_vdb

    tmp = tmp_path_factory.mktemp("vdb_tree")
    path = tmp / "tree.vdb"
    _vdb_tree(tmp, path, compression=tinyvdb.COMPRESS_ZIP | tinyvdb.COMPRESS_ACTIVE_MASK, clusters=20)
    assert 500_000 < path.stat().st_size < 3_000_000
    assert sum(w[0] for w in check_vdb(path) if w is not None) == 9_439
    ok = run_limited(read_vdb, str(path))
    assert ok.kind == "ok" and ok.peak_rss < 256 * MiB, ok
    return path


# One field of a node changed. Before the tree walk, under a 16 GiB address
# space, 8 of these made tinyvdb try to allocate more than that ("OOM"; across
# 1,188 such mutants of a 1 MB and a 4 MB tree, 274 did, 5 more reserved 4.3
# to 17.2 GB); "size 4" read as intact (tinyvdb reads the 4096 values whatever
# raw size the block declares; OpenVDB refuses it); "compression" desynced it.
@pytest.mark.parametrize(
    "field,width,value",
    [
        ("compression", 4, 1),  # zip without the active mask: the value counts change
        ("child mask 5", 8, 2**64 - 1),  # 64 more 16^3 children
        ("value mask 5", 8, 2**63 - 1),
        ("metadata 5", 1, 4),  # an inactive value and a selection mask that are not there
        ("size 5", 8, 1 << 40),  # a compressed block of 1 TB
        ("child mask 4", 8, 0xFFFFFF0000000000),
        ("value mask 4", 8, 2**63 - 1),
        ("metadata 4", 1, 5),
        ("size 4", 8, 2**64 - (1 << 31)),  # 2 GB of raw values for 4096
        ("leaf mask", 8, 1 << 31),  # tinyvdb counts the buffer's values with it
    ],
)
def test_vdb_node_fields_beyond_the_file_are_refused_before_tinyvdb(tmp_path, vdb_tree, field, width, value):
    from clvis.errors import DataError
    from clvis.gauss import read_vdb
    from clvis.io.vdb import check_vdb

    data = bytearray(vdb_tree.read_bytes())
    at = _tree_fields(bytes(data))[field]
    data[at : at + width] = value.to_bytes(width, "little")
    path = tmp_path / "node.vdb"
    path.write_bytes(bytes(data))
    with pytest.raises(DataError, match="malformed VDB file"):
        check_vdb(path)  # the walk, before tinyvdb opens the file
    r = _refused(str(path), read_vdb)
    assert "malformed VDB file" in r.detail and r.peak_rss < 256 * MiB, r
