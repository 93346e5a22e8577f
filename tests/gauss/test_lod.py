"""Sparse volumes (clvis.gauss.sparse) and their Gaussian levels of detail
(clvis.gauss.lod, kernels_cl/gauss/lod.cl) against clvis.reference.gauss.lod,
bit for bit, on every device and both tuning profiles; VDB files through
tinyvdb."""

import struct
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import clvis
from clvis import runtime
from clvis.errors import ClvisWarning
from clvis.gauss.gaussians import Gaussians
from clvis.gauss.lod import (
    BYTES_PER_AXIS_ALIGNED_GAUSSIAN,
    BYTES_PER_GAUSSIAN,
    LODS,
    gaussians_from_volume,
    lod_table,
)
from clvis.gauss.sparse import SparseVolume, read_vdb
from clvis.reference.gauss import lod as ref

F32 = np.float32


def _same(got: Gaussians, want: Gaussians):
    assert isinstance(got, Gaussians)
    assert len(got) == len(want)
    for k in ("means", "scales", "values"):
        a, b = getattr(got, k), getattr(want, k)
        assert a.dtype == np.float32
        # bit for bit (-0.0 and +0.0 differ, NaN never appears)
        np.testing.assert_array_equal(a.view(np.uint32), b.view(np.uint32), err_msg=k)
    np.testing.assert_array_equal(got.rotations, np.broadcast_to(np.eye(3, dtype=F32), (len(got), 3, 3)))
    np.testing.assert_array_equal(got.opacities, np.ones(len(got), F32))


def _check(queue, vol, lod, **kw):
    got = gaussians_from_volume(vol, lod, queue=queue, **kw)
    want = ref.gaussians_from_volume(vol, lod, **kw)
    _same(got, want)
    return got


def _cases():
    rng = np.random.default_rng(7)
    one = np.zeros((9, 10, 11), F32)
    one[4, 7, 9] = -2.5
    odd = rng.standard_normal((13, 17, 9)).astype(F32)
    neg = (rng.standard_normal((20, 12, 18)) * 100 - 30).astype(F32)
    equal = np.full((11, 19, 8), 3.25, F32)
    dense = rng.random((16, 16, 24)).astype(F32)
    dense[8:, 8:, :8] = -0.75  # one tile beside voxel leaves
    return [
        ("empty", np.zeros((5, 6, 7), F32), {"threshold": 0.0}),
        ("zero-size", np.zeros((0, 4, 4), F32), {}),
        ("one voxel", one, {"mask": one != 0}),
        ("full, tiles", np.full((16, 16, 16), 2.0, F32), {}),
        ("full, one tile", dense, {"spacing": (0.5, 0.25, 2.0)}),
        ("13x17x9 threshold", odd, {"threshold": 0.3}),
        (
            "random mask, negative",
            neg,
            {"mask": rng.random(neg.shape) < 0.35, "spacing": (0.1, 0.2, 0.3), "origin": (-5.0, 7.5, 1e3)},
        ),
        ("dense blocks", neg, {"mask": np.kron(rng.random((10, 6, 9)) < 0.7, np.ones((2, 2, 2), bool))}),
        ("all equal", equal, {"threshold": 3.0, "origin": (1.0, 2.0, 3.0)}),
    ]


@pytest.mark.parametrize("lod", LODS)
def test_matches_reference(queue, lod):
    for name, vol, kw in _cases():
        try:
            _check(queue, vol, lod, **kw)
        except AssertionError as e:
            raise AssertionError(f"case {name!r}: {e}") from None


def test_known_values(queue):
    # a full 16^3 volume of 2.0: 8 tiles
    vol = np.full((16, 16, 16), 2.0, F32)
    sp = (1.0, 2.0, 4.0)  # dz, dy, dx
    low = gaussians_from_volume(vol, "low", spacing=sp, queue=queue)
    assert len(low) == 8
    np.testing.assert_array_equal(low.scales, np.tile([[16.0, 8.0, 4.0]], (8, 1)))
    np.testing.assert_array_equal(low.means[0], [3.5 * 4, 3.5 * 2, 3.5])
    np.testing.assert_array_equal(low.means[1], [11.5 * 4, 3.5 * 2, 3.5])  # x fastest
    np.testing.assert_array_equal(low.values, np.full(8, 2.0, F32))
    med = gaussians_from_volume(vol, "medium", spacing=sp, queue=queue)
    assert len(med) == 64
    np.testing.assert_array_equal(med.scales[0], [8.0, 4.0, 2.0])
    np.testing.assert_array_equal(med.means[:2], [[1.5 * 4, 1.5 * 2, 1.5], [5.5 * 4, 1.5 * 2, 1.5]])
    high = gaussians_from_volume(vol, "high", spacing=sp, queue=queue)
    assert len(high) == 512
    np.testing.assert_array_equal(high.scales[0], [4.0, 2.0, 1.0])
    # one active voxel: one Gaussian at the voxel, sigma = spacing / 2, at every LOD
    one = np.zeros((9, 10, 11), F32)
    one[4, 7, 9] = -2.5
    for lod in LODS:
        g = gaussians_from_volume(
            one, lod, mask=one != 0, spacing=(0.5, 2.0, 3.0), origin=(1, 2, 3), queue=queue
        )
        np.testing.assert_array_equal(g.means, [[9 * 3.0 + 1, 7 * 2.0 + 2, 4 * 0.5 + 3]])
        np.testing.assert_array_equal(g.scales, [[1.5, 1.0, 0.25]])
        np.testing.assert_array_equal(g.values, [-2.5])


def test_medium_sparse_order(queue):
    """A full 2^3 block, a partial block and a lone voxel of one sparse leaf."""
    vol = np.arange(512, dtype=F32).reshape(8, 8, 8)
    m = np.zeros((8, 8, 8), bool)
    m[0:2, 0:2, 0:2] = True  # block 0: full
    m[1, 0, 2] = m[0, 1, 3] = True  # block 1 (x 2..3): voxels [0,1,3] then [1,0,2]
    m[7, 7, 7] = True  # block 63
    g = gaussians_from_volume(vol, "medium", mask=m, queue=queue)
    np.testing.assert_array_equal(g.means, [[0.5, 0.5, 0.5], [3, 1, 0], [2, 0, 1], [7, 7, 7]])
    np.testing.assert_array_equal(g.scales, [[1, 1, 1], [0.5] * 3, [0.5] * 3, [0.5] * 3])
    np.testing.assert_array_equal(g.values, [np.mean(vol[0:2, 0:2, 0:2]), vol[0, 1, 3], vol[1, 0, 2], 511])
    high = gaussians_from_volume(vol, "high", mask=m, queue=queue)
    np.testing.assert_array_equal(high.values, vol[m])  # z-y-x order
    low = gaussians_from_volume(vol, "low", mask=m, queue=queue)
    np.testing.assert_array_equal(low.means, [[3.5, 3.5, 3.5]])
    np.testing.assert_array_equal(low.scales, [[4, 4, 4]])
    np.testing.assert_allclose(low.values, [vol[m].mean()], rtol=1e-6)
    _same(low, ref.gaussians_from_volume(vol, "low", mask=m))


def test_low_mean(queue):
    """The low LOD's value is the mean of the active values (float32, fixed order)."""
    rng = np.random.default_rng(11)
    vol = (rng.standard_normal((24, 16, 16)) * 1e3).astype(F32)
    mask = rng.random(vol.shape) < 0.6
    g = _check(queue, vol, "low", mask=mask)
    sv = SparseVolume.from_dense(vol, mask=mask)
    for i, (z, y, x) in enumerate(sv.coords):
        leaf, lm = vol[z : z + 8, y : y + 8, x : x + 8], mask[z : z + 8, y : y + 8, x : x + 8]
        np.testing.assert_allclose(g.values[i], leaf[lm].astype(np.float64).mean(), rtol=1e-5, atol=1e-3)


@given(
    shape=st.tuples(st.integers(1, 20), st.integers(1, 20), st.integers(1, 20)),
    density=st.sampled_from([0.0, 0.05, 0.5, 0.95, 1.0]),
    seed=st.integers(0, 2**31),
    lod=st.sampled_from(LODS),
    blocky=st.booleans(),
)
def test_property(device, profile, shape, density, seed, lod, blocky):
    rng = np.random.default_rng(seed)
    vol = (rng.standard_normal(shape) * 10).astype(F32)
    if blocky:  # 2^3 blocks all active or not: full blocks in sparse leaves
        m = np.kron(rng.random([-(-s // 2) for s in shape]) < density, np.ones((2, 2, 2), bool))
        m = m[: shape[0], : shape[1], : shape[2]]
    else:
        m = rng.random(shape) < density
    with runtime.configure(tuning=profile):
        _check(runtime.queue_for(device), vol, lod, mask=m, spacing=(0.5, 1.5, 2.0), origin=(3.0, -1.0, 0.25))


# --------------------------------------------------------------------------
# the sparse layout


def test_sparse_from_dense_matches_reference():
    rng = np.random.default_rng(5)
    vols = [
        (rng.standard_normal((13, 17, 9)).astype(F32), {"threshold": 0.2}),
        (np.full((16, 8, 24), 1.5, F32), {}),
        (rng.standard_normal((8, 8, 8)).astype(np.float64), {"mask": rng.random((8, 8, 8)) < 0.1}),
        (np.zeros((3, 0, 2), F32), {}),
    ]
    for vol, kw in vols:
        sv = SparseVolume.from_dense(vol, **kw)
        want = ref.sparse_from_dense(vol, **kw)
        assert sv.shape == want["shape"]
        for k in ("coords", "masks", "tiles", "tile_values", "values"):
            np.testing.assert_array_equal(getattr(sv, k), want[k], err_msg=k)
            assert getattr(sv, k).dtype == want[k].dtype
        act = (vol > 0.2) if "threshold" in kw else kw.get("mask", np.ones(vol.shape, bool))
        np.testing.assert_array_equal(sv.active(), act)
        np.testing.assert_array_equal(sv.to_dense(), np.where(act, vol, 0).astype(F32))
        np.testing.assert_array_equal(sv.to_dense(background=-1), np.where(act, vol, -1).astype(F32))
        assert sv.n_active == act.sum()


def test_sparse_layout_details():
    vol = np.zeros((16, 16, 16), F32)
    vol[:8, :8, :8] = 4.0  # a tile
    vol[:8, :8, 8:] = 4.0
    vol[0, 0, 8] = 0.0  # one voxel differs: not a tile
    vol[8:, :8, :8] = 0.0  # all-active zeros: a tile of 0.0
    vol[8, 0, 0] = -0.0  # -0.0 differs in bits: not a tile
    sv = SparseVolume.from_dense(vol)
    np.testing.assert_array_equal(sv.coords[:3], [[0, 0, 0], [0, 0, 8], [0, 8, 0]])
    assert sv.tiles.tolist() == [True, False, True, True, False, True, True, True]
    assert sv.tile_values[0] == 4.0 and len(sv.values) == 2
    assert sv.nbytes == 8 * (12 + 64 + 1 + 4) + 2 * 2048
    assert (sv.masks == 0xFFFFFFFF).all()
    np.testing.assert_array_equal(sv.to_dense().view(np.uint32), vol.view(np.uint32))
    # sizes not a multiple of 8: voxels outside the volume are inactive
    sv = SparseVolume.from_dense(np.ones((9, 9, 9), F32))
    assert sv.n_leaves == 8 and sv.n_tiles == 1 and sv.n_active == 729
    np.testing.assert_array_equal(sv.active_masks()[1].reshape(8, 8, 8)[:, :, 0], True)
    np.testing.assert_array_equal(sv.active_masks()[1].reshape(8, 8, 8)[:, :, 1:], False)


def test_a_volume_read_from_a_file_brings_its_spacing_and_origin(queue):
    """gaussians_from_volume / SparseVolume.from_dense of a clvis.Volume: its
    data, spacing and origin, as if passed; given ones win."""
    from clvis.io import Volume

    data = np.random.default_rng(3).random((9, 10, 11)).astype(F32)
    vol = Volume(data, (0.5, 1.0, 2.0), (-3.0, 1.0, 0.25))
    sv = SparseVolume.from_dense(vol, threshold=0.5)
    assert sv.spacing == (0.5, 1.0, 2.0) and sv.origin == (-3.0, 1.0, 0.25)
    assert SparseVolume.from_dense(vol, spacing=(1, 1, 1)).spacing == (1.0, 1.0, 1.0)
    got = gaussians_from_volume(vol, "medium", threshold=0.5, queue=queue)
    want = gaussians_from_volume(
        data, "medium", threshold=0.5, spacing=(0.5, 1.0, 2.0), origin=(-3.0, 1.0, 0.25), queue=queue
    )
    np.testing.assert_array_equal(got.means, want.means)
    np.testing.assert_array_equal(got.scales, want.scales)


def test_bad_input():
    vol = np.ones((4, 5, 6), F32)
    with pytest.raises(ValueError, match="volume: expected a 3-D"):
        gaussians_from_volume(np.ones((4, 5)), "low")
    with pytest.raises(TypeError, match="volume: expected real numbers"):
        gaussians_from_volume(np.ones((4, 5, 6), bool), "low")
    with pytest.raises(ValueError, match="lod: expected one of"):
        gaussians_from_volume(vol, "ultra")
    with pytest.raises(ValueError, match="threshold, mask"):
        gaussians_from_volume(vol, "low", threshold=0.5, mask=vol > 0)
    with pytest.raises(TypeError, match="mask: expected a bool array"):
        gaussians_from_volume(vol, "low", mask=np.ones(vol.shape, np.uint8))
    with pytest.raises(ValueError, match=r"mask: shape \(4, 5, 5\) differs"):
        gaussians_from_volume(vol, "low", mask=np.ones((4, 5, 5), bool))
    with pytest.raises(ValueError, match="spacing"):
        gaussians_from_volume(vol, "low", spacing=(1, 0, 1))
    with pytest.raises(ValueError, match="origin"):
        gaussians_from_volume(vol, "low", origin=(1, np.inf, 1))
    with pytest.raises(ValueError, match="threshold: NaN"):
        gaussians_from_volume(vol, "low", threshold=float("nan"))
    sv = SparseVolume.from_dense(vol)
    with pytest.raises(ValueError, match="threshold: a SparseVolume already"):
        gaussians_from_volume(sv, "low", threshold=0)
    bad = vol.copy()
    bad[2, 3, 4] = np.nan
    with pytest.raises(clvis.DataError, match=r"active voxel \[z, y, x\] = \[2, 3, 4\] is nan"):
        gaussians_from_volume(bad, "medium")
    bad[2, 3, 4] = -np.inf
    with pytest.raises(clvis.DataError, match=r"\[2, 3, 4\] is -inf"):
        SparseVolume.from_dense(bad, mask=np.ones(bad.shape, bool))
    # NaN in an inactive voxel is fine (NaN is never above a threshold)
    bad[2, 3, 4] = np.nan
    assert SparseVolume.from_dense(bad, threshold=0.5).n_active == vol.size - 1
    with pytest.raises(clvis.DataError, match="leaves must be unique"):
        SparseVolume(
            (16, 8, 8),
            (1, 1, 1),
            (0, 0, 0),
            [[8, 0, 0], [0, 0, 0]],
            np.ones((2, 16), np.uint32),
            [False, False],
            [0, 0],
            np.zeros((2, 512)),
        )
    with pytest.raises(clvis.DataError, match="outside the volume"):
        SparseVolume(
            (4, 8, 8),
            (1, 1, 1),
            (0, 0, 0),
            [[0, 0, 0]],
            np.full((1, 16), 0xFFFFFFFF, np.uint32),
            [False],
            [0],
            np.zeros((1, 512)),
        )


def test_lod_table(queue):
    rng = np.random.default_rng(2)
    vol = rng.standard_normal((20, 24, 16)).astype(F32)
    vol[:8, :8, :8] = 1.0
    sv = SparseVolume.from_dense(vol, threshold=-0.5)
    table = lod_table(sv, queue=queue)
    assert (table.leaves, table.tiles, table.active_voxels) == (sv.n_leaves, 1, int((vol > -0.5).sum()))
    assert table.sparse_bytes == sv.nbytes
    want = ref.lod_table(sv)
    for lod in LODS:
        n = len(gaussians_from_volume(sv, lod, queue=queue))
        row = table[lod]
        assert row.gaussians == n == want[lod]
        assert row.bytes == n * BYTES_PER_GAUSSIAN == Gaussians(np.zeros((n, 3)), np.zeros((n, 3))).nbytes
        assert row.axis_aligned_bytes == n * BYTES_PER_AXIS_ALIGNED_GAUSSIAN
    assert table["low"].gaussians == sv.n_leaves
    assert "medium" in table.format()
    empty = lod_table(SparseVolume.from_dense(np.zeros((4, 4, 4)), threshold=1), queue=queue)
    assert [r.gaussians for r in empty.rows] == [0, 0, 0]


# --------------------------------------------------------------------------
# OpenVDB files: tinyvdb 0.9 writes a file only from one it has read, so the
# tests make a minimal OpenVDB file (header, grid descriptors, transform, an
# empty tree), let tinyvdb fill a grid and save it, and read that back.


def _s(text: str) -> bytes:
    b = text.encode()
    return struct.pack("<I", len(b)) + b


def _scale_translate(voxel_size, translation) -> bytes:
    vs, t = np.asarray(voxel_size, float), np.asarray(translation, float)
    return _s("ScaleTranslateMap") + b"".join(
        struct.pack("<3d", *v) for v in (t, vs, vs, 1 / vs, 1 / vs**2, 0.5 / vs)
    )


def _affine(m) -> bytes:
    return _s("AffineMap") + struct.pack("<16d", *np.asarray(m, float).ravel())


def _vdb_template(grids, root_tiles=()) -> bytes:
    """An OpenVDB (format 224) file of empty grids: (name, type, transform
    bytes); root_tiles: each float grid's root tiles ((i, j, k), value, active),
    or {grid index: its root tiles}."""
    out = struct.pack("<qIIIB", 0x56444220, 224, 11, 0, 1) + b"0EA4B2C5-0F55-4B24-9C25-5CFD16E1E1CE"
    out += struct.pack("<II", 0, len(grids))  # no file metadata; grid count
    for i, (name, type_name, transform) in enumerate(grids):
        body = struct.pack("<II", 0, 0) + transform + struct.pack("<I", 1)  # no compression, no metadata
        body += struct.pack("<i" if "int" in type_name else "<f", 0)  # background
        tiles = root_tiles.get(i, ()) if isinstance(root_tiles, dict) else root_tiles
        tiles = tiles if "float" in type_name else ()
        body += struct.pack("<ii", len(tiles), 0)  # root tiles, no children
        body += b"".join(struct.pack("<3ifB", *ijk, value, active) for ijk, value, active in tiles)
        out += _s(name) + _s(type_name) + _s("")
        pos = len(out) + 24
        out += struct.pack("<qqq", pos, pos + len(body), pos + len(body)) + body
    return out


def _write_vdb(tmp_path, name, grids, fill):
    """Write the template, fill grids with tinyvdb ({index: (ijk (N, 3), values)}) and save."""
    import tinyvdb  # a test dependency: fails (not skips) when missing

    template = tmp_path / f"{name}-template.vdb"
    template.write_bytes(_vdb_template(grids))
    path = tmp_path / f"{name}.vdb"
    with tinyvdb.open(str(template)) as f:
        f.read_grids()
        for i, (ijk, vals) in fill.items():
            f.extend_grid_from_sparse(
                i,
                np.ascontiguousarray(ijk, np.int32).tobytes(),
                np.ascontiguousarray(vals, np.float32).tobytes(),
                grids[i][0],
            )
        f.save(str(path))
    return path


def _random_voxels(seed=4):
    rng = np.random.default_rng(seed)
    vol = (rng.standard_normal((19, 14, 23)) * 5).astype(F32)
    act = rng.random(vol.shape) < 0.2
    act[:8, :8, :8] = True
    vol[:8, :8, :8] = 0.5  # a tile once aligned
    shift = np.array([-37, 5, 250])  # VDB index (i, j, k) = (x, y, z) + shift
    zyx = np.argwhere(act)
    return vol, act, zyx[:, ::-1] + shift, vol[act], shift


def test_vdb_round_trip(tmp_path):
    vol, act, ijk, vals, shift = _random_voxels()
    grids = [
        ("labels", "Tree_int32_5_4_3", _scale_translate((1, 1, 1), (0, 0, 0))),
        ("temperature", "Tree_float_5_4_3", _scale_translate((1, 1, 1), (0, 0, 0))),
        ("density", "Tree_float_5_4_3", _scale_translate((0.5, 0.25, 2.0), (1.0, -2.0, 3.5))),
    ]
    path = _write_vdb(tmp_path, "rt", grids, {1: (ijk[:5], vals[:5]), 2: (ijk, vals)})
    sv = read_vdb(path, grid="density")
    # the offset is leaf-aligned: x = -37 -> leaf origin -40; y = 5 -> 0; z = 250 -> 248
    off_xyz = np.array([-40, 0, 248])
    rel = shift - off_xyz  # where the volume's [0, 0, 0] lands
    assert sv.shape == tuple(int(s) for s in (np.argwhere(act).max(axis=0) + 1 + rel[::-1]))
    assert sv.spacing == (2.0, 0.25, 0.5)
    np.testing.assert_allclose(sv.origin, np.array([1.0, -2.0, 3.5]) + np.array([0.5, 0.25, 2.0]) * off_xyz)
    dense, active = sv.to_dense(), sv.active()
    z0, y0, x0 = rel[::-1]
    Z, Y, X = vol.shape
    np.testing.assert_array_equal(active[z0 : z0 + Z, y0 : y0 + Y, x0 : x0 + X], act)
    assert active.sum() == act.sum()
    np.testing.assert_array_equal(dense[z0 : z0 + Z, y0 : y0 + Y, x0 : x0 + X], np.where(act, vol, 0))
    # world positions agree: VDB's voxel_size * ijk + translation
    w_vdb = np.array([0.5, 0.25, 2.0]) * ijk + [1.0, -2.0, 3.5]
    idx = np.argwhere(active)[:, ::-1]
    w_sv = np.asarray(sv.origin) + idx * np.asarray(sv.spacing)[::-1]
    np.testing.assert_allclose(np.sort(w_sv, axis=0), np.sort(w_vdb, axis=0), rtol=1e-12)
    # default: the first float grid; by index
    assert read_vdb(path).n_active == 5
    assert read_vdb(path, grid=2).n_active == act.sum()
    assert sv.n_leaves == SparseVolume.from_dense(dense, mask=active).n_leaves
    for lod in LODS:
        _same(gaussians_from_volume(sv, lod), ref.gaussians_from_volume(sv, lod))
    _same_as_walked(path, "density", sv)


def _same_as_walked(path, grid, sv):
    """The grid as clvis's walk alone reads it (read_vdb's way for a file
    tinyvdb cannot read: names, transform, values, all from the walk) is sv."""
    from clvis.gauss import sparse
    from clvis.io.vdb import vdb_grids

    walked = sparse._read_walked(path, grid, vdb_grids(path), "why")
    assert (walked.shape, walked.spacing, walked.origin) == (sv.shape, sv.spacing, sv.origin)
    np.testing.assert_array_equal(walked.to_dense().view(np.uint32), sv.to_dense().view(np.uint32))
    np.testing.assert_array_equal(walked.active(), sv.active())


def test_vdb_grids_and_transforms(tmp_path):
    ijk = np.array([[0, 0, 0], [-8, 3, 17]])
    c, s = np.cos(0.3), np.sin(0.3)
    grids = [
        ("labels", "Tree_int32_5_4_3", _scale_translate((1, 1, 1), (0, 0, 0))),
        ("rot", "Tree_float_5_4_3", _affine([[c, s, 0, 0], [-s, c, 0, 0], [0, 0, 1, 0], [1, 2, 3, 1]])),
        ("diag", "Tree_float_5_4_3", _affine([[2, 0, 0, 0], [0, 3, 0, 0], [0, 0, 4, 0], [5, 6, 7, 1]])),
        ("empty", "Tree_float_5_4_3", _scale_translate((1, 1, 1), (0, 0, 0))),
    ]
    path = _write_vdb(tmp_path, "grids", grids, {1: (ijk, [1, 2]), 2: (ijk, [1, 2])})
    sv = read_vdb(path, grid="diag")
    assert sv.spacing == (4.0, 3.0, 2.0) and sv.shape == (18, 4, 9)
    np.testing.assert_allclose(sv.origin, [5 - 16, 6, 7])
    np.testing.assert_array_equal(sv.to_dense()[17, 3, 0], 2.0)
    _same_as_walked(path, "diag", sv)  # an affine map, from the walk
    with pytest.raises(clvis.DataError, match="rotates or shears") as e:
        read_vdb(path)  # the first float grid is "rot"
    assert str(path) in str(e.value)
    with pytest.raises(clvis.DataError, match="rotates or shears"):
        _same_as_walked(path, None, sv)
    # a mirrored axis: OpenVDB's scale map stores the scale (-2, 3, 4) and the
    # voxel size (2, 3, 4); read by the voxel size the grid came out
    # unmirrored, each voxel at the wrong place, and no error
    vs, sc = np.array([2.0, 3.0, 4.0]), np.array([-2.0, 3.0, 4.0])
    mirror = _s("ScaleTranslateMap") + b"".join(
        struct.pack("<3d", *v) for v in (np.zeros(3), sc, vs, 1 / sc, 1 / sc**2, 0.5 / sc)
    )
    mirrored = [("mirrored", "Tree_float_5_4_3", mirror)]
    mpath = _write_vdb(tmp_path, "mirror", mirrored, {0: (ijk, [1, 2])})
    with pytest.raises(clvis.DataError, match=r"mirrors an axis \(scale \(-2.0, 3.0, 4.0\)\)") as e:
        read_vdb(mpath)
    assert str(mpath) in str(e.value)
    with pytest.raises(clvis.DataError, match="mirrors an axis"):
        _same_as_walked(mpath, None, sv)
    with pytest.raises(clvis.DataError, match="'labels' is a Tree_int32_5_4_3, not a float grid"):
        read_vdb(path, grid="labels")
    with pytest.raises(clvis.DataError, match="no grid named 'nope'"):
        read_vdb(path, grid="nope")
    with pytest.raises(clvis.DataError, match="no grid 9"):
        read_vdb(path, grid=9)
    empty = read_vdb(path, grid="empty")
    assert empty.n_leaves == 0 and empty.shape == (0, 0, 0)
    assert len(gaussians_from_volume(empty, "high")) == 0
    only_int = tmp_path / "int.vdb"
    only_int.write_bytes(_vdb_template(grids[:1]))
    with pytest.raises(clvis.DataError, match="no float grid"):
        read_vdb(only_int)


def test_vdb_leaves_past_tinyvdbs_voxel_list_are_read(tmp_path):
    """tinyvdb 0.9's own voxel list (to_sparse) returns at most 64 leaves of a
    16^3 node: a 40x32x32 block (80 leaves) came back as 32^3 voxels, and
    read_vdb refused the grid. read_vdb now places each leaf by clvis's walk
    of the file and takes its values from tinyvdb's tree: the whole block,
    every value where it was written."""
    grids = [("density", "Tree_float_5_4_3", _scale_translate((1, 1, 1), (0, 0, 0)))]
    block = np.argwhere(np.ones((32, 32, 40)))[:, ::-1]  # (x, y, z), x 0..39: 5 x 4 x 4 leaves
    vals = (np.arange(len(block)) % 997).astype(F32)
    path = _write_vdb(tmp_path, "block", grids, {0: (block, vals)})
    sv = read_vdb(path)
    assert sv.n_active == 40 * 32 * 32 and sv.shape == (32, 32, 40) and sv.n_leaves == 80
    want = np.zeros((32, 32, 40), F32)
    want[block[:, 2], block[:, 1], block[:, 0]] = vals
    np.testing.assert_array_equal(sv.to_dense(), want)


def test_vdb_tinyvdb_tree_that_disagrees_with_the_file_is_refused(tmp_path):
    """The walk's leaves and tinyvdb's are matched leaf by leaf: a leaf too
    many or too few, or a leaf whose active count is not its value mask's,
    is a DataError naming the file and the grid, never voxels misplaced."""
    from clvis.gauss import sparse
    from clvis.io.vdb import vdb_leaves

    grids = [("density", "Tree_float_5_4_3", _scale_translate((1, 1, 1), (0, 0, 0)))]
    _, _, ijk, vals, _ = _random_voxels(seed=5)
    path = _write_vdb(tmp_path, "rnd", grids, {0: (ijk, vals)})
    walked = vdb_leaves(path)[0]
    assert walked is not None and len(walked) > 2

    class Node:
        def __init__(self, kind, count=0):
            self.type, self.active_voxel_count = kind, count
            self.data = None if kind != "leaf" else np.zeros(512, F32).tobytes()

    class Tree:
        def __init__(self, nodes):
            self.nodes, self.num_nodes = nodes, len(nodes)

        def node(self, i):
            return self.nodes[i]

    class Grid:
        def __init__(self, nodes):
            self.tree = Tree(nodes)

    counts = [int(np.unpackbits(m).sum()) for m in walked.masks]
    good = [Node("root"), Node("internal")] + [Node("leaf", c) for c in counts]
    at, lv, la = sparse._leaf_values(path, "density", Grid(good), walked)
    assert la.sum() == walked.active == len(ijk) and not lv.any()
    z, y, x = np.unravel_index(np.nonzero(la)[1], (8, 8, 8))
    got = at[np.nonzero(la)[0]] + np.stack([x, y, z], axis=1)
    np.testing.assert_array_equal(np.unique(got, axis=0), np.unique(ijk, axis=0))
    for nodes, match in [
        (good[:-1], f"tinyvdb read {len(counts) - 1} leaves of the file's {len(counts)}"),
        (good + [Node("leaf", 1)], "more leaves than the file's"),
        (good[:3] + [Node("leaf", counts[1] + 1)] + good[4:], "leaf 1 does not match the file's"),
    ]:
        with pytest.raises(clvis.DataError, match=match) as e:
            sparse._leaf_values(path, "density", Grid(nodes), walked)
        assert str(path) in str(e.value) and "'density'" in str(e.value)


def test_vdb_written_by_openvdb():
    """tests/data/openvdb_small.vdb, written by the OpenVDB library (10.0.1;
    tests/data/make_openvdb_small.py): a level-set sphere whose 94 leaves share
    one 16^3 node (tinyvdb 0.9's own voxel list returns 8,534 of its 12,790
    voxels) and a fog ball saved as half floats, both against their formulas."""
    path = Path(__file__).parents[1] / "data" / "openvdb_small.vdb"
    surface = read_vdb(path)  # the first float grid
    assert surface.n_active == 12_790 and surface.spacing == (1.0, 1.0, 1.0)
    act = surface.active()
    idx = np.argwhere(act)[:, ::-1]  # (x, y, z)
    world = np.asarray(surface.origin) + idx * np.asarray(surface.spacing)[::-1]
    sdf = np.linalg.norm(world - [60.0, 61.0, 62.0], axis=1) - 16.0
    np.testing.assert_allclose(surface.to_dense()[act], sdf, atol=1e-4)
    assert np.abs(sdf).max() <= 2.0 + 1e-6  # the narrow band: half width 2 voxels

    fog = read_vdb(path, grid="density")
    assert fog.n_active == 7_208 and fog.spacing == (0.25, 0.25, 0.25)
    act = fog.active()
    idx = np.argwhere(act)[:, ::-1]
    ijk = np.rint((np.asarray(fog.origin) + idx * 0.25) / 0.25).astype(int) - [-30, 4, 9]
    r = np.linalg.norm(ijk - 11.5, axis=1)
    want = np.clip(1 - r / 12, 0, 1).astype(F32).astype(np.float16).astype(F32)
    np.testing.assert_array_equal(fog.to_dense()[act], want)
    assert ((ijk >= 0) & (ijk < 24)).all() and (want > 0).all()
    for lod in LODS:
        _same(gaussians_from_volume(fog, lod), ref.gaussians_from_volume(fog, lod))

    # uniform regions stored as active tiles, a 128^3 one and 8^3 ones
    # (tinyvdb reads no tile: the grid came back as its 27 leaves)
    block = read_vdb(path, grid="block")
    want = np.full((160, 160, 160), 0.5, F32)
    i, j, k = np.mgrid[:20, :20, :20]
    want[140:, 140:, 140:] = ((i + 2 * j + 3 * k) % 7 / 7 + 0.25).astype(F32)
    assert block.shape == (160, 160, 160) and block.n_active == 160**3 and block.active().all()
    np.testing.assert_array_equal(block.to_dense(), want.transpose(2, 1, 0))  # [z, y, x] of (i, j, k)
    assert block.n_leaves == 20**3 and block.n_tiles == 20**3 - 27


def test_vdb_instance_grids_share_their_parents_tree(tmp_path):
    """tests/data/openvdb_instance.vdb (OpenVDB 10.0.1): "inst" shares the
    tree of "orig" (grid.copy()), which OpenVDB writes once: the instance
    stores only its transform, and a block offset of 0. The walk refused the
    whole file ("grid offsets ... outside the file"), every grid of it; now
    an instance is its parent's tree under its own transform."""
    from clvis.io.vdb import check_vdb

    path = Path(__file__).parents[1] / "data" / "openvdb_instance.vdb"
    assert check_vdb(path) == [(60, 1), (60, 1), (1, 1)]
    want = np.zeros((16, 16, 24), F32)  # [z, y, x] from x = -16
    want[:, :, :16] = 0.5  # eight active 8^3 tiles over (-16..-1, 0..15, 0..15)
    i, j, k = np.mgrid[:5, :4, :3]
    want[5 + k, 4 + j, 19 + i] = ((i + 2 * j + 3 * k) % 11 / 11).astype(F32)
    act = want != 0
    act[5:8, 4:8, 19:24] = True  # (0, 0, 0) of the formula is 0, and active
    for name, spacing, origin in [("orig", 1.0, (-16, 0, 0)), ("inst", 0.5, (1 - 8, 2, 3))]:
        sv = read_vdb(path, grid=name)
        assert sv.spacing == (spacing,) * 3 and sv.origin == origin and sv.n_tiles == 8
        np.testing.assert_array_equal(sv.active(), act)
        np.testing.assert_array_equal(sv.to_dense(), want)
    other = read_vdb(path, grid=2)
    assert other.n_active == 1 and other.to_dense()[-1, -1, -1] == 7.0 and other.origin == (-8, -8, -8)

    # an instance of a grid the file does not hold before it, or of another type
    data = path.read_bytes()
    desc = data.index(b"inst\x10\x00\x00\x00Tree_float_5_4_3\x04\x00\x00\x00orig")
    bad = tmp_path / "bad.vdb"
    for old, new, match in [
        (b"orig", b"oris", "grid 'inst' is an instance of grid 'oris', which no grid before it is"),
        (b"float", b"int32", r"grid 'inst' \(Tree_int32_5_4_3\) is an instance of grid 'orig', a Tree_float"),
    ]:
        at = data.index(old, desc + 4)
        bad.write_bytes(data[:at] + new + data[at + len(old) :])
        with pytest.raises(clvis.DataError, match=match) as e:
            check_vdb(bad)
        assert str(bad) in str(e.value)


def test_vdb_half_float_nodes_with_an_inactive_value_are_walked():
    """A grid saved as half floats stores a node's inactive values (metadata
    2, 4, 5: one or two values other than the background) as floats, 4 bytes
    each, not as halves: the walk skipped 2 bytes each, then read the next
    block from the wrong byte and refused the file as malformed
    (tests/data/openvdb_half_inactive.vdb, OpenVDB 10.0.1: a 16^3 node of
    active and inactive 8^3 tiles and a leaf with inactive voxels of 6.0).
    tinyvdb 0.9 misreads them too: read_vdb reads such a file from the walk
    alone (leaves, values, tiles, transform)."""
    from clvis.io.vdb import vdb_leaves

    path = Path(__file__).parents[1] / "data" / "openvdb_half_inactive.vdb"
    (g,) = vdb_leaves(path)
    assert g is not None and g.active == 64 + 27
    np.testing.assert_array_equal(g.origins, [[40, 0, 0], [56, 0, 0]])
    np.testing.assert_array_equal(g.tile_origins, [[0, 0, 0], [8, 0, 0]])
    np.testing.assert_array_equal(g.tile_log2, [3, 3])
    np.testing.assert_array_equal(g.tile_values(), [5.0, 5.0])
    bits = np.unpackbits(g.masks, axis=1, bitorder="little").reshape(2, 8, 8, 8)  # [leaf, x, y, z]
    want = np.zeros((2, 8, 8, 8), np.uint8)
    want[0, :4, :4, :4] = 1  # 1.5 over (40..43, 0..3, 0..3)
    want[1, 4:7, :3, :3] = 1  # 2.5 over (60..62, 0..2, 0..2)
    np.testing.assert_array_equal(bits, want)
    assert g.half_inactive == 2  # the 16^3 node and the first leaf
    # tinyvdb 0.9 cannot read such a file ("Failed to read BLOSC data", or
    # "OOM"): read_vdb reads it from the walk alone
    sv = read_vdb(path)
    want = np.zeros((8, 8, 63), F32)  # [z, y, x]
    want[:, :, :16] = 5.0
    want[:4, :4, 40:44] = 1.5
    want[:3, :3, 60:63] = 2.5
    assert sv.shape == want.shape and sv.n_active == 1024 + 91 and sv.n_tiles == 2
    np.testing.assert_array_equal(sv.to_dense(), want)
    np.testing.assert_array_equal(sv.active(), want != 0)


def test_vdb_half_float_subnormals_are_read_at_their_value():
    """tinyvdb 0.9 widens a half float's subnormal (below 2^-14) to half its
    value: tests/data/openvdb_half_subnormal.vdb (OpenVDB 10.0.1, saved as
    half floats) came back with 2^-24 as 2^-25, every subnormal halved and
    no error. A half-float grid's leaf values are now decoded by clvis's walk,
    bit for bit what OpenVDB reads."""
    path = Path(__file__).parents[1] / "data" / "openvdb_half_subnormal.vdb"
    sv = read_vdb(path)
    assert sv.shape == (2, 8, 8) and sv.n_active == 128 and sv.active().all()
    n = 1 + np.arange(8)[None, :] + 8 * np.arange(8)[:, None]  # [y, x] = 1 + x + 8 y
    want = np.stack([n * 2.0**-24, -n * 2.0**-14]).astype(F32)
    assert np.abs(want[0]).max() < 2.0**-14  # every value of z = 0 a subnormal half
    np.testing.assert_array_equal(sv.to_dense().view(np.uint32), want.view(np.uint32))


@pytest.mark.parametrize(
    "compression", ["ZIP | ACTIVE_MASK", "ZIP", "NONE", "ACTIVE_MASK", "BLOSC | ACTIVE_MASK"]
)
def test_vdb_active_tiles_under_each_compression(tmp_path, compression):
    """openvdb_small.vdb's "block" (a 128^3 tile, 8^3 tiles and 27 leaves)
    saved again by tinyvdb under each of OpenVDB's compressions: the tiles'
    values are decoded from their nodes' value blocks (zlib, blosc or raw; all
    values or the active ones), the same volume every time."""
    import tinyvdb

    src = Path(__file__).parents[1] / "data" / "openvdb_small.vdb"
    flags = 0
    for name in compression.split(" | "):
        flags |= getattr(tinyvdb, f"COMPRESS_{name}")
    path = tmp_path / "block.vdb"
    with tinyvdb.open(str(src)) as f:
        f.read_grids()
        f.save(str(path), compression=flags)
    want = np.full((160, 160, 160), 0.5, F32)
    i, j, k = np.mgrid[:20, :20, :20]
    want[140:, 140:, 140:] = ((i + 2 * j + 3 * k) % 7 / 7 + 0.25).astype(F32)
    block = read_vdb(path, grid="block")
    assert block.n_tiles == 20**3 - 27
    np.testing.assert_array_equal(block.to_dense(), want.transpose(2, 1, 0))
    seed = read_vdb(src.with_name("openvdb_tiles.vdb"))  # the fuzzing seed of tiles
    want = np.full((40, 40, 40), 0.5, F32)
    i, j, k = np.mgrid[:8, :8, :8]
    want[:8, :8, :8] = ((i + 2 * j + 3 * k) % 5 / 5).astype(F32)
    assert seed.n_tiles == 124
    np.testing.assert_array_equal(seed.to_dense(), want.transpose(2, 1, 0))


def _garbled_blosc() -> bytes:
    import blosc

    c = bytearray(blosc.compress(np.arange(64, dtype="<f4").tobytes(), typesize=4, cname="lz4"))
    c[16:] = bytes(x ^ 0xFF for x in c[16:])  # the header (sizes) kept
    return bytes(c)


def test_vdb_tile_blocks_that_do_not_decode_are_refused(tmp_path, monkeypatch):
    """A tile's values block that is not what its node declares (zlib that
    fails or decompresses to more, a blosc header of another size, raw bytes
    short) is a DataError naming the file and the node; without the blosc
    package a blosc-compressed tile is an ImportError saying what to install,
    never a grid read without its tiles."""
    import zlib

    from clvis.io import vdb

    def block(data, count, codec, half=False):
        return vdb._Values(data, count, codec, half, "node X")

    vals = np.arange(4, dtype="<f4")
    np.testing.assert_array_equal(vdb._decode(tmp_path, block(zlib.compress(vals.tobytes()), 4, "zip")), vals)
    np.testing.assert_array_equal(
        vdb._decode(tmp_path, block(vals.astype("<f2").tobytes(), 4, None, True)), vals
    )
    for bad, match in [
        (block(b"not zlib at all", 4, "zip"), "node X: Error"),
        (block(zlib.compress(np.zeros(1000, "<f4").tobytes()), 4, "zip"), "node X: 17 bytes for 4 values"),
        (
            block(b"\x02\x01\x01\x04" + (99).to_bytes(4, "little") + bytes(8), 4, "blosc"),
            "node X: a blosc block not of 16",
        ),
        (block(vals.tobytes()[:12], 4, None), "node X: 12 bytes for 4 values"),
        # a blosc header of the right sizes over bytes blosc cannot decompress
        # (blosc's own error class, not caught: found fuzzing half-float leaves)
        (block(_garbled_blosc(), 64, "blosc"), "node X: blosc: Error -1 while decompressing"),
    ]:
        with pytest.raises(clvis.DataError, match=f"malformed VDB file: {match}") as e:
            vdb._decode(tmp_path, bad)
        assert str(tmp_path) in str(e.value)
    path = Path(__file__).parents[1] / "data" / "openvdb_small.vdb"
    monkeypatch.setitem(sys.modules, "blosc", None)
    with pytest.raises(ImportError, match=r"blosc-compressed, which needs the blosc package: pip install"):
        read_vdb(path, grid="block")
    with pytest.raises(ImportError, match=r"half-float leaves are blosc-compressed, which needs the blosc"):
        read_vdb(path, grid="density")  # half floats: its leaves decoded by clvis
    assert read_vdb(path, grid="surface").n_active == 12_790  # no tiles, floats: no blosc needed


def test_vdb_tree_clvis_does_not_walk_is_read_from_tinyvdbs_voxel_list(tmp_path, monkeypatch):
    """A tree clvis's walk does not follow (a file version before 222, another
    tree configuration) is read from tinyvdb's own voxel list: the same
    volume as the walk gives where that list is whole."""
    from clvis.gauss import sparse

    _, _, ijk, vals, _ = _random_voxels(seed=6)
    grids = [("density", "Tree_float_5_4_3", _scale_translate((0.5, 1, 2), (1, 2, 3)))]
    path = _write_vdb(tmp_path, "rnd", grids, {0: (ijk, vals)})
    walked = read_vdb(path)
    monkeypatch.setattr(sparse, "vdb_grids", lambda p: [])  # as for a version-221 file
    listed = read_vdb(path)
    assert (listed.shape, listed.spacing, listed.origin) == (walked.shape, walked.spacing, walked.origin)
    np.testing.assert_array_equal(listed.to_dense(), walked.to_dense())
    np.testing.assert_array_equal(listed.active(), walked.active())


def test_vdb_non_finite_voxel_and_misplaced_node_are_refused(tmp_path):
    """A NaN among the active voxels is a DataError naming its (x, y, z);
    a root child whose origin is off the 8-voxel grid (a damaged file:
    OpenVDB's are multiples of 4096) is refused, not drawn shifted."""
    grids = [("density", "Tree_float_5_4_3", _scale_translate((1, 1, 1), (0, 0, 0)))]
    ijk = np.array([[0, 0, 0], [5, 6, 7], [-9, 3, 12]])
    path = _write_vdb(tmp_path, "nan", grids, {0: (ijk, [1.0, np.nan, 2.0])})
    with pytest.raises(clvis.DataError, match=r"active voxel \(x, y, z\) = \[5, 6, 7\] is not finite") as e:
        read_vdb(path)
    assert str(path) in str(e.value)
    path = _write_vdb(tmp_path, "one", grids, {0: (ijk[:1], [1.0])})
    data = path.read_bytes()
    at = data.index(struct.pack("<ii3i", 0, 1, 0, 0, 0))  # no root tiles, one child at (0, 0, 0)
    path.write_bytes(data[: at + 8] + struct.pack("<3i", 3, 0, 0) + data[at + 20 :])
    with pytest.raises(
        clvis.DataError, match=r"a leaf at \(x, y, z\) = \[3, 0, 0\] is not on the 8-voxel grid"
    ):
        read_vdb(path)


def test_vdb_active_root_tile_is_refused_for_its_memory(tmp_path):
    """An active tile of the root node covers 4096^3 voxels (512^3 leaves):
    refused before anything is read, naming the tiles' leaves; an inactive
    one is nothing."""
    grids = [("density", "Tree_float_5_4_3", _scale_translate((1, 1, 1), (0, 0, 0)))]
    path = tmp_path / "root.vdb"
    path.write_bytes(_vdb_template(grids, [((4096, 0, -4096), 0.5, 1)]))
    with pytest.raises(clvis.DeviceError, match=r"134,217,728 leaves of active tiles needs about") as e:
        read_vdb(path)
    assert str(path) in str(e.value)
    path.write_bytes(_vdb_template(grids, [((4096, 0, -4096), 0.5, 0)]))
    assert read_vdb(path).n_active == 0
    # only the grid read has its tiles made whole: another grid's root tile
    # refused the whole file (a 1-voxel grid beside it "needed 893 GB")
    two = grids + [("small", "Tree_float_5_4_3", grids[0][2])]
    path.write_bytes(_vdb_template(two, {0: [((4096, 0, -4096), 0.5, 1)]}))
    assert read_vdb(path, grid="small").n_active == 0
    with pytest.raises(clvis.DeviceError, match=r"134,217,728 leaves of active tiles needs about"):
        read_vdb(path, grid=0)


def test_vdb_malformed(tmp_path):
    _, _, ijk, vals, _ = _random_voxels(seed=9)
    grids = [("density", "Tree_float_5_4_3", _scale_translate((1, 1, 1), (0, 0, 0)))]
    good = _write_vdb(tmp_path, "good", grids, {0: (ijk, vals)}).read_bytes()
    bad = tmp_path / "bad.vdb"
    for cut in (0, 3, 8, 11, 20, 50, 60, 70, 100, 140, 300, len(good) // 2, len(good) - 1):
        bad.write_bytes(good[:cut])
        with pytest.raises(clvis.DataError, match="bad.vdb"):
            read_vdb(bad)
    for junk in (b"not a VDB file at all\n" * 20, bytes(range(256)) * 4, b"\x20BDV" + b"\xff" * 500):
        bad.write_bytes(junk)
        with pytest.raises(clvis.DataError, match="bad.vdb"):
            read_vdb(bad)
    # flipped bytes: a DataError naming the file, or a volume; never another error
    rng = np.random.default_rng(0)
    for _ in range(40):
        b = bytearray(good)
        for i in rng.integers(0, len(b), 4):
            b[i] = rng.integers(0, 256)
        bad.write_bytes(bytes(b))
        try:
            assert isinstance(read_vdb(bad), SparseVolume)
        except clvis.DataError as e:
            assert "bad.vdb" in str(e)
    with pytest.raises(FileNotFoundError):
        read_vdb(tmp_path / "missing.vdb")
    with pytest.raises(TypeError, match="grid: expected a name"):
        read_vdb(bad, grid=1.5)


def test_vdb_needs_tinyvdb(monkeypatch, tmp_path):
    monkeypatch.setitem(sys.modules, "tinyvdb", None)
    with pytest.raises(ImportError, match=r"pip install \".\[vdb\]\" in a clvis checkout"):
        read_vdb(tmp_path / "x.vdb")


def test_a_volume_float32_cannot_resolve_is_warned(queue):
    """A grid at map coordinates (origin 500,000, 4,000,000, 100; voxels of
    0.25) gave Gaussians a render showed fully transparent, without a word:
    now a ClvisWarning says so; the same grid near the origin says nothing."""
    vol = np.ones((8, 8, 8), F32)
    with pytest.warns(ClvisWarning, match="cannot resolve"):
        gaussians_from_volume(vol, "high", spacing=(0.25,) * 3, origin=(5e5, 4e6, 100.0), queue=queue)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        gaussians_from_volume(vol, "high", spacing=(0.25,) * 3, origin=(-200.0, 100.0, 30.0), queue=queue)
        gaussians_from_volume(vol, "high", spacing=(1e-6,) * 3, queue=queue)  # small, at the origin


def test_vdb_too_large_for_host_memory_is_refused_before_tinyvdb(tmp_path, monkeypatch):
    """read_vdb estimates the host memory a file's grids take from clvis's
    walk of its leaves (bytes a leaf and a voxel) and refuses, naming both
    figures, before tinyvdb reads a leaf (it read whatever the file held)."""
    import tinyvdb

    import clvis.gauss.sparse as sparse

    _, _, ijk, vals, _ = _random_voxels(seed=3)
    grids = [("density", "Tree_float_5_4_3", _scale_translate((1, 1, 1), (0, 0, 0)))]
    path = _write_vdb(tmp_path, "big", grids, {0: (ijk, vals)})
    assert read_vdb(path).n_active == len(ijk)
    monkeypatch.setattr(sparse, "_BYTES_PER_VOXEL", 1 << 40)  # as if each voxel took a TB

    def opened(*a, **k):
        raise AssertionError("tinyvdb opened the file")

    monkeypatch.setattr(tinyvdb, "open", opened)
    match = rf"{len(ijk):,} active voxels in \d+ leaves needs about"
    with pytest.raises(clvis.DeviceError, match=match) as e:
        read_vdb(path)
    assert str(path) in str(e.value) and "GB of host memory" in str(e.value)


def test_vdb_volume_made_dense_with_the_grids_background():
    """read_vdb_volume (clvis iso FILE.vdb): the grid dense, its inactive
    voxels the grid's background (a level set's: its band's outside, +2
    voxels of 1 here), its class from the file's metadata."""
    from clvis.gauss import read_vdb_volume

    path = Path(__file__).parents[1] / "data" / "openvdb_small.vdb"
    v, grid_class = read_vdb_volume(path)
    sv = read_vdb(path)
    assert grid_class == "level set" and v.array == "surface"
    assert (v.spacing, v.origin) == (sv.spacing, sv.origin)
    np.testing.assert_array_equal(v.data, sv.to_dense(2.0))
    assert (v.data[~sv.active()] == 2.0).all() and v.data.min() < 0
    fog, fog_class = read_vdb_volume(path, grid="density")
    assert fog_class is None and (fog.data[~read_vdb(path, grid="density").active()] == 0).all()


def test_vdb_grid_keeps_its_background_and_class_and_default_isovalue():
    """read_vdb's SparseVolume keeps the grid's background and class (the
    viewer's iso mode makes it dense from them, as read_vdb_volume does);
    default_isovalue: 0 for a level set, else Otsu's of the dense volume,
    the same from the leaves (never dense) as from the dense array, where
    otsu_level takes every k-th sample too; a background that is not finite
    is refused before a dense volume is made."""
    from clvis.gauss import default_isovalue, dense_volume, read_vdb_volume
    from clvis.io.volumes import otsu_level

    path = Path(__file__).parents[1] / "data" / "openvdb_small.vdb"
    sv = read_vdb(path)
    assert (sv.background, sv.grid_class) == (2.0, "level set")
    assert default_isovalue(sv) == 0.0 == default_isovalue(read_vdb_volume(path)[0].data, "level set")
    assert (sv.restricted(threshold=0.0).background, sv.restricted().grid_class) == (2.0, "level set")
    fog = read_vdb(path, grid="density")
    dense = read_vdb_volume(path, grid="density")[0].data
    assert (fog.background, fog.grid_class) == (0.0, None)  # no class written
    fog_class = read_vdb(path.with_name("openvdb_fog.vdb"))
    assert (fog_class.background, fog_class.grid_class, fog_class.n_active) == (0.0, "fog volume", 4224)
    np.testing.assert_array_equal(dense_volume(fog, "fog", "-"), dense)
    assert default_isovalue(fog) == otsu_level(dense) == default_isovalue(dense) and 0 < otsu_level(dense) < 1
    rng = np.random.default_rng(3)
    vol = np.zeros((150, 160, 170), F32)  # 4.08M samples: otsu_level takes every 2nd
    vol[20:130, 30:100, 8:150] = rng.random((110, 70, 142), F32)
    big = clvis.SparseVolume.from_dense(vol, threshold=0.2)
    big.background = 0.1
    want = otsu_level(big.to_dense(0.1))
    assert default_isovalue(big) == want != otsu_level(big.to_dense(0.0))
    big.background = float("nan")
    with pytest.raises(clvis.DataError, match=r"^big: its background value is nan \(not finite\)"):
        dense_volume(big, "big", "-")


def test_vdb_grid_beside_one_tinyvdb_cannot_parse_is_read_from_the_walk():
    """tinyvdb 0.9 fails a whole file when one grid has a frustum map; the
    file's linear grid is read from clvis's walk alone (every value where
    it was written), and the frustum grid is refused, naming the map."""
    path = Path(__file__).parents[1] / "data" / "openvdb_frustum.vdb"
    sv = read_vdb(path)  # the first float grid: "linear"
    i, j, k = np.mgrid[:8, :8, :8]
    want = ((i + 8 * j + 64 * k) % 7 + 1).astype(F32)  # [i, j, k]
    assert sv.shape == (8, 8, 8) and sv.n_active == 512
    np.testing.assert_array_equal(sv.to_dense(), want.transpose(2, 1, 0))
    with pytest.raises(
        clvis.DataError, match="NonlinearFrustumMap; clvis's walk does not read grid 'frustum'"
    ):
        read_vdb(path, grid="frustum")


def test_vdb_voxel_size_float32_cannot_hold_is_a_data_error(tmp_path):
    """A voxel size finite and > 0 in float64 but 0 in float32 (1e-50, a
    damaged map): a DataError naming the file and the grid, on both paths
    (tinyvdb's, and the walk's alone: fuzzing found a bare ValueError there)."""
    grids = [("density", "Tree_float_5_4_3", _scale_translate((1e-50, 1, 1), (0, 0, 0)))]
    ijk = np.array([[0, 0, 0], [3, 4, 5]])
    path = _write_vdb(tmp_path, "tiny", grids, {0: (ijk, [1.0, 2.0])})
    with pytest.raises(clvis.DataError, match=r"grid 'density': spacing: .* must be > 0") as e:
        read_vdb(path)
    assert str(path) in str(e.value)
    from clvis.gauss import sparse

    with pytest.raises(clvis.DataError, match=r"grid 'density': spacing: .* must be > 0"):
        sparse._read_walked(path, None, sparse.vdb_grids(path), "tinyvdb failed")
