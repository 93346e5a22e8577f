"""The stages of gauss/march.cl's march kernel, one probe kernel each (built
from an inline source that includes clvis/gauss.h, as march.cl does), against
clvis.reference.gauss.render: the ray-Gaussian hit test (bit for bit: the
reference repeats the float32 operations), the transfer-function entry, the
hit alpha of both models, a Gaussian's own colour, and the front-to-back compositing (render_rays does
those two in float64: compared to float32 rounding)."""

import math
import warnings

import numpy as np
import pyopencl as cl
import pyopencl.array as cla
import pytest

from clvis import runtime
from clvis.gauss.gaussians import GAUSSIAN_DTYPE
from clvis.reference.gauss import gaussians as ref_g
from clvis.reference.gauss import render as ref

PROBES = """
#pragma OPENCL FP_CONTRACT OFF
#include "clvis/gauss.h"

/* ray i against Gaussian i */
kernel void hit(global const clvis_gaussian *recs, global const float *o, global const float *d,
                global float *out)
{
    uint i = get_global_id(0);
    float oo[3] = {o[3 * i], o[3 * i + 1], o[3 * i + 2]};
    float dd[3] = {d[3 * i], d[3 * i + 1], d[3 * i + 2]};
    float t, m2, ts, a, op[3], dp[3];
    clvis_gauss_hit(recs + i, oo, dd, &t, &m2, &ts, &a, op, dp);
    out[5 * i] = t;
    out[5 * i + 1] = m2;
    out[5 * i + 2] = ts;
    out[5 * i + 3] = a;
    out[5 * i + 4] = clvis_gauss_alpha_absorption(recs[i].opacity, 1.5f, ts, a, op, dp);
}

kernel void tf_index(global const float *values, float tf_min, float tf_scale, uint tf_n,
                     global uint *out)
{
    uint i = get_global_id(0);
    out[i] = clvis_gauss_tf_index(values[i], tf_min, tf_scale, tf_n);
}

kernel void alpha_max_response(global const float *opac, global const float *m2, global float *out)
{
    uint i = get_global_id(0);
    out[i] = clvis_gauss_alpha_max_response(opac[i], m2[i]);
}

kernel void rgb8(global const uchar4 *c, global float4 *out)
{
    uint i = get_global_id(0);
    out[i] = clvis_gauss_rgb8(c[i]);
}

/* ray i composites hits [i * m, (i + 1) * m) front to back */
kernel void composite(global const float *alpha, global const float4 *colour, uint m,
                      global float4 *out)
{
    uint i = get_global_id(0);
    float T = 1.0f, cr = 0.0f, cg = 0.0f, cb = 0.0f;
    for (uint h = i * m; h < (i + 1) * m; ++h)
        clvis_gauss_composite(alpha[h], colour[h], &T, &cr, &cg, &cb);
    out[i] = (float4)(cr, cg, cb, 1.0f - T);
}
"""


@pytest.fixture
def probes(device):
    q = runtime.queue_for(device)
    with warnings.catch_warnings():  # drivers may log remarks on success
        warnings.simplefilter("ignore", cl.CompilerWarning)
        prg = cl.Program(q.context, PROBES).build(
            ["-I", str(runtime.INCLUDE_DIR), "-cl-fp32-correctly-rounded-divide-sqrt"]
        )
    return q, prg


def _dev(q, a, dtype=np.float32):
    return cla.to_device(q, np.ascontiguousarray(a, dtype))


def _scene(n, seed):
    """n Gaussians and one ray per Gaussian, aimed near it (float32)."""
    rng = np.random.default_rng(seed)
    means = rng.uniform(-1, 1, (n, 3))
    scales = rng.uniform(0.05, 0.5, (n, 3))
    scales[:20, 0] = 1e-9  # flat ones
    a = rng.normal(size=(n, 3, 3))
    rotations = np.linalg.qr(a)[0]
    values, opacities = rng.random(n), rng.uniform(0.05, 1.0, n)
    mean, value, w, opac = ref_g.gaussian_records(means, scales, rotations, values, opacities)
    recs = np.zeros(n, GAUSSIAN_DTYPE)
    recs["mean"], recs["value"], recs["w"], recs["opacity"] = mean, value, w, opac
    o = rng.uniform(-4, 4, (n, 3)).astype(np.float32)
    target = mean + rng.normal(size=(n, 3)).astype(np.float32) * 0.3
    d = target - o
    d[:10] = -d[:10]  # Gaussian behind the origin: t = 0
    d = (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)
    return recs, mean, w, opac, o, d


def test_hit_is_the_reference_bit_for_bit(probes):
    q, prg = probes
    n = 3000
    recs, mean, w, opac, o, d = _scene(n, seed=1)
    out = cla.empty(q, 5 * n, np.float32)
    prg.hit(q, (n,), None, _dev(q, recs, GAUSSIAN_DTYPE).data, _dev(q, o).data, _dev(q, d).data, out.data)
    got = out.get().reshape(n, 5)
    idx = np.arange(n)
    t, m2, ts, a, ms2 = (x[idx, idx] for x in ref.hits(o, d, mean, w))  # ray i against Gaussian i
    for k, want in enumerate((t, m2, ts, a)):
        np.testing.assert_array_equal(got[:, k].view(np.uint32), want.astype(np.float32).view(np.uint32))
    assert (got[:, 0] >= 0).all() and (got[:10, 0] == 0).all()
    hit = m2 <= np.float32(9.0)
    assert 200 < hit.sum() < n - 200

    # absorption alpha, density 1.5: render_rays's float64 formula on the same t, ts, a, ms2
    aa = a.astype(np.float64)
    arg = -ts.astype(np.float64) * np.sqrt(0.5 * aa)
    integral = (
        np.exp(-0.5 * ms2.astype(np.float64))
        * np.sqrt(np.pi / (2 * aa))
        * np.array([math.erfc(x) for x in arg])
    )
    want = 1 - np.exp(-1.5 * opac.astype(np.float64) * integral)
    np.testing.assert_allclose(got[hit, 4], want[hit], rtol=2e-5, atol=1e-6)


def test_tf_index(probes):
    q, prg = probes
    rng = np.random.default_rng(2)
    values = np.concatenate([rng.uniform(-0.5, 1.5, 5000), [0.0, 1.0, 0.25, -1e30, 1e30]]).astype(np.float32)
    kernel = cl.Kernel(prg, "tf_index")
    for tf_n, vmin, scale in ((256, 0.0, 1.0), (7, -0.25, 2.0), (1, 0.0, 1.0)):
        out = cla.empty(q, len(values), np.uint32)
        kernel(
            q,
            (len(values),),
            None,
            _dev(q, values).data,
            np.float32(vmin),
            np.float32(scale),
            np.uint32(tf_n),
            out.data,
        )
        table = np.arange(tf_n, dtype=np.float32)[:, None].repeat(4, axis=1)
        want = ref.tf_lookup(values, table, vmin, scale)[:, 0].astype(np.uint32)
        np.testing.assert_array_equal(out.get(), want)


def test_alpha_max_response(probes):
    q, prg = probes
    rng = np.random.default_rng(3)
    m = 5000
    opac = rng.uniform(0, 1, m).astype(np.float32)
    opac[:5] = 1.0
    m2 = rng.uniform(0, 9, m).astype(np.float32)
    m2[:5] = 0.0  # capped at 0.99
    out = cla.empty(q, m, np.float32)
    prg.alpha_max_response(q, (m,), None, _dev(q, opac).data, _dev(q, m2).data, out.data)
    want = np.minimum(0.99, opac.astype(np.float64) * np.exp(-0.5 * m2.astype(np.float64)))
    got = out.get()
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-7)
    assert (got[:5] == np.float32(0.99)).all() and (got <= np.float32(0.99)).all()


def test_composite(probes):
    q, prg = probes
    rng = np.random.default_rng(4)
    rays, m = 1000, 40
    alpha = rng.uniform(0, 0.99, (rays, m)).astype(np.float32)
    alpha[:, m // 2 :] *= rng.random((rays, 1)).astype(np.float32)
    colour = rng.random((rays, m, 4)).astype(np.float32)
    out = cla.empty(q, 4 * rays, np.float32)
    prg.composite(
        q,
        (rays,),
        None,
        _dev(q, alpha.ravel()).data,
        _dev(q, colour.reshape(-1, 4)).data,
        np.uint32(m),
        out.data,
    )
    got = out.get().reshape(rays, 4)
    # render_rays's compositing (float64): weights T_before * alpha, alpha = 1 - T_after
    a64 = alpha.astype(np.float64)
    after = np.cumprod(1 - a64, axis=1)
    before = np.concatenate([np.ones((rays, 1)), after[:, :-1]], axis=1)
    rgb = ((before * a64)[:, :, None] * colour[:, :, :3].astype(np.float64)).sum(axis=1)
    np.testing.assert_allclose(got[:, :3], rgb, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(got[:, 3], 1 - after[:, -1], rtol=1e-5, atol=1e-6)


def test_rgb8_is_the_reference_bit_for_bit(probes):
    q, prg = probes
    c = np.stack(np.meshgrid(np.arange(256), np.arange(4), indexing="ij"), -1).reshape(-1, 2)
    rgba8 = np.stack([c[:, 0], 255 - c[:, 0], (7 * c[:, 0]) % 256, c[:, 1]], axis=1).astype(np.uint8)
    out = cla.empty(q, 4 * len(rgba8), np.float32)
    prg.rgb8(q, (len(rgba8),), None, _dev(q, rgba8, np.uint8).data, out.data)
    got = out.get().reshape(-1, 4)
    np.testing.assert_array_equal(got[:, :3], ref.rgb8(rgba8))
    assert got[:, :3].min() == 0 and got[:, :3].max() == 1
