"""The device LRU block cache (clvis.iso.cache, kernels_cl/iso/cache.cl):
equal, update by update, to the NumPy model (clvis.reference.iso.cache) —
slot_of_block, block_of_slot, ages, capacity, stats — over random sequences
of needed sets (growth, all, none, repeats, marked neighbourhoods); the
cached bricks equal clvis.zfp.decode_blocks bit for bit; mark_blocks equals
the model; a slot is never shared and a needed block is never evicted."""

import functools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from clvis import runtime, zfp
from clvis.iso.cache import BlockCache, mark_blocks
from clvis.reference.iso import cache as ref

SHAPES = [(4, 4, 4), (9, 10, 11), (13, 8, 21), (1, 30, 5)]


@functools.cache
def _zv(shape, rate=7) -> zfp.ZfpVolume:
    rng = np.random.default_rng(sum(shape))
    v = rng.standard_normal(shape).astype(np.float32)
    v[: shape[0] // 2] = 0.0  # some all-zero blocks
    return zfp.compress(v, rate)


def _check(cache: BlockCache, model: ref.BlockCache, needed=None, before=None):
    s = cache.get_state()
    assert s["capacity"] == model.capacity == cache.capacity
    np.testing.assert_array_equal(s["slot_of_block"], model.slot_of_block)
    np.testing.assert_array_equal(s["block_of_slot"], model.block_of_slot)
    np.testing.assert_array_equal(s["ages"], model.ages)
    assert (cache.occupied, cache.decoded_last, cache.decoded_total, cache.evicted_last) == (
        model.occupied,
        model.decoded_last,
        model.decoded_total,
        model.evicted_last,
    )
    sob, bos = s["slot_of_block"], s["block_of_slot"]
    occ = np.flatnonzero(bos != ref.FREE)
    # a bijection: every occupied slot's block points back to it, nothing else does
    assert len(np.unique(bos[occ])) == len(occ)
    np.testing.assert_array_equal(sob[bos[occ]], occ)
    assert np.count_nonzero(sob >= 0) == len(occ)
    if needed is not None:
        nz = np.flatnonzero(needed)
        assert (sob[nz] >= 0).all()  # every needed block cached
        if before is not None:  # and none of them moved
            kept = nz[before[nz] >= 0]
            np.testing.assert_array_equal(sob[kept], before[kept])
    return s


def _check_bricks(cache: BlockCache, s):
    bos = s["block_of_slot"]
    occ = np.flatnonzero(bos != ref.FREE)
    if len(occ):
        want = zfp.decode_blocks(cache.volume, bos[occ].astype(np.int64), queue=cache.queue, host=True)
        np.testing.assert_array_equal(s["bricks"][occ].view(np.uint32), want.view(np.uint32))


@st.composite
def _passes(draw):
    shape = draw(st.sampled_from(SHAPES))
    nb = _zv(shape).nblocks
    cap = draw(st.one_of(st.none(), st.integers(1, nb + 3)))
    seq, prev = [], np.zeros(nb, np.uint8)
    for _ in range(draw(st.integers(1, 6))):
        kind = draw(st.sampled_from(["random", "random", "marked", "all", "none", "repeat"]))
        if kind == "random":
            p = draw(st.sampled_from([0.05, 0.2, 0.5, 0.9]))
            seed = draw(st.integers(0, 2**31))
            f = (np.random.default_rng(seed).random(nb) < p).astype(np.uint8)
        elif kind == "marked":
            ids = draw(st.lists(st.integers(0, nb + 2), max_size=6))
            f = ref.mark_blocks(ids, _zv(shape).blocks)
        elif kind == "all":
            f = np.ones(nb, np.uint8)
        elif kind == "none":
            f = np.zeros(nb, np.uint8)
        else:
            f = prev
        seq.append(f)
        prev = f
    return shape, cap, seq, draw(st.sampled_from([np.uint8, np.uint32, np.bool_]))


@settings(max_examples=25)
@given(case=_passes())
def test_sequences_match_model(device, profile, case):
    shape, cap, seq, dtype = case
    with runtime.configure(tuning=profile):
        q = runtime.queue_for(device)
        cache = BlockCache(_zv(shape), cap, queue=q)
        model = ref.BlockCache(cache.nblocks, cap)
        _check(cache, model)
        before = None
        for f in seq:
            nd = runtime.empty(q, f.size, dtype, "needed")  # device flags of each dtype
            nd.set((f * (3 if dtype == np.uint32 else 1)).astype(dtype), queue=q)
            assert cache.update(nd) == model.update(f)
            s = _check(cache, model, f, before)
            before = s["slot_of_block"]
        _check_bricks(cache, s)


def test_lru_order_by_hand(queue):
    zv = _zv((9, 10, 11))  # 3 x 3 x 3 = 27 blocks
    cache = BlockCache(zv, 3, queue=queue)
    assert (cache.capacity, cache.occupied) == (3, 0)

    def run(ids, dtype=np.uint8):
        f = np.zeros(zv.nblocks, dtype)
        f[list(ids)] = 1
        n = cache.update(f)
        s = cache.get_state()
        return n, list(s["block_of_slot"]), list(s["ages"])

    assert run([0, 1, 2]) == (3, [0, 1, 2], [0, 0, 0])
    assert run([1]) == (0, [0, 1, 2], [1, 0, 1])
    assert run([2], np.uint32) == (0, [0, 1, 2], [2, 1, 0])
    assert run([5], bool) == (1, [5, 1, 2], [0, 2, 1])  # slot 0 (age 3) is the oldest
    assert cache.evicted_last == 1 and cache.get_state()["slot_of_block"][0] == -1
    assert run([6, 7]) == (2, [5, 6, 7], [1, 0, 0])  # slot 1 (age 3), then slot 2 (age 2)
    assert run([]) == (0, [5, 6, 7], [2, 1, 1])
    assert run([9]) == (1, [9, 6, 7], [0, 2, 2])  # oldest
    assert run([8]) == (1, [9, 8, 7], [1, 0, 3])  # tie of ages 3: the lower slot
    # growth: 5 needed > 3 slots -> max(5, ceil(1.5 * 3)) = 5; the old blocks stay put
    # (free slots 3, 4 first, then slot 2's block 7, the only one not needed)
    assert run([9, 8, 20, 21, 22]) == (3, [9, 8, 22, 20, 21], [0, 0, 0, 0, 0])
    assert (cache.capacity, cache.occupied, cache.evicted_last, cache.decoded_total) == (5, 5, 1, 11)
    assert cache.nbytes == 5 * 256 + 5 * 4 + 5 * 4 + 27 * 4
    # growth with eviction: 6 needed, 5 slots -> max(6, 8) = 8
    # (free slots 5, 6, 7, then slots 0, 1, 2: all of age 1, by index)
    assert run([0, 1, 2, 3, 4, 5]) == (6, [3, 4, 5, 20, 21, 0, 1, 2], [0, 0, 0, 1, 1, 0, 0, 0])
    assert (cache.capacity, cache.occupied, cache.evicted_last) == (8, 8, 3)
    _check_bricks(cache, cache.get_state())


def test_age_saturation_ties(queue):
    zv = _zv((9, 10, 11))
    cache, model = BlockCache(zv, 4, queue=queue), ref.BlockCache(zv.nblocks, 4)
    f = np.zeros(zv.nblocks, np.uint8)
    f[:4] = 1
    cache.update(f), model.update(f)
    ages = np.array([ref.AGE_MAX - 1, ref.AGE_MAX, 7, ref.AGE_MAX - 1], np.uint32)
    cache.set_ages(ages)
    model.ages = ages.copy()
    for ids in ([10], [11], [12]):
        f = np.zeros(zv.nblocks, np.uint8)
        f[ids] = 1
        assert cache.update(f) == model.update(f) == 1
        _check(cache, model, f)
    # all of 0, 1, 3 were saturated at AGE_MAX, so they went in slot order
    assert list(model.block_of_slot) == [10, 11, 2, 12]


def test_ages_past_one_digit(queue):
    """Over 300 passes the ages pass 255, so the LRU sort's keys (cache.cl's
    top - age) need two 8-bit digits; the eviction order stays the model's
    (a sort on the low 8 bits only would take slot 2 before slot 1)."""
    zv = _zv((9, 10, 11))
    cache, model = BlockCache(zv, 4, queue=queue), ref.BlockCache(zv.nblocks, 4)

    def run(ids):
        f = np.zeros(zv.nblocks, np.uint8)
        f[ids] = 1
        assert cache.update(f) == model.update(f)

    run([0, 1, 2, 3])
    for i in range(300):
        run([1, 2] if i == 45 else [2, 3] if i == 250 else [2])
    np.testing.assert_array_equal(cache.get_state()["ages"], [300, 254, 0, 49])
    run([10, 11, 12])  # ages 301, 255, 1, 50: keys 2, 48, 302, 253 under top 303
    _check(cache, model)
    assert list(model.block_of_slot) == [10, 11, 2, 12]
    assert cache.evicted_last == 3


def test_shared_stream(queue):
    """stream=: a new cache decodes from another's device stream (no upload)
    and fills the same bricks; a stream of another volume or dtype is refused."""
    zv = _zv((9, 10, 11))
    first = BlockCache(zv, 4, queue=queue)
    cache = BlockCache(zv, 4, queue=queue, stream=first.stream)
    assert cache.stream is first.stream
    f = np.zeros(zv.nblocks, np.uint8)
    f[[0, 5, 26]] = 1
    cache.update(f)
    _check_bricks(cache, cache.get_state())
    other = _zv((13, 8, 21)).to_device(queue)
    with pytest.raises(ValueError, match="stream: expected the volume's"):
        BlockCache(zv, 4, queue=queue, stream=other)
    with pytest.raises(ValueError, match="stream: expected the volume's"):
        BlockCache(zv, 4, queue=queue, stream=first.stream.view(np.int64))
    with pytest.raises(TypeError, match="stream: expected a device array"):
        BlockCache(zv, 4, queue=queue, stream=np.frombuffer(zv.stream, "<u8"))


@pytest.mark.parametrize("dtype", [np.uint8, np.uint32])
def test_mark_blocks(queue, dtype):
    rng = np.random.default_rng(5)
    for blocks in [(1, 1, 1), (3, 4, 5), (1, 7, 1), (2, 1, 9)]:
        nb = int(np.prod(blocks))
        ids = rng.integers(0, nb + 3, 9)
        got = mark_blocks(ids.astype(np.uint32), blocks, queue=queue).get()
        np.testing.assert_array_equal(got, ref.mark_blocks(ids, blocks))
        # OR into an existing array of flags, device ids
        pre = (rng.random(nb) < 0.2).astype(dtype)
        nd = runtime.empty(queue, nb, dtype, "needed")
        nd.set(pre, queue=queue)
        idd = runtime.empty(queue, len(ids), np.uint32, "ids")
        idd.set(ids.astype(np.uint32), queue=queue)
        out = mark_blocks(idd, blocks, nd, queue=queue)
        assert out is nd and out.dtype == dtype
        np.testing.assert_array_equal(out.get(), np.maximum(pre, ref.mark_blocks(ids, blocks)))
    # the corner block marks only itself; block 0 marks its 7 neighbours
    assert ref.mark_blocks([59], (3, 4, 5)).sum() == 1
    assert np.flatnonzero(ref.mark_blocks([0], (3, 4, 5))).tolist() == [0, 1, 5, 6, 20, 21, 25, 26]


def test_marked_pass_feeds_cache(queue):
    zv = _zv((13, 8, 21))
    cache, model = BlockCache(zv, queue=queue), ref.BlockCache(zv.nblocks)
    assert cache.capacity == model.capacity == ref.default_capacity(zv.nblocks) == 48  # < 64: all
    for vis in ([0, 5], [23], list(range(0, 24, 3))):
        nd = mark_blocks(np.array(vis, np.uint32), zv, queue=queue)
        f = ref.mark_blocks(vis, zv.blocks)
        assert cache.update(nd) == model.update(f)
        _check(cache, model, f)
    _check_bricks(cache, cache.get_state())


def test_empty_volume_and_bad_input(queue):
    empty = zfp.ZfpVolume(b"", (0, 4, 4), 8)
    c = BlockCache(empty, queue=queue)
    assert c.update(np.zeros(0, np.uint8)) == 0 and c.capacity == 1 and c.occupied == 0
    zv = _zv((4, 4, 4))
    cache = BlockCache(zv, queue=queue)
    with pytest.raises(ValueError, match="needed"):
        cache.update(np.ones(2, np.uint8))
    with pytest.raises(TypeError, match="needed"):
        cache.update(np.ones(1, np.float32))
    with pytest.raises(ValueError, match="capacity"):
        BlockCache(zv, 0, queue=queue)
    with pytest.raises(TypeError, match="zfp_volume"):
        BlockCache(np.zeros((4, 4, 4)), queue=queue)
    with pytest.raises(TypeError, match="needed"):
        cache.update(runtime.zeros(queue, 1, np.int16, "x"))
    assert cache.update(np.ones(1, np.uint8)) == 1 and cache.update(np.ones(1, bool)) == 0


def test_larger_volume_growth_and_eviction(queue):
    rng = np.random.default_rng(11)
    zv = zfp.compress(rng.standard_normal((40, 36, 44)).astype(np.float32), 5)  # 990 blocks
    cache, model = BlockCache(zv, queue=queue), ref.BlockCache(zv.nblocks)
    assert cache.capacity == 64
    evicted, grown = 0, 0
    for p in [0.03, 0.05, 0.06, 0.02, 0.3, 0.1, 0.1, 0.5, 0.2, 1.0, 0.0]:
        f = (rng.random(zv.nblocks) < p).astype(np.uint8)
        cap = cache.capacity
        assert cache.update(f) == model.update(f)
        _check(cache, model, f)
        evicted += cache.evicted_last
        grown += cache.capacity > cap
    assert evicted > 100 and grown >= 2 and cache.capacity == zv.nblocks
    _check_bricks(cache, cache.get_state())
