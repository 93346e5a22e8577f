"""Scenes and the Python entry point (no browser)."""

import json
import re
import urllib.request
from pathlib import Path

import numpy as np
import pytest

import clvis
from clvis.raster import filter_gbuffers
from clvis.view import Orbit, PointScene, VolumeScene, scene_for

pytest.importorskip("tornado", reason="the view extra (tornado) is not installed")

VDB = Path(__file__).resolve().parents[1] / "data" / "openvdb_small.vdb"


@pytest.fixture(scope="module")
def points():
    rng = np.random.default_rng(2)
    pos = rng.random((5000, 3)).astype(np.float32)
    return clvis.PointCloud(pos, attributes={"height": pos[:, 2] * 10})


def test_settings_are_checked(points):
    s = PointScene(points)
    assert s.choices["color_by"] == ["height"]
    assert s.modes == ["points", "lidar", "narvis-scan", "gaussians", "narvis-scan|gaussians"]
    s.update({"colormap": "magma", "point_size": 3})
    assert s.settings["colormap"] == "magma" and s.settings["point_size"] == 3
    for bad, msg in (
        ({"mode": "narvis"}, "mode: expected one of"),  # no velocity: narvis-scan, not narvis
        ({"point_size": 99}, "point_size: expected 1..16"),
        ({"point_size": "big"}, "expected a number"),
        ({"path": "/etc/passwd"}, "unknown setting 'path'"),
    ):
        with pytest.raises(ValueError, match=msg):
            s.update(bad)
    assert s.settings["point_size"] == 3  # a refused change changes nothing


def test_point_size_and_colormap_change_the_picture(points):
    s = PointScene(points)
    cam = Orbit(s.lo, s.hi, points=s.fit_points).camera(1.0)
    one = next(s.frames(cam, 96, 96, s.settings, lambda: False)).image
    s.update({"point_size": 3})
    three = next(s.frames(cam, 96, 96, s.settings, lambda: False)).image
    from clvis.images import BACKGROUND

    bg = np.array(BACKGROUND)
    assert (three != bg).any(axis=2).sum() > (one != bg).any(axis=2).sum()


def test_progressive_iso_stops_when_superseded():
    vol = clvis.datasets.marschner_lobb(32)["volume"]
    s = VolumeScene(vol, isovalue=0.5)
    cam = Orbit(s.lo, s.hi).camera(1.0)
    full = list(s.frames(cam, 64, 64, s.settings, lambda: False))
    assert len(full) >= 2 and full[-1].final and not full[0].final
    assert [f.info["pass"] for f in full] == list(range(1, len(full) + 1))
    cut = list(s.frames(cam, 64, 64, s.settings, lambda: True))  # a newer view came at once
    assert len(cut) == 1 and not cut[0].final


def test_a_volumes_default_isovalue_is_the_commands_otsu_threshold():
    """clvis.view(array) took the middle of the range, clvis iso and clvis view
    FILE Otsu's threshold: on a scan with a bright outlier (nibabel's
    anatomical.nii: the middle drew a few blobs) the Python call drew another
    surface than the commands."""
    from clvis.io.volumes import otsu_level

    rng = np.random.default_rng(0)
    vol = rng.normal(100.0, 10.0, (24, 24, 24)).astype(np.float32)
    vol[6:18, 6:18, 6:18] += 300.0  # the tissue
    vol[0, 0, 0] = 5000.0  # one bright sample: the range's middle is 2500, above every tissue sample
    s = scene_for(vol)
    assert s.settings["isovalue"] == pytest.approx(otsu_level(vol))
    assert 150.0 < s.settings["isovalue"] < 350.0


def test_a_new_frame_size_trims_the_c_heap_after_its_frames(monkeypatch):
    """A size beyond the kept ones gives the pool's held blocks back; after
    that size's frames the C heap is trimmed too (trim_heap): the freed
    buffers' and arrays' pages stayed in glibc's heap, 3.6 MB a window size."""
    from clvis.runtime import memory
    from clvis.view.scenes import view_frames

    trims = []
    monkeypatch.setattr(memory, "trim_heap", lambda: trims.append(1) or True)
    s = VolumeScene(clvis.datasets.marschner_lobb(16)["volume"], isovalue=0.5)
    cam = Orbit(s.lo, s.hi).camera(1.0)
    for size in ((40, 40), (48, 48), (40, 40), (48, 48)):  # the kept sizes: no trim
        list(view_frames(s, cam, *size, s.settings, lambda: False))
    assert trims == []
    list(view_frames(s, cam, 56, 56, s.settings, lambda: False))  # a third size
    assert trims == [1, 1]  # free_held's, before its frames, and view_frames', after them
    list(view_frames(s, cam, 56, 56, s.settings, lambda: False))
    assert trims == [1, 1]


def test_scene_for_rejects_what_it_cannot_show():
    with pytest.raises(TypeError, match="clvis.view: expected"):
        scene_for(np.zeros((4, 4)))


def test_clvis_view_in_python(points):
    v = clvis.view(points, width=640, height=360)
    try:
        html = v._repr_html_()
        assert "<iframe" in html and v.url in html and 'width="640"' in html
        with urllib.request.urlopen(v.url, timeout=10) as r:
            assert r.status == 200
        assert isinstance(clvis.view, type(json)) and callable(clvis.view)  # the module, callable
        assert clvis.view.Viewer is type(v)
    finally:
        v.close()


def test_gaussian_modes_draw_something(points):
    from clvis.images import BACKGROUND

    bg = np.array(BACKGROUND)
    s = PointScene(points)
    s.update({"mode": "gaussians"})
    cam = Orbit(s.lo, s.hi, points=s.fit_points).camera(1.0)
    f = next(s.frames(cam, 48, 48, s.settings, lambda: False))
    assert f.info["gaussians"] == 5000 and (f.image != bg).any(axis=2).mean() > 0.05
    v = VolumeScene(clvis.datasets.marschner_lobb(24)["volume"], isovalue=0.5)
    v.update({"mode": "gaussians", "lod": "low"})
    f = next(v.frames(Orbit(v.lo, v.hi).camera(1.0), 48, 48, v.settings, lambda: False))
    assert f.info["gaussians"] > 0 and (f.image != bg).any(axis=2).mean() > 0.05


def test_hemisphere_presets_are_the_narvis_views(points):
    from clvis.view import ViewServer

    s = ViewServer(PointScene(points))
    try:
        cams = list(clvis.hemisphere_cameras(s.orbit.lo, s.orbit.hi))
        for k in (0, 37, 127):
            s.handle({"type": "preset", "hemisphere": k})
            assert np.allclose(s.orbit.eye, cams[k].eye) and np.allclose(
                s.orbit.target, (s.orbit.lo + s.orbit.hi) / 2
            )
        for bad in (128, -1, "3", True):
            with pytest.raises(ValueError, match="hemisphere: expected a view 0..127"):
                s.handle({"type": "preset", "hemisphere": bad})
    finally:
        s.close()
    one = ViewServer(PointScene(np.array([[1.0, 2.0, 3.0]], np.float32)))
    try:  # one point: the presets look from the orbit's unit sphere too, not from 1e-4 away
        one.handle({"type": "preset", "hemisphere": 3})
        assert 1.0 < one.orbit.distance < 10.0
    finally:
        one.close()


def test_split_views_show_both_sides_and_the_psnr():
    from clvis.view.scenes import psnr, split

    a, b = np.zeros((4, 6, 3), np.uint8), np.full((4, 6, 3), 255, np.uint8)
    assert psnr(a, a) == float("inf") and psnr(a, b) == 0.0
    both = split(a, b)
    assert (both[:, :2] == 0).all() and (both[:, 4:] == 255).all() and (both[:, 2:4] == 200).all()

    d = clvis.datasets.hurricane(20_000)
    cloud = clvis.PointCloud(d["positions"], attributes=d["attributes"], velocity=d["velocity"])
    s = PointScene(cloud)
    assert s.modes == ["points", "lidar", "narvis", "gaussians", "narvis|gaussians"]  # a velocity
    s.update({"mode": "narvis|gaussians", "color_by": "temperature"})
    f = next(s.frames(Orbit(s.lo, s.hi, points=s.fit_points).camera(1.0), 64, 64, s.settings, lambda: False))
    assert 5 < f.info["psnr dB"] < 60 and f.times["post"] > 0

    v = VolumeScene(clvis.datasets.marschner_lobb(32)["volume"], isovalue=0.5)
    v.update({"mode": "infill|iso"})
    f = next(v.frames(Orbit(v.lo, v.hi).camera(1.0), 64, 64, v.settings, lambda: False))
    assert f.info["fast completion"] >= 0.85 and f.info["slow completion"] == 1.0
    assert f.info["psnr dB"] > 15 and f.final


def test_the_in_fill_split_stops_near_its_completion_and_says_the_right_side_is_complete():
    """infill|iso on a 64^3 volume: the left half is the in-fill over the
    rays still running at 85 %, not at 99 % (the speculative passes went
    70 % -> 99 %: the page showed "completion 0.99" and looked stuck short
    of the end), and the frame names each side's completion."""
    d = clvis.datasets.marschner_lobb(64)
    v = VolumeScene(d["volume"], d["spacing"], d["origin"], 0.5)
    v.update({"mode": "infill|iso"})
    frames = list(v.frames(Orbit(v.lo, v.hi).camera(1.5), 96, 64, v.settings, lambda: False))
    assert len(frames) == 1 and frames[0].final
    info = frames[0].info
    assert 0.85 <= info["fast completion"] < 0.95, info
    assert info["slow completion"] == 1.0 and "completion" not in info


@pytest.mark.parametrize("mode", ["narvis", "narvis|gaussians"])
def test_narvis_modes_name_the_file_and_point_of_a_nan_velocity(mode):
    # "vel_x: 1 covered pixels with a NaN or infinite value" (narvis) or a
    # velocity message without the file (the split); a point never drawn (a NaN
    # coordinate) does not count, and the index is the file's
    d = clvis.datasets.hurricane(5_000)
    pos, vel = d["positions"].copy(), d["velocity"].copy()
    pos[2, 0] = vel[2, 0] = np.nan
    vel[40, 2] = np.inf
    s = PointScene(clvis.PointCloud(pos, attributes=d["attributes"], velocity=vel), description="storm.ply")
    s.update({"mode": "points", "color_by": "temperature"})
    cam = Orbit(s.lo, s.hi, points=s.fit_points).camera(1.0)
    assert next(s.frames(cam, 48, 48, s.settings, lambda: False)).image.std() > 0  # points mode: as ever
    s.update({"mode": mode})
    with pytest.raises(
        clvis.DataError, match=r"^storm\.ply: velocity: point 40 is \[.*, inf\], not finite \(1 of"
    ):
        next(s.frames(cam, 48, 48, s.settings, lambda: False))


def test_frames_are_the_renderers_pictures_over_the_background():
    """What a still frame shows, written out in NumPy from the renderers' own
    outputs: the fast paths (no screen velocity for points, 32-bit pixel
    compositing, device G-buffers for the networks) change no pixel."""
    from clvis.images import BACKGROUND

    bg = np.array(BACKGROUND, np.uint8)
    d = clvis.datasets.hurricane(20_000)
    cloud = clvis.PointCloud(d["positions"], attributes=d["attributes"], velocity=d["velocity"])
    s = PointScene(cloud)
    s.update({"color_by": "temperature", "point_size": 2})
    cam = Orbit(s.lo, s.hi, points=s.fit_points).camera(80 / 64)
    g = s.raster.render(cam, 80, 64, color_by="temperature", point_size=2)
    f = next(s.frames(cam, 80, 64, s.settings, lambda: False))
    want = np.where((g.index != 0xFFFFFFFF)[..., None], g.rgba[..., :3], bg)
    assert f.image.shape == (64, 80, 3) and f.image.dtype == np.uint8
    np.testing.assert_array_equal(f.image, want)
    assert f.info["points read"] > 0

    s.update({"mode": "narvis"})
    f = next(s.frames(cam, 80, 64, s.settings, lambda: False))
    g1 = s.raster.render(cam, 80, 64, color_by="temperature", point_size=1, planes=[])
    rgba = s._net("narvis")(g1)  # host G-buffers in
    assert (rgba[..., 3] == 255).all()
    np.testing.assert_array_equal(f.image, rgba[..., :3])

    v = VolumeScene(clvis.datasets.marschner_lobb(32)["volume"], isovalue=0.5)
    vcam = Orbit(v.lo, v.hi).camera(1.0)
    frames = list(v.frames(vcam, 64, 64, v.settings, lambda: False))
    passes = list(v.iso.passes(vcam, 64, 64, 0.5))
    assert len(frames) == len(passes) >= 2
    for fr, img in zip(frames, passes, strict=True):
        rgb = np.clip(np.rint(img.rgba[..., :3] * 255), 0, 255).astype(np.uint8)
        want = np.where(img.hit[..., None], rgb, bg)
        want[img.active & ~img.hit] = (70, 40, 75)
        np.testing.assert_array_equal(fr.image, want)


def test_jpeg_of_a_composited_frame_reads_its_pixels_in_place():
    from clvis.view.scenes import _over_background
    from clvis.view.server import _rgbx, encode_jpeg

    rng = np.random.default_rng(5)
    rgba = rng.integers(0, 256, (40, 56, 4), dtype=np.uint8)
    image = _over_background(rgba, rng.random((40, 56)) < 0.5)
    assert _rgbx(image) is not None  # the (H, W, 4) array under the RGB view
    flat = np.ascontiguousarray(image)
    assert _rgbx(flat) is None and _rgbx(rgba[1:, :, :3]) is None
    for q in (75, 92):
        assert encode_jpeg(image, q) == encode_jpeg(flat, q)


def test_a_still_progressive_view_starts_with_its_first_pass_at_the_preview_size(points):
    from clvis.view.scenes import view_frames

    v = VolumeScene(clvis.datasets.marschner_lobb(32)["volume"], isovalue=0.5)
    orbit = Orbit(v.lo, v.hi)
    cam, small = orbit.camera(96 / 64), (orbit.camera(48 / 32), 48, 32)
    frames = list(view_frames(v, cam, 96, 64, v.settings, lambda: False, small))
    first, rest = frames[0], frames[1:]
    assert first.image.shape == (32, 48, 3) and not first.final
    assert first.info["preview"] == "48x32" and first.info["pass"] == 1
    plain = list(v.frames(cam, 96, 64, v.settings, lambda: False))
    assert len(rest) == len(plain) >= 2 and rest[-1].final
    for a, b in zip(rest, plain, strict=True):  # then the full-size passes, unchanged
        np.testing.assert_array_equal(a.image, b.image)
    cut = list(view_frames(v, cam, 96, 64, v.settings, lambda: True, small))
    assert len(cut) == 1 and "preview" in cut[0].info  # superseded: the preview only
    # not progressive (one frame a view): the frame alone
    s = PointScene(points)
    pcam = Orbit(s.lo, s.hi, points=s.fit_points).camera(1.5)
    only = list(view_frames(s, pcam, 96, 64, s.settings, lambda: False, (pcam, 48, 32)))
    assert len(only) == 1 and only[0].image.shape == (64, 96, 3) and "preview" not in only[0].info


@pytest.fixture(scope="module")
def scan():
    """A coloured cloud without velocity: a LAS-like aerial strip scan."""
    from clvis.training.data import aerial_scene

    d = aerial_scene(8000, 3)
    return clvis.PointCloud(d["positions"], colors=d["colors"], attributes={"height": d["positions"][:, 2]})


def test_the_viewer_filters_what_narvis_scan_reads():
    """The viewer's narvis-scan frames read the G-buffers through the
    network's depth filter (its spec's): on a close view of the scanned
    object its far side shows through the near surface's gaps and the
    filter empties those pixels; the other networks read theirs as given."""
    from clvis import post
    from clvis.training import data
    from clvis.view.scenes import _prefiltered

    sc = data.scan_scene("object", 30000, 11)
    cams = data.scan_cameras(sc, np.random.default_rng(4), 4, 1.0)
    net = post.load("narvis-scan")
    removed = 0
    for cam in cams:
        g = sc.gbuffers(sc.rasterizer(), cam, 96, 96, net.planes)
        f = _prefiltered(net, g)
        want = filter_gbuffers(g, *net.spec.depth_filter)
        np.testing.assert_array_equal(np.asarray(f.index), want.index)
        removed += f.stats["depth_filter_removed"]
    assert removed > 0
    lidar = post.load("lidar")
    assert lidar.spec.depth_filter is None and _prefiltered(lidar, g) is g


def test_narvis_scan_mode_for_clouds_without_velocity(scan, monkeypatch):
    """A cloud without velocity gets narvis-scan and its split view; the radius
    plane is the points' knn_sigma, computed once per cloud (not per frame, not
    per mode), and the frames are the network on a Rasterizer with that radius
    and the 3DGS splat of the isotropic Gaussians it was trained to predict."""
    from clvis.gauss import points as gpoints
    from clvis.training.data import SCAN_K, ScanScene

    real = gpoints.knn_sigma
    calls = []

    def counted(positions, k=4):
        calls.append(k)
        return real(positions, k)

    monkeypatch.setattr(gpoints, "knn_sigma", counted)
    s = PointScene(scan)
    assert s.modes == ["points", "lidar", "narvis-scan", "gaussians", "narvis-scan|gaussians"]
    assert s.scan_radius is None and not s.raster.has_radius and calls == []  # nothing until chosen
    cam = Orbit(s.lo, s.hi, points=s.fit_points).camera(80 / 64)
    before = next(s.frames(cam, 80, 64, s.settings, lambda: False)).image
    s.update({"mode": "narvis-scan"})
    first = next(s.frames(cam, 80, 64, s.settings, lambda: False))
    again = next(s.frames(cam, 80, 64, s.settings, lambda: False))
    assert calls == [SCAN_K] and first.times["build"] > 0 and "build" not in again.times
    assert first.times["post"] > 0 and first.info["inference ms"] > 0
    radius = real(scan.positions, SCAN_K)
    np.testing.assert_array_equal(s.scan_radius, radius)

    g = clvis.Rasterizer(scan, radius=radius).render(cam, 80, 64, planes=[])  # host G-buffers
    assert np.asarray(g.radius_px)[g.covered].min() > 0
    net = s._net("narvis-scan")
    rgba = net(filter_gbuffers(g, *net.spec.depth_filter))  # its pipeline: the depth filter first
    assert (rgba[..., 3] == 255).all() and rgba[..., :3].std() > 0
    np.testing.assert_array_equal(first.image, rgba[..., :3])
    np.testing.assert_array_equal(again.image, rgba[..., :3])

    s.update({"mode": "narvis-scan|gaussians"})
    f = next(s.frames(cam, 80, 64, s.settings, lambda: False))
    assert calls == [SCAN_K]  # the split view reuses the radius
    assert 5 < f.info["psnr dB"] < 60 and f.times["post"] > 0 and f.info["slow ms"] > 0
    target = ScanScene(clvis.PointCloud(scan.positions, colors=scan.colors, radius=radius), "landscape", "t")
    slow = target.gaussian_renderer().render(cam, 80, 64).to_uint8((0, 0, 0))[..., :3]
    np.testing.assert_array_equal(f.image[:, :39], rgba[:, :39, :3])  # the network, a line, the target
    np.testing.assert_array_equal(f.image[:, 41:], slow[:, 41:])

    # coloured by an attribute through a colormap: both sides in those colours
    s.update({"color_by": "height", "colormap": "magma"})
    h = next(s.frames(cam, 80, 64, s.settings, lambda: False))
    assert 5 < h.info["psnr dB"] < 60 and (h.image[:, 41:] != f.image[:, 41:]).any() and calls == [SCAN_K]

    # the plain points from the Rasterizer with the radius: the same picture as before
    s.update({"mode": "points", "color_by": "rgb"})
    np.testing.assert_array_equal(next(s.frames(cam, 80, 64, s.settings, lambda: False)).image, before)


def test_gaussian_modes_take_the_finite_points(scan):
    """A cloud with a NaN / infinite point shows in the points mode (the
    rasterizer drops it); the Gaussian modes take the same points (they raised
    DataError: the kNN radius and gaussians_from_points refuse them), and give
    the pictures of the cloud without them."""
    pos = scan.positions.copy()
    pos[7, 0], pos[100, 2] = np.nan, -np.inf
    holes = clvis.PointCloud(pos, colors=scan.colors, attributes=scan.attributes)
    finite = np.isfinite(pos).all(axis=1)
    s, clean = PointScene(holes), PointScene(holes.subset(finite))
    cam = Orbit(clean.lo, clean.hi, points=clean.fit_points).camera(80 / 64)
    for mode in ("gaussians", "narvis-scan", "narvis-scan|gaussians"):
        s.update({"mode": mode})
        clean.update({"mode": mode})
        got = next(s.frames(cam, 80, 64, s.settings, lambda: False)).image
        want = next(clean.frames(cam, 80, 64, clean.settings, lambda: False)).image
        assert got.std() > 0, mode
        np.testing.assert_array_equal(got, want, err_msg=mode)
    assert s.scan_radius is not None and s.scan_radius[~finite].tolist() == [0, 0]
    np.testing.assert_array_equal(s.scan_radius[finite], clean.scan_radius)


def test_the_camera_text_of_a_georeferenced_cloud_renders_it_with_clvis_render(tmp_path, capsys):
    """A LAS-like cloud far from 0 (UTM): the viewer keeps positions relative
    to the cloud's origin, the camera it shows is in the file's coordinates,
    to enough digits, and `clvis render` with it draws the points (the text
    once gave the local coordinates: a blank picture). A camera typed in
    the page is in the file's coordinates too."""
    from clvis import cli
    from clvis.view import ViewServer

    rng = np.random.default_rng(3)
    world = rng.uniform((635_000.0, 4_850_000.0, 100.0), (635_300.0, 4_850_200.0, 160.0), (4000, 3))
    origin = world.min(axis=0)
    path = tmp_path / "utm.npz"
    np.savez(path, positions=world)
    s = ViewServer(PointScene(clvis.PointCloud(world - origin, origin=origin)))
    try:
        state = s.orbit.state(s.scene.file_origin)
        assert np.allclose(state["eye"], s.orbit.eye + origin) and np.allclose(
            state["target"], s.orbit.target + origin
        )
        cli_text = state["cli"]
        eye = [float(v) for v in cli_text.split("--eye ")[1].split()[0].split(",")]
        assert abs(eye[0] - state["eye"][0]) < 1e-3  # not 6 significant digits (635155 for 635155.219)
        s.orbit.zoom(0.5)  # move away, then type the camera back in
        s.handle({"type": "camera", "eye": state["eye"], "target": state["target"]})
        assert np.allclose(s.orbit.eye + origin, state["eye"]) and np.allclose(
            s.orbit.target + origin, state["target"]
        )
    finally:
        s.close()
    rc = cli.main(["render", str(path), *cli_text.split(), "--size", "96x64", "--out", str(tmp_path / "png")])
    out, err = capsys.readouterr()
    assert rc == 0, err
    covered = re.search(r"covered\s+([\d,]+) of", out)
    assert covered is not None and int(covered.group(1).replace(",", "")) > 200, out
    # clvis gauss reads the same text in the same coordinates
    rc = cli.main(["gauss", str(path), *cli_text.split(), "--size", "96x64", "--out", str(tmp_path / "g")])
    out, err = capsys.readouterr()
    assert rc == 0, err
    row = [line.split() for line in out.splitlines() if line.startswith("  points ")][-1]
    assert float(row[-2]) > 0.5, out  # hits a ray


def test_gaussians_mode_takes_the_colormap(points):
    # it drew viridis whatever the page's colormap
    s = PointScene(points)
    cam = Orbit(s.lo, s.hi, points=s.fit_points).camera(1.0)
    pictures = {}
    for cmap in ("viridis", "turbo", "viridis"):
        s.update({"mode": "gaussians", "colormap": cmap})
        f = next(s.frames(cam, 48, 48, s.settings, lambda: False))
        if cmap in pictures:  # back to viridis: the same picture again
            assert (f.image == pictures[cmap]).all()
        pictures[cmap] = f.image
    diff = np.abs(pictures["turbo"].astype(int) - pictures["viridis"].astype(int)).max(axis=2)
    assert (diff > 30).mean() > 0.02


def test_a_resized_window_does_not_grow_the_memory_pool():
    """Frames at many sizes (a window edge dragged): the queue's pool keeps
    held blocks of the last two sizes only, not one set a size (a volume
    grew the server by ~20 MB a size)."""
    from clvis import runtime

    s = VolumeScene(clvis.datasets.marschner_lobb(24)["volume"], isovalue=0.5)
    pool = runtime.allocator(s.iso.queue)
    held = []
    for i in range(8):
        w, h = 96 + 8 * i, 64 + 4 * i
        for _ in s.frames(Orbit(s.lo, s.hi).camera(w / h), w, h, dict(s.settings), lambda: False):
            pass
        held.append(pool.held_blocks)
    assert max(held[3:]) <= max(held[:3]) + 2, held
    # the still and the interaction size alternating keep their blocks
    s._sizes = ()
    for w in (120, 60, 120, 60):
        for _ in s.frames(Orbit(s.lo, s.hi).camera(2.0), w, w // 2, dict(s.settings), lambda: False):
            pass
    assert s._sizes == ((120, 60), (60, 30))


def test_the_pages_sizes_keep_their_blocks_and_a_closed_pages_go_back():
    """Two pages (the server sets kept_sizes to 4): their still and
    interaction sizes keep the pool's blocks; when one closes, release()
    drops its sizes and the pool gives back what it holds. However many
    pages, the kept sizes stay within KEEP_PIXELS."""
    from clvis import runtime
    from clvis.view.scenes import KEEP_PIXELS

    s = VolumeScene(clvis.datasets.marschner_lobb(24)["volume"], isovalue=0.5)
    pool = runtime.allocator(s.iso.queue)
    s.kept_sizes = 4
    sizes = [(96, 64), (48, 32), (80, 80), (40, 40)]
    for _ in range(2):
        for w, h in sizes:
            for _ in s.frames(Orbit(s.lo, s.hi).camera(w / h), w, h, dict(s.settings), lambda: False):
                pass
    assert sorted(s._sizes) == sorted(sizes) and pool.held_blocks > 0
    s.release([(96, 64), (48, 32)])
    assert sorted(s._sizes) == [(40, 40), (80, 80)] and pool.held_blocks == 0
    s.kept_sizes = 16  # 8 pages of the largest frames: not 16 sizes of blocks
    for w, h in ((3840, 2160), (1920, 1080), (3840, 2000), (1920, 1000)):
        s._sized(s.iso.queue, w, h)
    assert sum(w * h for w, h in s._sizes) <= KEEP_PIXELS and s._sizes[-1] == (1920, 1000)


def test_clvis_view_takes_read_volumes_volume_with_its_spacing(tmp_path):
    """clvis.view(clvis.read_volume(path)) said 'expected ... a 3-D volume,
    got Volume of shape ()', though IsoRenderer(vol) takes it."""
    from clvis.io.volumes import Volume

    data = clvis.datasets.marschner_lobb(16)["volume"]
    vol = Volume(data, spacing=(2.0, 1.0, 0.5), origin=(1.0, 2.0, 3.0), path="ml.nii")
    s = scene_for(vol, isovalue=0.5)
    assert s.spacing == (2.0, 1.0, 0.5) and s.origin == (1.0, 2.0, 3.0)
    np.testing.assert_allclose(s.hi, np.array((1.0, 2.0, 3.0)) + 15 * np.array((0.5, 1.0, 2.0)))
    assert "ml.nii" in s.description
    assert scene_for(vol, spacing=(1.0, 1.0, 1.0)).spacing == (1.0, 1.0, 1.0)  # a given one wins
    with pytest.raises(TypeError, match="read_volume reads it"):
        scene_for(str(tmp_path / "head.nii"))


@pytest.mark.parametrize(
    "bad, err", [(float("nan"), ValueError), (float("inf"), ValueError), ("0.5", TypeError)]
)
def test_a_volumes_isovalue_is_checked(bad, err):
    with pytest.raises(err, match="isovalue"):
        VolumeScene(clvis.datasets.marschner_lobb(16)["volume"], isovalue=bad)


@pytest.mark.parametrize("port, err", [(70000, ValueError), (-1, ValueError), ("8080", TypeError)])
def test_a_port_outside_the_range_is_refused_not_wrapped(points, port, err):
    """port=70000 served on 4464 (70000 % 65536)."""
    with pytest.raises(err, match="port"):
        clvis.view(points, port=port)


def test_a_viewer_is_a_context_manager(points):
    with clvis.view(points) as v:
        assert v.url.startswith("http://127.0.0.1:")
    v.server.thread.join(10)
    assert not v.server.thread.is_alive()  # closed at the block's end


@pytest.mark.parametrize("size", [{"width": 0}, {"height": -5}, {"width": 640.5}, {"height": "360"}])
def test_the_notebook_frames_size_is_checked(points, size):
    """width=0 gave an invisible iframe without a word."""
    with clvis.view(points, width=np.int64(320)) as v:  # numpy integers do
        assert v.width == 320
    with pytest.raises(ValueError, match="notebook frame"):
        clvis.view(points, **size)


def test_narvis_scan_mode_renders_a_sparse_cloud_smaller():
    """A cloud sparse on screen (300 points in a 320x240 window: a median
    splat radius far over narvis-scan's training frames') gets the network's
    frame rendered smaller and resized up (PostNetwork.render_scale), in its
    mode and in its split view; the frame says the scale."""
    from clvis import post

    rng = np.random.default_rng(3)
    cloud = clvis.PointCloud(rng.random((300, 3)).astype(np.float32), colors=rng.integers(0, 255, (300, 3)))
    s = PointScene(cloud)
    cam = Orbit(s.lo, s.hi, points=s.fit_points).camera(320 / 240)
    s.update({"mode": "narvis-scan"})
    f = next(s.frames(cam, 320, 240, s.settings, lambda: False))
    assert f.info["post scale"] == 3 and f.image.shape == (240, 320, 3)
    net = s._net("narvis-scan")
    small = s.raster.render(cam.with_aspect(107 / 80), 107, 80, planes=[])
    want = post.resized(
        net(filter_gbuffers(small, *net.spec.depth_filter)), 320, 240, smooth=post.SCALED_SMOOTH
    )
    np.testing.assert_array_equal(f.image, want[..., :3])
    s.update({"mode": "narvis-scan|gaussians"})
    f = next(s.frames(cam, 320, 240, s.settings, lambda: False))
    assert f.info["post scale"] == 3
    np.testing.assert_array_equal(f.image[:, :159], want[:, :159, :3])


def test_scenes_load_their_networks_from_a_model_dir(tmp_path):
    """model_dir (clvis view --model-dir): the network modes load the models
    of a `clvis train --out` folder, not the package's: a copy of the shipped
    ones gives the same frames, another network's model put in its place is
    refused when the mode is chosen, and a folder that is not one is refused
    when the scene is made."""
    import shutil

    from clvis.errors import DataError
    from clvis.post.infer import MODELS

    mine = tmp_path / "mine"
    mine.mkdir()
    for f in [*MODELS.glob("infill.*"), *MODELS.glob("lidar.*")]:
        shutil.copy(f, mine / f.name)
    d = clvis.datasets.marschner_lobb(32)
    frames = []
    for where in (None, mine):
        v = VolumeScene(d["volume"], isovalue=0.5, model_dir=where)
        v.update({"mode": "infill|iso"})
        frames.append(next(v.frames(Orbit(v.lo, v.hi).camera(1.0), 64, 64, v.settings, lambda: False)))
    np.testing.assert_array_equal(frames[0].image, frames[1].image)
    for f in MODELS.glob("lidar.*"):  # another network's model where infill's was
        shutil.copy(f, mine / f.name.replace("lidar", "infill", 1))
    v = VolumeScene(d["volume"], isovalue=0.5, model_dir=mine)
    v.update({"mode": "infill|iso"})
    with pytest.raises(DataError, match="the model card is for 'lidar', not 'infill'"):
        next(v.frames(Orbit(v.lo, v.hi).camera(1.0), 64, 64, v.settings, lambda: False))
    cloud = clvis.PointCloud(np.random.default_rng(1).random((500, 3)).astype(np.float32))
    s = scene_for(cloud, model_dir=mine)
    s.update({"mode": "lidar"})
    assert s._net("lidar").path == mine / "lidar.onnx"
    with pytest.raises(DataError, match="is not a folder"):
        PointScene(cloud, model_dir=tmp_path / "nowhere")
    with pytest.raises(TypeError, match="model_dir: expected a folder's path or None"):
        VolumeScene(d["volume"], isovalue=0.5, model_dir=3)


def test_sparse_volume_scene_draws_an_openvdb_grid_and_its_threshold():
    """A .vdb grid (read_vdb's SparseVolume) in the viewer: mode gaussians,
    never made dense (mode iso: the next test); the threshold drops the active voxels at or below it,
    the colours keep the grid's whole range; a threshold above every voxel is
    an error for the page, not a crash."""
    from clvis.images import BACKGROUND
    from clvis.view import SparseScene

    path = VDB
    sv = clvis.read_vdb(path, grid="surface")  # a level set: -2..2 around the sphere
    s = scene_for(sv, description=str(path))
    assert isinstance(s, SparseScene) and s.settings["mode"] == "gaussians"
    assert "12,790 active in 94 leaves" in s.description
    assert s.choices["threshold"]["min"] == s.settings["threshold"] < 0 < s.choices["threshold"]["max"]
    cam = Orbit(s.lo, s.hi).camera(1.0)
    bg = np.array(BACKGROUND)
    s.update({"lod": "high"})
    whole = next(s.frames(cam, 64, 64, s.settings, lambda: False))
    assert whole.info["gaussians"] == 12_790 and (whole.image != bg).any(axis=2).mean() > 0.2
    s.update({"threshold": 0.0})  # the outer half of the band
    outer = next(s.frames(cam, 64, 64, s.settings, lambda: False))
    kept = int((sv.leaf_values()[sv.active_masks()] > 0).sum())
    assert outer.info["gaussians"] == kept and 0 < kept < 12_790
    assert not np.array_equal(outer.image, whole.image)
    s.update({"threshold": s.choices["threshold"]["max"]})
    with pytest.raises(clvis.DataError, match="no active voxel above the threshold"):
        next(s.frames(cam, 64, 64, s.settings, lambda: False))
    with pytest.raises(ValueError, match="threshold: expected"):
        s.update({"threshold": 99.0})
    with pytest.raises(TypeError, match="expected a clvis.SparseVolume"):
        SparseScene(np.zeros((8, 8, 8)))
    # one value (an occupancy grid): the top colour, not viridis's darkest
    ones = SparseScene(clvis.SparseVolume.from_dense(np.ones((16, 16, 16), np.float32)))
    f = next(ones.frames(Orbit(ones.lo, ones.hi).camera(1.0), 32, 32, ones.settings, lambda: False))
    centre = f.image[8:24, 8:24].astype(float) / 255 @ [0.2126, 0.7152, 0.0722]
    assert centre.mean() > 0.6  # viridis's yellow


def _iso_frames(scene, size=64):
    cam = Orbit(scene.lo, scene.hi).camera(1.0)
    return list(scene.frames(cam, size, size, scene.settings, lambda: False))


def test_an_openvdb_grid_shows_the_isosurface_clvis_iso_draws():
    """A .vdb grid in the viewer showed only its Gaussians: mode iso draws
    what clvis iso FILE.vdb draws (the grid made dense with its background,
    read_vdb_volume's volume, through VolumeScene's progressive iso, pixel
    for pixel), at its default isovalue (0 for the level set, Otsu's of the
    dense volume for the fog ball); the gaussians mode is as it was."""
    from clvis.gauss import read_vdb_volume
    from clvis.images import BACKGROUND
    from clvis.io.volumes import otsu_level
    from clvis.view import SparseScene
    from clvis.view.scenes import view_frames

    bg = np.array(BACKGROUND)
    s = scene_for(clvis.read_vdb(VDB, grid="surface"), description=str(VDB))
    assert isinstance(s, SparseScene) and s.modes == ["gaussians", "iso", "iso+infill", "infill|iso"]
    assert s.settings["mode"] == "gaussians" and s.progressive == {"iso", "iso+infill"}
    assert s.description.endswith("12,790 active in 94 leaves, a level set")
    # the isovalue's range reaches the background, the level set's outside
    assert s.settings["isovalue"] == 0.0 and s.choices["isovalue"]["max"] == 2.0
    gaussians = next(s.frames(Orbit(s.lo, s.hi).camera(1.0), 64, 64, s.settings, lambda: False))
    s.update({"mode": "iso"})
    frames = _iso_frames(s)
    v, _ = read_vdb_volume(VDB)
    want = _iso_frames(VolumeScene(v.data, v.spacing, v.origin, isovalue=0.0))
    assert len(frames) == len(want) >= 2 and frames[-1].final and not frames[0].final
    for a, b in zip(frames, want, strict=True):
        np.testing.assert_array_equal(a.image, b.image)
    assert s._dense is not None and s._dense.modes == ["iso", "iso+infill", "infill|iso"]
    assert s._dense.volume is None  # the dense copy not kept on the host: compressed on the device
    drawn = (frames[-1].image != bg).any(axis=2).mean()
    assert 0.1 < drawn < 0.4, drawn  # the sphere (a quarter of the box's view), not the box
    # a still view starts with its first pass at the preview size, as a volume's iso does
    cam = Orbit(s.lo, s.hi).camera(1.0)
    first = next(view_frames(s, cam, 64, 64, s.settings, lambda: False, (cam, 32, 32)))
    assert first.image.shape == (32, 32, 3) and first.info["preview"] == "32x32"
    s.update({"isovalue": 1.0})  # the page's isovalue: a larger sphere
    assert (_iso_frames(s)[-1].image != bg).any(axis=2).mean() > drawn
    s.update({"mode": "gaussians"})
    again = next(s.frames(Orbit(s.lo, s.hi).camera(1.0), 64, 64, s.settings, lambda: False))
    np.testing.assert_array_equal(again.image, gaussians.image)

    fog = scene_for(clvis.read_vdb(VDB, grid="density"))
    d, _ = read_vdb_volume(VDB, grid="density")
    assert fog.settings["isovalue"] == otsu_level(d.data) and 0 < fog.settings["isovalue"] < 1
    assert fog.choices["isovalue"] == {"min": 0.0, "max": float(d.data.max())}
    fog.update({"mode": "iso"})
    np.testing.assert_array_equal(
        _iso_frames(fog)[-1].image, _iso_frames(VolumeScene(d.data, d.spacing, d.origin))[-1].image
    )
    given = SparseScene(clvis.read_vdb(VDB), isovalue=-1.0, rate=4)
    assert given.settings["isovalue"] == -1.0
    given.update({"mode": "iso"})
    _iso_frames(given, 32)
    assert given._dense is not None and given._dense.iso.volume.rate == 4
    with pytest.raises(ValueError, match="isovalue: expected a finite number"):
        SparseScene(clvis.read_vdb(VDB), isovalue=float("nan"))
    only = VolumeScene(v.data, modes=("iso", "iso+infill"))
    assert only.modes == ["iso", "iso+infill"] and only.volume is None
    with pytest.raises(ValueError, match="mode: expected one of"):
        only.update({"mode": "gaussians"})
    for bad in ("iso", ["isosurface"], []):
        with pytest.raises(ValueError, match="modes: expected some of"):
            VolumeScene(v.data, modes=bad)


def test_an_openvdb_grid_too_large_to_make_dense_is_refused_in_iso_mode_only(monkeypatch):
    """Mode iso of a grid whose dense volume would not fit in host memory: a
    DeviceError naming its size before anything is made dense (the page
    shows it in its status line), and the Gaussians still draw."""
    from clvis import runtime
    from clvis.images import BACKGROUND

    s = scene_for(clvis.read_vdb(VDB), description="big.vdb")
    monkeypatch.setattr(runtime, "host_available_bytes", lambda: 100_000)
    made = []
    monkeypatch.setattr(clvis.SparseVolume, "to_dense", lambda *a: made.append(1))
    s.update({"mode": "iso"})
    with pytest.raises(clvis.DeviceError, match=r"^big\.vdb: the grid made dense is 38x39x40 voxels") as e:
        _iso_frames(s)
    assert "only 0.00 GB is available (its Gaussians need no dense copy: mode gaussians)" in str(e.value)
    assert made == [] and s._dense is None
    s.update({"mode": "gaussians"})
    f = next(s.frames(Orbit(s.lo, s.hi).camera(1.0), 48, 48, s.settings, lambda: False))
    assert f.info["gaussians"] > 0 and (f.image != np.array(BACKGROUND)).any(axis=2).mean() > 0.1


def test_in_fill_frames_lie_over_the_background_by_their_coverage():
    """iso+infill's partial passes: the in-fill network's picture is colour
    premultiplied over black with the surface's coverage as alpha, so the
    frame is that colour over the scene's background (its empty pixels the
    background, not black), as the finished passes are. LiDAR's and NARVis's
    pictures have no alpha (alpha 255: colour over black): their frames are
    the colour as predicted (test_frames_are_the_renderers_pictures_over_the_background)."""
    from clvis.images import BACKGROUND

    bg = np.array(BACKGROUND, np.float32)
    v = VolumeScene(clvis.datasets.marschner_lobb(32)["volume"], isovalue=0.5)
    v.update({"mode": "iso+infill"})
    cam = Orbit(v.lo, v.hi).camera(1.0)
    frames = list(v.frames(cam, 64, 64, v.settings, lambda: False))
    partial = 0
    for fr, img in zip(frames, v.iso.passes(cam, 64, 64, 0.5), strict=True):
        if fr.final:
            continue
        partial += 1
        assert v._infill is not None
        rgba = v._infill(img)
        a = rgba[..., 3:4].astype(np.float32) / 255
        want = np.clip(np.rint(rgba[..., :3] + (1 - a) * bg), 0, 255).astype(np.uint8)
        np.testing.assert_array_equal(fr.image, want)
        empty = rgba[..., 3] == 0
        assert empty.mean() > 0.3 and (fr.image[empty] == np.array(BACKGROUND)).all()  # not black
    assert partial >= 1


def test_a_fog_volume_grid_is_drawn_as_a_fog_in_the_viewer():
    """A .vdb grid of class "fog volume" (tests/data/openvdb_fog.vdb, written
    by OpenVDB) in mode gaussians: its low values faint (FOG_OPACITY), so its
    bright inside shows, where the same grid of no class is drawn under the
    default opacity: an opaque shell of its lowest values (dark colours)."""
    from clvis.images import BACKGROUND

    sv = clvis.read_vdb(VDB.with_name("openvdb_fog.vdb"))
    plain = clvis.read_vdb(VDB.with_name("openvdb_fog.vdb"))
    plain.grid_class = None
    pictures = []
    for v in (sv, plain):
        s = scene_for(v)
        cam = Orbit(s.lo, s.hi).camera(1.0)
        pictures.append(next(s.frames(cam, 64, 64, s.settings, lambda: False)).image)
    fog, shell = pictures
    drawn = (fog != np.array(BACKGROUND)).any(axis=2)
    lum = [(p[drawn].astype(np.float64) @ [0.2126, 0.7152, 0.0722]).max() for p in (fog, shell)]
    assert lum[0] > 1.5 * lum[1], lum  # viridis's bright top against its dark bottom


def test_a_gaussians_mode_draws_its_budget_while_the_camera_moves(monkeypatch):
    """Potree's point budget for the gaussians modes: an interaction frame
    (settings["interacting"], the server's) of more Gaussians than
    GAUSS_BUDGET draws a fixed subset of that many, each sqrt(N / budget)
    times as wide, over the whole set's colours (16 M Gaussians took 5.7 s a
    frame on 2 cores whether the camera moved or not); a still view starts
    with that frame at its size (not final), then draws them all unless it
    was superseded; a set within the budget is drawn whole, once."""
    from clvis.images import BACKGROUND
    from clvis.view import scenes

    monkeypatch.setattr(scenes, "GAUSS_BUDGET", 1000)
    rng = np.random.default_rng(5)
    xy = rng.random((8000, 2)).astype(np.float32)
    pos = np.c_[xy, 0.05 * np.sin(6 * xy[:, 0])].astype(np.float32)  # a surface: a gently waved square
    cloud = clvis.PointCloud(pos, attributes={"x": xy[:, 0].copy()})
    s = scene_for(cloud)
    s.update({"mode": "gaussians", "color_by": "x"})
    cam = Orbit(s.lo, s.hi).camera(1.0)
    preview, still = s.frames(cam, 96, 96, s.settings, lambda: False)
    (moving,) = s.frames(cam, 96, 96, {**s.settings, "interacting": True}, lambda: False)
    assert still.info == {"gaussians": 8000} and moving.info == {"gaussians": 1000, "of": 8000}
    assert preview.info == {"gaussians": 1000, "of": 8000, "preview": "budget"} and not preview.final
    assert np.array_equal(preview.image, moving.image) and still.final
    (first,) = s.frames(cam, 96, 96, s.settings, lambda: True)  # superseded after it: no full frame
    assert "preview" in first.info
    # superseded while the whole set is drawn (640x480: two bands of rows on a CPU): given up
    # after its first band, not drawn to the end while a new drag waits (a 5 s frame at 16 M)
    asked = []

    def later():
        asked.append(1)
        return len(asked) > 1  # not yet after the preview; then, at the first band, yes

    frames = list(s.frames(cam.with_aspect(640 / 480), 640, 480, s.settings, later))
    assert [f.info.get("preview") for f in frames] == ["budget"] and len(asked) == 2
    bg = np.array(BACKGROUND)
    a, b = (f.image.astype(float) for f in (still, moving))
    ca, cb = ((np.abs(img - bg).sum(axis=2) > 30) for img in (a, b))
    assert ca.mean() > 0.3 and (ca & ~cb).mean() < 0.01  # the square still covered: no holes (softer edges)
    assert np.abs(a[ca] - b[ca]).mean() < 30  # the same colours (x through viridis), not the subset's range
    assert np.array_equal(list(s.frames(cam, 96, 96, s.settings, lambda: False))[-1].image, still.image)
    monkeypatch.setattr(scenes, "GAUSS_BUDGET", 8000)  # within the budget: whole, once
    s.update({"colormap": "magma"})
    for interacting in (True, False):
        (whole,) = s.frames(cam, 96, 96, {**s.settings, "interacting": interacting}, lambda: False)
        assert whole.info == {"gaussians": 8000} and whole.final


def test_an_openvdb_grids_isosurface_gets_the_infill_network_as_a_volumes_does():
    """A .vdb grid's modes iso+infill and infill|iso: the in-fill network on
    its isosurface, frame for frame a VolumeScene's of the same dense volume
    (it offered iso alone)."""
    from clvis.gauss import read_vdb_volume

    sv = clvis.read_vdb(VDB)
    s = scene_for(sv, description=str(VDB))
    v = read_vdb_volume(VDB)[0]
    ref = scene_for(v.data, spacing=v.spacing, origin=v.origin, isovalue=s.settings["isovalue"], rate=s.rate)
    cam = Orbit(s.lo, s.hi).camera(48 / 32)
    for mode in ("iso+infill", "infill|iso"):
        s.update({"mode": mode})
        ref.update({"mode": mode})
        got = list(s.frames(cam, 48, 32, s.settings, lambda: False))
        want = list(ref.frames(cam, 48, 32, ref.settings, lambda: False))
        assert len(got) == len(want) >= 1
        for a, b in zip(got, want, strict=True):
            np.testing.assert_array_equal(a.image, b.image)
        assert got[-1].image.std() > 0
