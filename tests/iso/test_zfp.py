"""ZFP fixed-rate 3-D float decoding (clvis.zfp, kernels_cl/iso/zfp.cl,
kernels_cl/include/clvis/zfp.h): the OpenCL decode equals zfpy's own
decompression bit for bit for every integer rate 1..32 on every device and
both tuning profiles; the NumPy reference (clvis.reference.iso.zfp) equals zfpy
too; bad streams and arguments raise clear errors."""

import functools
import re
import zlib

import numpy as np
import pyopencl.array as cla
import pytest
import zfpy
from hypothesis import given
from hypothesis import strategies as st

import clvis
from clvis import runtime, zfp
from clvis.reference.iso import zfp as ref

F32 = np.float32
RATES = range(1, 33)
SHAPES = [(4, 4, 4), (1, 1, 1), (5, 6, 7), (9, 17, 33), (64, 64, 64)]
SMALL = [(4, 4, 4), (1, 1, 1), (5, 6, 7), (2, 9, 3)]


def _volume(kind: str, shape) -> np.ndarray:
    """A float32 test volume of `kind`."""
    rng = np.random.default_rng(zlib.crc32(f"{kind} {tuple(shape)}".encode()))
    z, y, x = np.meshgrid(*[np.arange(n, dtype=np.float64) for n in shape], indexing="ij")
    if kind == "random":
        v = rng.standard_normal(shape)
    elif kind == "smooth":
        v = np.sin(0.31 * x) + np.cos(0.17 * y + 0.4) * np.sin(0.23 * z) + 0.5 * np.sin(0.05 * (x + y + z))
    elif kind == "real":  # the explosion, cropped: exact zeros and a sparse support
        full = clvis.datasets.explosion((40, 44, 36))["volume"]
        reps = [-(-s // f) for s, f in zip(shape, full.shape, strict=True)]
        v = np.tile(full, reps)[: shape[0], : shape[1], : shape[2]]
    elif kind == "constant":
        v = np.full(shape, 3.25)
    elif kind == "zeros":
        v = np.zeros(shape)
    elif kind == "huge":  # up to float32's largest: decoded values may overflow to inf
        v = rng.uniform(-1, 1, shape) * np.where(rng.random(shape) < 0.5, 1e30, 3.4e38)
    elif kind == "tiny":
        v = rng.standard_normal(shape) * 1e-30
    elif kind == "denormal":  # subnormal floats: the product's rounding to subnormals
        v = rng.standard_normal(shape) * 1e-40
    elif kind == "underflow":  # block maxima 2^-119..2^-96: products that round to subnormals
        blocks = rng.uniform(-119, -96, [-(-n // 4) for n in shape])
        scale = np.kron(blocks, np.ones((4, 4, 4)))[: shape[0], : shape[1], : shape[2]]
        v = np.sign(rng.standard_normal(shape)) * 2.0 ** (scale - rng.uniform(0, 30, shape))
    elif kind == "negative":
        v = -np.abs(rng.standard_normal(shape)) * 100 - 5
    elif kind == "magnitudes":  # every exponent, both signs
        v = np.sign(rng.standard_normal(shape)) * 10.0 ** rng.uniform(-45, 38, shape)
    else:
        raise AssertionError(kind)
    return np.asarray(v, F32)


KINDS = [
    "random",
    "smooth",
    "real",
    "constant",
    "zeros",
    "huge",
    "tiny",
    "denormal",
    "underflow",
    "negative",
    "magnitudes",
]


def zfpy_decompress(stream: bytes, shape, rate: int) -> np.ndarray:
    """zfpy's own decompression of a headerless fixed-rate stream."""
    return zfpy._decompress(stream, zfpy.type_float, list(shape), rate=float(rate))


@functools.cache
def _case(kind, shape, rate):
    """(ZfpVolume, zfpy's decompression), shared by every device and profile."""
    zv = zfp.compress(_volume(kind, shape), rate)
    return zv, zfpy_decompress(zv.stream, shape, rate)


def assert_bits_equal(got, want, msg=""):
    assert got.dtype == np.float32 and got.shape == want.shape, msg
    bad = got.view(np.uint32) != want.view(np.uint32)
    if bad.any():
        i = tuple(int(k) for k in np.argwhere(bad)[0])
        raise AssertionError(
            f"{msg}: {int(bad.sum())} values differ; first at {i}: {got[i]!r} != {want[i]!r}"
        )


# --------------------------------------------------------------------------
# the format, zfpy and the reference


def test_headerless_stream_is_the_payload_of_the_header_stream():
    """write_header=False drops zfp's 96-bit header and nothing else, and
    zfpy's headerless decompression equals its decompression with header."""
    for shape, rate in [((5, 6, 7), 8), ((9, 17, 33), 1), ((4, 4, 4), 32), ((1, 1, 1), 3)]:
        v = _volume("random", shape)
        bare = zfpy.compress_numpy(v, rate=rate, write_header=False)
        full = zfpy.compress_numpy(v, rate=rate)
        assert len(bare) == zfp.expected_nbytes(shape, rate)
        assert int.from_bytes(full, "little") >> 96 == int.from_bytes(bare, "little")
        assert len(full) == -(-(96 + 8 * len(bare)) // 64) * 8
        assert_bits_equal(zfpy_decompress(bare, shape, rate), zfpy.decompress_numpy(full), str(shape))


def test_stream_length_is_rate_words_per_block():
    for shape in SHAPES:
        for rate in (1, 7, 32):
            zv, _ = _case("smooth", shape, rate)
            nb = np.prod([-(-s // 4) for s in shape])
            assert zv.nbytes == len(zv.stream) == nb * rate * 8 == ref.expected_nbytes(shape, rate)
            assert zv.blocks == ref.grid(shape) and zv.nblocks == nb


def test_perm_table_of_the_header_is_the_reference_table():
    src = (runtime.INCLUDE_DIR / "clvis" / "zfp.h").read_text()
    body = src.split("clvis_zfp_perm3[64] = {")[1].split("}")[0]
    table = [int(t) for t in re.findall(r"\d+", body)]
    assert table == list(ref.PERM_3)
    assert sorted(table) == list(range(64))
    # (x, y, z) by x + y + z, then x^2 + y^2 + z^2
    keys = [(sum(c), sum(k * k for k in c)) for c in ((i & 3, i >> 2 & 3, i >> 4) for i in table)]
    assert keys == sorted(keys)


@pytest.mark.parametrize("kind", KINDS)
def test_reference_matches_zfpy(kind):
    for shape in SMALL:
        for rate in RATES:
            zv, want = _case(kind, shape, rate)
            assert_bits_equal(ref.decode(zv.stream, shape, rate), want, f"{kind} {shape} rate {rate}")


# --------------------------------------------------------------------------
# the OpenCL decoder

_DEQUANTIZE_PROBE = """
#include "clvis/zfp.h"
kernel void probe(global const int *i, global const int *emax, uint n, global float *out)
{
    uint k = get_global_id(0);
    if (k < n)
        out[k] = clvis_zfp_dequantize(i[k], emax[k]);
}
"""


def test_dequantize_every_exponent(queue, tmp_path):
    """zfp.h's int -> float step against float32(i) * float32(2^(emax - 30))
    for every emax an 8-bit field gives: normal, subnormal (ties included),
    underflow to +-0 and overflow to inf."""
    edge = [0, 1, -1, 2, 3, 5, 7, 0x7FFFFFFF, -0x7FFFFFFF - 1, 0x1000001, 0x1000003, -0x1000001, 0x2000006]
    edge += [s * (1 << k) + d for k in range(31) for d in (-1, 0, 1) for s in (1, -1)]
    rng = np.random.default_rng(4)
    vals = np.concatenate(
        [
            np.array(edge, np.int64),
            rng.integers(-(2**31), 2**31, 600),
            (rng.standard_normal(300) * 2.0 ** rng.uniform(0, 31, 300)).astype(np.int64),
        ]
    )
    vals = np.clip(vals, -(2**31), 2**31 - 1).astype(np.int32)
    emaxes = np.arange(-127, 129, dtype=np.int32)
    i, e = (a.ravel() for a in np.meshgrid(vals, emaxes))
    path = tmp_path / "probe.cl"
    path.write_text(_DEQUANTIZE_PROBE)
    k = runtime.get_program(queue.context, str(path), {}).probe
    i_d, e_d = cla.to_device(queue, i), cla.to_device(queue, e)
    out = cla.empty(queue, i.size, F32)
    wg = 64
    runtime.launch(queue, k, -(-i.size // wg) * wg, wg, i_d.data, e_d.data, np.uint32(i.size), out.data)
    want = np.concatenate([ref.dequantize(i[e == m], int(m)) for m in emaxes])
    assert_bits_equal(out.get(), want)
    assert np.isinf(want).any() and (want == 0).any()
    sub = (want != 0) & (np.abs(want) < np.finfo(F32).tiny)
    assert sub.sum() > 1000
    # numpy's float32 ldexp rounds 2^-150 (a tie) to 0 and keeps 2^-149, as ldexpf does
    assert ref.dequantize(np.array([1], np.int32), -120)[0] == 0
    assert ref.dequantize(np.array([1], np.int32), -119)[0] == np.float32(2.0**-149)


@pytest.mark.parametrize("kind", KINDS)
def test_decode_matches_zfpy(queue, kind):
    for shape in SHAPES:
        for rate in RATES:
            zv, want = _case(kind, shape, rate)
            assert_bits_equal(zfp.decode(zv, queue=queue), want, f"{kind} {shape} rate {rate}")


def test_decode_real_volume_every_rate(queue):
    v = clvis.datasets.explosion((40, 44, 36))["volume"]
    assert (v == 0).mean() > 0.5
    for rate in RATES:
        zv = zfp.compress(v, rate)
        assert_bits_equal(
            zfp.decode(zv.stream, v.shape, rate, queue=queue),
            zfpy_decompress(zv.stream, v.shape, rate),
            f"rate {rate}",
        )


def test_decode_blocks_are_the_blocks_of_the_volume(queue):
    shape = (9, 17, 33)
    for rate in (1, 5, 16, 32):
        zv, full = _case("magnitudes", shape, rate)
        rng = np.random.default_rng(rate)
        ids = rng.integers(0, zv.nblocks, 40)
        ids[:3] = [0, zv.nblocks - 1, 0]  # repeats and the last (partial) block
        bricks = zfp.decode_blocks(zv, ids, queue=queue)
        assert isinstance(bricks, cla.Array) and bricks.shape == (40, 64) and bricks.dtype == F32
        bricks = bricks.get()
        # whole bricks, padding included, as the reference decodes them
        assert_bits_equal(bricks, ref.decode_blocks(zv.stream, ids, shape, rate), f"rate {rate}")
        # the in-range part as the full decode
        for j, b in enumerate(ids):
            z, y, x = zv.block_origin(int(b))
            part = full[z : z + 4, y : y + 4, x : x + 4]
            brick = bricks[j].reshape(4, 4, 4)[: part.shape[0], : part.shape[1], : part.shape[2]]
            assert_bits_equal(np.ascontiguousarray(brick), part, f"block {b}")


def test_decode_blocks_device_ids_and_out_of_range(queue):
    zv, _ = _case("random", (5, 6, 7), 8)
    ids = cla.to_device(queue, np.array([7, 8, 0, 0xFFFFFFFF, 3], np.uint32))
    got = zfp.decode_blocks(zv, ids, queue=queue, host=True)
    want = ref.decode_blocks(zv.stream, [7, 0, 3], zv.shape, 8)
    assert_bits_equal(got[[0, 2, 4]], want)
    assert np.isnan(got[[1, 3]]).all()  # ids >= nblocks: NaN bricks, nothing read
    empty = zfp.decode_blocks(zv, np.zeros(0, np.int64), queue=queue, host=True)
    assert empty.shape == (0, 64)


def test_each_block_reads_only_its_own_words(queue):
    """Decoding block b depends on its `rate` words alone: the words of every
    other block replaced by random bits give the same brick."""
    zv, _ = _case("smooth", (9, 17, 33), 4)
    words = np.frombuffer(zv.stream, np.uint64).reshape(zv.nblocks, 4)
    noise = np.random.default_rng(3).integers(0, 2**64, words.shape, dtype=np.uint64)
    for b in (0, 17, zv.nblocks - 1):
        mixed = noise.copy()
        mixed[b] = words[b]
        got = zfp.decode_blocks(mixed.tobytes(), [b], zv.shape, 4, queue=queue, host=True)
        assert_bits_equal(got, zfp.decode_blocks(zv, [b], queue=queue, host=True), f"block {b}")


def test_device_inputs_and_outputs(queue):
    zv, want = _case("smooth", (9, 17, 33), 6)
    out = zfp.decode(zv, queue=queue, host=False)
    assert isinstance(out, cla.Array) and out.shape == zv.shape and out.dtype == F32
    assert out.queue is queue
    assert_bits_equal(out.get(), want)
    words = zv.to_device(queue)
    assert words.dtype == np.uint64 and words.nbytes == zv.nbytes
    assert_bits_equal(zfp.decode(words, zv.shape, zv.rate, host=True), want, "uint64 words")
    as_bytes = cla.to_device(queue, np.frombuffer(zv.stream, np.uint8))
    assert_bits_equal(zfp.decode(as_bytes, zv.shape, zv.rate), want, "uint8 bytes")
    # a view with an offset (copied to a whole buffer)
    padded = cla.to_device(
        queue, np.concatenate([np.zeros(3, np.uint64), np.frombuffer(zv.stream, np.uint64)])
    )
    assert_bits_equal(zfp.decode(padded[3:], zv.shape, zv.rate), want, "offset view")
    assert_bits_equal(zfp.decode(np.frombuffer(zv.stream, np.uint8), zv.shape, zv.rate, queue=queue), want)
    assert_bits_equal(zv.decode(queue=queue), want, "ZfpVolume.decode")


def test_corrupt_stream_decodes_like_zfp_without_error(queue):
    """Flipped bits of a stream of the right length: no error, no NaN, and the
    same values as zfpy and the reference decode from the same bits."""
    rng = np.random.default_rng(11)
    for rate in (1, 3, 8, 32):
        zv, _ = _case("smooth", (5, 6, 7), rate)
        raw = np.frombuffer(zv.stream, np.uint8).copy()
        flips = rng.integers(0, raw.size * 8, 1 + raw.size // 4)
        np.bitwise_xor.at(raw, flips // 8, (1 << (flips % 8)).astype(np.uint8))
        for bad in (raw.tobytes(), b"\xff" * zv.nbytes, rng.integers(0, 256, zv.nbytes, np.uint8).tobytes()):
            got = zfp.decode(bad, zv.shape, rate, queue=queue)
            assert not np.isnan(got).any()
            assert_bits_equal(got, zfpy_decompress(bad, zv.shape, rate), f"rate {rate}")
            assert_bits_equal(got, ref.decode(bad, zv.shape, rate), f"rate {rate} (reference)")


@given(
    shape=st.tuples(st.integers(1, 20), st.integers(1, 20), st.integers(1, 20)),
    rate=st.integers(1, 32),
    kind=st.sampled_from(KINDS),
    seed=st.integers(0, 2**31),
    profile=st.sampled_from(["cpu", "gpu"]),
)
def test_property(device, shape, rate, kind, seed, profile):
    v = _volume(kind, shape)
    if kind in ("random", "magnitudes"):
        v = v * F32(np.random.default_rng(seed).uniform(0.5, 2.0))
    zv = zfp.compress(v, rate)
    with runtime.configure(tuning=profile):
        q = runtime.queue_for(device)
        assert_bits_equal(zfp.decode(zv, queue=q), zfpy_decompress(zv.stream, shape, rate), f"{shape} {rate}")
        b = int(np.random.default_rng(seed).integers(0, zv.nblocks))
        brick = zfp.decode_blocks(zv, [b], queue=q, host=True)
        assert_bits_equal(brick, ref.decode_blocks(zv.stream, [b], shape, rate))


# --------------------------------------------------------------------------
# compress and ZfpVolume


def test_compress_converts_to_float32():
    rng = np.random.default_rng(2)
    for dtype in (np.uint8, np.uint16, np.int16, np.int32, np.int64, np.float64, np.float16):
        v = (rng.random((6, 7, 9)) * 200).astype(dtype)
        zv = zfp.compress(v, 9)
        assert zv.stream == zfpy.compress_numpy(v.astype(F32), rate=9, write_header=False), dtype
    v = _volume("smooth", (8, 12, 10))
    assert zfp.compress(v.transpose(2, 1, 0), 4).stream == zfpy.compress_numpy(
        np.ascontiguousarray(v.transpose(2, 1, 0)), rate=4, write_header=False
    )
    assert zfp.compress(v, 5.0).rate == 5


def test_zfp_volume():
    zv, _ = _case("smooth", (9, 17, 33), 4)
    assert zv.shape == (9, 17, 33) and zv.rate == 4 and zv.blocks == (3, 5, 9) and zv.nblocks == 135
    assert zv.nbytes == 135 * 32 and zv.compression_ratio == pytest.approx(4 * 9 * 17 * 33 / (135 * 32))
    for b in (0, 1, 9, 44, 134):
        assert zv.block_id(*(o // 4 for o in zv.block_origin(b))) == b
    assert zv.block_origin(10) == (0, 4, 4)
    assert "rate=4" in repr(zv) and "nbytes=4320" in repr(zv)
    assert zfp.ZfpVolume(bytearray(zv.stream), [9, 17, 33], 4) == zv
    with pytest.raises(ValueError, match="outside"):
        zv.block_origin(135)
    with pytest.raises(ValueError, match="outside"):
        zv.block_id(3, 0, 0)


def test_empty_volume(queue):
    zv = zfp.compress(np.zeros((0, 5, 3), F32), 8)
    assert zv.stream == b"" and zv.nblocks == 0
    out = zfp.decode(zv, queue=queue)
    assert out.shape == (0, 5, 3) and out.dtype == F32
    assert zfp.decode_blocks(zv, [], queue=queue, host=True).shape == (0, 64)


# --------------------------------------------------------------------------
# bad input


def test_short_and_long_streams_raise_data_error():
    zv, _ = _case("random", (5, 6, 7), 8)
    for bad, what in [
        (zv.stream[:-8], "8 bytes short"),
        (zv.stream[:-1], "1 bytes short"),
        (b"", "512 bytes short"),
        (zv.stream + bytes(8), "8 bytes too many"),
    ]:
        with pytest.raises(clvis.DataError, match=f"{len(bad)} bytes.*exactly 512 bytes.*{what}"):
            zfp.decode(bad, (5, 6, 7), 8)
        with pytest.raises(clvis.DataError, match="exactly 512"):
            zfp.decode_blocks(bad, [0], (5, 6, 7), 8)
        with pytest.raises(clvis.DataError, match="exactly 512"):
            zfp.ZfpVolume(bad, (5, 6, 7), 8)
    with_header = zfpy.compress_numpy(_volume("random", (5, 6, 7)), rate=8)
    with pytest.raises(clvis.DataError, match="zfp header"):
        zfp.decode(with_header, (5, 6, 7), 8)


def test_wrong_shape_or_rate_raise_data_error(queue):
    zv, _ = _case("random", (5, 6, 7), 8)
    with pytest.raises(clvis.DataError, match="shape \\(9, 6, 7\\) at rate 8"):
        zfp.decode(zv.stream, (9, 6, 7), 8, queue=queue)
    with pytest.raises(clvis.DataError, match="at rate 4"):
        zfp.decode(zv.stream, (5, 6, 7), 4, queue=queue)
    with pytest.raises(clvis.DataError):
        zfp.decode(cla.to_device(queue, np.frombuffer(zv.stream, np.uint8)[:-8]), (5, 6, 7), 8)
    with pytest.raises(ValueError, match="differs from the ZfpVolume"):
        zfp.decode(zv, (5, 6, 8))
    with pytest.raises(ValueError, match="differs from the ZfpVolume"):
        zfp.decode(zv, rate=9)
    with pytest.raises(TypeError, match="shape and rate"):
        zfp.decode(zv.stream)


@pytest.mark.parametrize(
    "rate, err",
    [
        (8.5, ValueError),
        (0, ValueError),
        (33, ValueError),
        (-1, ValueError),
        (float("nan"), ValueError),
        (True, TypeError),
        ("8", TypeError),
    ],
)
def test_bad_rates(rate, err):
    v = _volume("random", (4, 4, 4))
    with pytest.raises(err, match="rate"):
        zfp.compress(v, rate)
    with pytest.raises(err, match="rate"):
        zfp.decode(bytes(64), (4, 4, 4), rate)


@pytest.mark.parametrize(
    "shape, err",
    [
        ((4, 4), ValueError),
        ((4, 4, 4, 4), ValueError),
        ((4, -1, 4), ValueError),
        ((4, 4.0, 4), TypeError),
        (None, TypeError),
        ((1 << 31, 1, 1), ValueError),
    ],
)
def test_bad_shapes(shape, err):
    with pytest.raises(err, match="shape"):
        zfp.decode(bytes(64), shape, 8)


def test_compress_rejects_non_finite_and_bad_volumes():
    v = _volume("random", (5, 6, 7))
    v[2, 3, 4] = np.nan
    v[4, 0, 1] = np.inf
    with pytest.raises(clvis.DataError, match=r"2 non-finite values.*\(2, 3, 4\)"):
        zfp.compress(v, 8)
    big = np.ones((4, 4, 4))
    big[1, 2, 3] = 1e39
    with pytest.raises(clvis.DataError, match=r"after conversion to float32.*\(1, 2, 3\)"):
        zfp.compress(big, 8)
    with pytest.raises(ValueError, match="3-D"):
        zfp.compress(np.zeros((4, 4), F32), 8)
    with pytest.raises(TypeError, match="dtype"):
        zfp.compress(np.zeros((4, 4, 4), np.complex64), 8)
    with pytest.raises(TypeError, match="dtype"):
        zfp.compress(np.zeros((4, 4, 4), bool), 8)
    with pytest.raises(TypeError, match="volume"):
        zfp.compress(None, 8)


def test_decode_blocks_bad_ids():
    zv, _ = _case("random", (5, 6, 7), 8)
    with pytest.raises(clvis.DataError, match=r"ids\[2\] = 8 is not a block.*8 blocks"):
        zfp.decode_blocks(zv, [0, 7, 8])
    with pytest.raises(clvis.DataError, match=r"ids\[0\] = -1"):
        zfp.decode_blocks(zv, [-1])
    with pytest.raises(TypeError, match="ids"):
        zfp.decode_blocks(zv, [[0, 1]])
    with pytest.raises(TypeError, match="ids"):
        zfp.decode_blocks(zv, [0.5])
