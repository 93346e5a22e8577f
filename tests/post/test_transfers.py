"""Host <-> device traffic of the documented pipelines, counted and held to
the floor.

Every byte that crosses between host and device memory goes through
``pyopencl.enqueue_copy`` (``Array.get``/``set``/``to_device`` call it) or
``pyopencl.enqueue_map_buffer``; the ``transfers`` fixture wraps both and
records each transfer's direction and size. A map counts as the copy it is on
a discrete GPU (a read map downloads, a write map uploads at its unmap),
though on a CPU device it copies nothing: the figures are the same on every
device.

The floor of a frame through a network, per pixel (Hp x Wp: the image padded
to the network's stride):

- down, C_in x 4 bytes per padded pixel: onnxruntime runs on the host, so it
  must read the network's float32 input tensor (the map of the host-visible
  buffer pack writes);
- up, C_out x 4 bytes per padded pixel: onnxruntime writes the output on the
  host and the unpack kernel reads it (the unmap of the second host-visible
  buffer);
- down, 4 bytes per pixel: the RGBA8 picture the call returns.

A network whose card has a ``head`` (NARVis since issue 28: the graph stops
at its kernel-prediction head's logits, clvis.post.kpn's kernels apply the
head) crosses up its graph's outputs instead of the image: the logits (K + 2
channels: 38 for the shipped card) and the nearness plane, (K + 3) x 4
bytes per padded pixel, each the unmap of its host-visible buffer. That is
the floor of a head applied on the device: onnxruntime writes the logits on
the host. (On a CPU device, what the suite measures the frame time on, the
maps copy nothing.)

Nothing else a pixel: the renderers' planes stay on the device, pack reads
them where they are. What remains are counts that size the next launch and
input checks, a few bytes each (SMALL in all), never a plane. So each
pipeline must show exactly those three per-pixel transfers, in that order.

The guarded calls (clvis.post.guard: LiDAR's default, in-fill's with
guard=True) blend on the host, so they are above the floor by design; each
is held to its own exact count (_guard_accounting).
"""

import numpy as np
import pyopencl as cl
import pyopencl.array as cla
import pytest

import clvis
from clvis import post, runtime
from clvis.raster import Rasterizer, depth_filter_mask, rgbda

# everything that is not a plane, in bytes a frame: the camera, the pack and
# depth filter input checks, the iso pass loop's counts (a few per pass)
SMALL = 4096


class Transfers:
    def __init__(self):
        self.log = []

    def clear(self):
        self.log.clear()

    def planes(self, npix):
        """(direction, bytes) of every transfer of at least a byte a pixel."""
        return [(d, n) for d, n in self.log if n >= npix]

    def small(self, npix):
        return sum(n for _, n in self.log if n < npix)


@pytest.fixture
def transfers(monkeypatch):
    t = Transfers()
    copy, map_buffer = cl.enqueue_copy, cl.enqueue_map_buffer

    def counted_copy(queue, dest, src, **kw):
        to_dev, from_dev = isinstance(dest, cl.MemoryObjectHolder), isinstance(src, cl.MemoryObjectHolder)
        if to_dev and not from_dev:
            t.log.append(("up", memoryview(src).nbytes))
        elif from_dev and not to_dev:
            t.log.append(("down", memoryview(dest).nbytes))
        return copy(queue, dest, src, **kw)

    def counted_map(queue, buf, flags, offset, shape, dtype, *args, **kw):
        nbytes = int(np.prod(shape)) * np.dtype(dtype).itemsize
        if flags & cl.map_flags.READ:
            t.log.append(("down", nbytes))
        if flags & (cl.map_flags.WRITE | cl.map_flags.WRITE_INVALIDATE_REGION):
            t.log.append(("up", nbytes))
        return map_buffer(queue, buf, flags, offset, shape, dtype, *args, **kw)

    monkeypatch.setattr(cl, "enqueue_copy", counted_copy)
    monkeypatch.setattr(cl, "enqueue_map_buffer", counted_map)
    return t


def test_the_counter_sees_every_transfer(device, transfers):
    """Uploads, read-backs and maps are counted with their sizes; copies
    between device buffers are not transfers."""
    q = runtime.queue_for(device)
    x = np.arange(1000, dtype=np.float32)
    a = cla.to_device(q, x)
    b = a.copy()
    a.set(x[::-1].copy())
    b.get()
    m, _ = cl.enqueue_map_buffer(q, a.base_data, cl.map_flags.READ, 0, (1000,), np.float32)
    m.base.release()
    m, _ = cl.enqueue_map_buffer(q, a.base_data, cl.map_flags.WRITE_INVALIDATE_REGION, 0, (10,), np.float32)
    m.base.release()
    assert transfers.log == [("up", 4000), ("up", 4000), ("down", 4000), ("down", 4000), ("up", 40)]


def _floor(net, h, w):
    hp, wp = post.padded_shape(h, w, net.stride)
    if net.head is None:
        outputs = [net.channels_out]
    else:  # the logits, then the nearness plane (depth_select)
        outputs = [net.head.channels] + [1] * net.head.depth_select
    return [
        ("down", net.channels_in * 4 * hp * wp),
        *[("up", c * 4 * hp * wp) for c in outputs],
        ("down", 4 * h * w),
    ]


def _hurricane(queue, w, h):
    from clvis.training.data import narvis_radius

    d = clvis.datasets.hurricane(20_000, 3)
    ras = Rasterizer(
        d["positions"],
        colors=d["colors"],
        attributes=d["attributes"],
        velocity=d["velocity"],
        radius=narvis_radius(d["positions"]),  # the shipped narvis's radius plane: GR's sigma
        queue=queue,
    )
    cam = clvis.Camera.fit(d["positions"].min(0), d["positions"].max(0), aspect=w / h)
    return ras, cam


# not multiples of the networks' stride (32): the padding is part of the floor
W, H = 100, 60


def net_head_channels():
    """(logit channels, nearness planes) of the shipped NARVis card's head."""
    head = post.load("narvis").head
    assert head is not None
    return head.channels, int(head.depth_select)


def test_narvis_pipeline_is_at_the_floor(device, transfers):
    """README's NARVis call on the device path: G-buffers with only the
    planes the network reads, never read back. down 44 B/pixel at 512 x 512
    (10 input channels, the picture), up 156 (the graph's 38 logit channels
    and the nearness plane, which the head's kernels read; 12, the 3 output
    channels, while the head was in the graph, issue 28); the numpy
    G-buffers the same call used to take cost 80 down and 48 up. The picture
    is the host path's."""
    assert net_head_channels() == (38, 1)
    q = runtime.queue_for(device)
    ras, cam = _hurricane(q, W, H)
    net = post.load("narvis", queue=q)
    assert net.attribute_planes == ()  # the shipped card: rgb, depth, vel2d, radius
    g = ras.render(cam, W, H, color_by="temperature", planes=net.attribute_planes, host=False)
    transfers.clear()
    got = net(g)
    assert transfers.planes(W * H) == _floor(net, H, W)
    assert transfers.small(W * H) <= SMALL
    transfers.clear()
    ras.render(cam, W, H, color_by="temperature", planes=net.attribute_planes, host=False)
    assert transfers.planes(W * H) == [] and transfers.small(W * H) <= SMALL
    np.testing.assert_array_equal(got, net(ras.render(cam, W, H, color_by="temperature")))


def test_narvis_host_planes_cross_once(device, transfers):
    """numpy G-buffers: each plane the network reads is uploaded once (the
    velocity's x and y are one plane, read in place), planes it does not
    read never: rgba 4 + index 4 + depth 4 + vel2d 8 + angle 4 + speed 4
    (+ radius 4 for a card with that plane, the shipped one) = 28 (32)
    bytes a pixel up, over the floor."""
    q = runtime.queue_for(device)
    ras, cam = _hurricane(q, W, H)
    net = post.load("narvis", queue=q)
    g = ras.render(cam, W, H, color_by="temperature")
    assert len(g.attributes) == 3  # resolved, but not read by the network
    transfers.clear()
    net(g)
    npix = W * H
    floor = _floor(net, H, W)
    uploads = [n for d, n in transfers.planes(npix)[: -len(floor)] if d == "up"]
    want = [4 * npix, 4 * npix, 4 * npix, 8 * npix, 4 * npix, 4 * npix]
    want += [4 * npix] * ("radius" in net.planes)
    assert sorted(uploads) == sorted(want)
    assert transfers.planes(npix)[-len(floor) :] == floor
    assert len(transfers.planes(npix)) == len(floor) + len(want)


def test_infill_pipeline_is_at_the_floor(device, transfers):
    """README's in-fill call on the device path (IsoRenderer.render(...,
    host=False)): down 24 B/pixel (5 input channels, the picture), up 16
    (4 output channels), padding aside; the host image cost 26 B/pixel down
    and 18 up more. The picture is the host path's."""
    q = runtime.queue_for(device)
    d = clvis.datasets.marschner_lobb(32)
    r = clvis.IsoRenderer(d["volume"], spacing=d["spacing"], origin=d["origin"], queue=q)
    cam = clvis.Camera.look_at((2.2, -2.6, 1.8), (0, 0, 0), aspect=W / H)
    net = post.load("infill", queue=q)
    transfers.clear()
    part = r.render(cam, W, H, isovalue=0.5, completion=0.85, speculation=False, host=False)
    assert transfers.planes(W * H) == []  # the pass loop reads counts only
    passes = part.stats["passes"]
    assert transfers.small(W * H) <= SMALL + 64 * passes
    transfers.clear()
    got = net(part)
    assert transfers.planes(W * H) == _floor(net, H, W)
    assert transfers.small(W * H) <= SMALL
    want = net(r.render(cam, W, H, isovalue=0.5, completion=0.85, speculation=False))
    np.testing.assert_array_equal(got, want)


def test_lidar_pipeline_is_at_the_floor(device, transfers):
    """Device G-buffers through the depth filter into the LiDAR network, both
    ways: depth_filter(g) (its planes stay on the device) and the mask and
    RGBDA image made by hand: down 24 B/pixel (5 input channels, the
    picture), up 12 (3 output channels), padding aside. The picture is
    depth_filter's host path's."""
    from clvis.raster import depth_filter

    q = runtime.queue_for(device)
    ras, cam = _hurricane(q, W, H)
    net = post.load("lidar", queue=q)
    assert net.attribute_planes == ()
    # the network's own pipeline: its guard (on by default, clvis.post.guard)
    # reads the planes back and runs it twice by design
    want = net(depth_filter(ras.render(cam, W, H, planes=[]), 4), guard=False)
    for by_hand in (False, True):
        transfers.clear()
        g = ras.render(cam, W, H, planes=[], host=False)
        image = rgbda(g.rgba, g.depth, depth_filter_mask(g.depth, 4)) if by_hand else depth_filter(g, 4)
        got = net(image, guard=False)
        assert transfers.planes(W * H) == _floor(net, H, W)
        assert transfers.small(W * H) <= SMALL
        np.testing.assert_array_equal(got, want)


def _guard_accounting(net, h, w, reads, uploads, pushpull):
    """The guarded call's transfers: the input's planes read back (`reads`,
    bytes a pixel each), then the network on the input with some known pixels
    withheld and push-pull on the same (the scoring), then the candidates
    some tile took on the whole input (the network, push-pull: net.stats).
    A network run uploads the host planes (`uploads`), maps its input tensor
    down and its output up, and reads the padded output back (the guard
    blends floats on the host); push-pull uploads the colours (`pushpull`
    bytes a pixel) and the known mask and reads its fill back."""
    npix = h * w
    hp, wp = post.padded_shape(h, w, net.stride)
    run = [("up", b * npix) for b in uploads] + [
        ("down", net.channels_in * 4 * hp * wp),
        ("up", net.channels_out * 4 * hp * wp),
        ("down", net.channels_out * 4 * hp * wp),
    ]
    pp = [("up", pushpull * npix), ("up", npix), ("down", pushpull * npix)]
    whole = (run if net.stats["guard_network"] > 0 else []) + (pp if net.stats["guard_pushpull"] > 0 else [])
    return [("down", b * npix) for b in reads] + run + pp + whole


def test_guarded_lidar_pipeline_is_counted(device, transfers):
    """README's LiDAR one-liner as written, post.load("lidar")(depth_filter(g)):
    the guard is on by default for LiDAR and works on the host (clvis.post.guard),
    so it is not at the floor: the RGBDA image comes back once (20 B/pixel)
    and the G-buffers' point index (4: the guard withholds whole points),
    the network runs twice on host input (20 up, its tensors, and its
    float output read back: 12 a padded pixel), push-pull once or twice
    (12 + 1 up, 12 down). At 512x512 (no padding) that is 100 B/pixel down
    and 77 up with push-pull once, against the unguarded call's 24 and 12;
    held here to exactly that, so the guard's traffic cannot grow unnoticed.
    The picture is the host path's."""
    from clvis.raster import depth_filter

    q = runtime.queue_for(device)
    ras, cam = _hurricane(q, W, H)
    net = post.load("lidar", queue=q)
    assert net.guard is True  # LiDAR's default (its spec)
    want = net(depth_filter(ras.render(cam, W, H, planes=[]), 4))
    g = ras.render(cam, W, H, planes=[], host=False)
    image = depth_filter(g, 4)
    transfers.clear()
    got = net(image)
    assert transfers.planes(W * H) == _guard_accounting(net, H, W, [20, 4], [20], 12)
    assert transfers.small(W * H) <= SMALL
    np.testing.assert_array_equal(got, want)


def test_guarded_infill_pipeline_is_counted(device, transfers):
    """README's in-fill call with guard=True (off by default; clvis iso
    --infill --post-guard): the input's planes come back once (rgba, hit,
    active, candidates, t, next_t for the 8-plane model: 27 B/pixel), the
    network runs twice on host planes (the same up, its tensors, its float
    output read back: 16 a padded pixel), push-pull once or twice (16 + 1
    up, 16 down). Held to exactly that."""
    q = runtime.queue_for(device)
    d = clvis.datasets.marschner_lobb(32)
    r = clvis.IsoRenderer(d["volume"], spacing=d["spacing"], origin=d["origin"], queue=q)
    cam = clvis.Camera.look_at((2.2, -2.6, 1.8), (0, 0, 0), aspect=W / H)
    net = post.load("infill", queue=q)
    part = r.render(cam, W, H, isovalue=0.5, completion=0.85, speculation=False, host=False)
    want = net(r.render(cam, W, H, isovalue=0.5, completion=0.85, speculation=False), guard=True)
    transfers.clear()
    got = net(part, guard=True)
    # rgba, hit, active, (a 6- or 8-channel model's) candidates, (an 8-channel one's) t and next_t
    planes = [16, 1, 1] + [1] * (min(net.channels_in, 6) - 5) + ([4, 4] if net.channels_in == 8 else [])
    assert transfers.planes(W * H) == _guard_accounting(net, H, W, planes, planes, 16)
    assert transfers.small(W * H) <= SMALL
    np.testing.assert_array_equal(got, want)
