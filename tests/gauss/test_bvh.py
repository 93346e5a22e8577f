"""clvis.gauss.bvh (the device LBVH) against clvis.reference.gauss.bvh:
nodes, order and leaf boxes equal bit for bit, and the tree invariants
(check_bvh) hold, on every device and both work shapes; the node layout and
the slab helpers of clvis/ray.h through probe kernels."""

import warnings

import numpy as np
import pyopencl as cl
import pyopencl.array as cla
import pytest
from hypothesis import given
from hypothesis import strategies as st

import clvis
from clvis import runtime
from clvis.gauss import bvh
from clvis.reference.gauss import bvh as ref

SIZES = [0, 1, 2, 3, 5, 1000, 2**16 + 1]


def random_boxes(n, seed=0, spread=10.0, size=0.5):
    rng = np.random.default_rng(seed)
    c = rng.uniform(-spread, spread, (n, 3))
    h = rng.uniform(0, size, (n, 3))
    return np.concatenate([c - h, c + h], axis=1).astype(np.float32)


def check(boxes, queue):
    """Build on the device, compare with the reference exactly, check the invariants."""
    t = bvh.build_bvh(boxes, queue=queue)
    host = boxes.get() if isinstance(boxes, cla.Array) else np.asarray(boxes)
    n = host.shape[0]
    nodes, order, leaf_boxes = t.get()
    want_nodes, want_order, want_leaves = ref.build_bvh(host)
    assert t.n == n
    assert nodes.dtype == bvh.BVH_NODE_DTYPE and nodes.shape == want_nodes.shape
    np.testing.assert_array_equal(order, want_order)
    np.testing.assert_array_equal(leaf_boxes.view(np.uint32), want_leaves.view(np.uint32))
    for field in ("left", "right"):
        np.testing.assert_array_equal(nodes[field], want_nodes[field], err_msg=field)
    for field in ("lo", "hi"):  # bits: -0.0 and +0.0 count
        np.testing.assert_array_equal(
            nodes[field].view(np.uint32), want_nodes[field].view(np.uint32), err_msg=field
        )
    assert nodes.tobytes() == want_nodes.tobytes()
    ref.check_bvh(nodes, order, leaf_boxes, host)
    np.testing.assert_array_equal(t.codes.get(), ref.morton_codes(host)[want_order])
    assert t.nbytes == nodes.nbytes + order.nbytes + leaf_boxes.nbytes + 4 * n
    assert t.build_seconds > 0
    if n:
        np.testing.assert_array_equal(t.bounds[0], host[:, :3].min(axis=0))
        np.testing.assert_array_equal(t.bounds[1], host[:, 3:].max(axis=0))
        centres = (host[:, :3] + host[:, 3:]) * np.float32(0.5)
        np.testing.assert_array_equal(t.centre_bounds[0], centres.min(axis=0))
        np.testing.assert_array_equal(t.centre_bounds[1], centres.max(axis=0))
    return t


@pytest.mark.parametrize("n", SIZES)
def test_sizes(queue, n):
    t = check(random_boxes(n, seed=n), queue)
    assert isinstance(t.nodes, cla.Array) and isinstance(t.order, cla.Array)
    assert t.nodes.shape == ((max(n - 1, 1),) if n else (0,))
    if n == 1:
        node = t.nodes.get()[0]
        assert node["left"] == bvh.BVH_LEAF and node["right"] == bvh.BVH_NONE


@pytest.mark.parametrize("n", [2, 257, 1000])
def test_identical_boxes(queue, n):
    """All codes equal: the tree is split by index bits alone (balanced)."""
    boxes = np.tile(np.array([[1, 2, 3, 1.5, 2.5, 3.5]], np.float32), (n, 1))
    check(boxes, queue)


def test_duplicates_and_points(queue):
    """Many equal codes in runs, point boxes (lo == hi), -0.0 beside +0.0."""
    rng = np.random.default_rng(3)
    c = rng.integers(-3, 4, (3000, 3)).astype(np.float32) * np.float32(0.5)
    c[rng.random(c.shape) < 0.2] = -0.0
    boxes = np.concatenate([c, c], axis=1)
    boxes[::3, 3:] = np.where(boxes[::3, 3:] == 0, np.float32(0.0), boxes[::3, 3:])  # +0.0 hi beside -0.0 lo
    check(boxes, queue)


def test_flat_axis(queue):
    """Boxes on the plane z = 2 (a flat axis quantizes to 0), and on a line."""
    b = random_boxes(5000, seed=4)
    b[:, 2] = b[:, 5] = 2.0
    check(b, queue)
    b[:, 1] = b[:, 4] = -1.0
    check(b, queue)


def test_clustered(queue):
    """Two tight clusters far apart: long runs of equal codes and a deep tree."""
    rng = np.random.default_rng(5)
    c = np.concatenate([rng.normal(0, 1e-4, (3000, 3)), 1e4 + rng.normal(0, 1e-4, (50, 3))])
    b = np.concatenate([c - 1e-5, c + 1e-5], axis=1).astype(np.float32)
    check(b, queue)


def test_device_input(queue):
    """A device array stays on the device (and an offset view works)."""
    host = random_boxes(3001, seed=6)
    d = cla.to_device(queue, host)
    t = check(d, queue)
    assert t.queue is queue
    view = cla.to_device(queue, random_boxes(3101, seed=7))[100:]
    assert view.offset
    check(view, queue)


@given(
    n=st.integers(0, 600),
    seed=st.integers(0, 2**32 - 1),
    profile=st.sampled_from(["cpu", "gpu"]),
    spread=st.sampled_from([1e-3, 1.0, 1e5]),
    size=st.sampled_from([0.0, 0.01, 1.0, 100.0]),
    grid=st.booleans(),
)
def test_property(device, n, seed, profile, spread, size, grid):
    """Random sizes and boxes (on a coarse grid: many equal codes and ties)."""
    boxes = random_boxes(n, seed, spread, size)
    if grid:
        boxes = np.round(boxes * 2 / spread) * np.float32(spread / 2)
        boxes[:, 3:] = np.maximum(boxes[:, 3:], boxes[:, :3])
    with runtime.configure(tuning=profile):
        check(boxes.astype(np.float32), runtime.queue_for(device))


@pytest.fixture(scope="module")
def large():
    """2^20 boxes and their reference tree (built and checked once)."""
    boxes = random_boxes(2**20, seed=8, size=0.01)
    want = ref.build_bvh(boxes)
    ref.check_bvh(*want, boxes)
    return boxes, want


def test_large(device, large):
    """2^20 boxes: deep searches in the Karras kernel, many refit levels; equal
    to the (checked) reference, so the invariants hold too."""
    boxes, want = large
    got = bvh.build_bvh(boxes, queue=runtime.queue_for(device)).get()
    for g, w in zip(got, want, strict=True):
        assert g.tobytes() == w.tobytes()


def test_check_bvh_rejects_corruption():
    """check_bvh can fail: every kind of damage is reported."""
    boxes = random_boxes(200, seed=9)
    nodes, order, leaves = ref.build_bvh(boxes)
    ref.check_bvh(nodes, order, leaves, boxes)

    def rejects(match, nodes=nodes, order=order, leaves=leaves):
        with pytest.raises(AssertionError, match=match):
            ref.check_bvh(nodes, order, leaves, boxes)

    leafy = int(np.flatnonzero(nodes["left"] & bvh.BVH_LEAF)[0])
    bad = nodes.copy()
    bad["right"][leafy] = nodes["left"][leafy]  # a leaf twice (boxes still contain it)
    rejects(f"leaf {nodes['left'][leafy] & ~bvh.BVH_LEAF} is reached more than once", nodes=bad)
    bad = nodes.copy()
    inner = int(np.flatnonzero((nodes["right"] & bvh.BVH_LEAF) == 0)[-1])
    bad["right"][inner] = 0  # a cycle back to the root
    rejects("internal node 0 is reached more than once", nodes=bad)
    bad = nodes.copy()
    bad["left"][3] = 5000  # out of range
    rejects("out of range", nodes=bad)
    bad = nodes.copy()
    bad["right"][7] = bvh.BVH_NONE
    rejects("NONE", nodes=bad)
    bad = nodes.copy()
    bad["lo"][0, 1] += np.float32(1.0)  # the root no longer contains a child
    rejects("does not contain", nodes=bad)
    bad = nodes.copy()
    bad["hi"][leafy, 0] = bad["lo"][leafy, 0]
    rejects("does not contain", nodes=bad)
    bad_order = order.copy()
    bad_order[[0, 1]] = bad_order[[1, 0]]
    rejects(r"leaf_boxes\[0\]", order=bad_order)
    bad_order = order.copy()
    bad_order[0] = bad_order[1]
    rejects("permutation", order=bad_order)
    bad_leaves = leaves.copy()
    bad_leaves[17, 4] += 1
    rejects(r"leaf_boxes\[17\]", leaves=bad_leaves)
    rejects("internal nodes", nodes=nodes[:-1])
    one = random_boxes(1, seed=1)
    n1, o1, l1 = ref.build_bvh(one)
    ref.check_bvh(n1, o1, l1, one)
    n1["right"][0] = 0
    with pytest.raises(AssertionError, match="1-box tree"):
        ref.check_bvh(n1, o1, l1, one)


def test_bad_input(queue):
    good = random_boxes(10)
    with pytest.raises(TypeError, match="boxes"):
        bvh.build_bvh(good.astype(np.float64), queue=queue)
    with pytest.raises(TypeError, match="boxes"):
        bvh.build_bvh(None, queue=queue)
    with pytest.raises(ValueError, match="boxes"):
        bvh.build_bvh(good[:, :5], queue=queue)
    with pytest.raises(ValueError, match="boxes"):
        bvh.build_bvh(good.ravel(), queue=queue)
    for row, col, value in [(7, 1, np.nan), (3, 4, np.inf), (9, 0, -np.inf), (0, 5, np.nan)]:
        b = good.copy()
        b[row, col] = value
        with pytest.raises(clvis.DataError, match=f"row {row}"):
            bvh.build_bvh(b, queue=queue)
    b = good.copy()
    b[4, 2] = b[4, 5] + 1  # lo > hi
    b[8, 0] = np.nan
    with pytest.raises(clvis.DataError, match="row 4"):
        bvh.build_bvh(b, queue=queue)
    with pytest.raises(clvis.DataError, match="row 6"):
        bvh.build_bvh(
            cla.to_device(queue, np.where(np.arange(10)[:, None] == 6, np.nan, good).astype(np.float32)),
            queue=queue,
        )
    big = np.finfo(np.float32).max
    b = good.copy()
    b[2] = [big, 0, 0, big, 1, 1]  # lo + hi overflows: no finite centre
    with pytest.raises(clvis.DataError, match="row 2"):
        bvh.build_bvh(b, queue=queue)
    huge = np.lib.stride_tricks.as_strided(good, shape=(2**31, 6), strides=(0, 4))
    with pytest.raises(clvis.DeviceError, match="boxes"):
        bvh.build_bvh(huge, queue=queue)


def _build(queue, src):
    with warnings.catch_warnings():  # drivers may log remarks on success
        warnings.simplefilter("ignore", cl.CompilerWarning)
        return cl.Program(queue.context, src).build(["-I", str(runtime.INCLUDE_DIR)])


def test_node_layout(device):
    """BVH_NODE_DTYPE is clvis_bvh_node: size, offsets, and the fields as a
    kernel reads them from records the host wrote."""
    q = runtime.queue_for(device)
    prg = _build(
        q,
        """
    #include "clvis/bvh.h"
    kernel void probe(global const clvis_bvh_node *nodes, global const float *leaf_boxes, global uint *out) {
        out[0] = sizeof(clvis_bvh_node);
        global const char *base = (global const char *)nodes;
        out[1] = (uint)((global const char *)&nodes[0].lo - base);
        out[2] = (uint)((global const char *)&nodes[0].left - base);
        out[3] = (uint)((global const char *)&nodes[0].hi - base);
        out[4] = (uint)((global const char *)&nodes[0].right - base);
        out[5] = CLVIS_BVH_LEAF;
        out[6] = CLVIS_BVH_NONE;
        float3 lo = clvis_bvh_node_lo(nodes + 1), hi = clvis_bvh_node_hi(nodes + 1);
        vstore3(as_uint3(lo), 0, out + 8);
        out[11] = nodes[1].left;
        vstore3(as_uint3(hi), 0, out + 12);
        out[15] = nodes[1].right;
        clvis_bvh_leaf_box(leaf_boxes, 1, &lo, &hi);
        vstore3(as_uint3(lo), 0, out + 16);
        vstore3(as_uint3(hi), 0, out + 19);
    }""",
    )
    dt = bvh.BVH_NODE_DTYPE
    rec = np.zeros(2, dt)
    rec[1] = ((1.5, -2.0, 3.25), 0x80000007, (4.0, 5.5, -0.0), 42)
    out = cla.zeros(q, 22, np.uint32)
    leaves = np.arange(12, dtype=np.float32).reshape(2, 6)
    prg.probe(q, (1,), (1,), cla.to_device(q, rec).data, cla.to_device(q, leaves).data, out.data)
    got = out.get()
    np.testing.assert_array_equal(got[16:22].view(np.float32), leaves[1])
    assert (
        list(got[:5])
        == [dt.itemsize, dt.fields["lo"][1], dt.fields["left"][1], dt.fields["hi"][1], dt.fields["right"][1]]
        == [32, 0, 12, 16, 28]
    )
    assert got[5] == bvh.BVH_LEAF and got[6] == bvh.BVH_NONE
    assert got[8:16].tobytes() == rec[1].tobytes()
    assert ref.BVH_NODE_DTYPE == dt and ref.BVH_LEAF == bvh.BVH_LEAF and ref.BVH_NONE == bvh.BVH_NONE


def test_slab(device):
    """clvis_ray_inv_dir + clvis_ray_slab (clvis/ray.h, march.cl's box test):
    zero and -0.0 direction components, faces, origins inside; random rays
    agree with a float64 slab test (outside a thin margin around grazing)."""
    q = runtime.queue_for(device)
    prg = _build(
        q,
        """
    #pragma OPENCL FP_CONTRACT OFF
    #include "clvis/ray.h"
    kernel void slab(global const float *o, global const float *d, global const float *box,
                     float tmin, float tmax, global float *out) {
        uint i = get_global_id(0);
        float oi[3], inv[3];
        for (int k = 0; k < 3; ++k) {
            oi[k] = o[3 * i + k];
            inv[k] = clvis_ray_inv_dir(d[3 * i + k]);
        }
        global const float *b = box + 6 * i;
        float te, tx;
        clvis_ray_slab(oi, inv, b[0], b[1], b[2], b[3], b[4], b[5], &te, &tx);
        te = clvis_ray_max(te, tmin);     /* clipped to [tmin, tmax] as march.cl clips to t >= lower */
        tx = clvis_ray_min(tx, tmax);
        out[3 * i] = te <= tx; out[3 * i + 1] = te; out[3 * i + 2] = tx;
        vstore3(vload3(0, inv), i, out + 3 * get_global_size(0));
    }""",
    )
    kernel = cl.Kernel(prg, "slab")

    def run(o, d, box, tmin=0.0, tmax=np.inf):
        o, d, box = (np.ascontiguousarray(a, np.float32) for a in (o, d, box))
        m = o.shape[0]
        out = cla.empty(q, 6 * m, np.float32)
        kernel(
            q,
            (m,),
            None,
            cla.to_device(q, o).data,
            cla.to_device(q, d).data,
            cla.to_device(q, box).data,
            np.float32(tmin),
            np.float32(tmax),
            out.data,
        )
        r = out.get()
        return r[: 3 * m].reshape(m, 3), r[3 * m :].reshape(m, 3)

    unit = [0, 0, 0, 1, 1, 1]
    cases = [  # origin, direction, hit, t_enter, t_exit
        ((-1, 0.5, 0.5), (1, 0, 0), 1, 1.0, 2.0),
        ((-1, 1.5, 0.5), (1, 0, 0), 0, None, None),  # parallel, outside the y slab
        # in a face plane, parallel to it: the zero's sign says which side
        ((-1, 1.0, 0.5), (1, -0.0, 0), 1, 1.0, 2.0),  # face y = 1, moving in (-0.0)
        ((-1, 1.0, 0.5), (1, 0.0, 0), 0, None, None),  # face y = 1, moving out (+0.0)
        ((-1, 0.0, 0.5), (1, 0.0, 0), 1, 1.0, 2.0),  # face y = 0, moving in
        ((-1, 0.0, 0.5), (1, -0.0, 0), 0, None, None),  # face y = 0, moving out
        ((0.5, 0.5, 0.5), (0, 0, -1), 1, 0.0, 0.5),  # from inside
        ((2, 0.5, 0.5), (1, 0, 0), 0, None, None),  # behind
        ((0.5, 0.5, -3), (0, -0.0, 2), 1, 1.5, 2.0),
        ((0.5, 0.5, -3), (1e-30, -1e-38, 2), 1, 1.5, 2.0),  # tiny and subnormal components
        ((-1, -1, -1), (1, 1, 1), 1, 1.0, 2.0),  # through the corners
    ]
    o = np.array([c[0] for c in cases])
    d = np.array([c[1] for c in cases])
    res, inv = run(o, d, np.tile(unit, (len(cases), 1)))
    assert np.isfinite(inv).all() and (inv != 0).all()
    assert not np.isnan(res).any()
    for (_, _, hit, te, tx), r in zip(cases, res, strict=True):
        assert r[0] == hit, (cases, res)
        if hit:
            assert r[1] == pytest.approx(te, abs=1e-6) and r[2] == pytest.approx(tx, rel=1e-6)
    # tmin/tmax clip the interval
    r, _ = run(o[:1], d[:1], [unit], tmin=1.5, tmax=1.75)
    assert r[0, 0] == 1 and r[0, 1] == 1.5 and r[0, 2] == 1.75
    r, _ = run(o[:1], d[:1], [unit], tmin=0.0, tmax=0.5)
    assert r[0, 0] == 0

    rng = np.random.default_rng(10)
    m = 20000
    lo = rng.uniform(-1, 0.5, (m, 3)).astype(np.float32)
    box = np.concatenate([lo, lo + rng.uniform(0, 1, (m, 3)).astype(np.float32)], axis=1)
    o = rng.uniform(-3, 3, (m, 3)).astype(np.float32)
    # half the rays aimed at a point of their box, half anywhere; 20 % zero components
    target = box[:, :3] + rng.random((m, 3)).astype(np.float32) * (box[:, 3:] - box[:, :3])
    d = np.where(rng.random((m, 1)) < 0.5, target - o, rng.normal(size=(m, 3))).astype(np.float32)
    zero = rng.random((m, 3)) < 0.2
    zero[zero.all(axis=1), 0] = False
    d[zero] = 0.0
    o[zero] = target[zero]
    res, _ = run(o, d, box)
    # float64 reference: per axis the parameter interval, exact for zero components
    o64, d64, lo64, hi64 = (
        o.astype(np.float64),
        d.astype(np.float64),
        box[:, :3].astype(np.float64),
        box[:, 3:].astype(np.float64),
    )
    with np.errstate(divide="ignore", invalid="ignore"):
        t0, t1 = (lo64 - o64) / d64, (hi64 - o64) / d64
    inside = (o64 >= lo64) & (o64 <= hi64)
    zero = d64 == 0
    tn = np.where(zero, np.where(inside, -np.inf, np.inf), np.minimum(t0, t1))
    tf = np.where(zero, np.where(inside, np.inf, -np.inf), np.maximum(t0, t1))
    te, tx = np.maximum(tn.max(axis=1), 0.0), tf.min(axis=1)
    clear_hit = tx - te > 1e-4 * np.maximum(1, np.abs(tx))
    clear_miss = te - tx > 1e-4 * np.maximum(1, np.abs(te))
    assert clear_hit.sum() > 1000 and clear_miss.sum() > 1000
    assert (res[clear_hit, 0] == 1).all()
    assert (res[clear_miss, 0] == 0).all()
    np.testing.assert_allclose(res[clear_hit, 1], te[clear_hit], rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(res[clear_hit, 2], tx[clear_hit], rtol=1e-5, atol=1e-5)
    # no widening: the exit is the float64 one up to the rounding of 1/d, lo - o and the product
    assert (np.abs(res[clear_hit, 2] - tx[clear_hit]) <= 4e-7 * np.abs(tx[clear_hit]) + 1e-30).all()
