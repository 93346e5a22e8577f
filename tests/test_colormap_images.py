"""clvis.colormap against matplotlib and a scalar loop; clvis.images."""

import math

import matplotlib
import numpy as np
import pytest
from PIL import Image

from clvis import colormap, images

F32 = np.float32


@pytest.mark.parametrize(
    "name", ["viridis", "magma", "inferno", "twilight", "gray", "jet", "tab10", "coolwarm_r"]
)
@pytest.mark.parametrize("n", [1, 2, 5, 256, 1000])
def test_lut_is_matplotlibs(name, n):
    expected = matplotlib.colormaps[name].resampled(n)(np.arange(n), bytes=True)
    got = colormap.lut(name, n)
    assert got.dtype == np.uint8 and got.shape == (n, 4)
    np.testing.assert_array_equal(got, expected)


def test_lut_copies_from_its_cache():
    a = colormap.lut("viridis", 16)
    a[:] = 0
    assert colormap.lut("viridis", 16).any()


def test_lut_errors():
    with pytest.raises(ValueError, match="viridis"):
        colormap.lut("viridiss")
    for n in (0, -3, 2**24 + 1):
        with pytest.raises(ValueError, match="n"):
            colormap.lut("viridis", n)
    with pytest.raises(TypeError, match="n"):
        colormap.lut("viridis", 2.0)
    with pytest.raises(TypeError, match="name"):
        colormap.lut(3)


def test_names():
    names = colormap.names()
    assert names == sorted(names)
    assert {"viridis", "magma", "twilight", "inferno"} <= set(names)


def _apply_loop(values, lut, vmin, vmax):
    """The index rule written element by element in np.float32 scalars."""
    n = len(lut)
    scale = F32(0.0) if vmax == vmin else F32(1.0 / (float(vmax) - float(vmin)))
    out = np.zeros(np.shape(values) + (4,), np.uint8)
    for k, v in np.ndenumerate(np.asarray(values)):
        v = F32(v)
        if math.isnan(v):
            continue
        x = (F32(v - F32(vmin)) * scale) * F32(n)
        assert type(x) is F32
        if math.isnan(x) or x < 0:
            i = 0
        elif x >= n - 1:
            i = n - 1
        else:
            i = math.floor(x)
        out[k] = lut[i]
    return out


def _index_lut(n):
    """A table whose entry i spells i, so colours read back as indices."""
    i = np.arange(n)
    return np.stack([i % 256, i // 256 % 256, np.zeros(n), np.full(n, 255)], axis=1).astype(np.uint8)


def _indices(rgba):
    return rgba[..., 0].astype(np.int64) + 256 * rgba[..., 1].astype(np.int64)


SPECIAL = [np.nan, np.inf, -np.inf, 0.0, -0.0, 1.0, -1.0, 1e-30, -1e-30, 3e38, -3e38, 1e-45]


@pytest.mark.parametrize("n", [1, 2, 3, 256, 1000])
@pytest.mark.parametrize(
    "vmin, vmax",
    [
        (0.0, 1.0),
        (-1.0, 3.0),
        (0.1, 0.7),
        (2.5, 2.5),
        (0.0, 0.0),
        (-3e38, 3e38),
        (1e-30, 2e-30),
        (0.0, 1e-39),
        (1.0, 1.0 + 1e-7),
        (100.0, 100.0001),
    ],
)
def test_apply_matches_scalar_loop(n, vmin, vmax):
    rng = np.random.default_rng(n)
    lo, hi = F32(vmin), F32(vmax)
    with np.errstate(over="ignore"):
        values = np.concatenate(
            [
                np.array(
                    SPECIAL
                    + [
                        vmin,
                        vmax,
                        lo,
                        hi,
                        np.nextafter(lo, F32(-np.inf)),
                        np.nextafter(hi, F32(np.inf)),
                        (vmin + vmax) / 2,
                    ],
                    dtype=np.float32,
                ),
                rng.uniform(vmin - 0.1 * (vmax - vmin), vmax + 0.1 * (vmax - vmin), 300).astype(np.float32),
                (vmin + (vmax - vmin) * np.arange(n + 1) / n).astype(np.float32),  # bin edges
            ]
        )
    lut = _index_lut(n)
    with np.errstate(over="ignore", invalid="ignore"):
        expected = _apply_loop(values, lut, vmin, vmax)
    got = colormap.apply(values, lut, vmin, vmax)
    assert got.shape == values.shape + (4,) and got.dtype == np.uint8
    np.testing.assert_array_equal(got, expected)


def test_apply_documented_cases():
    lut = _index_lut(10)
    v = np.array([np.nan, -np.inf, -1.0, 0.0, 0.05, 0.1, 0.55, 0.99, 1.0, 2.0, np.inf], np.float32)
    got = colormap.apply(v, lut, 0.0, 1.0)
    assert (got[0] == 0).all()
    assert _indices(got[1:]).tolist() == [0, 0, 0, 0, 1, 5, 9, 9, 9, 9]
    flat = colormap.apply(v, lut, 0.5, 0.5)  # vmin == vmax: entry 0, NaN transparent
    assert (flat[0] == 0).all() and (_indices(flat[1:]) == 0).all() and (flat[1:, 3] == 255).all()


def test_apply_keeps_shape_and_takes_other_dtypes():
    lut = colormap.lut("viridis", 8)
    v = np.linspace(0, 1, 24, dtype=np.float64).reshape(2, 3, 4)
    got = colormap.apply(v, lut, 0, 1)
    assert got.shape == (2, 3, 4, 4)
    np.testing.assert_array_equal(got, colormap.apply(v.astype(np.float32), lut, 0, 1))
    np.testing.assert_array_equal(colormap.apply(np.arange(3), lut, 0, 2)[:, 0], lut[[0, 4, 7], 0])
    assert colormap.apply(np.float32(0.5), lut, 0, 1).shape == (4,)


@pytest.mark.parametrize("n", [7, 256])
def test_apply_agrees_with_matplotlib_within_one_entry(n):
    """matplotlib divides by (vmax - vmin) where the rule multiplies by a
    float32 reciprocal; they differ at most by one entry, and rarely."""
    rng = np.random.default_rng(5)
    v = rng.uniform(-0.5, 2.5, 100_000).astype(np.float32)
    lut = _index_lut(n)
    ours = _indices(colormap.apply(v, lut, -0.3, 2.2))
    norm = matplotlib.colors.Normalize(-0.3, 2.2)
    rgba = matplotlib.colors.ListedColormap(lut / 255.0)(norm(v))
    theirs = _indices(np.rint(rgba * 255).astype(np.uint8))
    assert np.abs(ours - theirs).max() <= 1
    assert np.mean(ours != theirs) < 1e-3


def test_apply_errors():
    lut = colormap.lut("viridis", 4)
    with pytest.raises(TypeError, match="lut"):
        colormap.apply([0.5], lut.astype(np.float32), 0, 1)
    with pytest.raises(ValueError, match="lut"):
        colormap.apply([0.5], lut[:, :3], 0, 1)
    with pytest.raises(ValueError, match="lut"):
        colormap.apply([0.5], lut[:0], 0, 1)
    with pytest.raises(ValueError, match="vmin"):
        colormap.apply([0.5], lut, 1, 0)
    with pytest.raises(ValueError, match="vmax"):
        colormap.apply([0.5], lut, 0, np.inf)
    with pytest.raises(ValueError, match="vmin"):
        colormap.apply([0.5], lut, 1e39, 2e39)
    with pytest.raises(TypeError, match="vmin"):
        colormap.apply([0.5], lut, "0", 1)
    with pytest.raises(TypeError, match="values"):
        colormap.apply(np.array([1j]), lut, 0, 1)


def test_value_range():
    assert colormap.value_range(np.array([np.nan, 2.0, -np.inf, -1.5, np.inf], np.float32)) == (-1.5, 2.0)
    lo, hi = colormap.value_range(np.array([0.1], np.float32))
    assert lo == hi == float(F32(0.1)) and type(lo) is float
    assert colormap.value_range(np.array([np.nan, np.inf])) == (0.0, 1.0)
    assert colormap.value_range(np.zeros((0, 3), np.float32)) == (0.0, 1.0)
    assert colormap.value_range([[3, 1], [2, 5]]) == (1.0, 5.0)


def _depth():
    d = np.full((4, 5), np.inf, np.float32)
    d[0, 0], d[1, 1], d[2, 2], d[3, 3] = 2.0, 4.0, 6.0, np.nan
    return d


def test_depth_image_transparent_where_empty_and_closer_brighter():
    d = _depth()
    img = images.depth_image(d)
    assert img.shape == (4, 5, 4) and img.dtype == np.uint8
    empty = ~np.isfinite(d)
    assert (img[empty] == 0).all() and (img[~empty, 3] == 255).all()
    magma = colormap.lut("magma")
    np.testing.assert_array_equal(img[0, 0], magma[-1])  # nearest: last entry
    np.testing.assert_array_equal(img[2, 2], magma[0])  # farthest: first entry
    assert img[0, 0, :3].astype(int).sum() > img[1, 1, :3].astype(int).sum() > img[2, 2, :3].astype(int).sum()
    clamped = images.depth_image(d, "viridis", near=3.0, far=5.0)
    viridis = colormap.lut("viridis")
    np.testing.assert_array_equal(clamped[0, 0], viridis[-1])
    np.testing.assert_array_equal(clamped[2, 2], viridis[0])
    np.testing.assert_array_equal(clamped[1, 1], viridis[128])
    assert (images.depth_image(np.full((2, 2), np.inf, np.float32)) == 0).all()


def test_depth_image_errors():
    with pytest.raises(ValueError, match="near"):
        images.depth_image(_depth(), near=5.0, far=1.0)
    with pytest.raises(ValueError, match="depth"):
        images.depth_image(np.zeros((2, 2, 1), np.float32))
    with pytest.raises(TypeError, match="depth"):
        images.depth_image(np.zeros((2, 2), np.int32))
    with pytest.raises(ValueError, match="colormap"):
        images.depth_image(_depth(), colormap="nope")


def test_velocity_images():
    v = np.full((3, 4, 2), np.nan, np.float32)
    v[0, 0] = (1.0, 0.0)  # right: angle 0
    v[0, 1] = (0.0, 2.0)  # down in the image: angle +pi/2
    v[0, 2] = (-3.0, 0.0)  # left: angle pi
    v[1, 1] = (0.0, 0.0)
    v[2, 2] = (np.nan, 1.0)  # one NaN component: empty
    angle, mag = images.velocity_images(v)
    assert angle.shape == mag.shape == (3, 4, 4)
    empty = np.isnan(v).any(axis=2)
    for img in (angle, mag):
        assert (img[empty] == 0).all() and (img[~empty, 3] == 255).all()
    twilight, inferno = colormap.lut("twilight"), colormap.lut("inferno")
    np.testing.assert_array_equal(angle[0, 0], colormap.apply(np.float32(0), twilight, -np.pi, np.pi))
    np.testing.assert_array_equal(angle[0, 1], twilight[192])
    np.testing.assert_array_equal(angle[0, 2], twilight[255])
    top = float(np.percentile(np.array([1.0, 2.0, 3.0, 0.0], np.float32), 99))
    np.testing.assert_array_equal(mag[0, 0], colormap.apply(np.float32(1.0), inferno, 0.0, top))
    np.testing.assert_array_equal(mag[1, 1], inferno[0])
    np.testing.assert_array_equal(mag[0, 2], inferno[255])
    a, m = images.velocity_images(np.full((2, 2, 2), np.nan, np.float32))
    assert not a.any() and not m.any()
    with pytest.raises(ValueError, match="vel2d"):
        images.velocity_images(np.zeros((2, 2, 3), np.float32))


def test_attribute_image():
    plane = np.array([[np.nan, 0.0], [0.5, 1.0]], np.float32)
    img = images.attribute_image(plane)
    np.testing.assert_array_equal(img, colormap.apply(plane, colormap.lut("viridis"), 0.0, 1.0))
    assert (img[0, 0] == 0).all()
    lut = colormap.lut("gray", 4)
    np.testing.assert_array_equal(
        images.attribute_image(plane, lut, vmin=0.0, vmax=2.0), colormap.apply(plane, lut, 0.0, 2.0)
    )
    with pytest.raises(ValueError, match="plane"):
        images.attribute_image(np.zeros(3, np.float32))


def test_side_by_side():
    a = np.full((2, 3, 4), 10, np.uint8)
    b = np.full((4, 1, 4), 20, np.uint8)
    out = images.side_by_side([a, b], pad=2)
    assert out.shape == (4, 6, 4)
    assert (out[:2, :3] == 10).all() and (out[2:, :3] == 0).all()
    assert (out[:, 3:5] == 0).all() and (out[:, 5:] == 20).all()
    np.testing.assert_array_equal(images.side_by_side([a], pad=7), a)
    assert images.side_by_side([a, a], pad=0).shape == (2, 6, 4)
    with pytest.raises(ValueError, match="images"):
        images.side_by_side([])
    with pytest.raises(ValueError, match=r"images\[1\]"):
        images.side_by_side([a, a[..., :3]])
    with pytest.raises(ValueError, match="pad"):
        images.side_by_side([a], pad=-1)
    with pytest.raises(TypeError, match="pad"):
        images.side_by_side([a], pad=1.5)


@pytest.mark.parametrize("channels", [None, 3, 4])
def test_save_png_round_trip(tmp_path, channels):
    rng = np.random.default_rng(0)
    shape = (5, 7) if channels is None else (5, 7, channels)
    img = rng.integers(0, 256, shape, dtype=np.uint8)
    path = images.save_png(tmp_path / "a" / "b" / "img.png", img)
    assert path == tmp_path / "a" / "b" / "img.png"
    with Image.open(path) as f:
        assert f.mode == {None: "L", 3: "RGB", 4: "RGBA"}[channels]
        np.testing.assert_array_equal(np.asarray(f), img)
    assert sorted(p.name for p in path.parent.iterdir()) == ["img.png"]


@pytest.mark.parametrize(
    "bad",
    [
        np.zeros((2, 2, 4), np.float32),
        np.zeros((2, 2, 2), np.uint8),
        np.zeros((0, 3, 4), np.uint8),
        np.zeros(5, np.uint8),
        np.zeros((2, 2, 4, 1), np.uint8),
    ],
)
def test_save_png_rejects(tmp_path, bad):
    with pytest.raises(ValueError, match="image"):
        images.save_png(tmp_path / "x.png", bad)
    assert not any(tmp_path.iterdir())


def _panel(h=30, w=50):
    a = np.zeros((h, w, 4), np.uint8)
    a[5:8, 10:15] = (200, 40, 40, 255)
    a[9, 3] = (10, 200, 10, 128)
    return a


def test_opaque_has_no_transparent_pixel():
    a = _panel()
    out = images.opaque(a, (1, 2, 3))
    assert out.shape == a.shape and out.dtype == np.uint8 and (out[..., 3] == 255).all()
    assert tuple(out[0, 0]) == (1, 2, 3, 255)  # empty: the background
    assert tuple(out[6, 12]) == (200, 40, 40, 255)  # opaque: kept
    np.testing.assert_array_equal(
        out[9, 3, :3],
        [
            (10 * 128 + 1 * 127 + 127) // 255,
            (200 * 128 + 2 * 127 + 127) // 255,
            (10 * 128 + 3 * 127 + 127) // 255,
        ],
    )
    assert (images.opaque(a)[0, 0, :3] == images.BACKGROUND).all()
    with pytest.raises(ValueError, match="background"):
        images.opaque(a, (0, 0, 300))
    with pytest.raises(ValueError, match="rgba"):
        images.opaque(a[..., :3])


def test_from_premultiplied():
    f = np.array([[[0.5, 0.25, 0.0, 0.5], [0.0, 0.0, 0.0, 0.0], [1.0, 1.0, 1.0, 1.0]]], np.float32)
    out = images.from_premultiplied(f)
    np.testing.assert_array_equal(out[0], [[255, 128, 0, 128], [0, 0, 0, 0], [255, 255, 255, 255]])


@pytest.mark.parametrize("width", [16, 64, 160, 480, 1920])
def test_label_adds_a_band_above(width):
    a = _panel(40, width)
    out = images.label(a, "temperature (viridis)")
    band = images.label_height(width)
    assert 10 <= band <= 40
    assert out.shape == (40 + band, width, 4) and out.dtype == np.uint8
    np.testing.assert_array_equal(out[band:], a)  # the image is untouched
    assert (out[:band, :, 3] == 255).all()  # the band is opaque
    text = out[:band, :, :3].astype(int)
    assert (np.abs(text - images.BAND).sum(axis=2) > 200).sum() > 5  # and has bright text
    if width >= 160:  # it fits: the font is not shrunk
        assert band >= 18


@pytest.mark.parametrize("width", [240, 320, 400])
def test_a_shrunk_label_keeps_its_spaces(width):
    """A label shrunk to fit (clvis iso's title at 320 pixels) keeps a visible
    space between its words: Pillow's default font draws a 2-pixel space at
    8 to 11 pixels, which read "rays still running" as "raysstill running"."""
    text = "isovalue 5.5, completion 0.830 (magenta: rays still running)"
    band = images.label(_panel(10, width), text)[: images.label_height(width), :, :3].astype(int)
    ink = (np.abs(band - images.BAND).sum(axis=2) > 60).any(axis=0)
    blank, runs = 0, []  # the runs of empty columns between the first and last ink
    for c in ink[int(np.argmax(ink)) :]:
        if c and blank:
            runs.append(blank)
        blank = 0 if c else blank + 1
    assert sorted(runs, reverse=True)[: text.count(" ")][-1] >= 3, runs


def test_label_cuts_text_that_does_not_fit():
    out = images.label(_panel(10, 20), "a very long label " * 20)
    assert out.shape[1] == 20
    with pytest.raises(TypeError, match="text"):
        images.label(_panel(), 3)


@pytest.mark.parametrize("name", ["viridis", "inferno", "coolwarm_r"])
@pytest.mark.parametrize("width", [2, 50, 333])
def test_colorbar_ends_are_the_colormaps_ends(name, width):
    lut = colormap.lut(name)
    bar = images.colorbar(name, -2.5, 7.0, width, title="value")
    assert bar.shape[1] == width and bar.dtype == np.uint8 and (bar[..., 3] == 255).all()
    assert bar.shape[0] >= images.label_height(width)
    np.testing.assert_array_equal(bar[0, 0], lut[0])
    np.testing.assert_array_equal(bar[0, -1], lut[-1])
    expected = colormap.apply(np.linspace(-2.5, 7.0, width), lut, -2.5, 7.0)
    np.testing.assert_array_equal(bar[0], expected)
    np.testing.assert_array_equal(images.colorbar(lut, 1.0, 1.0, width)[0, 0], lut[0])  # a flat range


def test_colorbar_errors():
    with pytest.raises(ValueError, match="vmin"):
        images.colorbar("viridis", 2.0, 1.0, 50)
    with pytest.raises(ValueError, match="width"):
        images.colorbar("viridis", 0.0, 1.0, 1)
    with pytest.raises(ValueError, match="colormap"):
        images.colorbar("nope", 0.0, 1.0, 50)


def test_compose_grid():
    a, b, c = _panel(30, 50), _panel(20, 40), _panel(10, 60)
    out = images.compose([a, b, c], columns=2, pad=3, background=(9, 8, 7))
    assert out.shape == (30 + 3 + 10, 60 + 3 + 40, 4)  # columns as wide as their widest
    np.testing.assert_array_equal(out[:30, :50], a)
    np.testing.assert_array_equal(out[:20, 63:103], b)
    np.testing.assert_array_equal(out[33:43, :60], c)
    assert tuple(out[25, 55]) == (9, 8, 7, 255) and tuple(out[31, 10]) == (9, 8, 7, 255)
    row = images.compose([a, b], pad=0, background=None)
    assert row.shape == (30, 90, 4) and (row[25:, 50:] == 0).all()
    with pytest.raises(ValueError, match="panels"):
        images.compose([])
    with pytest.raises(ValueError, match=r"panels\[1\]"):
        images.compose([a, a[..., :3]])
    with pytest.raises(ValueError, match="columns"):
        images.compose([a], columns=0)


def test_class_palette():
    from clvis.colormap import ASPRS_CLASSES, categorical, class_name, class_palette

    t = class_palette()
    assert t.shape == (256, 4) and t.dtype == np.uint8 and (t[:, 3] == 255).all()
    assert tuple(t[2, :3]) == ASPRS_CLASSES[2][1] and class_name(2) == "ground"
    assert class_name(9) == "water" and class_name(64) == "class 64"
    # every ASPRS class has its own colour, and 1 and 2 are not two blues
    assert len({tuple(t[k, :3]) for k in ASPRS_CLASSES}) == len(ASPRS_CLASSES)
    assert categorical(np.array([1, 2, 2], np.uint8)) and categorical(np.array([0.0, 6.0, 255.0]))
    assert not categorical(np.array([0.5, 2.0])) and not categorical(np.array([-1, 3]))
    assert not categorical(np.array([256.0])) and not categorical(np.array([], np.uint8))


def test_legend():
    entries = [((166, 118, 66), "2 ground"), ((50, 110, 230), "9 water")]
    a = images.legend(entries, 400)
    assert a.dtype == np.uint8 and a.shape[1] == 400 and (a[..., 3] == 255).all()
    colours = {tuple(c) for c in a[..., :3].reshape(-1, 3)}
    assert (166, 118, 66) in colours and (50, 110, 230) in colours
    # narrow: one entry a row
    assert images.legend(entries, 60).shape[0] == 2 * images.legend(entries[:1], 60).shape[0]
    with pytest.raises(ValueError, match="entries\\[0\\]"):
        images.legend([((300, 0, 0), "x")], 100)
    with pytest.raises(ValueError, match="width"):
        images.legend(entries, 1)


def test_colorbar_ends_differ_where_the_values_do():
    from clvis.images import _numbers

    assert _numbers(177.5, 576.0) == ("177.5", "576")  # 4 significant digits
    lo, hi = _numbers(1e9, 1e9 + 50)  # a cloud's z far from the origin
    assert lo != hi and float(hi) == 1e9 + 50
    assert _numbers(3.0, 3.0) == ("3", "3")
    # 5 to 7 whole digits are all shown: a scan's easting read "6.36e+05" .. "6.372e+05"
    assert _numbers(636024.3, 637155.9) == ("636024", "637156")
    assert _numbers(0.0, 65535.0) == ("0", "65535") and _numbers(2816.0, 37890.0) == ("2816", "37890")


@pytest.mark.parametrize("width", [120, 160, 200, 320])
def test_colorbar_title_never_runs_into_an_end(width):
    """The centred title is drawn only where it clears both end labels: the
    text under the ramp is the ends' own runs of columns, plus the title's
    apart from them, never a title fused to the longer end ("value1.301e+04"
    at 160 px)."""

    def runs(bar):
        band = bar[bar.shape[0] - images.label_height(width) :, :, :3].astype(int)
        ink = (np.abs(band - band[0, 0]).sum(axis=2) > 60).any(axis=0)
        cols = np.flatnonzero(ink)
        # columns with text, the glyphs of one word within 5 px of each other
        cuts = np.flatnonzero(np.diff(cols) > 5)
        return list(zip(cols[np.r_[0, cuts + 1]], cols[np.r_[cuts, len(cols) - 1]], strict=True))

    plain = runs(images.colorbar("viridis", 0.0, 13010.0, width))
    titled = runs(images.colorbar("viridis", 0.0, 13010.0, width, title="value"))
    assert len(plain) == 2 and titled[0] == plain[0] and titled[-1] == plain[-1], (plain, titled)
    assert len(titled) in (2, 3)
