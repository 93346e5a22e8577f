"""clvis.radix_sort against clvis.reference.primitives.radix_sort.

Keys are compared bit for bit (so -0.0/+0.0 and NaN payloads count), values
carry the input positions (so stability is checked too).
"""

import os

import numpy as np
import pyopencl.array as cla
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import clvis
from clvis.reference import primitives as ref

KEY_DTYPES = [np.uint32, np.int32, np.float32, np.uint64, np.int64, np.float64]
SIZES = [0, 1, 2, 3, 255, 256, 257, 1023, 1024, 1025, 4097, 65537]


def bits(a):
    a = np.asarray(a)
    return a.view(f"u{a.dtype.itemsize}")


def random_keys(n, dtype, rng):
    dtype = np.dtype(dtype)
    if dtype.kind == "f":
        return (rng.standard_normal(n) * rng.choice([1e-3, 1.0, 1e6], n)).astype(dtype)
    info = np.iinfo(dtype)
    return rng.integers(info.min, info.max, n, dtype=dtype, endpoint=True)


def check(keys, queue, with_values=True, key_bits=None):
    n = keys.shape[0]
    if with_values:
        vals = np.arange(n, dtype=np.uint32)
        gk, gv = clvis.radix_sort(keys, vals, key_bits=key_bits, queue=queue)
        wk, wv = ref.radix_sort(keys, vals, key_bits=key_bits)
        np.testing.assert_array_equal(gv, wv)
    else:
        gk = clvis.radix_sort(keys, key_bits=key_bits, queue=queue)
        wk = ref.radix_sort(keys, key_bits=key_bits)
    assert gk.dtype == keys.dtype
    np.testing.assert_array_equal(bits(gk), bits(wk))


@pytest.mark.parametrize("with_values", [True, False], ids=["pairs", "keys"])
@pytest.mark.parametrize("dtype", KEY_DTYPES, ids=lambda d: np.dtype(d).name)
def test_parity_sizes(queue, dtype, with_values):
    rng = np.random.default_rng(13)
    for n in SIZES:
        check(random_keys(n, dtype, rng), queue, with_values)


@pytest.mark.parametrize("dtype", KEY_DTYPES, ids=lambda d: np.dtype(d).name)
@pytest.mark.parametrize("kind", ["equal", "sorted", "reversed", "extremes", "few"])
def test_adversarial(queue, dtype, kind):
    rng = np.random.default_rng(17)
    n = 20011
    dt = np.dtype(dtype)
    info = np.finfo(dt) if dt.kind == "f" else np.iinfo(dt)
    if kind == "equal":
        keys = np.full(n, info.max, dt)
    elif kind == "sorted":
        keys = np.sort(random_keys(n, dt, rng))
    elif kind == "reversed":
        keys = np.sort(random_keys(n, dt, rng))[::-1].copy()
    elif kind == "extremes":
        keys = rng.choice(np.array([info.min, info.max, 0, 1], dt), n)
    else:
        keys = rng.integers(0, 3, n).astype(dt)
    check(keys, queue)


@pytest.fixture
def msd_always(monkeypatch):
    """The CPU form's MSD-first path (top digit, then each bucket by LSD in
    cache) for every size, not only from MSD_MIN_N keys."""
    monkeypatch.setattr(clvis.primitives, "MSD_MIN_N", 0)


@pytest.mark.parametrize("dtype", KEY_DTYPES, ids=lambda d: np.dtype(d).name)
def test_msd_first(queue, msd_always, dtype):
    rng = np.random.default_rng(31)
    dt = np.dtype(dtype)
    for n in [2, 3, 257, 20011, 300_001]:
        check(random_keys(n, dt, rng), queue)
    check(random_keys(20011, dt, rng), queue, with_values=False)
    # clustered keys: digits every key shares skip their pass, an odd number
    # of skips ends a bucket in the other buffer (then copied back)
    n = 50_000
    info = np.iinfo(dt) if dt.kind != "f" else None
    if info is not None:
        hi = np.array(dt.itemsize * 8 - 8, dt)
        low = rng.integers(0, 1 << 16, n).astype(dt)
        top = (
            (rng.integers(0, 256, n).astype(dt) << hi)
            if dt.kind == "u"
            else rng.integers(-3, 3, n).astype(dt)
        )
        for keys in (low | top if dt.kind == "u" else low + top * (1 << 20), top, np.full(n, 7, dt)):
            check(keys, queue)
    check(
        rng.choice(np.array([-0.0, 0.0, np.inf, -np.inf, np.nan, 1.5], dt), 20011)
        if dt.kind == "f"
        else np.full(5, 1, dt),
        queue,
    )


@pytest.mark.parametrize("key_bits", [1, 9, 17, 30])
def test_msd_first_key_bits(queue, msd_always, key_bits):
    rng = np.random.default_rng(key_bits)
    check(rng.integers(0, 1 << key_bits, 70_001, dtype=np.uint32), queue, key_bits=key_bits)


@pytest.mark.parametrize("dtype", KEY_DTYPES, ids=lambda d: np.dtype(d).name)
@pytest.mark.parametrize("slack", [-8, -1], ids=["wide", "9-bit"])
def test_msd_first_bucket_digits(queue, msd_always, monkeypatch, dtype, slack):
    """radix_bucket_lsd's digits as wide as the buckets allow (2 x 12 bits
    for 32-bit keys at 2^24; here forced on small buckets by BUCKET_SLACK):
    12-bit digits (32-bit keys), 10 (64-bit keys, the counters capped), 11
    (44-bit keys), and the 8-bit ones a narrower limit gives back; and the
    staged top-digit scatter every one of these sorts goes through."""
    built = []
    get_kernel = clvis.primitives.runtime.get_kernel

    def spy(queue, path, name, defines, *args):
        built.append((name, dict(defines)))
        return get_kernel(queue, path, name, defines, *args)

    monkeypatch.setattr(clvis.primitives.runtime, "get_kernel", spy)
    monkeypatch.setattr(clvis.primitives, "BUCKET_SLACK", slack)
    rng = np.random.default_rng(5)
    dt = np.dtype(dtype)
    n = 70_001  # ~273 keys a bucket
    keys = random_keys(n, dt, rng)
    check(keys, queue)
    check(keys[: n // 3], queue, with_values=False)
    check(rng.integers(0, 3, n).astype(dt), queue)  # long runs of equal keys: stability
    if dt.kind == "u":
        check(
            rng.integers(0, 1 << 44, n, dtype=np.uint64).astype(dt),
            queue,
            key_bits=44 if dt.itemsize == 8 else None,
        )
    digits = {d["RADIX_BITS"] for name, d in built if name == "radix_bucket_lsd"}
    staged = {
        d["STAGE"] for name, d in built if name == "radix_scatter" and "STAGE" in d and d["RADIX_BITS"] == 8
    }
    if clvis.runtime.tuning_profile(queue) != "cpu":  # the gpu shape sorts by LSD passes only
        assert digits == staged == set()
    elif slack == -8:
        assert digits == ({12} if dt.itemsize == 4 else {10, 11} if dt.kind == "u" else {10})
    else:
        assert digits == {8}
    if clvis.runtime.tuning_profile(queue) == "cpu":
        assert staged == {int(queue.device.mem_base_addr_align >= 8 * 16 * dt.itemsize)}


def test_bucket_digits():
    """2^24 random 32-bit keys: an 8-bit top digit, then 2 passes of 12 bits
    in each 2^16-key bucket; 2^22: 3 of 8 (the buckets too small for 4096
    counters); 64-bit keys: 6 passes of 10 bits (the counters capped)."""
    f = clvis.primitives._bucket_digits
    assert f(24, 1 << 16, 8) == (2, 12)
    assert f(24, 1 << 14, 8) == (3, 8)
    assert f(56, 1 << 16, 8) == (6, 10)
    assert f(32, 1464, 8) == (4, 8)  # the tile renderer's 44-bit keys, 6 M of them


@pytest.mark.parametrize("key_bits", [12, 13, 20, 41, 44, 47, 52])
def test_msd_first_wide_top_digit(queue, msd_always, key_bits):
    """The top digit takes the bits the 8-bit LSD digits leave, up to 12
    (44 bits: 12 + 4 x 8, the tile renderer's keys): keys of a few tiles each
    (most of the 2^12 buckets empty, the last one included), equal depths
    inside a tile (stability), and uniform keys."""
    assert clvis.primitives.MSD_MAX_BITS == 12
    rng = np.random.default_rng(key_bits)
    n = 30_011
    low = key_bits - min(12, key_bits - 8)
    top = (1 << (key_bits - low)) - 1  # the last bucket
    tiles = rng.choice(np.array([0, 1, 5, top // 2, top], np.uint64), n) << np.uint64(low)
    depth = rng.integers(0, 1 << min(low, 10), n, dtype=np.uint64) << np.uint64(max(0, low - 10))
    check(tiles | depth, queue, key_bits=key_bits)
    check(rng.integers(0, 1 << key_bits, n, dtype=np.uint64), queue, key_bits=key_bits)


@pytest.mark.parametrize("dtype", [np.float32, np.float64], ids=lambda d: np.dtype(d).name)
def test_float_total_order(queue, dtype):
    """-inf < ... < -0.0 < +0.0 < ... < +inf < NaN; NaNs of either sign and any
    payload come last, in input order, with their bits intact."""
    dt = np.dtype(dtype)
    u = np.dtype(f"u{dt.itemsize}")
    if dt.itemsize == 4:
        nans = np.array([0x7FC00000, 0xFFC00000, 0x7F800001, 0xFFFFFFFF], u).view(dt)
    else:
        nans = np.array(
            [0x7FF8000000000000, 0xFFF8000000000000, 0x7FF0000000000001, 0xFFFFFFFFFFFFFFFF], u
        ).view(dt)
    tiny = np.finfo(dt).smallest_subnormal
    special = np.concatenate(
        [
            nans,
            np.array(
                [np.inf, -np.inf, 0.0, -0.0, tiny, -tiny, np.finfo(dt).max, np.finfo(dt).min, 1, -1], dt
            ),
        ]
    )
    rng = np.random.default_rng(3)
    keys = rng.choice(special, 10007)
    check(keys, queue)
    got = clvis.radix_sort(keys, queue=queue)
    finite = got[~np.isnan(got)]
    assert np.all(finite[1:] >= finite[:-1])
    assert np.isnan(got[-int(np.isnan(keys).sum()) :]).all()
    zeros = bits(got[got == 0])
    neg_zero = bits(np.array([-0.0], dt))[0]
    assert np.all(np.diff((zeros != neg_zero).astype(int)) >= 0)  # all -0.0 before +0.0
    np.testing.assert_array_equal(bits(got[np.isnan(got)]), bits(keys[np.isnan(keys)]))


@pytest.mark.parametrize(
    "dtype,key_bits",
    [(np.uint32, 12), (np.uint32, 1), (np.int32, 20), (np.uint64, 40), (np.int64, 33), (np.uint32, 32)],
)
def test_key_bits(queue, dtype, key_bits):
    rng = np.random.default_rng(5)
    keys = rng.integers(0, 1 << min(key_bits, 62), 50001, dtype=np.uint64).astype(dtype)
    check(keys, queue, key_bits=key_bits)


def test_key_bits_violation(queue):
    keys = np.arange(5000, dtype=np.uint32)
    keys[1234] = 1 << 20
    saved = keys.copy()
    with pytest.raises(clvis.DataError, match=r"key_bits=16 .*0x10"):
        clvis.radix_sort(keys, key_bits=16, queue=queue)
    np.testing.assert_array_equal(keys, saved)  # input untouched
    with pytest.raises(clvis.DataError, match="key_bits=31"):
        clvis.radix_sort(np.array([5, -1, 3], np.int32), key_bits=31, queue=queue)
    with pytest.raises(clvis.DataError, match="key_bits=0"):
        clvis.radix_sort(np.array([0, 1], np.uint32), key_bits=0, queue=queue)
    np.testing.assert_array_equal(
        clvis.radix_sort(np.zeros(7, np.uint32), key_bits=0, queue=queue), np.zeros(7)
    )


@pytest.mark.parametrize("n", [1, 5000, 70_001])
def test_key_bits_unchecked(queue, monkeypatch, n):
    """check=False: device keys that keep the promise sort as with the check,
    and nothing is read back (the check's read is what it leaves out); a key
    outside the promise is not detected and the pairs come back permuted."""
    import pyopencl as cl

    rng = np.random.default_rng(n)
    keys = rng.integers(0, 1 << 18, n, dtype=np.uint32)
    vals = np.arange(n, dtype=np.uint32)
    kd, vd = cla.to_device(queue, keys), cla.to_device(queue, vals)
    queue.finish()
    reads = []
    copy = cl.enqueue_copy

    def counting(q, dst, src, **kw):
        if isinstance(dst, np.ndarray):
            reads.append(dst.nbytes)
        return copy(q, dst, src, **kw)

    monkeypatch.setattr(cl, "enqueue_copy", counting)
    gk, gv = clvis.radix_sort(kd, vd, key_bits=18, check=False, queue=queue)
    assert reads == []
    monkeypatch.setattr(cl, "enqueue_copy", copy)
    wk, wv = ref.radix_sort(keys, vals, key_bits=18, check=False)
    np.testing.assert_array_equal(gk.get(), wk)
    np.testing.assert_array_equal(gv.get(), wv)
    # with the check, the same sort reads the key check back
    monkeypatch.setattr(cl, "enqueue_copy", counting)
    clvis.radix_sort(kd, vd, key_bits=18, queue=queue)
    monkeypatch.setattr(cl, "enqueue_copy", copy)
    assert reads
    bad = keys.copy()
    bad[n // 2] = 1 << 20
    gk, gv = clvis.radix_sort(bad, vals, key_bits=18, check=False, queue=queue)
    np.testing.assert_array_equal(np.sort(gv), vals)
    np.testing.assert_array_equal(gk, bad[gv])


def test_values_dtypes(queue):
    rng = np.random.default_rng(8)
    keys = rng.integers(0, 100, 9999).astype(np.uint32)
    for vdt in (np.int32, np.float32):
        vals = rng.standard_normal(9999).astype(vdt)
        gk, gv = clvis.radix_sort(keys, vals, queue=queue)
        wk, wv = ref.radix_sort(keys, vals)
        assert gv.dtype == vdt
        np.testing.assert_array_equal(bits(gv), bits(wv))


def _check_sorted_permutation(keys, gk, gv):
    """Sorted, a permutation (the values index the input), stable — O(n)."""
    k = gk if gk.dtype.kind == "u" else ref.sort_key(gk)  # unsigned keys are their own order
    assert np.all(k[1:] >= k[:-1])
    moved = bits(keys[gv])
    # np.array_equal first (assert_array_equal costs seconds at 2^27 keys);
    # assert_array_equal then only explains a mismatch
    if not np.array_equal(moved, bits(gk)):
        np.testing.assert_array_equal(moved, bits(gk))
    assert np.bincount(gv, minlength=gv.size).max() == 1  # each input position once
    same = k[1:] == k[:-1]
    assert np.all(gv[1:][same] > gv[:-1][same])


@pytest.mark.parametrize("dtype", [np.uint32, np.float32], ids=lambda d: np.dtype(d).name)
def test_2_24(device, dtype):
    q = clvis.runtime.queue_for(device)
    rng = np.random.default_rng(24)
    keys = random_keys(1 << 24, dtype, rng)
    vals = np.arange(keys.size, dtype=np.uint32)
    gk, gv = clvis.radix_sort(keys, vals, queue=q)
    _check_sorted_permutation(keys, gk, gv)


@pytest.mark.large
@pytest.mark.skipif(os.environ.get("CLVIS_LARGE") != "1", reason="set CLVIS_LARGE=1 (2^27 keys, ~2 GB)")
def test_2_27(device):
    q = clvis.runtime.queue_for(device)
    rng = np.random.default_rng(27)
    keys = rng.integers(0, 1 << 32, 1 << 27, dtype=np.uint32)  # drawn as uint32: no uint64 copy
    vals = np.arange(keys.size, dtype=np.uint32)
    gk, gv = clvis.radix_sort(keys, vals, queue=q)
    _check_sorted_permutation(keys, gk, gv)


def test_device_arrays(queue):
    rng = np.random.default_rng(1)
    keys = rng.integers(0, 1000, 30000).astype(np.uint32)
    kd = cla.to_device(queue, keys)
    vd = cla.to_device(queue, np.arange(30000, dtype=np.uint32))
    gk, gv = clvis.radix_sort(kd, vd)
    assert isinstance(gk, cla.Array) and isinstance(gv, cla.Array)
    assert gk.data is not kd.data
    np.testing.assert_array_equal(kd.get(), keys)  # input untouched
    wk, wv = ref.radix_sort(keys, np.arange(30000, dtype=np.uint32))
    np.testing.assert_array_equal(gk.get(), wk)
    np.testing.assert_array_equal(gv.get(), wv)


@given(keys=hnp.arrays(st.sampled_from([np.uint32, np.int32, np.int64, np.float32]), st.integers(0, 3000)))
def test_property(device, keys):
    check(keys, clvis.runtime.queue_for(device))


def test_bad_input():
    with pytest.raises(TypeError, match="keys: dtype int16"):
        clvis.radix_sort(np.zeros(4, np.int16))
    with pytest.raises(ValueError, match="keys: expected a 1-D array"):
        clvis.radix_sort(np.zeros((2, 2), np.uint32))
    with pytest.raises(ValueError, match="values: length 3 differs from keys' 4"):
        clvis.radix_sort(np.zeros(4, np.uint32), np.zeros(3, np.uint32))
    with pytest.raises(TypeError, match="values: dtype uint64"):
        clvis.radix_sort(np.zeros(4, np.uint32), np.zeros(4, np.uint64))
    with pytest.raises(ValueError, match="key_bits: only integer keys"):
        clvis.radix_sort(np.zeros(4, np.float32), key_bits=8)
    with pytest.raises(ValueError, match="key_bits: expected 0..32"):
        clvis.radix_sort(np.zeros(4, np.uint32), key_bits=33)
    with pytest.raises(TypeError, match="key_bits: expected an int"):
        clvis.radix_sort(np.zeros(4, np.uint32), key_bits=8.0)


@pytest.mark.parametrize("msd", [False, True], ids=["lsd", "msd-first"])
@pytest.mark.parametrize("dtype", [np.uint32, np.int32, np.uint64, np.int64], ids=lambda d: np.dtype(d).name)
def test_key_bits_edges(queue, monkeypatch, msd, dtype):
    """key_bits at its ends and at the digit boundaries (8-bit LSD digits, the
    MSD-first top digit of up to 12 bits) for 0, 1, 2, 5 and 4097 keys, with
    and without values: each key with one boundary bit set and the largest
    key the promise allows sort as the reference does; a key one bit above the
    promise raises DataError, in both forms and for a single key too."""
    if msd:
        monkeypatch.setattr(clvis.primitives, "MSD_MIN_N", 0)
    dt = np.dtype(dtype)
    nbits = dt.itemsize * 8
    top = nbits if dt.kind == "u" else nbits - 1  # a signed key's sign bit is never a promise
    rng = np.random.default_rng(nbits)
    for kb in sorted({0, 1, 8, 9, 12, 13, 20, 21, 44, 63, 64, nbits - 1, nbits}):
        if kb > nbits:
            continue
        for n in (0, 1, 2, 5, 4097):
            hi = min(kb, top, 62)
            keys = rng.integers(0, 1 << hi, n, dtype=np.uint64) if hi else np.zeros(n, np.uint64)
            for j, b in enumerate(
                b for b in (kb - 1, min(kb, 12) - 1, kb - 12, 8, 7) if 0 <= b < min(kb, top)
            ):
                if j < n:
                    keys[j] = np.uint64(1) << np.uint64(b)
            if n and 0 < kb <= top:
                keys[-1] = np.uint64((1 << kb) - 1)  # the largest key the promise allows
            keys = keys.astype(dt)
            check(keys, queue, with_values=True, key_bits=kb)
            check(keys, queue, with_values=False, key_bits=kb)
            if n and kb < top:
                bad = keys.copy()
                bad[n // 2] = dt.type(1) << dt.type(kb)
                with pytest.raises(clvis.DataError, match=f"key_bits={kb} "):
                    clvis.radix_sort(bad, key_bits=kb, queue=queue)
            if n and dt.kind == "i" and kb < nbits:
                bad = keys.copy()
                bad[0] = -1  # every bit set
                with pytest.raises(clvis.DataError, match=f"key_bits={kb} "):
                    clvis.radix_sort(bad, key_bits=kb, queue=queue)


def test_bad_key_bits():
    with pytest.raises(ValueError, match="key_bits: expected 0..32 for uint32 keys, got -1"):
        clvis.radix_sort(np.zeros(4, np.uint32), key_bits=-1)
    with pytest.raises(ValueError, match="key_bits: expected 0..64 for uint64 keys, got 65"):
        clvis.radix_sort(np.zeros(4, np.uint64), key_bits=65)
    with pytest.raises(ValueError, match="key_bits: expected 0..64"):
        clvis.radix_sort(np.zeros(4, np.uint64), key_bits=2**70)
    for bad in (True, "8", 8.5, np.float32(8)):
        with pytest.raises(TypeError, match="key_bits: expected an int"):
            clvis.radix_sort(np.zeros(4, np.uint32), key_bits=bad)
    np.testing.assert_array_equal(
        clvis.radix_sort(np.array([3, 1], np.uint64), key_bits=np.int64(64)), [1, 3]
    )
    with pytest.raises(TypeError, match="keys: expected an array, got str"):
        clvis.radix_sort("abc")
    with pytest.raises(TypeError, match="keys: expected numbers"):
        clvis.radix_sort(np.array([1, None], object))
    with pytest.raises(TypeError, match="keys: dtype bool"):
        clvis.radix_sort(np.zeros(3, bool))
    with pytest.raises(ValueError, match=r"keys: expected a 1-D array, got shape \(\)"):
        clvis.radix_sort(np.uint32(5))
    with pytest.raises(TypeError, match="values: dtype float64"):
        clvis.radix_sort(np.zeros(4, np.uint32), np.zeros(4))
    with pytest.raises(TypeError, match="queue: expected a pyopencl.CommandQueue"):
        clvis.radix_sort(np.zeros(4, np.uint32), queue="cpu")
