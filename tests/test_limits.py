"""clvis.limits: the one place image-size limits live, and what each family takes from it."""

import numpy as np
import pytest

from clvis import limits
from clvis.cli import _common
from clvis.gauss import render as gauss_render
from clvis.iso import render as iso_render
from clvis.limits import ImageLimits, check_image_size
from clvis.post import infer, pack
from clvis.raster import inputs


def test_families_take_their_limits_from_here():
    assert (inputs.MAX_IMAGE_SIDE, inputs.MAX_PIXELS) == (limits.RASTER.max_side, limits.RASTER.max_pixels)
    assert iso_render.MAX_PIXELS == limits.ISO.max_pixels + 1  # iso's is exclusive
    assert (pack.MAX_SIDE, pack.MAX_PIXELS) == (limits.POST_PACK.max_side, limits.POST_PACK.max_pixels)
    assert (infer.MAX_SIDE, infer.MAX_PIXELS) == (limits.POST_INFER.max_side, limits.POST_INFER.max_pixels)
    assert (_common.MAX_SIDE, _common.MAX_PIXELS) == (limits.RASTER.max_side, limits.RASTER.max_pixels)
    for lim in (limits.RASTER, limits.ISO, limits.POST_PACK, limits.POST_INFER):
        assert lim.max_pixels < 2**31 and lim.max_side <= lim.max_pixels and lim.why
    # gauss: unsigned 32-bit pixel indices (gauss/render.py applies it: tests/gauss/test_render.py)
    assert limits.GAUSS.max_pixels == limits.GAUSS.max_side == 2**32 - 1 and limits.GAUSS.why
    assert gauss_render.LIMITS is limits.GAUSS


def test_check_image_size():
    lim = ImageLimits(100, 5000, "a reason")
    assert check_image_size(np.int64(100), 50, lim) == (100, 50)
    assert type(check_image_size(np.int64(7), 3, lim)[0]) is int
    with pytest.raises(TypeError, match="width: expected an int, got bool"):
        check_image_size(True, 3, lim)
    with pytest.raises(TypeError, match="height: expected an int, got float"):
        check_image_size(3, 3.0, lim)
    with pytest.raises(ValueError, match=r"height: 0 is outside \[1, 100\]"):
        check_image_size(3, 0, lim)
    with pytest.raises(ValueError, match=r"width: 101 is outside \[1, 100\]"):
        check_image_size(101, 1, lim)
    with pytest.raises(ValueError, match=r"width x height: 100x51 = 5100 pixels; at most 5000 \(a reason\)"):
        check_image_size(100, 51, lim)
    with pytest.raises(
        ValueError, match=r"at most 2\^31 - 1 \(the kernels index pixels with 32-bit integers\)"
    ):
        check_image_size(65536, 32768, limits.ISO)
    assert check_image_size(2**20, 1, limits.ISO) == (2**20, 1)  # iso: no side limit of its own
