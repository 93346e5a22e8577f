"""The exported graphs against their reference, the PyTorch modules
(clvis.post.nets): onnxruntime = torch eager within 1e-4 in fp32 on random
and real inputs, fp16 and int8 within stated tolerances; dynamic height and
width; no Gather-lowered ops; the architectures as the papers state them."""

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="the train extra (torch==2.13.0) is part of the test venv")
ort = pytest.importorskip("onnxruntime")

from clvis.post import nets  # noqa: E402
from clvis.post.pack import pack_iso, pack_rgbda  # noqa: E402
from clvis.training import data, train  # noqa: E402


@pytest.fixture(scope="module")
def real_inputs():
    """A real partial iso image and a real depth-filtered scan, packed."""
    f = data.iso_frames(("blobs",), 1, 5, 96, 64, views=1, n=32)[0]
    # the 8-plane W-Net's input (candidates and depth planes)
    iso = pack_iso(*f.planes(0.85), candidates=f.candidates_at(0.85), depth=(f.t, f.next_t[0.85]), stride=32)
    lf = data.lidar_frames(("town",), 1, 5, 96, 64, views=1, dense_points=100_000)[0]
    lidar = pack_rgbda(lf.rgbda, stride=32)
    sc = data.narvis_scene("hurricane", 30_000, 5)
    nf = data.narvis_frames(
        sc, data.narvis_cameras(sc, "hemisphere", 1.5)[7:8], 96, 64, ("rgb", "depth", "vel2d")
    )[0]
    planes = train.SPECS["narvis-scan"]["arch"]["planes"]
    sf = data.scan_frames(("town",), 1, 5, 96, 64, planes, views=1, densities=(1.0, 1.0))[0]
    return {
        "infill": (iso, f),
        "lidar": (lidar, lf),
        "narvis": (nf.x[None], nf),
        "narvis-scan": (sf.x[None], sf),
    }


#: the kernel-predicting NARVis networks (NarvisKPN): the flows' and the scans'
KPN = ("narvis", "narvis-scan")


@pytest.fixture(scope="module", params=list(train.SPECS))
def exported(request, tmp_path_factory, real_inputs):
    """A randomly initialised network of each kind, exported as clvis train does."""
    name = request.param
    torch.manual_seed(3)
    net = nets.build(name, **train.SPECS[name]["arch"]).eval()
    with torch.no_grad():  # the residual U-Nets start at zero: give them a say
        for m in net.modules():
            if isinstance(m, nets._UNet):
                torch.nn.init.normal_(m.out.weight, std=0.2)
                torch.nn.init.normal_(m.out.bias, std=0.05)
    if name in KPN:  # the kernel head starts at a fixed prior: give it a say
        with torch.no_grad():
            torch.nn.init.normal_(net.out.weight, std=0.5)
    if name == "lidar":  # BN statistics other than the identity, so folding them is checked
        with torch.no_grad():
            for m in net.modules():
                if isinstance(m, torch.nn.BatchNorm2d):
                    m.running_mean.uniform_(-0.2, 0.2)
                    m.running_var.uniform_(0.5, 2.0)
    x, frame = real_inputs[name]
    x = np.ascontiguousarray(x[:, : net.channels_in])  # the in-fill's packed planes: the net's first
    y = (
        frame.rgb.transpose(2, 0, 1)
        if name != "infill"
        else np.concatenate([frame.rgb, frame.hit[..., None]], 2).transpose(2, 0, 1)
    )
    out = tmp_path_factory.mktemp(name)
    files = train.export(net, name, out, [x[0]], {None: [(x[0], np.ascontiguousarray(y, np.float32))]}, print)
    return name, net, out, files


def _session(path):
    return ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])


def _run(path, x, net=None):
    """The graph's image of x; NarvisKPN's graph stops at its head's logits
    (issue 28), so its head is applied as clvis train's export check
    applies it: clvis.post.kpn's kernels (tests/post/test_kpn.py holds them
    to their NumPy reference and the torch module)."""
    return train._run(path, x, net.head() if hasattr(net, "trunk") else None)


def _torch(net, x):
    with torch.no_grad():
        return net(torch.from_numpy(x)).numpy()


@pytest.mark.parametrize("size", [(32, 32), (64, 96), (128, 64)])
def test_onnx_equals_torch_on_random_inputs(exported, size):
    name, net, out, _ = exported
    rng = np.random.default_rng(sum(size))
    x = rng.random((1, net.channels_in, *size), dtype=np.float32)
    if name == "infill":
        x[:, 3:5] = rng.random((1, 2, *size)) < 0.3  # hit and active are masks
    if name in KPN:
        x = _narvis_input(rng, *size, planes=net.planes)
    got, want = _run(out / f"{name}.onnx", x, net), _torch(net, x)
    assert got.shape == want.shape == (1, net.channels_out, *size)
    np.testing.assert_allclose(got, want, atol=1e-4, rtol=0)


def test_onnx_equals_torch_on_real_inputs(exported, real_inputs):
    name, net, out, files = exported
    x = np.ascontiguousarray(real_inputs[name][0][:, : net.channels_in])
    np.testing.assert_allclose(_run(out / f"{name}.onnx", x, net), _torch(net, x), atol=1e-4, rtol=0)
    assert files["fp32"]["max_abs_vs_torch"] < 1e-4


def test_fp16_and_int8_within_tolerance(exported, real_inputs):
    """fp16: 2e-2 of a [0, 1] output; int8 (QDQ, per-channel): 0.1. The
    quality change in dB is what the card reports; this bounds the values."""
    name, net, out, files = exported
    x = np.ascontiguousarray(real_inputs[name][0][:, : net.channels_in])
    want = _torch(net, x)
    np.testing.assert_allclose(_run(out / files["fp16"]["file"], x, net), want, atol=2e-2, rtol=0)
    if files["int8"]["file"] is not None:
        np.testing.assert_allclose(_run(out / files["int8"]["file"], x, net), want, atol=0.1, rtol=0)
    # NarvisKPN makes none: int8 activations lose its softmax mask
    assert (files["int8"]["file"] is None) == (name in KPN)


def test_graph_is_plain_convolutions(exported):
    """Dynamic height and width, opset >= 17, no Gather (F.unfold's lowering)."""
    import onnx

    name, _, out, _ = exported
    m = onnx.load(str(out / f"{name}.onnx"))
    assert max(o.version for o in m.opset_import if o.domain in ("", "ai.onnx")) >= train.OPSET
    ops = {n.op_type for n in m.graph.node}
    assert "Gather" not in ops and "Conv" in ops
    dims = m.graph.input[0].type.tensor_type.shape.dim
    assert dims[2].dim_param and dims[3].dim_param
    outputs = [o.name for o in m.graph.output]
    if name in KPN:  # up to the head's logits: no gather, softmax or weighted sum (issue 28)
        assert outputs == ["logits", "nearness"] == exported[1].head()["outputs"]
        assert "Tanh" not in ops and "Softplus" not in ops and "Exp" not in ops
        assert m.graph.output[0].type.tensor_type.shape.dim[1].dim_value == exported[1].candidates + 2
    else:
        assert outputs == ["image"]


def test_finished_pixels_pass_through():
    """The in-fill graph keeps the finished rays' R, G, B and hit exactly."""
    torch.manual_seed(0)
    net = nets.InfillWNet().eval()
    with torch.no_grad():
        torch.nn.init.normal_(net.second.out.weight, std=0.2)
    rng = np.random.default_rng(1)
    x = rng.random((1, 5, 32, 64), dtype=np.float32)
    x[:, 4] = rng.random((32, 64)) < 0.2
    y = _torch(net, x)
    done = x[0, 4] == 0
    np.testing.assert_array_equal(y[0, :4][:, done], x[0, :4][:, done])
    assert not np.array_equal(y[0, :4][:, ~done], x[0, :4][:, ~done])


def test_graph_pushpull_is_the_baseline():
    """The networks' push-pull front (nets.PushPull) is clvis.post.pushpull's
    definition wherever no hole is wider than its pyramid: every 32 x 32
    block holds a known pixel. An untrained network (its corrections start
    at zero) outputs exactly that fill."""
    from clvis.reference.post.pushpull import pushpull

    rng = np.random.default_rng(4)
    h, w = 96, 160
    image = rng.random((h, w, 4), dtype=np.float32)
    valid = rng.random((h, w)) < 0.3
    valid[::32, ::32] = True
    want = pushpull(image, valid)
    c = torch.from_numpy(np.ascontiguousarray(image.transpose(2, 0, 1)[None]))
    wt = torch.from_numpy(valid.astype(np.float32)[None, None])
    got = nets.PushPull(5)(c, wt)[0].numpy().transpose(1, 2, 0)
    np.testing.assert_allclose(got, want, atol=2e-6, rtol=0)
    x = np.concatenate([image.transpose(2, 0, 1), (~valid)[None].astype(np.float32)])[None]
    y = _torch(nets.InfillWNet().eval(), np.ascontiguousarray(x))
    np.testing.assert_allclose(y[0].transpose(1, 2, 0), want, atol=2e-6, rtol=0)
    # holes wider than the pyramid take the weighted mean of the image
    valid2 = np.zeros((h, w), bool)
    valid2[:8, :8] = True
    got2 = nets.PushPull(5)(c, torch.from_numpy(valid2.astype(np.float32)[None, None]))[0].numpy()
    np.testing.assert_allclose(got2[:, 80:, 100:].mean((1, 2)), image[:8, :8].mean((0, 1)), atol=1e-5)


def test_architectures():
    """In-fill: e4-e8-e16-d32-d16-d8-d4 twice, ~0.12 MB of fp32 weights (the
    paper: 0.135 MB); LiDAR U-Net: conv-BN-ReLU x 2 per stage."""
    w = nets.InfillWNet()
    assert [b[0].out_channels for b in w.first.enc] == [4, 8, 16] and w.first.mid[0].out_channels == 32
    assert [b[0].out_channels for b in w.first.dec] == [16, 8, 4]
    assert 0.10e6 < 4 * nets.count_parameters(w) < 0.14e6 and w.stride == 32
    u = nets.RgbdaUNet(width=8)
    kinds = [type(m).__name__ for m in u.net.enc[0]]
    assert kinds == ["Conv2d", "BatchNorm2d", "ReLU"] * 2 and u.stride == 32
    assert nets.count_parameters(nets.RgbdaUNet(width=64)) > 30e6  # the authors' widths: 31 M


def test_export_card_json_serialisable(exported):
    json.dumps(exported[3])


# ---------------------------------------------------------------------------
# NARVis: the gated convolution and the multi-scale injection, restated


def _conv_numpy(x, w, b):
    """'same' 2-D convolution (cross-correlation, zero padding) of (C, H, W)
    with (O, C, k, k) weights, in float64 loops over the kernel taps."""
    o, c, k, _ = w.shape
    p = k // 2
    xp = np.pad(x.astype(np.float64), ((0, 0), (p, p), (p, p)))
    h, wd = x.shape[1:]
    out = np.zeros((o, h, wd)) + b[:, None, None]
    for dy in range(k):
        for dx in range(k):
            out += np.einsum("oc,chw->ohw", w[:, :, dy, dx], xp[:, dy : dy + h, dx : dx + wd])
    return out


def _elu(v):
    return np.where(v > 0, v, np.expm1(np.minimum(v, 0)))


def test_gated_convolution_restated():
    """Yu et al.'s gated convolution: ELU(W_f * x + b_f) * sigmoid(W_g * x + b_g)."""
    torch.manual_seed(1)
    g = nets.GatedConv2d(5, 7).eval()
    x = np.random.default_rng(2).normal(size=(5, 11, 13)).astype(np.float32)
    p = {k: v.detach().numpy().astype(np.float64) for k, v in g.state_dict().items()}
    f = _conv_numpy(x, p["features.weight"], p["features.bias"])
    gate = _conv_numpy(x, p["gate.weight"], p["gate.bias"])
    want = _elu(f) / (1 + np.exp(-gate))
    got = _torch(g, x[None])[0]
    np.testing.assert_allclose(got, want, atol=1e-5, rtol=0)


def _narvis_input(rng, h=64, w=96, planes=("rgb", "depth", "vel2d")):
    from clvis.post.names import gbuffer_channels

    c = len(gbuffer_channels(planes))
    x = rng.random((1, c, h, w)).astype(np.float32)
    cov = rng.random((h, w)) < 0.4
    x[0, 3] = cov
    x[0, 4:] *= 50.0
    x[0, :, ~cov] = 0
    return x


def test_narvis_normalisation():
    """Depth to [0, 1] over the covered range, nearest 1, empty 0; the
    screen velocity over the covered pixels' mean length; the angle / pi;
    attributes to [0, 1] over their covered range."""
    rng = np.random.default_rng(3)
    net = nets.NarvisUNet(("rgb", "depth", "vel2d", "temperature"), widths=(4, 4, 4, 4, 4))
    x = _narvis_input(rng, planes=net.planes)
    got = net.normalise(torch.from_numpy(x))[0].numpy()
    cov = x[0, 3] > 0
    d = x[0, 4]
    want_d = np.where(cov, 1 - (d - d[cov].min()) / (d[cov].max() - d[cov].min()), 0)
    np.testing.assert_allclose(got[4], want_d, atol=1e-6)
    mean = x[0, 8][cov].mean()
    np.testing.assert_allclose(got[5:7], x[0, 5:7] / mean, rtol=1e-5)
    np.testing.assert_allclose(got[7], x[0, 7] / np.pi, rtol=1e-6)
    np.testing.assert_allclose(got[8], x[0, 8] / mean, rtol=1e-5)
    t = x[0, 9]
    np.testing.assert_allclose(got[9], np.where(cov, (t - t[cov].min()) / np.ptp(t[cov]), 0), atol=1e-6)
    np.testing.assert_array_equal(got[:4], x[0, :4])


def test_narvis_scan_radius_is_normalised_absolute():
    """The splat radius in pixels (narvis-scan's radius plane) as
    log2(1 + r) / 4 at covered pixels, 0 elsewhere: absolute, so a frame of
    2-pixel splats and one of 8-pixel splats differ (a per-frame [0, 1]
    would give both the same planes)."""
    rng = np.random.default_rng(4)
    net = nets.NarvisKPN(("rgb", "depth", "radius"), widths=(4, 4, 4, 4, 4), depth_select=True)
    assert net.layout == ["r", "g", "b", "coverage", "depth", "radius_px"]
    x = _narvis_input(rng, planes=net.planes)
    cov = x[0, 3] > 0
    x[0, 5] = np.where(cov, rng.uniform(0.3, 20, cov.shape), 0)
    got = net.normalise(torch.from_numpy(x))[0].numpy()
    np.testing.assert_allclose(got[5], np.where(cov, np.log2(1 + x[0, 5]) / 4, 0), rtol=1e-5, atol=1e-7)
    y = x.copy()
    y[0, 5] *= 4
    assert not np.allclose(net.normalise(torch.from_numpy(y))[0, 5].numpy()[cov], got[5][cov])


def test_narvis_multiscale_injection():
    """The G-buffers pass a 1x1 convolution (channels kept), are halved by
    2x2 means four times, and each resolution is concatenated to the input
    of the encoder's block at that resolution (after the pooled features)."""
    torch.manual_seed(4)
    net = nets.NarvisUNet(widths=(6, 7, 8, 9, 10)).eval()
    x = _narvis_input(np.random.default_rng(5))
    seen = []
    hooks = [b.register_forward_hook(lambda m, i, o: seen.append(i[0].numpy())) for b in net.enc]
    _torch(net, x)
    for h in hooks:
        h.remove()
    xn = net.normalise(torch.from_numpy(x))[0].numpy().astype(np.float64)
    w = net.inject.weight.detach().numpy()[:, :, 0, 0].astype(np.float64)
    g = np.einsum("oc,chw->ohw", w, xn) + net.inject.bias.detach().numpy()[:, None, None]
    c = net.channels_in
    assert [s.shape[1] for s in seen] == [c, 6 + c, 7 + c, 8 + c, 9 + c]
    for level, s in enumerate(seen):
        if level:
            g = g.reshape(c, g.shape[1] // 2, 2, g.shape[2] // 2, 2).mean(axis=(2, 4))
        assert s.shape[2:] == (64 >> level, 96 >> level)
        np.testing.assert_allclose(s[0, -c:], g, atol=1e-5)


def test_narvis_architecture():
    """Gated convolutions at 5 resolutions, ELU and average pooling; the
    shipped widths and NPBG's 16..256 (about 2 M parameters, the paper's
    7.73 MB of U-Net); transposed up-sampling where asked."""
    net = nets.NarvisUNet()
    assert [b.features.out_channels for b in net.enc] == [16, 32, 64, 128, 256]
    assert [b.features.out_channels for b in net.dec] == [128, 64, 32, 16]
    assert all(isinstance(b, nets.GatedConv2d) for b in [*net.enc, *net.dec]) and net.stride == 16
    assert net.inject.in_channels == net.inject.out_channels == 9 and net.inject.kernel_size == (1, 1)
    assert 1.9e6 < nets.count_parameters(net) < 2.2e6
    shipped = nets.build("narvis", **train.SPECS["narvis"]["arch"])
    assert isinstance(shipped, nets.NarvisKPN)
    assert nets.count_parameters(shipped) < nets.count_parameters(net)
    t = nets.NarvisUNet(up="transposed")
    assert sum(isinstance(m, torch.nn.ConvTranspose2d) for m in t.modules()) == 4
    y = _torch(t.eval(), _narvis_input(np.random.default_rng(6), 32, 48))
    assert y.shape == (1, 3, 32, 48) and y.min() >= 0 and y.max() <= 1
    with pytest.raises(ValueError, match="rgb"):
        nets.NarvisUNet(("depth",))
    with pytest.raises(ValueError, match="twice"):
        nets.NarvisUNet(("rgb", "depth", "depth"))


# ---------------------------------------------------------------------------
# NARVis's kernel prediction (nets.NarvisKPN), restated


def _kpn_candidates(x, kernels):
    """Per pixel, the candidates of NarvisKPN in NumPy: for each (k, s), the
    k x k blocks of s x s pixels around the pixel's block, each block's
    colour the mean of its covered pixels and valid where it has one.
    Returns colours (K, 3, H, W) and validity (K, H, W)."""
    rgb, cov = x[0, :3].astype(np.float64), x[0, 3].astype(np.float64)
    _, h, w = rgb.shape
    cols, valid = [], []
    for k, s in kernels:
        hb, wb = h // s, w // s
        n = cov.reshape(hb, s, wb, s).sum(axis=(1, 3))
        tot = (rgb * cov).reshape(3, hb, s, wb, s).sum(axis=(2, 4))
        colour = np.where(n > 0, tot / np.maximum(n, 1), 0)
        r = k // 2
        cp = np.pad(colour, ((0, 0), (r, r), (r, r)))
        npad = np.pad(n > 0, r)
        by, bx = np.arange(h) // s, np.arange(w) // s
        for dy in range(k):
            for dx in range(k):
                yy, xx = by[:, None] + dy, bx[None, :] + dx
                cols.append(cp[:, yy, xx])
                valid.append(npad[yy, xx])
    return np.stack(cols), np.stack(valid)


def test_narvis_kernel_prediction_restated():
    """The output is sum_k softmax(logits)_k x candidate_k over the valid
    candidates and a background (black) weight: shifting by constant slices
    and nearest up-sampling = the NumPy gather above."""
    torch.manual_seed(7)
    kernels = ((5, 1), (3, 2), (3, 4))
    net = nets.NarvisKPN(widths=(4, 4, 4, 4, 4), kernels=kernels).eval()
    with torch.no_grad():
        torch.nn.init.normal_(net.out.weight, std=0.7)
    x = _narvis_input(np.random.default_rng(8), 32, 48)
    x[0, :, :8, :] = 0  # a band wider than a 4 x 4 block with no point
    logits = []
    hook = net.out.register_forward_hook(lambda m, i, o: logits.append(o.numpy()[0].astype(np.float64)))
    got = _torch(net, x)[0]
    hook.remove()
    cols, valid = _kpn_candidates(x, kernels)
    assert cols.shape[0] == net.candidates == 25 + 9 + 9
    b = nets.NarvisKPN.LOGIT_BOUND  # the logits are bounded: b * tanh(logit / b)
    lg = np.where(
        np.concatenate([valid, np.ones((1, *valid.shape[1:]), bool)]), b * np.tanh(logits[0] / b), -np.inf
    )
    wts = np.exp(lg - lg.max(0))
    wts /= wts.sum(0)
    want = np.einsum("khw,kchw->chw", wts[:-1], cols)
    np.testing.assert_allclose(got, want, atol=2e-5, rtol=0)
    np.testing.assert_allclose(_torch_weights(net, x), wts, atol=2e-5)
    # rows 0-1 have no covered block within reach of even the coarsest scale: black
    assert np.abs(got[:, :2]).max() == 0


def test_narvis_depth_select_restated():
    """depth_select: each candidate's bounded logit gains gamma x its
    nearness (the normalised depth, 1 nearest; a block's: the mean over its
    covered pixels) less the pixel's nearest candidate's, gamma =
    depth_scale x softplus(the extra output channel); an untrained network
    leans to the nearest of the finest scale."""
    torch.manual_seed(12)
    kernels = ((3, 1), (3, 2), (3, 8))
    net = nets.NarvisKPN(widths=(4, 4, 4, 4, 4), kernels=kernels, depth_select=True).eval()
    assert net.out.out_channels == net.candidates + 2
    with torch.no_grad():
        torch.nn.init.normal_(net.out.weight, std=0.5)
    x = _narvis_input(np.random.default_rng(13), 32, 48)
    x[0, :, 16:, :8] = 0
    logits = []
    hook = net.out.register_forward_hook(lambda m, i, o: logits.append(o.numpy()[0].astype(np.float64)))
    got = _torch(net, x)[0]
    hook.remove()
    with torch.no_grad():
        near = net.normalise(torch.from_numpy(x))[0, 4:5].numpy()  # the layout's depth channel
    k = net.candidates
    cols, valid = _kpn_candidates(x, kernels)
    # the nearness of each candidate, through the same gather (a plane in the R channel)
    xn = np.zeros_like(x)
    xn[0, 0], xn[0, 3] = near[0], x[0, 3]
    cand_near, _ = _kpn_candidates(xn, kernels)
    near_rel = cand_near[:, 0] - cand_near[:, 0].max(0)  # <= 0: behind the pixel's nearest candidate
    gamma = net.depth_scale * np.log1p(np.exp(logits[0][k + 1]))
    b = nets.NarvisKPN.LOGIT_BOUND
    lg = b * np.tanh(logits[0][: k + 1] / b)
    lg[:k] += gamma * near_rel
    lg = np.where(np.concatenate([valid, np.ones((1, *valid.shape[1:]), bool)]), lg, -np.inf)
    wts = np.exp(lg - lg.max(0))
    wts /= wts.sum(0)
    np.testing.assert_allclose(got, np.einsum("khw,kchw->chw", wts[:-1], cols), atol=2e-5, rtol=0)
    with pytest.raises(ValueError, match="depth_select"):
        nets.NarvisKPN(planes=("rgb", "vel2d"), depth_select=True)
    # untrained: the nearest of each pixel's 3 x 3 weighs the most
    net0 = nets.NarvisKPN(widths=(4, 4, 4, 4, 4), kernels=kernels, depth_select=True).eval()
    w = _torch_weights(net0, x)
    cand0, _ = _kpn_candidates(xn, ((3, 1),))
    inner = (slice(None), slice(2, -2), slice(2, -2))
    nearest = cand0[:, 0][inner].argmax(0)
    both = valid[:9][inner].sum(0) >= 2  # pixels with a choice to make
    assert (w[:9][inner].argmax(0) == nearest)[both].mean() > 0.95


def test_shifted_is_the_neighbourhood():
    """nets.shifted: channel dy * k + dx is the pixel at offset
    ((dy - k // 2) * s, (dx - k // 2) * s), zero beyond the border."""
    x = np.random.default_rng(14).random((1, 1, 8, 12)).astype(np.float32)
    for k, s in ((3, 1), (5, 1), (3, 2), (3, 4)):
        u = nets.shifted(torch.from_numpy(x), k, s)[0].numpy()
        r = (k // 2) * s
        xp = np.pad(x[0, 0], r)
        for j in range(k * k):
            dy, dx = (j // k) * s, (j % k) * s
            np.testing.assert_array_equal(u[j], xp[dy : dy + 8, dx : dx + 12])


def _torch_weights(net, x):
    with torch.no_grad():
        return net.weights(torch.from_numpy(x))[0].numpy()


def test_narvis_output_is_a_convex_combination_of_input_colours():
    """A colour the input does not hold cannot appear: with every point one
    colour (here one no colormap of the training holds), every output pixel
    is that colour times a coverage in [0, 1], whatever the weights."""
    torch.manual_seed(9)
    net = nets.NarvisKPN(widths=(4, 4, 4, 4, 4)).eval()
    with torch.no_grad():
        torch.nn.init.normal_(net.out.weight, std=2.0)
        torch.nn.init.normal_(net.out.bias, std=2.0)
    x = _narvis_input(np.random.default_rng(10), 32, 32)
    colour = np.array([0.9, 0.1, 0.6], np.float32)
    x[0, :3] = colour[:, None, None] * x[0, 3]
    y = _torch(net, x)[0]
    alpha = y[0] / colour[0]
    np.testing.assert_allclose(y, colour[:, None, None] * alpha, atol=1e-6)
    assert alpha.min() >= 0 and alpha.max() <= 1 + 1e-6 and alpha.max() > 0.5
    # an untrained network: the finest scale's covered neighbours, mostly
    y0 = _torch(nets.NarvisKPN(widths=(4, 4, 4, 4, 4)).eval(), x)[0]
    assert (y0[0] > 0).mean() > 0.95


def test_onehot_unfold_is_the_neighbourhood():
    x = np.random.default_rng(11).random((1, 1, 6, 7)).astype(np.float32)
    u = torch.nn.functional.conv2d(torch.from_numpy(x), nets.onehot_unfold(3), padding=1)[0].numpy()
    xp = np.pad(x[0, 0], 1)
    for j in range(9):
        np.testing.assert_array_equal(u[j], xp[j // 3 : j // 3 + 6, j % 3 : j % 3 + 7])
    with pytest.raises(ValueError, match="kernels"):
        nets.NarvisKPN(kernels=((4, 1),))
    with pytest.raises(ValueError, match="kernels"):
        nets.NarvisKPN(kernels=((3, 3),))
