"""DistributedRasterizer on a real LocalCluster (two one-thread worker
processes) against the single-device Rasterizer of the concatenated cloud:
the same G-buffers bit for bit (index, depth, rgba, attributes, velocity,
radius) for clouds split unevenly, with empty partitions, ties across
partitions, LAS tiles with their own origins and dask arrays; faults (a
worker killed in the middle of a frame), malformed files and workers
without an OpenCL device."""

import os
import pickle
import signal

import numpy as np
import pytest
from dask_cluster import TIMEOUT, distributed, local_cluster

from clvis import Camera
from clvis.distributed import DistributedRasterizer, concatenate
from clvis.distributed.cluster import connected_workers
from clvis.errors import DataError, DeviceError
from clvis.io import PointCloud, read_points, save_npz
from clvis.raster import EMPTY, Rasterizer

W, H = 64, 48
SIZES = (700, 0, 2300, 1, 0, 513)  # uneven, with empty partitions


def _cam(eye=(3.0, -2.2, 2.0), **kw):
    return Camera.look_at(eye, (0.5, 0.5, 0.4), (0, 0, 1), fov_y=45, aspect=W / H, near=0.1, far=20, **kw)


def _clouds(seed=0, sizes=SIZES, dup=True):
    """Partitions with their own origins, colours, a float and a uint8
    attribute, velocity and radius; with dup, the third partition has the
    first's origin and its first 200 points repeat the first's (exact ties
    across partitions)."""
    rng = np.random.default_rng(seed)
    out = []
    for i, n in enumerate(sizes):
        origin = rng.uniform(-0.5, 0.5, 3) * (i % 3) if not (dup and i == 2) else out[0].origin
        p = rng.uniform(0, 1, (n, 3)) - origin
        out.append(
            PointCloud(
                p,
                rng.integers(0, 256, (n, 4), dtype=np.uint8),
                {"a": rng.normal(size=n).astype(np.float32), "c": rng.integers(0, 9, n).astype(np.uint8)},
                rng.normal(size=(n, 3)),
                rng.uniform(0.001, 0.01, n),
                origin,
            )
        )
    if dup:
        first, third = out[0], out[2]
        third.positions[:200] = first.positions[:200]
    return out


def _files(tmp_path, clouds):
    paths = []
    for i, c in enumerate(clouds):
        paths.append(tmp_path / f"tile{i}.npz")
        save_npz(paths[-1], c)
    return paths


def _same(got, want):
    for f in ("index", "depth", "rgba", "vel2d", "vel_angle", "vel_speed", "radius_px"):
        a, b = getattr(got, f), getattr(want, f)
        assert (a is None) == (b is None), f
        if a is not None:
            assert a.dtype == b.dtype and a.shape == b.shape, f
            assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), f
    assert list(got.attributes) == list(want.attributes)
    for k, a in got.attributes.items():
        assert np.array_equal(a, want.attributes[k], equal_nan=a.dtype.kind == "f"), k


@pytest.fixture(scope="module")
def tiles(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("tiles")
    clouds = _clouds()
    paths = _files(tmp, clouds)
    return paths, concatenate([read_points(p) for p in paths])


@pytest.mark.parametrize("compositing", ["direct", "tree"])
def test_tiles_equal_the_single_device_render(client, tiles, compositing):
    paths, whole = tiles
    single = Rasterizer(whole)
    with DistributedRasterizer(paths, client, compositing=compositing, timeout=TIMEOUT) as dr:
        assert dr.n == len(whole) and dr.offsets == [0, 700, 700, 3000, 3001, 3001]
        np.testing.assert_array_equal(dr.origin, whole.origin)
        for kw in ({}, {"color_by": "a", "colormap": "magma"}, {"point_size": 3, "planes": ["c"]}):
            got, want = dr.render(_cam(), W, H, **kw), single.render(_cam(), W, H, **kw)
            _same(got, want)
            assert got.covered.sum() > 300
            # the tied points: drawn from the first partition (lower ids), as on one device
            tied = np.isin(got.index, np.arange(200))
            assert tied.sum() >= 10 and not np.isin(got.index, np.arange(700, 900)).any()
            s = got.stats
            assert s["points"] == len(whole) and s["partitions"] == 6 and s["compositing"] == compositing
            assert s["points_read"] == want.stats["points_read"] or s["batches"] >= want.stats["batches"]
            assert set(s["bytes_sent"]) <= set(connected_workers(client))
            assert sum(s["bytes_sent"].values()) >= got.index.nbytes  # at least the frame reaches the client
        # a view from the other side: the depth order of the partitions flips
        _same(dr.render(_cam((-2.0, 3.0, -1.0)), W, H), single.render(_cam((-2.0, 3.0, -1.0)), W, H))


def test_las_tiles_with_their_own_origins(client, tmp_path):
    laspy = pytest.importorskip("laspy")
    rng = np.random.default_rng(3)
    paths = []
    for i in range(3):
        header = laspy.LasHeader(point_format=3, version="1.2")
        header.scales, header.offsets = [0.001] * 3, [600000.0, 5200000.0, 100.0]
        las = laspy.LasData(header)
        n = 400 + 300 * i
        las.x = 600000 + i * 7 + np.round(rng.random(n) * 10000) / 1000
        las.y = 5200000 + np.round(rng.random(n) * 10000) / 1000
        las.z = 100 + np.round(rng.random(n) * 3000) / 1000
        las.red, las.green, las.blue = rng.integers(0, 65536, (3, n)).astype(np.uint16)
        las.intensity = rng.integers(0, 65536, n)
        las.write(str(tmp_path / f"t{i}.las"))
        paths.append(tmp_path / f"t{i}.las")
    whole = concatenate([read_points(p) for p in paths])
    lo, hi = whole.bounds()
    cam = Camera.look_at(
        (hi + lo) / 2 + [0, -25, 12], (hi + lo) / 2, (0, 0, 1), fov_y=50, aspect=W / H, near=1, far=100
    )
    with DistributedRasterizer(paths, client, fields=["intensity"], timeout=TIMEOUT) as dr:
        got = dr.render(cam, W, H, color_by="intensity")
    want = Rasterizer(
        whole.positions, colors=whole.colors, attributes={"intensity": whole.attributes["intensity"]}
    )
    want = want.render(cam, W, H, color_by="intensity")
    _same(got, want)
    assert got.covered.sum() > 200
    # every field of the files (point format 3 has 13 attributes, more than
    # one render resolves): the rasterizers take the clouds whole
    assert len(whole.attributes) > 8
    with DistributedRasterizer(paths, client, timeout=TIMEOUT) as dr:
        got = dr.render(cam, W, H, color_by="intensity", planes=["classification"])
    _same(got, Rasterizer(whole).render(cam, W, H, color_by="intensity", planes=["classification"]))


def test_framing_is_one_devices(client, tmp_path):
    """framing(): the box of the bulk and the points a fit view frames, as
    one device finds them in the concatenated cloud (robust_bounds: stray
    points left out, non-finite ones never counted; every k-th of the kept
    points), bit for bit, whether some points are stray or none."""
    from clvis.camera import robust_bounds

    clouds = _clouds(seed=5, dup=False)
    calm = _files(tmp_path, clouds)
    clouds[0].positions[3] = [40.0, 40.0, 40.0]  # strays in two partitions ...
    clouds[2].positions[[5, 900]] = [-30.0, 2.0, 1.0]
    clouds[5].positions[7] = np.nan  # ... and a point that is not finite
    (tmp_path / "stray").mkdir()
    stray = _files(tmp_path / "stray", clouds)
    for paths, strays in ((stray, 3), (calm, 0)):
        whole = concatenate([read_points(p) for p in paths])
        rb = robust_bounds(whole.positions)
        assert rb.total - rb.kept == strays
        framed = whole.positions[rb.inside] if strays else whole.positions
        with DistributedRasterizer(paths, client, timeout=TIMEOUT) as dr:
            assert np.array_equal(dr.origin, whole.origin)
            for limit in (200_000, 97):  # every point; every k-th of those kept
                lo, hi, points, kept, total = dr.framing(limit)
                assert (kept, total) == (rb.kept, rb.total)
                assert lo.dtype == hi.dtype == np.float64
                assert np.array_equal(lo, rb.lo) and np.array_equal(hi, rb.hi)
                want = framed[:: max(1, len(framed) // limit)]
                assert points.dtype == np.float32 and len(points) == len(want) > 30
                assert np.array_equal(points, want, equal_nan=True)
            with pytest.raises(ValueError, match="limit: expected a positive int"):
                dr.framing(0)


def test_dask_arrays(client):
    da = pytest.importorskip("dask.array")
    rng = np.random.default_rng(5)
    n = 3001
    pos = rng.uniform(0, 1, (n, 3)).astype(np.float32)
    pos[1500:1600] = pos[:100]  # ties across chunks
    col = rng.integers(0, 256, (n, 3), dtype=np.uint8)
    att = rng.random(n).astype(np.float32)
    chunks = ((1000, 0, 1501, 500),)
    dpos = da.from_array(pos, chunks=chunks + ((3,)))
    with DistributedRasterizer(
        dpos,
        client,
        colors=da.from_array(col, chunks=(1000, 3)),  # rechunked like the positions
        attributes={"t": da.from_array(att, chunks=chunks)},
        timeout=TIMEOUT,
    ) as dr:
        assert dr.counts == [1000, 0, 1501, 500]
        got = dr.render(_cam(), W, H, color_by="t")
    want = Rasterizer(pos, colors=col, attributes={"t": att}).render(_cam(), W, H, color_by="t")
    _same(got, want)


def test_the_client_holds_no_points(client, tiles):
    """The futures the client holds are handles (a few hundred bytes): the
    partitions stay on the workers across frames, never sent back."""
    paths, whole = tiles
    with DistributedRasterizer(paths, client, timeout=TIMEOUT) as dr:
        handles = client.gather(dr._handles)
        assert all(len(pickle.dumps(h)) < 4096 for h in handles)
        assert dr.device_bytes >= whole.positions.nbytes
        first = dr.render(_cam(), W, H)
        # the second frame renders the resident partitions: nothing is opened again
        tokens = {h.token for h in handles}
        resident = client.run(lambda: sorted(_resident_tokens()))
        assert tokens == {t for ts in resident.values() for t in ts}
        _same(dr.render(_cam(), W, H), first)
    gone = client.run(lambda: sorted(_resident_tokens()))
    assert not tokens & {t for ts in gone.values() for t in ts}  # close() let go of them


def _resident_tokens():
    from clvis.distributed.cluster import REGISTRY

    return REGISTRY.tokens()


def test_a_malformed_file_names_itself(client, tmp_path, tiles):
    paths, _ = tiles
    bad = tmp_path / "broken.npz"
    bad.write_bytes(b"PK\x03\x04 this is not an archive")
    with pytest.raises(DataError, match="broken.npz"):
        DistributedRasterizer([paths[0], bad, paths[2]], client, timeout=TIMEOUT)
    missing = tmp_path / "nowhere.las"
    with pytest.raises(DataError, match="nowhere.las: no such file"):
        DistributedRasterizer([missing], client, timeout=TIMEOUT)
    other = tmp_path / "other.npz"
    save_npz(other, PointCloud(np.zeros((3, 3)), attributes={"zz": np.ones(3)}))
    with pytest.raises(DataError, match="other.npz: its attributes"):
        DistributedRasterizer([paths[0], other], client, timeout=TIMEOUT)
    # the other partitions are unaffected: the same workers render them
    with DistributedRasterizer([paths[0], paths[2]], client, timeout=TIMEOUT) as dr:
        want = Rasterizer(concatenate([read_points(paths[0]), read_points(paths[2])])).render(_cam(), W, H)
        _same(dr.render(_cam(), W, H), want)


def test_bad_arguments(client, tiles):
    paths, _ = tiles
    with pytest.raises(ValueError, match="compositing"):
        DistributedRasterizer(paths, client, compositing="binary-swap")
    with pytest.raises(TypeError, match="sources"):
        DistributedRasterizer([np.zeros((3, 3))], client)
    with pytest.raises(ValueError, match="sources: no partition"):
        DistributedRasterizer([], client)
    with pytest.raises(ValueError, match="only with dask array sources"):
        DistributedRasterizer(paths, client, colors=np.zeros((3, 4), np.uint8))
    with pytest.raises(TypeError, match="client"):
        DistributedRasterizer(paths, client=42)
    with DistributedRasterizer(paths[:1], client, timeout=TIMEOUT) as dr:
        with pytest.raises(ValueError, match="color_by: no attribute 'nope'"):
            dr.render(_cam(), W, H, color_by="nope")
        with pytest.raises(ValueError, match="width"):
            dr.render(_cam(), 0, H)
        with pytest.raises(TypeError, match="camera"):
            dr.render("camera", W, H)


def test_a_worker_killed_in_the_middle_of_a_frame(tmp_path):
    """SIGKILL one worker process while the frame's tasks are in flight: the
    scheduler re-runs them (file-backed partitions are read again on the
    other worker) and the frame equals the single device's."""
    clouds = _clouds(seed=7, sizes=(900, 1200, 600, 0, 800), dup=True)
    paths = _files(tmp_path, clouds)
    want = Rasterizer(concatenate([read_points(p) for p in paths])).render(_cam(), W, H, color_by="a")
    with local_cluster() as cluster, distributed.Client(cluster, timeout=TIMEOUT) as c:
        c.wait_for_workers(2, timeout=TIMEOUT)
        with DistributedRasterizer(paths, c, timeout=TIMEOUT) as dr:
            _same(dr.render(_cam(), W, H, color_by="a"), want)
            where = set(dr._who_has(dr._handles).values())
            victim = sorted(where)[0]
            pid = c.run(os.getpid, workers=[victim])[victim]
            view = dr._view(_cam(), W, H, "a", "viridis", None, None, 1)
            frame, _ = dr.submit_frame(distributed_render_task(), view)
            os.kill(pid, signal.SIGKILL)
            from clvis.distributed import composite

            distributed.wait(frame, timeout=TIMEOUT)
            whole = composite.assemble(c.gather(frame))
            assert np.array_equal(composite.ids_of(whole.key), want.index)
            assert np.array_equal(composite.depths_of(whole.key), want.depth)
            assert np.array_equal(whole.planes["rgba"], want.rgba)
            assert victim not in connected_workers(c)  # it was killed, and replaced
            # and the next frames too, on whatever workers there are now
            _same(dr.render(_cam(), W, H, color_by="a"), want)


def distributed_render_task():
    from clvis.distributed import raster

    return raster.render_one


def test_workers_without_a_device(tmp_path, monkeypatch, tiles):
    paths, _ = tiles
    monkeypatch.setenv("CLVIS_DEVICE", "no-such-opencl-device")  # inherited by the worker processes
    with local_cluster(n_workers=1) as cluster, distributed.Client(cluster, timeout=TIMEOUT) as c:
        c.wait_for_workers(1, timeout=TIMEOUT)
        (addr,) = connected_workers(c)
        with pytest.raises(
            DeviceError, match=f"worker {addr}: no usable OpenCL device.*no-such-opencl-device"
        ):
            DistributedRasterizer(paths[:2], c, timeout=TIMEOUT)


def test_a_local_cluster_of_its_own(tiles):
    paths, whole = tiles
    with DistributedRasterizer(paths[:3], workers=1, timeout=TIMEOUT) as dr:
        cluster = dr._cluster
        assert dr.client.status == "running"
        want = Rasterizer(concatenate([read_points(p) for p in paths[:3]])).render(_cam(), W, H)
        got = dr.render(_cam(), W, H)
        _same(got, want)
        assert got.stats["workers"] == 1 and (got.index != EMPTY).any()
    assert dr.client.status == "closed" and cluster.status.name == "closed"


def test_a_stretched_camera_warns_once(client, tiles):
    """A camera of another aspect than the frame's: one AspectWarning on the
    client, at the caller's line (the workers' renders say nothing more)."""
    import warnings

    from clvis.errors import AspectWarning

    paths, _ = tiles
    with DistributedRasterizer(paths, client, timeout=TIMEOUT) as dr:
        with pytest.warns(AspectWarning, match=r"with_aspect\(64 / 48\)") as caught:
            dr.render(_cam().with_aspect(1.0), W, H)
        assert len(caught) == 1 and caught[0].filename == __file__
        with warnings.catch_warnings():
            warnings.simplefilter("error", AspectWarning)
            dr.render(_cam(), W, H)
