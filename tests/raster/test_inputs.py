"""clvis.raster.inputs: the raster input rules, public for every caller (the
Rasterizer, the distributed layer). Host-only checks: no device needed."""

import types

import numpy as np
import pytest

from clvis import Camera, PointCloud
from clvis.raster import inputs


def _cam(**kw):
    return Camera.look_at(
        (0.3, -6.0, 1.2), (0, 0, 0), (0, 0, 1), fov_y=50, aspect=1.0, near=0.5, far=20, **kw
    )


def test_check_camera():
    buf, near, far = inputs.check_camera(_cam())
    assert buf.dtype == np.float32 and buf.size == 20 and (near, far) == (np.float32(0.5), np.float32(20))
    with pytest.raises(TypeError, match="expected a clvis.Camera"):
        inputs.check_camera("camera")
    # render.cl takes near and far as finite floats (its vector projection
    # relies on it): a camera-like object whose far overflows float32 is refused
    c = _cam()
    far = types.SimpleNamespace(**{k: getattr(c, k) for k in ("matrix", "depth_row", "near", "projection")})
    far.far = 1e39
    with pytest.raises(ValueError, match="finite in float32"):
        inputs.check_camera(far)


def test_check_size_and_point_size():
    assert inputs.check_size(np.int32(64), 48) == (64, 48)
    with pytest.raises(ValueError, match=rf"width: {inputs.MAX_IMAGE_SIDE + 1} is outside"):
        inputs.check_size(inputs.MAX_IMAGE_SIDE + 1, 1)
    with pytest.raises(TypeError, match="height: expected an int"):
        inputs.check_size(4, 4.0)
    assert inputs.check_point_size(np.uint8(3)) == 3
    with pytest.raises(ValueError, match="point_size: 65 pixels is outside"):
        inputs.check_point_size(65)
    with pytest.raises(TypeError, match="point_size: expected an int"):
        inputs.check_point_size(True)


def test_soft_tolerance():
    assert inputs.soft_tolerance(None, _cam()) is None and inputs.soft_tolerance(False, _cam()) is None
    assert inputs.soft_tolerance(True, _cam()) == 1.01 and inputs.soft_tolerance(2, _cam()) == 2.0
    with pytest.raises(ValueError, match=">= 1"):
        inputs.soft_tolerance(0.5, _cam())


def test_raster_input_normalises_a_cloud():
    rng = np.random.default_rng(0)
    pos = rng.normal(size=(10, 3))  # float64: converted
    cloud = PointCloud(
        pos,
        colors=rng.integers(0, 256, (10, 3), dtype=np.uint8),
        attributes={
            "t": rng.normal(size=10),
            "label": np.arange(10, dtype=np.uint8),
            "flag": np.ones(10, bool),
        },
    )
    inp = inputs.RasterInput(cloud)
    assert inp.n == 10 and inp.positions.dtype == np.float32 and inp.colors.shape == (10, 4)
    assert (
        inp.names == ["t", "label", "flag"] and list(inp.f32) == ["t"] and list(inp.u8) == ["label", "flag"]
    )
    raw = inputs.RasterInput(pos.astype(np.float32), colors=np.zeros((10, 3), np.uint8))
    assert (raw.colors[:, 3] == 255).all() and raw.names == []
    with pytest.raises(ValueError, match=r"positions: expected shape \(N, 3\)"):
        inputs.RasterInput(np.zeros((4, 2), np.float32))
    with pytest.raises(ValueError, match="attributes: 9 given; at most 8"):
        inputs.RasterInput(pos, attributes={str(i): np.zeros(10) for i in range(9)})
