"""DistributedIsoRenderer on a real LocalCluster against the single-device
IsoRenderer: the bricks (aligned to ZFP's 4^3 blocks, each with its
neighbour block) cover every cell once; the image has the same hit mask and
depths within the iso tests' tolerance (clvis.reference.iso.agreement on
the reference's reliable pixels, and against the single device's image),
whether the volume comes as an array or as a .npy, .raw or NIfTI file read
brick by brick on the workers."""

import gzip

import numpy as np
import pytest
from dask_cluster import TIMEOUT

from clvis import Camera, datasets, zfp
from clvis.distributed.iso import DistributedIsoRenderer, brick_plan, worker_plan
from clvis.errors import DataError
from clvis.iso import IsoRenderer
from clvis.reference import iso as ref

W, H = 48, 40
RATE = 16
_ML = datasets.marschner_lobb(41)


def _cam(eye=(2.2, -2.6, 1.8)):
    return Camera.look_at(eye, (0, 0, 0), (0, 0, 1), fov_y=40, aspect=W / H, near=0.05, far=20)


@pytest.fixture(scope="module")
def single():
    v, sp, org = _ML["volume"], _ML["spacing"], _ML["origin"]
    r = IsoRenderer(v, RATE, sp, org)
    want = {
        eye: ref.render(zfp.decode(r.volume), _cam(eye), W, H, 0.5, spacing=sp, origin=org) for eye in _EYES
    }
    return r, want


_EYES = ((2.2, -2.6, 1.8), (-1.5, 2.0, -2.5))


def _check(img, single, eye):
    r, want = single
    one = r.render(_cam(eye), W, H, 0.5)
    a = ref.agreement(want[eye], img.hit, img.depth)
    assert a["ok"] and a["reliable"] > 0.9 * W * H, a
    assert ref.agreement(want[eye], one.hit, one.depth)["ok"]
    # against the single device: the same hits; depths within the rule's tolerance
    rel = ref.reliable(want[eye])
    assert (img.hit[rel] == one.hit[rel]).all()
    both = img.hit & one.hit
    assert both.sum() > 200
    assert np.abs(img.depth[both] - one.depth[both]).max() <= ref.DEPTH_TOLERANCE * want[eye].diagonal
    np.testing.assert_allclose(img.rgba[both], one.rgba[both], atol=2e-3)
    assert (img.rgba[~img.hit] == 0).all() and np.isinf(img.depth[~img.hit]).all()
    assert not img.active.any() and img.completion == 1.0


@pytest.mark.parametrize("shape", [(41, 41, 41), (9, 17, 5), (2, 2, 2), (13, 8, 30)])
@pytest.mark.parametrize("edge", [4, 8, (12, 4, 16)])
def test_brick_plan_covers_every_cell_once(shape, edge):
    cover = np.zeros([n - 1 for n in shape], np.int32)
    for ranges in brick_plan(shape, edge):
        assert all(a % 4 == 0 and b - a >= 2 for a, b in ranges)
        e = (edge,) * 3 if isinstance(edge, int) else edge
        own = tuple(slice(a, min(a + k, n - 1)) for (a, _), k, n in zip(ranges, e, shape, strict=True))
        cover[own] += 1
        # the samples held: the owned cells' corners and the rest of the neighbour ZFP block
        assert all(b == min(a + k + 4, n) for (a, b), k, n in zip(ranges, e, shape, strict=True))
    assert (cover == 1).all()


@pytest.mark.parametrize("per_worker", [True, False])
@pytest.mark.parametrize("compositing", ["direct", "tree"])
def test_array_bricks_equal_the_single_device(client, single, compositing, per_worker):
    v, sp, org = _ML["volume"], _ML["spacing"], _ML["origin"]
    with DistributedIsoRenderer(
        v,
        client,
        rate=RATE,
        spacing=sp,
        origin=org,
        brick=12,
        compositing=compositing,
        timeout=TIMEOUT,
        per_worker=per_worker,
    ) as dr:
        assert len(dr.bricks) == 64
        for eye in _EYES:
            img = dr.render(_cam(eye), W, H, 0.5)
            _check(img, single, eye)
            assert img.stats["bricks"] == 64 and img.stats["compositing"] == compositing
            assert img.stats["renderers"] == (2 if per_worker else 64)
            assert sum(img.stats["bytes_sent"].values()) >= img.depth.nbytes


def test_auto_compositing_is_direct_send_bit_for_bit_on_two_workers(client):
    """compositing="auto" (the default) on 2 workers takes direct-send: its
    image equals the one direct-send gives bit for bit (the tree's too:
    min-key compositing does not depend on the grouping)."""
    v, sp, org = _ML["volume"], _ML["spacing"], _ML["origin"]
    with DistributedIsoRenderer(
        v, client, rate=RATE, spacing=sp, origin=org, brick=12, timeout=TIMEOUT
    ) as dr:
        assert dr.compositing == "auto"
        imgs = {}
        for how in ("auto", "direct", "tree"):
            dr.compositing = how
            imgs[how] = dr.render(_cam(), W, H, 0.5)
        assert imgs["auto"].stats["workers"] == 2
        assert imgs["auto"].stats["compositing"] == imgs["direct"].stats["compositing"] == "direct"
        assert imgs["tree"].stats["compositing"] == "tree"
        for how in ("direct", "tree"):
            for f in ("rgba", "depth", "hit", "t"):
                a, b = getattr(imgs["auto"], f), getattr(imgs[how], f)
                assert a.dtype == b.dtype and np.array_equal(a, b), (how, f)
        assert imgs["auto"].hit.sum() > 200


@pytest.mark.parametrize("fmt", ["npy", "raw", "nii", "mgz", "hdr"])
def test_files_read_brick_by_brick_on_the_workers(client, single, tmp_path, fmt):
    v, sp, org = _ML["volume"].astype(np.float32), _ML["spacing"], _ML["origin"]
    kw = {}
    if fmt == "npy":
        path = tmp_path / "ml.npy"
        np.save(path, v)
    elif fmt == "raw":
        path = tmp_path / "ml_41x41x41_float32.raw"
        v.astype("<f4").tofile(path)
    else:
        nib = pytest.importorskip("nibabel")
        path = tmp_path / f"ml.{fmt}"
        image = {"nii": nib.Nifti1Image, "mgz": nib.MGHImage, "hdr": nib.AnalyzeImage}[fmt]
        nib.save(image(v.transpose(2, 1, 0), np.eye(4)), str(path))
    with DistributedIsoRenderer(
        path, client, rate=RATE, spacing=sp, origin=org, brick=16, timeout=TIMEOUT, **kw
    ) as dr:
        assert dr.volume_shape == (41, 41, 41) and len(dr.bricks) == 27
        _check(dr.render(_cam(), W, H, 0.5), single, _EYES[0])


@pytest.mark.parametrize("order", ["las", "sar", "analyze"])
def test_a_nifti_file_is_sliced_in_the_order_read_volume_gives(tmp_path, order):
    """The workers' bricks of a NIfTI / MGH / Analyze file stored out of RAS+
    order (x reversed: LAS, as Analyze's default; axes permuted: SAR, as
    FreeSurfer's) are the bricks of the volume read_volume returns (its
    closest RAS+ order), so a cluster and one process draw the same,
    unmirrored, subject. Layout and brick reads are the workers' tasks,
    called here directly."""
    from clvis.distributed.iso import _layout, _read_brick
    from clvis.io import read_volume

    nib = pytest.importorskip("nibabel")
    ijk = np.random.default_rng(3).random((7, 6, 5)).astype(np.float32)
    if order == "las":
        path, image, affine = tmp_path / "v.nii", nib.Nifti1Image, np.diag([-1.0, 1.0, 1.0, 1.0])
    elif order == "sar":
        path, image = tmp_path / "v.mgz", nib.MGHImage
        affine = np.array([[0, 0, 2.0, 0], [0, 1.0, 0, 0], [0.5, 0, 0, 0], [0, 0, 0, 1]])
    else:
        path, image, affine = tmp_path / "v.hdr", nib.AnalyzeImage, np.eye(4)
    nib.save(image(ijk, affine), str(path))
    whole = read_volume(path)
    lay = _layout(str(path), None, None, None)
    assert lay["shape"] == whole.shape and lay["spacing"] == pytest.approx(whole.spacing)
    # not stored in RAS+ order: read_volume reorders it
    assert whole.shape != (5, 6, 7) or not np.array_equal(whole.data, ijk.transpose(2, 1, 0))
    z, y, x = whole.shape
    for ranges in (((0, z), (0, y), (0, x)), ((1, z - 1), (2, y), (0, x - 3))):
        got = _read_brick({"ranges": ranges, "source": (str(path), lay)})
        want = whole.data[tuple(slice(*r) for r in ranges)]
        np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("names", [("v.hdr.gz", "v.img.gz"), ("v.Hdr", "V.IMG"), ("v.Nii.Gz",)])
def test_compressed_and_any_case_files_are_sliced_as_read_volume_reads_them(tmp_path, names):
    """A .hdr.gz/.img.gz pair, a pair in mixed case (which nibabel.load
    alone does not find) and a mixed-case .nii.gz: the workers' layout and
    bricks are those of the volume read_volume returns, by either name of
    a pair; a missing half is named as read_volume names it."""
    from clvis.distributed.iso import _layout, _read_brick
    from clvis.io import read_volume

    nib = pytest.importorskip("nibabel")
    ijk = np.random.default_rng(4).random((7, 6, 5)).astype(np.float32)
    image = nib.Nifti1Image if len(names) == 1 else nib.AnalyzeImage
    saved = tmp_path / ("t.nii.gz" if len(names) == 1 else "t.hdr.gz")
    nib.save(image(ijk, np.diag([-1.0, 1.0, 2.0, 1.0])), str(saved))
    for name, made in zip(names, [saved, saved.with_name("t.img.gz")], strict=False):
        raw = made.read_bytes()
        (tmp_path / name).write_bytes(raw if name.lower().endswith(".gz") else gzip.decompress(raw))
    whole = read_volume(tmp_path / names[0])
    for name in names:
        lay = _layout(str(tmp_path / name), None, None, None)
        assert lay["shape"] == whole.shape and lay["spacing"] == pytest.approx(whole.spacing)
        z, y, x = whole.shape
        ranges = ((1, z), (0, y - 1), (2, x))
        got = _read_brick({"ranges": ranges, "source": (str(tmp_path / name), lay)})
        np.testing.assert_array_equal(got, whole.data[tuple(slice(*r) for r in ranges)])
    if len(names) == 2:
        (tmp_path / names[1]).unlink()
        with pytest.raises(DataError, match=f"{names[0]}: an Analyze header; its data file .* is missing"):
            _layout(str(tmp_path / names[0]), None, None, None)


def test_bad_files_and_arguments(client, tmp_path):
    bad = tmp_path / "broken.npy"
    bad.write_bytes(b"\x93NUMPY garbage")
    with pytest.raises(DataError, match="broken.npy"):
        DistributedIsoRenderer(bad, client, timeout=TIMEOUT)
    flat = tmp_path / "flat.npy"
    np.save(flat, np.zeros((4, 4)))
    with pytest.raises(DataError, match="flat.npy: expected a 3-D volume"):
        DistributedIsoRenderer(flat, client, timeout=TIMEOUT)
    short = tmp_path / "v_8x8x8_float32.raw"
    short.write_bytes(b"\0" * 100)
    with pytest.raises(DataError, match="v_8x8x8_float32.raw: 100 bytes"):
        DistributedIsoRenderer(short, client, timeout=TIMEOUT)
    nan = tmp_path / "nan.npy"
    a = np.zeros((9, 9, 9), np.float32)
    a[8, 8, 8] = np.nan
    np.save(nan, a)
    with pytest.raises(DataError, match="nan.npy: non-finite samples in brick"):
        DistributedIsoRenderer(nan, client, brick=4, timeout=TIMEOUT)
    with pytest.raises(DataError, match="nowhere.npy: no such file"):
        DistributedIsoRenderer(tmp_path / "nowhere.npy", client, timeout=TIMEOUT)
    cut = tmp_path / "cut.hdr"  # a truncated Analyze header: nibabel's own error, named
    cut.write_bytes(b"\x5c\x01\x00\x00" + b"\0" * 40)
    (tmp_path / "cut.img").write_bytes(b"\0" * 64)
    with pytest.raises(DataError, match="cut.hdr: "):
        DistributedIsoRenderer(cut, client, timeout=TIMEOUT)
    with pytest.raises(ValueError, match="brick: expected a multiple of 4"):
        DistributedIsoRenderer(np.zeros((8, 8, 8)), client, brick=6)
    with pytest.raises(DataError, match="at least 2 samples"):
        DistributedIsoRenderer(np.zeros((1, 8, 8)), client)
    with pytest.raises(ValueError, match="volume: expected a 3-D real array"):
        DistributedIsoRenderer(np.zeros((8, 8)), client)
    with DistributedIsoRenderer(np.zeros((8, 8, 8)), client, brick=4, timeout=TIMEOUT) as dr:
        with pytest.raises(TypeError, match="isovalue"):
            dr.render(_cam(), W, H, "0.5")
        img = dr.render(_cam(), W, H, 0.5)  # nothing to hit
        assert not img.hit.any() and np.isinf(img.depth).all()


def test_footprints_render_and_send_only_the_bricks_rectangles(client, single):
    """Each brick renders the rectangle of the frame its box projects to (a
    window camera: the frame's rays, rounded apart): the image agrees with
    the full-frame bricks' under the iso rule, every hit of a brick's full
    frame lies inside its rectangle, and fewer pixels are rendered and
    fewer bytes sent than with full frames."""
    from clvis.distributed import iso as diso

    v, sp, org = _ML["volume"], _ML["spacing"], _ML["origin"]
    with DistributedIsoRenderer(
        v, client, rate=RATE, spacing=sp, origin=org, brick=12, timeout=TIMEOUT, per_worker=False
    ) as dr:
        for eye in _EYES:
            rect_img = dr.render(_cam(eye), W, H, 0.5)
            full_img = dr.render(_cam(eye), W, H, 0.5, footprints=False)
            _check(rect_img, single, eye)
            _check(full_img, single, eye)
            assert rect_img.stats["pixels"] < 0.6 * full_img.stats["pixels"] == 0.6 * 64 * W * H
            assert sum(rect_img.stats["bytes_sent"].values()) <= sum(full_img.stats["bytes_sent"].values())
        # the volume small in the frame: each worker sends the union of its footprints, not the frame
        far = tuple(3 * c for c in _EYES[0])
        small = dr.render(_cam(far), W, H, 0.5)
        whole = dr.render(_cam(far), W, H, 0.5, footprints=False)
        assert (small.hit != whole.hit).sum() <= 2 and small.hit.sum() > 20
        sent = [sum(i.stats["bytes_sent"].values()) for i in (small, whole)]
        assert sent[0] < 0.8 * sent[1], sent
        # one brick alone: its full frame's hits lie inside its footprint, where the window agrees
        r = IsoRenderer(v, RATE, sp, org)
        for spec in dr._specs[::7]:
            (z0, z1), (y0, y1), (x0, x1) = spec["ranges"]
            b = IsoRenderer(v[z0:z1, y0:y1, x0:x1], RATE, sp, spec["origin"], queue=r.queue)
            full = b.render(_cam(), W, H, 0.5)
            rect = diso.footprint(spec, _cam(), W, H)
            r0, r1, c0, c1 = rect
            inside = np.zeros((H, W), bool)
            inside[r0:r1, c0:c1] = True
            assert not (full.hit & ~inside).any()
            if r1 > r0 and c1 > c0:
                win = b.render(diso.window(_cam(), W, H, rect), c1 - c0, r1 - r0, 0.5)
                sub = full.hit[r0:r1, c0:c1]
                assert (win.hit != sub).sum() <= 2
                both = win.hit & sub
                d = np.abs(win.depth[both] - full.depth[r0:r1, c0:c1][both])
                assert d.size == 0 or d.max() <= ref.DEPTH_TOLERANCE * 3 * max(sp) * 40


def test_worker_plan_makes_one_slab_per_worker_of_whole_brick_layers():
    bricks = brick_plan((41, 30, 17), 8)  # 5 z layers of 4 x 2 bricks
    plan = worker_plan(bricks, 2)
    assert [c for _, c in plan] == [24, 16]  # 3 layers, 2 layers
    assert plan[0][0] == ((0, 28), (0, 30), (0, 17)) and plan[1][0] == ((24, 41), (0, 30), (0, 17))
    assert worker_plan(bricks, 6) == [(r, 1) for r in bricks]  # fewer layers than workers: the bricks
    assert [c for _, c in worker_plan(bricks, 5)] == [8] * 5


def test_a_stretched_camera_warns_once_and_the_image_records_its_camera(client):
    """A camera of another aspect than the frame's: one AspectWarning, at
    the caller's line (not one per brick or window); the image records the
    frame's camera, and sample_hits takes it from there."""
    import warnings

    from clvis import iso
    from clvis.errors import AspectWarning

    v, sp, org = _ML["volume"], _ML["spacing"], _ML["origin"]
    with DistributedIsoRenderer(
        v, client, rate=RATE, spacing=sp, origin=org, brick=20, timeout=TIMEOUT
    ) as dr:
        square = _cam().with_aspect(1.0)
        with pytest.warns(AspectWarning, match=r"with_aspect\(48 / 40\)") as caught:
            dr.render(square, W, H, 0.5)
        assert len(caught) == 1 and caught[0].filename == __file__
        cam = _cam()
        with warnings.catch_warnings():
            warnings.simplefilter("error", AspectWarning)
            img = dr.render(cam, W, H, 0.5)
    assert img.camera is cam
    vals = iso.sample_hits(img, field=v, spacing=sp, origin=org)
    assert img.hit.sum() > 200
    np.testing.assert_allclose(vals[img.hit], 0.5, atol=0.02)
