"""clvis.distributed.composite against its NumPy definition
(clvis.reference.distributed.composite): the keys, the per-pixel min-key
choice over any number of partials, and that any grouping of the partials
(bands, trees, orders) gives the same frame."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from clvis.distributed import composite as C
from clvis.reference.distributed import composite as ref


def _partials(rng, n_parts, h, w, cover=0.6, tie_depths=False):
    """Partials of a (h, w) frame: random depths (few distinct values with
    tie_depths), unique ids across partials, planes of several shapes."""
    parts = []
    for i in range(n_parts):
        covered = rng.random((h, w)) < cover
        depth = (rng.integers(0, 3, (h, w)) * 0.5 if tie_depths else rng.uniform(-2, 50, (h, w))).astype(
            np.float32
        )
        depth[~covered] = np.inf
        ids = (rng.integers(0, 1000, (h, w)) * n_parts + i).astype(np.uint32)  # unique per partial
        ids[~covered] = 0xFFFFFFFF
        rgba = rng.integers(0, 256, (h, w, 4), dtype=np.uint8)
        rgba[~covered] = 0  # empty pixels look the same in every partial (only they tie)
        planes = {
            "index": ids,
            "depth": depth,
            "rgba": rgba,
            "attr": np.where(covered, rng.random((h, w)), np.nan).astype(np.float32),
        }
        parts.append(C.Partial((0, h), C.depth_keys(depth, ids, covered), planes, f"w{i % 2}"))
    return parts


def test_depth_keys_match_the_reference_and_keep_the_order():
    d = np.array([-np.inf, -3.5, -1e-30, -0.0, 0.0, 1e-30, 0.25, 1.0, 7e5, np.inf], np.float32)
    ids = np.arange(d.size, dtype=np.uint32)
    covered = np.ones(d.size, bool)
    got = C.depth_keys(d, ids, covered)
    assert got.dtype == np.uint64
    np.testing.assert_array_equal(got, ref.keys(d, ids, covered))
    assert (np.diff(got.astype(object)) > 0).all()  # float order is key order
    covered[3] = False
    keys = C.depth_keys(d, ids, covered)
    assert keys[3] == C.EMPTY_KEY == 2**64 - 1
    # the key carries id and depth: both come back exactly (-0.0 too), empty as EMPTY / +inf
    ids_back, depth_back = C.ids_of(keys), C.depths_of(keys)
    want_ids = np.where(covered, ids, 0xFFFFFFFF)
    np.testing.assert_array_equal(ids_back, want_ids)
    want_depth = np.where(covered, d, np.inf).astype(np.float32)
    np.testing.assert_array_equal(depth_back.view(np.uint32), want_depth.view(np.uint32))


@pytest.mark.parametrize("n_parts", [1, 2, 3, 7])
@pytest.mark.parametrize("ties", [False, True], ids=["distinct", "tied-depths"])
def test_composite_matches_the_reference(n_parts, ties):
    rng = np.random.default_rng(n_parts)
    parts = _partials(rng, n_parts, 9, 13, tie_depths=ties)
    got = C.composite(parts, "w0")
    want_key, want = ref.composite([p.key for p in parts], [p.planes for p in parts])
    np.testing.assert_array_equal(got.key, want_key)
    for name in want:
        np.testing.assert_array_equal(got.planes[name], want[name])
    # on tied depths the lower id wins, as on one device
    both = (parts[0].key != C.EMPTY_KEY) & (parts[-1].key != C.EMPTY_KEY)
    tie = both & (parts[0].planes["depth"] == parts[-1].planes["depth"])
    tie &= got.planes["depth"] == parts[0].planes["depth"]  # and no third partial nearer
    if n_parts > 1:
        lo = np.minimum(parts[0].planes["index"], parts[-1].planes["index"])
        assert (got.planes["index"][tie] <= lo[tie]).all()
    # bytes from the other worker's partials are counted as sent by it
    other = sum(p.nbytes for p in parts if p.worker != "w0")
    assert got.sent.get("w1", 0) == other


@given(
    seed=st.integers(0, 2**32 - 1),
    n_parts=st.integers(1, 6),
    n_bands=st.integers(1, 5),
    h=st.integers(1, 8),
)
def test_any_grouping_gives_the_same_frame(seed, n_parts, n_bands, h):
    """Direct-send (bands composited separately then assembled), a binary
    tree and a shuffled order all equal the all-at-once reference."""
    rng = np.random.default_rng(seed)
    parts = _partials(rng, n_parts, h, 5, tie_depths=bool(seed % 2))
    want_key, want = ref.composite([p.key for p in parts], [p.planes for p in parts])
    bands = C.bands(h, n_bands)
    direct = C.assemble([C.composite([C.split(p, b, j == 0) for p in parts]) for j, b in enumerate(bands)])
    level = list(parts)
    rng.shuffle(level)
    while len(level) > 1:
        level = [C.composite(level[k : k + 2]) for k in range(0, len(level), 2)]
    for got in (direct, level[0]):
        assert got.rows == (0, h)
        np.testing.assert_array_equal(got.key, want_key)
        for name in want:
            np.testing.assert_array_equal(got.planes[name], want[name])


def test_bands_split_and_assemble():
    assert C.bands(10, 3) == [(0, 4), (4, 7), (7, 10)]
    assert C.bands(2, 3) == [(0, 1), (1, 2), (2, 2)]
    assert C.bands(0, 1) == [(0, 0)]
    rng = np.random.default_rng(0)
    (p,) = _partials(rng, 1, 10, 4)
    p.seconds, p.counts = {"render w0": 1.0}, {"points": 5}
    pieces = [C.split(p, b, j == 0) for j, b in enumerate(C.bands(10, 3))]
    assert [x.key.base is None for x in pieces] == [True] * 3  # copies, not views of the frame
    whole = C.assemble(pieces[::-1])
    np.testing.assert_array_equal(whole.key, p.key)
    assert whole.seconds == {"render w0": 1.0} and whole.counts == {"points": 5}  # counted once


def test_bad_input():
    rng = np.random.default_rng(0)
    a, b = _partials(rng, 2, 4, 4)
    with pytest.raises(ValueError, match="parts: nothing"):
        C.composite([])
    with pytest.raises(ValueError, match="cannot be composited"):
        C.composite([a, C.split(b, (0, 2))])
    del b.planes["attr"]
    with pytest.raises(ValueError, match="planes"):
        C.composite([a, b])
    with pytest.raises(ValueError, match="rows: .* not inside"):
        C.split(a, (2, 9))
    with pytest.raises(ValueError, match="do not meet"):
        C.assemble([C.split(a, (0, 1)), C.split(a, (2, 4))])
    with pytest.raises(ValueError, match="n: expected at least one band"):
        C.bands(4, 0)


def _crossover(direct, tree):
    """The largest worker count at which direct-send's projected frame is
    not slower than the tree's (the tree cheaper at every count after it, to 64)."""
    return max(p for p in range(1, 65) if direct(p) <= tree(p) or p == 1)


def _levels(p):
    return (p - 1).bit_length()  # ceil(log2 p): the tree's levels


def test_auto_thresholds_are_the_projections_crossovers():
    """The constants behind compositing="auto" are where the models of
    bench/results/distributed-cpu.md cross (seconds; 1 ms of scheduler time
    per task). Points, 10^10 at 1920x1080: render a + b n, a frame merged in
    93 ms and sent in 20 ms (twice for direct-send: to the peers, to the
    client); volumes, 512^3 at 512x512: footprints of 0.76 F P^(-2/3)
    pixels, 28 B each, merged at 20 ns per pixel and piece."""
    render = lambda p: 0.056 + 7.9e-9 * 1e10 / p  # noqa: E731
    pd = lambda p: render(p) + 0.093 + 0.040 + (p * p + 2 * p) * 1e-3  # noqa: E731
    pt = lambda p: render(p) + _levels(p) * 0.113 + (2 * p - 1) * 1e-3  # noqa: E731
    assert C.DIRECT_SEND_MAX_WORKERS_POINTS == _crossover(pd, pt) == 20
    f = 512 * 512
    vr = lambda p: 0.58 / p + 0.03  # noqa: E731
    union = lambda p, k: min(f, 0.76 * f * (2**k / p) ** (2 / 3))  # noqa: E731
    vd = lambda p: (  # noqa: E731
        vr(p) + f / p * p ** (1 / 3) * 20e-9 + (union(p, 0) + f / p) * 28 / 1.25e9 + (p * p + 2 * p) * 1e-3
    )
    vt = lambda p: (  # noqa: E731
        vr(p)
        + sum(union(p, k) for k in range(1, _levels(p) + 1)) * (40e-9 + 28 / 1.25e9)
        + (2 * p - 1) * 1e-3
    )
    # up to 5 workers the two are within 8 ms (2 and 4: the tree by 2 ms); from 6 the tree wins
    assert all(abs(vd(p) - vt(p)) < 0.008 for p in range(2, 6))
    assert all(vt(p) < vd(p) for p in range(6, 65))
    assert C.DIRECT_SEND_MAX_WORKERS_VOLUMES == 5


@pytest.mark.parametrize("limit", [C.DIRECT_SEND_MAX_WORKERS_POINTS, C.DIRECT_SEND_MAX_WORKERS_VOLUMES])
def test_auto_picks_direct_send_up_to_the_threshold_and_the_tree_beyond(limit):
    assert [C.schedule("auto", p, limit) for p in range(1, limit + 1)] == ["direct"] * limit
    assert [C.schedule("auto", p, limit) for p in (limit + 1, limit + 2, 64, 512)] == ["tree"] * 4
    for p in (1, 2, limit + 1, 512):  # an explicit schedule is kept whatever the count
        assert C.schedule("direct", p, limit) == "direct" and C.schedule("tree", p, limit) == "tree"
    with pytest.raises(ValueError, match="compositing: expected one of"):
        C.schedule("binary-swap", 2, limit)


def test_auto_is_the_renderers_default_with_their_family_threshold():
    import inspect

    from clvis.distributed import DistributedRasterizer
    from clvis.distributed.iso import DistributedIsoRenderer

    for cls, limit in (
        (DistributedRasterizer, C.DIRECT_SEND_MAX_WORKERS_POINTS),
        (DistributedIsoRenderer, C.DIRECT_SEND_MAX_WORKERS_VOLUMES),
    ):
        assert inspect.signature(cls.__init__).parameters["compositing"].default == "auto"
        assert cls.direct_send_max == limit
