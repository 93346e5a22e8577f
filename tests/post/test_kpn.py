"""clvis.post.kpn (kernels_cl/post/kpn.cl) against clvis.reference.post.kpn on
every device and tuning profile, the reference against the PyTorch module
it was written from (NarvisKPN.forward = trunk + head), the shipped card's
head, and bad input.

Tolerance: 1e-5 absolute on [0, 1] colours. The kernel computes in float32
(tanh, exp, log1p, block means over up to 16 x 16 pixels and the softmax's
sums in its own order), the reference in float64: the difference is float32
rounding (measured up to 2.3e-6, at s = 16 with depth_select), some 400
times below an 8-bit level (1/255)."""

import json

import numpy as np
import pyopencl.array as cla
import pytest

from clvis.post.infer import MODELS
from clvis.post.kpn import KPNHead, kpn_head
from clvis.reference.post.kpn import kpn_head as ref_head

SHIPPED = tuple(tuple(k) for k in json.loads((MODELS / "narvis.json").read_text())["head"]["kernels"])
KERNELS = [SHIPPED, ((5, 1), (3, 2), (3, 4)), ((1, 1),), ((3, 16),)]
SHAPES = [(16, 16), (48, 64), (32, 96)]
ATOL = 1e-5


def inputs(shape, kernels, depth_select, seed, covered=0.4, scale=3.0):
    rng = np.random.default_rng(seed)
    h, w = shape
    x = rng.random((1, 9, h, w), dtype=np.float32)
    x[0, 3] = rng.random((h, w)) < covered
    k = sum(a * a for a, _ in kernels) + 1 + int(depth_select)
    logits = rng.normal(0.0, scale, (1, k, h, w)).astype(np.float32)
    near = (rng.random((1, 1, h, w)) * x[:, 3:4]).astype(np.float32) if depth_select else None
    return x, logits, near


def check(queue, kernels, depth_select, x, logits, near):
    got = kpn_head(x, logits, near, kernels=kernels, depth_select=depth_select, queue=queue)
    want = ref_head(x, logits, near, kernels, depth_select=depth_select)
    assert isinstance(got, np.ndarray) and got.shape == want.shape and got.dtype == np.float32
    assert np.isfinite(got).all()
    np.testing.assert_allclose(got, want, atol=ATOL, rtol=0)


@pytest.mark.parametrize("depth_select", [True, False])
@pytest.mark.parametrize("kernels", KERNELS, ids=str)
@pytest.mark.parametrize("shape", SHAPES, ids=str)
def test_kernel_equals_reference(queue, kernels, depth_select, shape):
    if shape[0] % max(s for _, s in kernels) or shape[1] % max(s for _, s in kernels):
        shape = (32, 48)
    check(queue, kernels, depth_select, *inputs(shape, kernels, depth_select, seed=sum(shape)))


@pytest.mark.parametrize("covered", [0.0, 0.02, 1.0])
def test_coverage_extremes(queue, covered):
    """No covered pixel (every candidate masked: black), one in fifty (the
    coarse scales carry the pixel), all."""
    x, logits, near = inputs((32, 48), SHIPPED, True, seed=3, covered=covered)
    check(queue, SHIPPED, True, x, logits, near)
    if covered == 0.0:
        got = kpn_head(x, logits, near, kernels=SHIPPED, depth_select=True, queue=queue)
        assert not got.any()


def test_extreme_logits(queue):
    """Logits far beyond the bound (tanh saturates: no overflow in exp) and
    a gamma logit past softplus's threshold of 20 (torch's identity branch)."""
    x, logits, near = inputs((32, 32), SHIPPED, True, seed=4, scale=1e4)
    logits[0, -1] = np.where(np.arange(32) % 2, 25.0, -25.0)[None, :]
    check(queue, SHIPPED, True, x, logits, near)


def test_device_arrays_and_out(queue):
    x, logits, near = inputs((32, 48), SHIPPED, True, seed=5)
    want = ref_head(x, logits, near, SHIPPED, depth_select=True)
    dx, dl, dn = (cla.to_device(queue, a) for a in (x, logits, near))
    got = kpn_head(dx, dl, dn, kernels=SHIPPED, depth_select=True, queue=queue)
    assert isinstance(got, cla.Array)
    np.testing.assert_allclose(got.get(), want, atol=ATOL, rtol=0)
    out = cla.zeros(queue, (1, 3, 32, 48), np.float32)
    head = KPNHead(SHIPPED, depth_select=True)
    assert head(dx, dl, dn, out=out, queue=queue) is out
    np.testing.assert_allclose(out.get(), want, atol=ATOL, rtol=0)


def test_shipped_card_head():
    card = json.loads((MODELS / "narvis.json").read_text())
    head = card["head"]
    assert head == {
        "kind": "kpn",
        "kernels": [[3, 1], [3, 2], [3, 4], [3, 8]],
        "depth_select": True,
        "depth_scale": 20.0,
        "logit_bound": 6.0,
        "outputs": ["logits", "nearness"],
    }
    h = KPNHead(head["kernels"], depth_select=True)
    assert (h.candidates, h.channels, h.stride) == (36, 38, 8)


def test_torch_module_parity(queue):
    """NarvisKPN.forward = its trunk (what the graph outputs) + this head,
    on a network with random head weights (so the softmax is not the
    untrained box filter)."""
    torch = pytest.importorskip("torch", reason="the train extra (torch) is not installed")
    from clvis.post.nets import NarvisKPN

    torch.manual_seed(0)
    for depth_select in (True, False):
        net = NarvisKPN(widths=(4, 8, 8, 8, 8), kernels=SHIPPED, depth_select=depth_select).eval()
        with torch.no_grad():
            net.out.weight.normal_(0.0, 1.0)
            net.out.bias.normal_(0.0, 1.0)
        x, _, _ = inputs((48, 64), SHIPPED, depth_select, seed=6)
        x[:, 4] *= x[:, 3]
        with torch.no_grad():
            want = net(torch.from_numpy(x)).numpy()
            trunk = [t.numpy() for t in net.trunk(torch.from_numpy(x))]
        assert len(trunk) == 1 + depth_select and net.head()["depth_select"] == depth_select
        got = kpn_head(x, *trunk, kernels=SHIPPED, depth_select=depth_select, queue=queue)
        np.testing.assert_allclose(got, want, atol=2e-6, rtol=0)


def test_bad_input(device):
    x, logits, near = inputs((32, 48), SHIPPED, True, seed=7)
    kw = {"kernels": SHIPPED, "depth_select": True}
    for kernels in ([], [(2, 1)], [(3, 3)], [(3, 0)], [(3.5, 1)], "x", [(3,)], None, [(17, 1)]):
        with pytest.raises(ValueError, match="kernels"):
            KPNHead(kernels, depth_select=True)
    with pytest.raises(TypeError, match="depth_select"):
        KPNHead(SHIPPED, depth_select=1)
    with pytest.raises(ValueError, match="depth_scale"):
        KPNHead(SHIPPED, depth_select=True, depth_scale=-1.0)
    with pytest.raises(ValueError, match="logit_bound"):
        KPNHead(SHIPPED, depth_select=True, logit_bound=0.0)
    with pytest.raises(ValueError, match="logits"):
        kpn_head(x, logits[:, :-1], near, **kw)
    with pytest.raises(ValueError, match="nearness"):
        kpn_head(x, logits, None, **kw)
    with pytest.raises(ValueError, match="nearness"):
        kpn_head(x, logits, near[:, :, :16], **kw)
    with pytest.raises(ValueError, match="nearness"):
        kpn_head(x, logits[:, :-1], near, kernels=SHIPPED, depth_select=False)
    with pytest.raises(ValueError, match="multiple"):
        kpn_head(x[:, :, :, :44], logits[:, :, :, :44], near[:, :, :, :44], **kw)
    with pytest.raises(ValueError, match="planes"):
        kpn_head(x[:, :3], logits, near, **kw)
    with pytest.raises(TypeError):
        kpn_head(x.astype(np.float64), logits, near, **kw)
    with pytest.raises(ValueError, match="out"):
        kpn_head(x, logits, near, out=np.zeros((1, 3, 32, 48), np.float32), **kw)
