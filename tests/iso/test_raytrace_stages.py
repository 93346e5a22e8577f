"""The stages of iso/raytrace.cl's raytrace_blocks, one probe kernel each
(built from an inline source that includes clvis/iso.h, as the kernel does),
against the functions of the NumPy reference clvis.reference.iso: the cell
cubic, the first zero of a cubic, the trilinear gradient and the shading.
The kernel works in float32 and the reference in float64, so the values are
compared to float32 rounding."""

import warnings

import numpy as np
import pyopencl as cl
import pyopencl.array as cla
import pytest

from clvis import runtime
from clvis.reference import iso as ref

PROBES = """
#pragma OPENCL FP_CONTRACT OFF
#include "clvis/iso.h"

kernel void cell_cubic(global const float *v, global const float *u, global const float *D,
                       global float *cf)
{
    uint i = get_global_id(0);
    float vv[8], uu[3], dd[3], c[4];
    for (int k = 0; k < 8; ++k)
        vv[k] = v[8 * i + k];
    for (int a = 0; a < 3; ++a) {
        uu[a] = u[3 * i + a];
        dd[a] = D[3 * i + a];
    }
    clvis_iso_cell_cubic(vv, uu, dd, c);
    for (int k = 0; k < 4; ++k)
        cf[4 * i + k] = c[k];
}

kernel void first_zero(global const float *cf, global const float *len, int steps,
                       global int *found, global float *s)
{
    uint i = get_global_id(0);
    float c[4] = {cf[4 * i], cf[4 * i + 1], cf[4 * i + 2], cf[4 * i + 3]};
    float si = NAN;
    found[i] = clvis_iso_first_zero(c, len[i], steps, &si);
    s[i] = si;
}

kernel void gradient(global const float *v, global const float *w, global float *g)
{
    uint i = get_global_id(0);
    float vv[8], ww[3] = {w[3 * i], w[3 * i + 1], w[3 * i + 2]}, gg[3];
    for (int k = 0; k < 8; ++k)
        vv[k] = v[8 * i + k];
    clvis_iso_trilinear_gradient(vv, ww, gg);
    for (int a = 0; a < 3; ++a)
        g[3 * i + a] = gg[a];
}

kernel void shade(global const float *g, global const float *d, global float4 *rgba)
{
    uint i = get_global_id(0);
    float gg[3] = {g[3 * i], g[3 * i + 1], g[3 * i + 2]};
    float dd[3] = {d[3 * i], d[3 * i + 1], d[3 * i + 2]};
    rgba[i] = clvis_iso_shade(gg, dd);
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


def _dev(q, a):
    return cla.to_device(q, np.ascontiguousarray(a, np.float32))


def _cell_cubic(q, prg, v, u, D):
    cf = cla.empty(q, 4 * len(v), np.float32)
    prg.cell_cubic(q, (len(v),), None, _dev(q, v).data, _dev(q, u).data, _dev(q, D).data, cf.data)
    return cf.get().reshape(-1, 4)


def _cells(m, seed):
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(m, 8)).astype(np.float32)
    u = rng.random((m, 3)).astype(np.float32)
    D = (rng.normal(size=(m, 3)) * rng.uniform(0.2, 2.0, (m, 1))).astype(np.float32)
    return v, u, D


def _corners(v):
    """v[x + 2 y + 4 z] -> the reference's corners [z, y, x]."""
    return np.asarray(v, np.float64).reshape(-1, 2, 2, 2)


def test_cell_cubic(probes):
    q, prg = probes
    v, u, D = _cells(4000, seed=1)
    got = _cell_cubic(q, prg, v, u, D)
    want = np.stack(ref.cell_cubic(_corners(v), u, D), axis=1)
    scale = np.abs(v).sum(axis=1, keepdims=True) * (1 + np.abs(D).max(axis=1, keepdims=True)) ** 3
    assert (np.abs(got - want) <= 1e-6 * scale).all()


def test_cell_cubic_is_the_interpolant(probes):
    """f(s) of the coefficients equals the trilinear interpolant at u + s D."""
    q, prg = probes
    v, u, D = _cells(500, seed=2)
    u = (u * 0.5).astype(np.float32)
    D = (D / np.abs(D).max(axis=1, keepdims=True) * 0.4).astype(np.float32)  # u + s D stays in the cell
    cf = _cell_cubic(q, prg, v, u, D).astype(np.float64)
    c = _corners(v)
    for s in (0.0, 0.5, 1.0):
        x = u + s * D.astype(np.float64)
        w = [np.stack([1 - x[:, a], x[:, a]], axis=1) for a in range(3)]
        tri = np.einsum("mzyx,mz,my,mx->m", c, w[2], w[1], w[0])
        f = ((cf[:, 3] * s + cf[:, 2]) * s + cf[:, 1]) * s + cf[:, 0]
        np.testing.assert_allclose(f, tri, atol=2e-5 * np.abs(v).sum(axis=1).max())


@pytest.mark.parametrize("steps", [0, 3, 8])
def test_first_zero(probes, steps):
    q, prg = probes
    v, u, D = _cells(4000, seed=3)
    cf = _cell_cubic(q, prg, v, u, D)
    rng = np.random.default_rng(4)
    length = rng.uniform(0.1, 2.0, len(cf)).astype(np.float32)
    found = cla.empty(q, len(cf), np.int32)
    s = cla.empty(q, len(cf), np.float32)
    prg.first_zero(
        q, (len(cf),), None, _dev(q, cf).data, _dev(q, length).data, np.int32(steps), found.data, s.data
    )
    found, s = found.get().astype(bool), s.get()
    c64 = tuple(cf[:, k].astype(np.float64) for k in range(4))
    want_found, want_s, margin, _ = ref.cubic_first_zero(
        c64, length.astype(np.float64), refine=("illinois", steps)
    )
    clear = margin > 1e-3
    assert clear.sum() > 3000 and want_found[clear].sum() > 500 and (~want_found[clear]).sum() > 500
    np.testing.assert_array_equal(found[clear], want_found[clear])
    both = clear & want_found
    assert (s[both] >= 0).all() and (s[both] <= length[both]).all()
    np.testing.assert_allclose(s[both], want_s[both], atol=2e-4 * 2.0 ** (8 - steps))
    assert np.isnan(s[~found]).all()  # not written where nothing is found


def test_first_zero_edge_cases(probes):
    q, prg = probes
    cases = [  # c0..c3, length, found, s
        ((0.0, 1.0, 0.0, 0.0), 1.0, True, 0.0),  # zero at the start
        ((-1.0, 2.0, 0.0, 0.0), 1.0, True, 0.5),  # linear
        ((1.0, 0.0, 0.0, 0.0), 1.0, False, None),  # constant, no zero
        ((0.25, -1.0, 1.0, 0.0), 1.0, True, 0.5),  # double root at the minimum
        ((1.0, -1.0, 0.0, 0.0), 0.5, False, None),  # root beyond the length
    ]
    cf = np.array([c[0] for c in cases], np.float32)
    length = np.array([c[1] for c in cases], np.float32)
    found = cla.empty(q, len(cases), np.int32)
    s = cla.empty(q, len(cases), np.float32)
    prg.first_zero(
        q, (len(cases),), None, _dev(q, cf).data, _dev(q, length).data, np.int32(8), found.data, s.data
    )
    for (_, _, f, want), gf, gs in zip(cases, found.get(), s.get(), strict=True):
        assert bool(gf) == f
        if f:
            assert gs == pytest.approx(want, abs=1e-5)


def test_trilinear_gradient(probes):
    q, prg = probes
    v, w, _ = _cells(4000, seed=5)
    w[:10] = np.round(w[:10])  # corners
    g = cla.empty(q, 3 * len(v), np.float32)
    prg.gradient(q, (len(v),), None, _dev(q, v).data, _dev(q, w).data, g.data)
    want = ref.raytrace._trilinear_gradient(_corners(v), w.astype(np.float64))
    np.testing.assert_allclose(g.get().reshape(-1, 3), want, rtol=1e-5, atol=1e-5)


def test_shade(probes):
    q, prg = probes
    rng = np.random.default_rng(6)
    m = 4000
    g = (rng.normal(size=(m, 3)) * rng.uniform(1e-3, 1e3, (m, 1))).astype(np.float32)
    g[:5] = 0.0  # no gradient: lit as if facing the viewer
    d = rng.normal(size=(m, 3))
    d = (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)
    d[5:10] = g[5:10] / np.linalg.norm(g[5:10], axis=1, keepdims=True)  # head on
    rgba = cla.empty(q, 4 * m, np.float32)
    prg.shade(q, (m,), None, _dev(q, g).data, _dev(q, d).data, rgba.data)
    got = rgba.get().reshape(m, 4)
    g64, d64 = g.astype(np.float64), d.astype(np.float64)
    length = np.linalg.norm(g64, axis=1)
    normal = np.where((length > 0)[:, None], g64 / np.where(length > 0, length, 1.0)[:, None], -d64)
    want = ref.shade(normal, d64, np.ones(m, bool))
    np.testing.assert_allclose(got, want, atol=2e-6)
    assert (got[:, 3] == 1.0).all()
