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
    iso = pack_iso(*f.planes(0.85), stride=32)
    lf = data.lidar_frames(("town",), 1, 5, 96, 64, views=1, dense_points=100_000)[0]
    lidar = pack_rgbda(lf.rgbda, stride=32)
    return {"infill": (iso, f), "lidar": (lidar, lf)}


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
    if name == "lidar":  # BN statistics other than the identity, so folding them is checked
        with torch.no_grad():
            for m in net.modules():
                if isinstance(m, torch.nn.BatchNorm2d):
                    m.running_mean.uniform_(-0.2, 0.2)
                    m.running_var.uniform_(0.5, 2.0)
    x, frame = real_inputs[name]
    y = (
        frame.rgb.transpose(2, 0, 1)
        if name == "lidar"
        else np.concatenate([frame.rgb, frame.hit[..., None]], 2).transpose(2, 0, 1)
    )
    out = tmp_path_factory.mktemp(name)
    files = train.export(net, name, out, [x[0]], {None: [(x[0], np.ascontiguousarray(y, np.float32))]}, print)
    return name, net, out, files


def _session(path):
    return ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])


def _run(path, x):
    s = _session(path)
    return s.run(None, {s.get_inputs()[0].name: x})[0]


def _torch(net, x):
    with torch.no_grad():
        return net(torch.from_numpy(x)).numpy()


@pytest.mark.parametrize("size", [(32, 32), (64, 96), (128, 64)])
def test_onnx_equals_torch_on_random_inputs(exported, size):
    name, net, out, _ = exported
    rng = np.random.default_rng(sum(size))
    x = rng.random((1, 5, *size), dtype=np.float32)
    if name == "infill":
        x[:, 3:5] = rng.random((1, 2, *size)) < 0.3  # hit and active are masks
    got, want = _run(out / f"{name}.onnx", x), _torch(net, x)
    assert got.shape == want.shape == (1, net.channels_out, *size)
    np.testing.assert_allclose(got, want, atol=1e-4, rtol=0)


def test_onnx_equals_torch_on_real_inputs(exported, real_inputs):
    name, net, out, files = exported
    x = real_inputs[name][0]
    np.testing.assert_allclose(_run(out / f"{name}.onnx", x), _torch(net, x), atol=1e-4, rtol=0)
    assert files["fp32"]["max_abs_vs_torch"] < 1e-4


def test_fp16_and_int8_within_tolerance(exported, real_inputs):
    """fp16: 2e-2 of a [0, 1] output; int8 (QDQ, per-channel): 0.1. The
    quality change in dB is what the card reports; this bounds the values."""
    name, net, out, files = exported
    x = real_inputs[name][0]
    want = _torch(net, x)
    np.testing.assert_allclose(_run(out / files["fp16"]["file"], x), want, atol=2e-2, rtol=0)
    if files["int8"]["file"] is not None:
        np.testing.assert_allclose(_run(out / files["int8"]["file"], x), want, atol=0.1, rtol=0)


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
