"""clvis.reference.iso, the dense NumPy isosurface raycaster the OpenCL iso
family is tested against: against scikit-image's marching cubes, analytic
surfaces (sphere, planes on block boundaries), edge cases of the traversal
(camera inside, axis-parallel rays, faces), the macrocell grids against brute
force, and Marmitt's cubic root against dense sampling."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from meshes import closest_on_triangles as _closest_on_triangles
from meshes import mesh_distance as _mesh_distance
from skimage.measure import marching_cubes

from clvis import DataError, datasets
from clvis.camera import Camera, ray_buffer
from clvis.reference import iso
from clvis.reference.camera import camera_rays

# ---------------------------------------------------------------------------
# helpers


def _trilinear(vol, g):
    """The trilinear interpolant of vol [z, y, x] at index-space points g (M, 3) x, y, z."""
    n = np.array(vol.shape[::-1])
    c = np.clip(np.floor(g).astype(np.int64), 0, n - 2)
    u = g - c
    out = np.zeros(len(g))
    for dz in (0, 1):
        for dy in (0, 1):
            for dx in (0, 1):
                w = (
                    (u[:, 0] if dx else 1 - u[:, 0])
                    * (u[:, 1] if dy else 1 - u[:, 1])
                    * (u[:, 2] if dz else 1 - u[:, 2])
                )
                out += w * vol[c[:, 2] + dz, c[:, 1] + dy, c[:, 0] + dx]
    return out


def _sphere_volume(
    shape=(40, 44, 48),
    spacing=(0.5, 0.45, 0.4),
    origin=(-9.0, -10.0, -4.0),
    centre=(0.3, -0.2, 4.1),
    sign=1.0,
):
    """The distance to `centre` (world), sampled on the grid; (vol, spacing, origin)."""
    nz, ny, nx = shape
    dz, dy, dx = spacing
    z, y, x = np.meshgrid(
        np.arange(nz) * dz + origin[2],
        np.arange(ny) * dy + origin[1],
        np.arange(nx) * dx + origin[0],
        indexing="ij",
    )
    r = np.sqrt((x - centre[0]) ** 2 + (y - centre[1]) ** 2 + (z - centre[2]) ** 2)
    return (sign * r).astype(np.float32), spacing, origin


def _ray_sphere(o, d, centre, radius):
    """(t_near, t_far) of rays o + t d (d unit) with the sphere, NaN at misses."""
    oc = o - np.asarray(centre)
    b = (oc * d).sum(1)
    disc = b * b - ((oc * oc).sum(1) - radius * radius)
    with np.errstate(invalid="ignore"):
        s = np.sqrt(disc)
    return -b - s, -b + s


def _rays_of(camera, w, h):
    o, d = camera_rays(ray_buffer(camera, w, h), w, h)
    return o.astype(np.float64), d.astype(np.float64)


CAM = Camera.look_at((2.2, -2.9, 2.0), (0, 0, 0), (0, 0, 1), fov_y=40, near=0.1, far=20)


# ---------------------------------------------------------------------------
# against marching cubes


@pytest.mark.parametrize(
    "name, mean_limit, max_limit",
    [
        ("marschner_lobb", 0.05, 0.5),
        ("turbulence", 0.02, 0.35),
    ],
)
def test_hits_lie_on_the_marching_cubes_mesh(name, mean_limit, max_limit):
    ds = datasets.marschner_lobb(64) if name == "marschner_lobb" else datasets.turbulence(128)
    vol, spacing, origin = ds["volume"], ds["spacing"], ds["origin"]
    verts, faces, _, _ = marching_cubes(vol, 0.5, spacing=spacing)
    verts = verts[:, ::-1] + np.asarray(origin)  # [z, y, x] index * spacing -> world x, y, z
    img = iso.render(vol, CAM, 128, 128, 0.5, spacing, origin)
    assert img.hit.sum() > 4000
    dist = _mesh_distance(img.position[img.hit], verts, faces) / spacing[0]
    print(
        f"{name}: {img.hit.sum()} hits, distance to the mesh mean {dist.mean():.4f}, "
        f"max {dist.max():.4f} voxel"
    )
    assert dist.mean() < 0.1 and dist.mean() < mean_limit
    assert dist.max() < max_limit
    # every hit lies on the trilinear surface
    # (in the renderer's float32-rounded spacing)
    sp32 = np.asarray(spacing, np.float32).astype(np.float64)[::-1]
    g = (img.position[img.hit] - np.asarray(origin)) / sp32
    assert np.abs(_trilinear(vol.astype(np.float64), g) - 0.5).max() < 1e-9
    # and everything the image says is consistent
    proj = CAM.project(img.position[img.hit], 128, 128)
    np.testing.assert_allclose(proj.depth, img.depth[img.hit], rtol=1e-5)
    assert (np.linalg.norm(img.normal[img.hit], axis=1) - 1 < 1e-12).all()
    _, d = _rays_of(CAM, 128, 128)
    assert ((img.normal.reshape(-1, 3) * d).sum(1)[img.hit.ravel()] <= 0).all()
    assert (img.rgba[img.hit, 3] == 1).all() and (img.rgba[~img.hit] == 0).all()
    assert np.isinf(img.depth[~img.hit]).all() and np.isinf(img.t[~img.hit]).all()


def test_closest_point_on_triangle_against_dense_sampling():
    rng = np.random.default_rng(1)
    a, b, c, p = (rng.normal(size=(300, 3)) for _ in range(4))
    d = np.linalg.norm(_closest_on_triangles(p, a, b, c) - p, axis=1)
    u, v = np.meshgrid(np.linspace(0, 1, 201), np.linspace(0, 1, 201))
    keep = u + v <= 1
    u, v = u[keep], v[keep]
    pts = a[:, None] + u[None, :, None] * (b - a)[:, None] + v[None, :, None] * (c - a)[:, None]
    brute = np.linalg.norm(pts - p[:, None], axis=2).min(axis=1)
    assert (d <= brute + 1e-12).all() and (brute - d).max() < 5e-3


# ---------------------------------------------------------------------------
# analytic surfaces


def _interpolation_bound(spacing, radius):
    """How far inside the sphere the isosurface of the trilinearly interpolated
    distance field can lie: the distance r is convex, so its interpolant is >= r
    (the surface lies inside), by at most sum_i h_i^2 / 8 * max d2r/dx_i^2 and
    d2r/dx_i^2 <= 1 / r."""
    return sum(h * h for h in spacing) / (8 * (radius - 0.1))


@pytest.mark.parametrize("radius", [3.0, 5.5])
def test_sphere_depth_and_normals(radius):
    vol, spacing, origin = _sphere_volume()
    centre = np.array((0.3, -0.2, 4.1))
    cam = Camera.look_at((14.0, -11.0, 9.0), centre, (0, 0, 1), fov_y=35, near=0.5, far=100)
    w, h = 64, 48
    img = iso.render(vol, cam, w, h, radius, spacing, origin)
    o, d = _rays_of(cam, w, h)
    hit = img.hit.ravel()
    bound = _interpolation_bound(spacing, radius)
    # rays well inside the silhouette hit, rays outside miss
    oc = o - centre
    closest = np.linalg.norm(oc - (oc * d).sum(1)[:, None] * d, axis=1)
    assert hit[closest < radius - bound - 0.01].all()
    assert not hit[closest > radius + 1e-6].any()
    assert hit.sum() > 200
    # the hits lie inside the sphere by at most the interpolation bound
    p = img.position.reshape(-1, 3)[hit]
    dist = np.linalg.norm(p - centre, axis=1) - radius
    print(f"sphere r={radius}: radial error {dist.min():.4f} .. {dist.max():.4f} (bound {bound:.4f})")
    assert (dist <= 1e-5).all() and (dist >= -bound).all()
    # the depth: later than the sphere's by at most bound / cos of the incidence
    t_near, _ = _ray_sphere(o, d, centre, radius)
    radial = (p - centre) / np.linalg.norm(p - centre, axis=1)[:, None]
    cos = np.abs((radial * d[hit]).sum(1))
    err = img.t.ravel()[hit] - t_near[hit]
    steep = cos > 0.5
    assert (err >= -1e-5).all() and (err[steep] <= bound / 0.5).all()
    # normals: the radial direction up to the O(h / r) error of the interpolant's gradient
    angle = np.arccos(np.clip((img.normal.reshape(-1, 3)[hit] * radial).sum(1), -1, 1))
    print(f"normal error mean {np.degrees(angle.mean()):.2f}, max {np.degrees(angle.max()):.2f} degrees")
    assert angle.max() < max(spacing) / radius and angle.mean() < 0.5 * max(spacing) / radius
    # the shading of the headlight model from the normal
    x = np.abs((img.normal.reshape(-1, 3)[hit] * d[hit]).sum(1))
    expect = np.clip(np.array([0.9, 0.75, 0.4]) * (0.15 + 0.75 * x)[:, None] + (0.3 * x**32)[:, None], 0, 1)
    np.testing.assert_allclose(img.rgba.reshape(-1, 4)[hit, :3], expect, atol=1e-6)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_camera_inside_the_volume_sees_the_sphere_from_inside(sign):
    vol, spacing, origin = _sphere_volume(sign=sign)
    centre, radius = np.array((0.3, -0.2, 4.1)), 4.0
    eye = centre + (0.4, -0.3, 0.2)
    cam = Camera.look_at(eye, eye + (1.0, 0.3, -0.2), (0, 0, 1), fov_y=90, near=0.05, far=100)
    img = iso.render(vol, cam, 32, 32, sign * radius, spacing, origin)
    o, d = _rays_of(cam, 32, 32)
    _, t_far = _ray_sphere(o, d, centre, radius)
    assert img.hit.all()
    # from inside the surface (inside the sphere) comes a little early
    err = t_far - img.t.ravel()
    assert (err >= -1e-5).all() and (err <= 2 * _interpolation_bound(spacing, radius)).all()
    # the normal faces the viewer: inwards
    p = img.position.reshape(-1, 3)
    assert ((img.normal.reshape(-1, 3) * (p - centre)).sum(1) < 0).all()


@pytest.mark.parametrize("axis", [0, 1, 2])
@pytest.mark.parametrize("plane", [8, 16])  # a block boundary; a coarse-cell boundary
@pytest.mark.parametrize("side", [-1, 1])
def test_plane_on_a_block_boundary(axis, plane, side):
    """value = index along `axis` - plane: the surface is the sample plane, which
    is a face shared by two 4^3 blocks (plane 8) or two coarse cells (16)."""
    shape = (21, 23, 34)
    spacing = (0.7, 1.1, 0.9)
    origin = np.array((-2.0, 1.5, 0.25))
    grid = np.meshgrid(*(np.arange(s) for s in shape), indexing="ij")[2 - axis]
    vol = (grid - plane).astype(np.float32)
    sp_xyz = np.asarray(spacing, np.float32).astype(np.float64)[::-1]  # as the renderer rounds it
    box = (np.array(shape[::-1]) - 1) * sp_xyz
    target = origin + 0.5 * box
    target[axis] = origin[axis] + plane * sp_xyz[axis]
    eye = target.copy()
    eye[axis] += side * 40.0
    eye[(axis + 1) % 3] += 3.0
    up = np.zeros(3)
    up[(axis + 2) % 3] = 1.0
    cam = Camera.look_at(eye, target, up, fov_y=20, near=1.0, far=200)
    img = iso.render(vol, cam, 40, 30, 0.0, spacing, tuple(origin))
    assert img.hit.mean() > 0.3
    x = img.position[img.hit][:, axis]
    assert np.abs(x - target[axis]).max() < 1e-9
    # the macrocells that hold a hit cell's minimum corner contain the isovalue
    g = (img.position[img.hit] - origin) / sp_xyz
    cell = np.clip(np.floor(g), 0, np.array(shape[::-1]) - 2).astype(int)
    blo, bhi = iso.block_ranges(vol)
    clo, chi = iso.coarse_ranges((blo, bhi))
    for lo, hi, size in ((blo, bhi, 4), (clo, chi, 16)):
        b = cell // size
        assert (lo[b[:, 2], b[:, 1], b[:, 0]] <= 0).all() and (hi[b[:, 2], b[:, 1], b[:, 0]] >= 0).all()
    # the range without the +1 dilation would have skipped the plane seen from below
    naive = vol[tuple(slice(0, 4 * (s // 4)) for s in shape)]
    nb = tuple(s // 4 for s in shape)
    naive_hi = naive.reshape(nb[0], 4, nb[1], 4, nb[2], 4).max(axis=(1, 3, 5))
    below = [slice(None)] * 3
    below[2 - axis] = plane // 4 - 1
    assert (naive_hi[tuple(below)] < 0).all()


def test_axis_parallel_rays_against_dense_sampling():
    rng = np.random.default_rng(5)
    shape = (9, 10, 11)
    vol = rng.uniform(0, 1, shape).astype(np.float32)
    origins, dirs = [], []
    for axis in range(3):
        for sign in (1.0, -1.0):
            for _ in range(40):
                o = rng.uniform(0, np.array(shape[::-1]) - 1)
                if rng.random() < 0.5:
                    o = np.round(o)  # on grid lines / faces
                o[axis] = -2.0 if sign > 0 else shape[2 - axis] + 1.0
                d = np.zeros(3)
                d[axis] = sign
                d[(axis + 1) % 3] = -0.0 if rng.random() < 0.5 else 0.0
                origins.append(o)
                dirs.append(d)
    o, d = np.array(origins), np.array(dirs)
    r = iso.render_rays(vol, o, d, 0.45)
    # dense sampling of the field along each ray inside the box
    ts = np.linspace(0, 30, 30001)
    v64 = vol.astype(np.float64)
    hi = np.array(shape[::-1]) - 1
    # a ray lying in a face plane of the box that moves outwards by the sign of its zero misses
    signbit = np.signbit(d)
    leaves = (((o == 0) & (d == 0) & signbit) | ((o == hi) & (d == 0) & ~signbit)).any(axis=1)
    assert 5 <= leaves.sum() < len(o) - 100
    for i in range(len(o)):
        g = o[i] + ts[:, None] * d[i]
        inside = ((g >= 0) & (g <= hi)).all(axis=1)
        f = _trilinear(v64, g[inside]) - np.float64(np.float32(0.45))
        tt = ts[inside]
        change = np.nonzero((f[:-1] <= 0) != (f[1:] <= 0))[0]
        if change.size == 0 or leaves[i]:
            assert not r["hit"][i]
        else:
            assert r["hit"][i]
            assert tt[change[0]] - 1e-9 <= r["t"][i] <= tt[change[0] + 1] + 1e-9


def test_rays_in_a_face_plane_follow_the_sign_of_zero():
    vol = np.zeros((5, 6, 7), np.float32)
    vol[3:] = 1.0  # surface at z = 2.5 at iso 0.5
    o = np.array([[0.0, 2.0, -3.0], [0.0, 2.0, -3.0], [6.0, 2.0, -3.0], [6.0, 2.0, -3.0]])
    d = np.array([[0.0, 0.0, 1.0], [-0.0, 0.0, 1.0], [-0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    r = iso.render_rays(vol, o, d, 0.5)
    # on the x = 0 face: +0 enters, -0 leaves at t = 0 (never reaching the box at t = 3);
    # on the x = 6 face the other way round
    np.testing.assert_array_equal(r["hit"], [True, False, True, False])
    np.testing.assert_allclose(r["t"][r["hit"]], 5.5)


def test_exact_isovalue_at_a_sample_is_a_hit():
    vol = np.zeros((4, 4, 4), np.float32)
    vol[2, 1, 1] = 1.0  # touches 1.0 exactly at one sample
    o = np.array([[1.0, 1.0, -1.0], [1.0, 1.25, -1.0]])
    d = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    r = iso.render_rays(vol, o, d, 1.0)
    np.testing.assert_array_equal(r["hit"], [True, False])
    assert r["t"][0] == 3.0 and r["margin"][0] == 0.0  # a tangential touch: unreliable
    # and a zero at the entry point is a hit at t_enter
    r = iso.render_rays(np.full((3, 3, 3), 2.0, np.float32), o, d, 2.0)
    assert r["hit"].all() and (r["t"] == 1.0).all()


def test_empty_volume_and_isovalues_outside_the_range():
    ds = datasets.marschner_lobb(24)
    vol = ds["volume"]
    args = (ds["spacing"], ds["origin"])
    for v, level in (
        (np.zeros_like(vol), 0.5),
        (vol, float(vol.max()) + 0.01),
        (vol, float(vol.min()) - 0.01),
    ):
        img = iso.render(v, CAM, 24, 20, level, *args)
        assert not img.hit.any() and (img.rgba == 0).all() and np.isinf(img.depth).all()
        assert np.isnan(img.position).all() and np.isnan(img.normal).all()
    # a constant volume at the isovalue is hit wherever a ray meets the box, normal -d
    img = iso.render(np.full((5, 5, 5), 0.5, np.float32), CAM, 24, 20, 0.5, (0.5, 0.5, 0.5), (-1, -1, -1))
    assert img.hit.any()
    _, d = _rays_of(CAM, 24, 20)
    np.testing.assert_allclose(img.normal[img.hit], -d[img.hit.ravel()])


def test_refinement_methods_meet_their_documented_accuracy():
    ds = datasets.marschner_lobb(64)
    args = (ds["volume"], CAM, 96, 96, 0.5, ds["spacing"], ds["origin"])
    exact = iso.render(*args)
    assert iso.agreement(exact, exact.hit, exact.depth)["ok"]
    illinois = iso.render(*args, refine=("illinois", 6))
    a = iso.agreement(exact, illinois.hit, illinois.depth)
    assert a["ok"] and a["depth_error"] < 1e-5
    marmitt = iso.render(*args, refine=3)
    m = iso.agreement(exact, marmitt.hit, marmitt.depth)
    print(f"Marmitt 3: {m}; Illinois 6: {a}")
    assert m["mask_mismatches"] == 0 and not m["ok"]  # the depth is not within 1e-4
    # agreement notices a flipped hit and a shifted depth
    flipped = exact.hit.copy()
    py, px = np.argwhere(iso.reliable(exact) & exact.hit)[0]
    flipped[py, px] = False
    assert iso.agreement(exact, flipped, exact.depth)["mask_mismatches"] == 1
    assert not iso.agreement(exact, exact.hit, exact.depth + 2e-4 * exact.diagonal)["ok"]


def test_spacing_and_origin_are_honoured():
    vol, spacing, origin = _sphere_volume()
    # the same world surface from a differently sampled grid
    vol2, spacing2, origin2 = _sphere_volume(
        shape=(52, 50, 64), spacing=(0.4, 0.4, 0.3), origin=(-10.0, -10.0, -2.0)
    )
    cam = Camera.look_at((14.0, -11.0, 9.0), (0.3, -0.2, 4.1), (0, 0, 1), fov_y=35, near=0.5, far=100)
    a = iso.render(vol, cam, 32, 32, 4.0, spacing, origin)
    b = iso.render(vol2, cam, 32, 32, 4.0, spacing2, origin2)
    both = a.hit & b.hit
    assert both.sum() > 100 and (a.hit ^ b.hit).sum() <= 4
    # two interpolants of the same sphere: apart by the interpolation bounds, along steep rays
    _, d = _rays_of(cam, 32, 32)
    steep = np.abs((a.normal * d.reshape(32, 32, 3)).sum(-1)) > 0.5
    bound = _interpolation_bound(spacing, 4.0) + _interpolation_bound(spacing2, 4.0)
    assert np.abs(a.depth[both & steep] - b.depth[both & steep]).max() < bound / 0.5


def test_bad_input():
    with pytest.raises(DataError, match="volume"):
        iso.render(np.zeros((4, 4)), CAM, 4, 4, 0.5)
    with pytest.raises(DataError, match="volume"):
        iso.render(np.zeros((1, 4, 4)), CAM, 4, 4, 0.5)
    bad = np.zeros((3, 3, 3))
    bad[1, 1, 1] = np.nan
    with pytest.raises(DataError, match="volume"):
        iso.render(bad, CAM, 4, 4, 0.5)
    with pytest.raises(ValueError, match="spacing"):
        iso.render(np.zeros((3, 3, 3)), CAM, 4, 4, 0.5, spacing=(1, 0, 1))
    with pytest.raises(ValueError, match="isovalue"):
        iso.render(np.zeros((3, 3, 3)), CAM, 4, 4, np.inf)
    with pytest.raises(ValueError, match="refine"):
        iso.render(np.zeros((3, 3, 3)), CAM, 4, 4, 0.5, refine=("newton", 3))
    with pytest.raises(ValueError, match="block"):
        iso.block_ranges(np.zeros((3, 3, 3)), 0)


# ---------------------------------------------------------------------------
# macrocell grids against brute force


@pytest.mark.parametrize("shape", [(2, 2, 2), (5, 9, 16), (17, 13, 8), (9, 4, 21)])
def test_block_and_coarse_ranges_against_brute_force(shape):
    rng = np.random.default_rng(sum(shape))
    vol = rng.normal(size=shape).astype(np.float32)
    lo, hi = iso.cell_ranges(vol)
    assert lo.shape == tuple(s - 1 for s in shape)
    k, j, i = (rng.integers(0, s - 1, 20) for s in shape)
    cube = np.stack([vol[k + a, j + b, i + c] for a in (0, 1) for b in (0, 1) for c in (0, 1)])
    np.testing.assert_array_equal(lo[k, j, i], cube.min(0))
    np.testing.assert_array_equal(hi[k, j, i], cube.max(0))

    blo, bhi = iso.block_ranges(vol)
    assert blo.shape == tuple(-(-s // 4) for s in shape)
    for bz, by, bx in np.ndindex(blo.shape):
        b = np.array([bz, by, bx])
        if (4 * b > np.array(shape) - 2).any():  # no cell has its minimum corner here
            assert blo[bz, by, bx] == np.inf and bhi[bz, by, bx] == -np.inf
            continue
        sl = tuple(slice(4 * x, min(4 * x + 5, s)) for x, s in zip(b, shape, strict=True))
        assert blo[bz, by, bx] == vol[sl].min() and bhi[bz, by, bx] == vol[sl].max()

    clo, chi = iso.coarse_ranges((blo, bhi), 4)
    assert clo.shape == tuple(-(-s // 4) for s in blo.shape)
    for c in np.ndindex(clo.shape):
        sl = tuple(slice(4 * x, 4 * x + 4) for x in c)
        assert clo[c] == blo[sl].min() and chi[c] == bhi[sl].max()
    # coarse over cells directly = coarse over 16-sample blocks
    np.testing.assert_array_equal(iso.block_ranges(vol, 16)[0], iso.coarse_ranges((blo, bhi))[0])


# ---------------------------------------------------------------------------
# the cubic in a cell


def _segment(local, direction):
    """Length of local + s direction inside the unit cube, s >= 0."""
    with np.errstate(all="ignore"):
        t = np.where(
            direction > 0, (1 - local) / direction, np.where(direction < 0, -local / direction, np.inf)
        )
    return t.min()


@given(
    corners=arrays(np.float64, (2, 2, 2), elements=st.floats(-1, 1)),
    local=arrays(np.float64, 3, elements=st.floats(0, 1)),
    direction=arrays(np.float64, 3, elements=st.floats(-1, 1)),
    refine=st.sampled_from([None, 3, ("illinois", 6)]),
)
def test_cubic_first_zero_against_dense_sampling(corners, local, direction, refine):
    if np.linalg.norm(direction) < 1e-3:
        direction = np.array([0.3, -0.5, 0.8])
    length = _segment(local, direction)
    c = iso.cell_cubic(corners[None], local[None], direction[None])
    s = np.linspace(0, length, 4001)
    f = _trilinear(corners, local + s[:, None] * direction)
    # the cubic is the trilinear interpolant along the segment
    np.testing.assert_allclose(c[0] + s * (c[1] + s * (c[2] + s * c[3])), f, atol=1e-12)
    found, root, margin, bracket = iso.cubic_first_zero(c, np.array([length]), refine)
    found, root = bool(found[0]), root[0]
    tol = 1e-12  # |f| below this: a float tie, either way
    changed = np.nonzero(f * np.sign(f[0]) < -tol)[0]  # strict sign changes from f(0)
    if not found:
        assert abs(f[0]) > 0 and changed.size == 0  # no sign change anywhere
        assert margin[0] > 0
        return
    assert 0 <= root <= length
    if refine is None:
        assert abs(_trilinear(corners, (local + root * direction)[None])[0]) < tol
    else:
        assert bracket[0, 0] <= root <= bracket[0, 1]
    if f[0] == 0:
        assert root == 0
    if changed.size:  # no earlier sign change was missed
        assert bracket[0, 0] <= s[changed[0]]
        if refine is None:
            assert root <= s[changed[0]] + 1e-12


def test_cubic_first_zero_on_many_random_cells():
    """The same on 4000 random cells at once, with corners near the isovalue."""
    rng = np.random.default_rng(11)
    m = 4000
    corners = rng.normal(0.3, 1.0, (m, 2, 2, 2))
    local = rng.random((m, 3))
    direction = rng.normal(size=(m, 3))
    direction /= np.linalg.norm(direction, axis=1)[:, None]
    length = np.array([_segment(a, b) for a, b in zip(local, direction, strict=True)])
    c = iso.cell_cubic(corners, local, direction)
    found, root, _, _ = iso.cubic_first_zero(c, length)
    s = np.linspace(0, 1, 1001)[None, :] * length[:, None]
    f = c[0][:, None] + s * (c[1][:, None] + s * (c[2][:, None] + s * c[3][:, None]))
    strict = f * np.sign(f[:, :1]) < -1e-12
    first = np.where(strict.any(axis=1), np.argmax(strict, axis=1), -1)
    has_change = first >= 0
    assert 500 < has_change.sum() < m - 500
    assert found[has_change].all()
    rows = np.nonzero(has_change)[0]
    assert (root[rows] <= s[rows, first[rows]] + 1e-12).all()
    assert (root[rows] >= s[rows, first[rows] - 1] - 1e-12).all()
    assert np.abs(iso.raytrace._horner(tuple(x[found] for x in c), root[found])).max() < 1e-12


# ---------------------------------------------------------------------------
# the iso datasets


def test_marschner_lobb():
    ds = datasets.marschner_lobb(65)
    v = ds["volume"]
    assert v.shape == (65, 65, 65) and v.dtype == np.float32
    assert ds["spacing"] == (2 / 64, 2 / 64, 2 / 64) and ds["origin"] == (-1.0, -1.0, -1.0)
    # at the centre: (1 - 0 + 0.25 (1 + cos(2 pi 6))) / 2.5 = 0.6
    assert v[32, 32, 32] == pytest.approx(0.6, abs=1e-6)
    # at (x, y, z) = (1, 0, -1): r = 1, rho_r = cos(0) = 1 -> (1 + 1 + 0.5) / 2.5 = 1
    assert v[0, 32, 64] == pytest.approx(1.0, abs=1e-6)
    # [z, y, x]: symmetric in x and y, not in z
    np.testing.assert_array_equal(v, v.transpose(0, 2, 1))
    assert 0 <= v.min() and v.max() <= 1
    np.testing.assert_array_equal(datasets.marschner_lobb(65)["volume"], v)
    assert datasets.marschner_lobb()["volume"].shape == (64, 64, 64)
    with pytest.raises(ValueError, match="n"):
        datasets.marschner_lobb(1)


def test_turbulence():
    ds = datasets.turbulence(64)
    v = ds["volume"]
    assert v.shape == (64, 64, 64) and v.dtype == np.float32
    assert ds["spacing"] == (2 / 63,) * 3 and ds["origin"] == (-1.0, -1.0, -1.0)
    assert v.min() == 0 and v.max() == 1 and abs(v.mean() - 0.49) < 0.02
    assert ((v == 0) | (v == 1)).mean() < 0.01
    np.testing.assert_array_equal(datasets.turbulence(64)["volume"], v)
    # a dense surface at the documented isovalue
    lo, hi = iso.block_ranges(v)
    level = datasets.TURBULENCE_ISOVALUE
    assert ((lo <= level) & (hi >= level)).mean() > 0.4
    with pytest.raises(ValueError, match="n"):
        datasets.turbulence(0)
