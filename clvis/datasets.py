"""Embedded default data, generated in closed form (no files, no downloads).

Each generator returns a plain dict::

    {"positions": (N, 3) float32, "colors": (N, 4) uint8 RGBA,
     "velocity": (N, 3) float32 or None, "attributes": {name: (N,) array}}

deterministic for a given `seed` (``numpy.random.default_rng``), with the
points in random order, so any prefix is a uniform subsample. Axes are
right-handed with z up.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ._arrays import nonnegative_int

__all__ = ["explosion", "hurricane", "marschner_lobb", "terrain", "turbulence"]

# hurricane parameters (km, m/s, hPa, K)
R_MAX_WIND = 30.0  # radius of maximum wind
V_MAX = 65.0  # maximum tangential wind, at the surface
DECAY = 0.6  # V ~ r^-DECAY outside R_MAX_WIND
TOP = 15.0  # height of the storm, km
RADIUS = 100.0  # particles lie within this radius
P_ENV, P_DROP, HOLLAND_B = 1010.0, 70.0, 1.5
SCALE_HEIGHT = 8.0  # of pressure, km
T_SURFACE, LAPSE = 301.0, 6.5  # K, K/km
WARM_CORE, WARM_CORE_R, WARM_CORE_Z = 10.0, 40.0, 10.0


def hurricane(n: int = 2_000_000, seed: int | None = 0, time: float = 0.0) -> dict:
    """A hurricane-like vortex of `n` cloud particles, centred on the z axis in
    a box about 200 x 200 x 15 km (positions in km, x, y in [-100, 100], z in
    [0, 15]).

    Particles: 40 % in the eyewall (an outward-sloping ring just outside the
    radius of maximum wind, 30 km), 35 % in four logarithmic spiral rain bands
    (pitch 15 degrees, 40-100 km), 15 % in a low inflow layer (z < 2 km) and
    10 % in the cirrus outflow canopy (z 11-15 km); the eye (r < ~24 km) is
    clear.

    Flow (m/s), counter-clockwise seen from above (northern hemisphere):

    - tangential: modified Rankine, ``V_MAX * r / R`` inside ``R = R_MAX_WIND``,
      ``V_MAX * (R / r) ** 0.6`` outside, weakening linearly with height to
      45 % at the top (warm core, thermal wind);
    - radial and vertical from an axisymmetric streamfunction ``psi(r, z)``
      (``u_r = -dpsi/dz / r``, ``w = dpsi/dr / r``): inflow in the lowest
      ~2 km, outflow above ~12 km, updraft in the eyewall, weak subsidence
      outside it;
    - plus turbulence, normal with 1 m/s per component.

    `time` (seconds, default 0) advects every particle along its tangential
    wind for that long: each turns about the axis by ``v_t(r, z) / r * time``
    (radius and height kept, so the flow field is the same), which winds the
    rain bands up the way the differential rotation of a real storm does; the
    storm a few minutes on is a time slice never seen at time 0.

    Attributes (N,) float32: ``pressure`` (hPa, a Holland profile
    ``p_c + dp * exp(-(R / r) ** 1.5)`` at the surface, 940 hPa in the eye,
    1010 hPa far out, its deficit shrinking with height, times
    ``exp(-z / 8 km)``), ``temperature`` (K, 301 K at the surface minus
    6.5 K/km, plus a warm core of 10 K at 10 km over the eye) and ``speed``
    (``|velocity|``). Colours are white-grey cloud shades, brighter aloft.
    """
    n = _count(n)
    rng = np.random.default_rng(seed)
    counts = _split(n, (0.40, 0.35, 0.15, 0.10))

    # eyewall: inner edge slopes outward with height, density skewed outward
    z_ew = TOP * rng.random(counts[0]) ** 1.3
    r_ew = R_MAX_WIND * (0.8 + 0.5 * z_ew / TOP) + rng.gamma(2.0, 3.0, counts[0])
    th_ew = rng.uniform(0.0, 2 * np.pi, counts[0])

    # rain bands: log spirals theta = 2 pi k / 4 - ln(r / 40) / tan(15 deg),
    # winding inward counter-clockwise; Gaussian cross-section 4 km wide
    pitch = np.tan(np.radians(15.0))
    r_b = _truncated_exponential(rng, counts[1], 40.0, RADIUS, 35.0)
    arm = rng.integers(0, 4, counts[1])
    th_b = (
        2 * np.pi * arm / 4
        - np.log(r_b / 40.0) / pitch
        + rng.normal(0.0, 4.0, counts[1]) / (r_b * np.sin(np.arctan(pitch)))
    )
    z_b = (9.0 - 5.0 * (r_b - 40.0) / (RADIUS - 40.0)) * rng.random(counts[1]) ** 0.8

    # inflow layer and outflow canopy
    r_in = _truncated_exponential(rng, counts[2], R_MAX_WIND, RADIUS, 50.0)
    th_in = rng.uniform(0.0, 2 * np.pi, counts[2])
    z_in = rng.exponential(0.6, counts[2]) % 2.0
    r_out = _truncated_exponential(rng, counts[3], R_MAX_WIND, RADIUS, 40.0)
    th_out = rng.uniform(0.0, 2 * np.pi, counts[3])
    z_out = 14.5 - 3.0 * (r_out - R_MAX_WIND) / (RADIUS - R_MAX_WIND) + rng.normal(0.0, 0.3, counts[3])

    r = np.concatenate([r_ew, r_b, r_in, r_out])
    theta = np.concatenate([th_ew, th_b, th_in, th_out])
    z = np.clip(np.concatenate([z_ew, z_b, z_in, z_out]), 0.0, TOP)
    order = rng.permutation(n)
    r, theta, z = r[order], theta[order], z[order]
    r = np.minimum(r, RADIUS)
    v_t = _tangential_wind(r) * (1.0 - 0.55 * z / TOP)
    time = float(time)
    if not np.isfinite(time):
        raise ValueError(f"time: expected a finite number of seconds, got {time!r}")
    if time:
        theta = theta + v_t / (1000.0 * np.maximum(r, 1e-3)) * time  # m/s over km
    cos, sin = np.cos(theta), np.sin(theta)

    u_r, w = _secondary_circulation(r, z)
    velocity = np.empty((n, 3), np.float32)
    velocity[:, 0] = u_r * cos - v_t * sin
    velocity[:, 1] = u_r * sin + v_t * cos
    velocity[:, 2] = w
    velocity += rng.standard_normal((n, 3), dtype=np.float32)

    positions = np.empty((n, 3), np.float32)
    positions[:, 0] = r * cos
    positions[:, 1] = r * sin
    positions[:, 2] = z

    deficit = P_DROP * (1.0 - np.exp(-((R_MAX_WIND / np.maximum(r, 1e-3)) ** HOLLAND_B)))
    pressure = (P_ENV - deficit * (1.0 - 0.7 * z / TOP)) * np.exp(-z / SCALE_HEIGHT)
    temperature = (
        T_SURFACE - LAPSE * z + WARM_CORE * np.exp(-((r / WARM_CORE_R) ** 2) - ((z - WARM_CORE_Z) / 4.0) ** 2)
    )

    shade = 150.0 + 100.0 * (z / TOP) ** 0.7 + rng.normal(0.0, 12.0, n)
    colors = np.empty((n, 4), np.uint8)
    colors[:, 0] = colors[:, 1] = np.clip(shade, 110, 250)
    colors[:, 2] = np.clip(shade + 5.0, 115, 255)
    colors[:, 3] = 255

    return {
        "positions": positions,
        "colors": colors,
        "velocity": velocity,
        "attributes": {
            "pressure": pressure.astype(np.float32),
            "temperature": temperature.astype(np.float32),
            "speed": np.linalg.norm(velocity, axis=1).astype(np.float32),
        },
    }


def _tangential_wind(r):
    """Modified Rankine vortex at the surface, m/s."""
    return np.where(
        r < R_MAX_WIND, V_MAX * r / R_MAX_WIND, V_MAX * (R_MAX_WIND / np.maximum(r, R_MAX_WIND)) ** DECAY
    )


def _secondary_circulation(r, z):
    """(u_r, w) in m/s from psi = A F(r) G(z), zero normal flow at z = 0 and TOP.

    F = r^6 / (r^6 + R_up^6) * exp(-(r - R_up) / 80) is 0 in the eye, steps up
    at the eyewall (updraft) and decays slowly outside (subsidence);
    G = (1 - exp(-z / 1.2)) (1 - exp(-(TOP - z) / 2.5)) turns inflow below into
    outflow aloft.
    """
    a, r_up, h_in, h_out = 1500.0, 1.15 * R_MAX_WIND, 1.2, 2.5
    r = np.maximum(r, 1e-3)
    s = r**6 / (r**6 + r_up**6)
    decay = np.exp(-(r - r_up) / 80.0)
    f = s * decay
    df = decay * (6.0 * s * (1.0 - s) / r - s / 80.0)
    e_in, e_out = np.exp(-z / h_in), np.exp(-(TOP - z) / h_out)
    g = (1.0 - e_in) * (1.0 - e_out)
    dg = e_in / h_in * (1.0 - e_out) - (1.0 - e_in) * e_out / h_out
    return -a * f * dg / r, a * df * g / r


# terrain parameters (m): buildings as (centre x, centre y, half size x, half size y, height)
BUILDINGS = np.array(
    [
        (-120.0, 80.0, 25.0, 15.0, 18.0),
        (-60.0, 110.0, 12.0, 30.0, 32.0),
        (30.0, 60.0, 35.0, 20.0, 12.0),
        (110.0, 120.0, 18.0, 18.0, 45.0),
        (-40.0, -70.0, 40.0, 12.0, 9.0),
        (90.0, -90.0, 22.0, 35.0, 24.0),
    ]
)
TREE_RADIUS, TREE_HEIGHT = 6.0, 14.0
# ASPRS LAS classes
GROUND, HIGH_VEGETATION, BUILDING = 2, 5, 6


def terrain(n: int = 1_000_000, seed: int | None = 0) -> dict:
    """An airborne LiDAR-like scan of `n` points over 400 x 400 m (positions in
    m, x, y in [-200, 200], z up): rolling ground ``z = f(x, y)`` (about 0-26 m), six
    flat-roofed box buildings (roofs and, 6 % of the points, walls), and a row
    of trees whose canopies hide 70 % of the ground below (the rest of the
    returns there are ground). Gaussian range noise 5 cm.

    ``velocity`` is None. Attributes: ``intensity`` (N,) float32 in [0, 1]
    and ``classification`` (N,) uint8 (ASPRS codes: 2 ground, 5 high
    vegetation, 6 building). Colours by height, green low to white high.
    """
    n = _count(n)
    rng = np.random.default_rng(seed)
    n_wall = _split(n, (0.94, 0.06))[1]
    n_top = n - n_wall

    # seen from above: roof, canopy or ground
    x = rng.uniform(-200.0, 200.0, n_top)
    y = rng.uniform(-200.0, 200.0, n_top)
    z = _ground(x, y)
    cls = np.full(n_top, GROUND, np.uint8)
    for cx, cy, hx, hy, h in BUILDINGS:
        inside = (np.abs(x - cx) <= hx) & (np.abs(y - cy) <= hy)
        z[inside] = _ground(cx, cy) + h
        cls[inside] = BUILDING
    # trees every 24 m along y = 25 sin(x / 50) - 10; the one nearest in x is
    # the only one whose crown can cover the point (crown radius < 12 m)
    tx = -180.0 + 24.0 * np.clip(np.rint((x + 180.0) / 24.0), 0, 15)
    ty = 25.0 * np.sin(tx / 50.0) - 10.0
    d2 = (x - tx) ** 2 + (y - ty) ** 2
    hit = (d2 < TREE_RADIUS**2) & (cls == GROUND) & (rng.random(n_top) < 0.7)
    crown = TREE_HEIGHT - 4.0 + 4.0 * np.sqrt(np.maximum(0.0, 1.0 - d2 / TREE_RADIUS**2))
    z[hit] = _ground(tx[hit], ty[hit]) + crown[hit] + rng.normal(0.0, 0.6, hit.sum())
    cls[hit] = HIGH_VEGETATION

    # walls, uniform over their area
    hx, hy, h = BUILDINGS[:, 2], BUILDINGS[:, 3], BUILDINGS[:, 4]
    area = np.stack([hx, hx, hy, hy], axis=1) * h[:, None]  # faces -y, +y, -x, +x
    face = rng.choice(area.size, n_wall, p=(area / area.sum()).ravel())
    b, side = face // 4, face % 4
    cx, cy = BUILDINGS[b, 0], BUILDINGS[b, 1]
    along = rng.uniform(-1.0, 1.0, n_wall)
    sign = np.where(side % 2 == 0, -1.0, 1.0)
    wx = np.where(side < 2, cx + along * hx[b], cx + sign * hx[b])
    wy = np.where(side < 2, cy + sign * hy[b], cy + along * hy[b])
    base = _ground(cx, cy)
    wz = base + rng.random(n_wall) * h[b]

    x, y = np.concatenate([x, wx]), np.concatenate([y, wy])
    z = np.concatenate([z, wz]) + rng.normal(0.0, 0.05, n)
    cls = np.concatenate([cls, np.full(n_wall, BUILDING, np.uint8)])
    order = rng.permutation(n)
    x, y, z, cls = x[order], y[order], z[order], cls[order]

    positions = np.stack([x, y, z], axis=1).astype(np.float32)
    reflectance = np.select([cls == GROUND, cls == HIGH_VEGETATION], [0.35, 0.25], 0.6)
    intensity = np.clip(reflectance + rng.normal(0.0, 0.08, n), 0.0, 1.0).astype(np.float32)

    stops = np.array([[40, 90, 40], [120, 160, 70], [190, 170, 120], [235, 235, 230]], np.float64)
    level = np.clip(z / 60.0, 0.0, 1.0)
    at = np.linspace(0.0, 1.0, len(stops))
    colors = np.empty((n, 4), np.uint8)
    for c in range(3):
        colors[:, c] = np.interp(level, at, stops[:, c])
    colors[:, 3] = 255

    return {
        "positions": positions,
        "colors": colors,
        "velocity": None,
        "attributes": {"intensity": intensity, "classification": cls},
    }


def _ground(x, y):
    """The ground height, m: two hills on a gentle slope with small undulations."""
    return (
        12.0
        + 0.03 * (x + y)
        + 14.0 * np.exp(-((x + 90.0) ** 2 + (y + 120.0) ** 2) / (2 * 60.0**2))
        + 9.0 * np.exp(-((x - 130.0) ** 2 + (y - 20.0) ** 2) / (2 * 45.0**2))
        + 1.5 * np.sin(x / 23.0) * np.cos(y / 31.0)
    )


def _count(n) -> int:
    return nonnegative_int("n", n)


def _split(n: int, fractions) -> list[int]:
    """Counts summing to n in the given proportions (the remainder to the last)."""
    counts = [int(n * f) for f in fractions[:-1]]
    return counts + [n - sum(counts)]


def _truncated_exponential(rng, size, lo, hi, scale):
    """Samples of lo + Exp(scale) conditioned on < hi, by inverting the CDF."""
    u = rng.random(size)
    return lo - scale * np.log1p(-u * -np.expm1(-(hi - lo) / scale))


# explosion parameters (the volume spans [-1, 1]^3)
EXPLOSION_RADIUS = 0.55  # mean radius of the fireball
EXPLOSION_SHELL = 0.22  # density falls off over this distance outside the radius
# turbulence: (frequency, amplitude) octaves of a sum of products of sines
_OCTAVES = ((3.0, 0.5), (6.1, 0.25), (12.3, 0.125), (24.7, 0.0625))


def _turbulence(x, y, z):
    """A fixed closed-form turbulence in about [-1, 1]: four octaves of products
    of sines along rotated axes (no randomness)."""
    out = np.zeros_like(x)
    for i, (f, a) in enumerate(_OCTAVES):
        c, s_ = np.cos(0.7 * i + 0.3), np.sin(0.7 * i + 0.3)
        u = c * x - s_ * y
        v = s_ * x + c * y
        w = z + 0.37 * i
        out += a * (
            np.sin(f * u + 1.1 * i) * np.sin(f * v + 0.5) * np.sin(f * w + 2.3 * i)
            + 0.5 * np.sin(f * (u + v + w) + i)
        )
    return out / 0.9


def explosion(shape: Sequence[int] = (96, 96, 96)) -> dict:
    """A fireball: a turbulent, rising density field in closed form, zero
    outside it (a sparse volume, about 11% of the voxels non-zero at the
    default size).

    Returns ``{"volume": (Z, Y, X) float32 density in [0, 1], "spacing":
    (dz, dy, dx), "origin": (x, y, z)}``: the volume spans [-1, 1]^3 in world
    space (sample [z, y, x] at origin + (x dx, y dy, z dz)).
    """
    try:
        zs, ys, xs = (nonnegative_int("shape", s) for s in shape)
    except TypeError:
        raise TypeError(f"shape: expected three integers, got {shape!r}") from None
    if min(zs, ys, xs) < 2:
        raise ValueError(f"shape: each size must be at least 2, got {tuple(shape)}")
    z, y, x = np.meshgrid(
        np.linspace(-1, 1, zs), np.linspace(-1, 1, ys), np.linspace(-1, 1, xs), indexing="ij"
    )
    n = _turbulence(x, y, z)
    # a mushroom: the fireball rises and flattens, on a narrower stem
    cz = z - 0.15
    r = np.sqrt(x * x + y * y + (1.3 * cz) ** 2)
    radius = EXPLOSION_RADIUS * (1 + 0.35 * n)
    ball = np.clip((radius - r) / EXPLOSION_SHELL + 0.5, 0, 1)
    stem_r = np.sqrt(x * x + y * y)
    stem = np.clip((0.16 * (1 + 0.4 * n) - stem_r) / 0.08, 0, 1) * (z < 0.0) * (z > -0.95)
    density = np.maximum(ball * (0.55 + 0.45 * np.clip(n + 0.3, 0, 1)), 0.6 * stem)
    density[density < 0.02] = 0.0
    step = 2.0 / (np.array([zs, ys, xs]) - 1)
    return {
        "volume": density.astype(np.float32),
        "spacing": tuple(float(v) for v in step),
        "origin": (-1.0, -1.0, -1.0),
    }


# ---------------------------------------------------------------------------
# volumes for isosurface raycasting (the iso family): dense, closed form

MARSCHNER_LOBB_FM = 6.0  # f_M
MARSCHNER_LOBB_ALPHA = 0.25  # alpha
MARSCHNER_LOBB_ISOVALUE = 0.5
TURBULENCE_ISOVALUE = 0.5
# turbulence octaves: (frequency in radians per unit, amplitude, rotation axis, angle in radians)
_TURBULENCE_OCTAVES = (
    (2.3, 1.0, (1.0, 2.0, 3.0), 0.4),
    (4.9, 0.6, (-2.0, 1.0, 1.0), 1.1),
    (9.7, 0.36, (3.0, -1.0, 2.0), 1.9),
    (19.1, 0.22, (1.0, 1.0, -2.0), 2.6),
)


def _grid_axis_coords(n: int, name: str = "n"):
    n = nonnegative_int(name, n)
    if n < 2:
        raise ValueError(f"{name}: must be at least 2, got {n}")
    return n, np.linspace(-1.0, 1.0, n)


def _cube_volume(values, n: int) -> dict:
    step = 2.0 / (n - 1)
    return {
        "volume": values.astype(np.float32, copy=False),
        "spacing": (step, step, step),
        "origin": (-1.0, -1.0, -1.0),
    }


def marschner_lobb(n: int = 64) -> dict:
    """The Marschner–Lobb test signal (Marschner & Lobb 1994) sampled on an
    n^3 grid over [-1, 1]^3 (both ends included)::

        rho(x, y, z) = (1 - sin(pi z / 2) + alpha (1 + rho_r(sqrt(x^2 + y^2)))) / (2 (1 + alpha))
        rho_r(r) = cos(2 pi f_M cos(pi r / 2))

    with f_M = 6 and alpha = 0.25; values in [0, 1]. The isosurface usually
    drawn is rho = 0.5 (``MARSCHNER_LOBB_ISOVALUE``): rings of ripples about
    the z axis on a surface near z = 0, a hard case for reconstruction filters.

    Returns ``{"volume": (n, n, n) float32 [z, y, x], "spacing": (dz, dy, dx)
    = 2 / (n - 1) each, "origin": (-1, -1, -1)}`` (sample [k, j, i] at
    origin + (i dx, j dy, k dz)). Deterministic.
    """
    n, c = _grid_axis_coords(n)
    z, y, x = np.meshgrid(c, c, c, indexing="ij")
    rho_r = np.cos(2 * np.pi * MARSCHNER_LOBB_FM * np.cos(np.pi * np.sqrt(x * x + y * y) / 2))
    rho = (1 - np.sin(np.pi * z / 2) + MARSCHNER_LOBB_ALPHA * (1 + rho_r)) / (2 * (1 + MARSCHNER_LOBB_ALPHA))
    return _cube_volume(rho, n)


def _rotation(axis, angle) -> np.ndarray:
    """Rodrigues' rotation matrix about `axis` by `angle` radians."""
    k = np.asarray(axis, np.float64) / np.linalg.norm(axis)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * kx + (1 - np.cos(angle)) * (kx @ kx)


def turbulence(n: int = 128) -> dict:
    """A dense turbulent field on an n^3 grid over [-1, 1]^3, in closed form
    (no randomness): four octaves (frequencies 2.3, 4.9, 9.7, 19.1 radians per
    unit, amplitudes 1, 0.6, 0.36, 0.22), each the product of sines along
    three axes rotated by a fixed rotation per octave plus a sine along their
    diagonal::

        p' = R_o p;  o-th term = a_o (sin(f p'x + 1.3 o) sin(f p'y + 0.7) sin(f p'z + 2.1 o)
                                      + 0.5 sin(f (p'x + p'y + p'z) / sqrt(3) + o))
        value = clamp(0.5 + 0.5 * sum / 1.6, 0, 1)

    (R_o: the rotation about the axis by the angle in ``_TURBULENCE_OCTAVES``.)
    Values lie in [0, 1] (0.3 % clamped), mean about 0.49. The isosurface
    value 0.5 (``TURBULENCE_ISOVALUE``) is a labyrinth of sheets filling the
    whole volume: in a frame filled by the volume 96 % of the rays hit, after
    a median of 31 cells at n = 128 (16 at n = 64), and about a quarter of the 4^3 blocks hold surface
    at n = 128 (45 % at n = 64). The finest octave has a wavelength of about
    0.33, i.e. 21 samples at n = 128 (10 at n = 64).

    Returns ``{"volume": (n, n, n) float32 [z, y, x], "spacing": 2 / (n - 1)
    each, "origin": (-1, -1, -1)}``.
    """
    n, c = _grid_axis_coords(n)
    out = np.empty((n, n, n), np.float32)
    # z slabs of about 2^20 samples: the float64 temporaries (coordinates,
    # rotated coordinates, sines) are a slab's, not the volume's (at n = 512
    # the whole-volume arrays needed 13 GB; now the peak is the float32
    # result plus about 0.2 GB); the arithmetic per sample is unchanged
    step = max(1, (1 << 20) // (n * n))
    rotations = [_rotation(axis, angle).T for _, _, axis, angle in _TURBULENCE_OCTAVES]
    for z0 in range(0, n, step):
        z, y, x = np.meshgrid(c[z0 : z0 + step], c, c, indexing="ij")
        p = np.stack([x, y, z], axis=-1)
        total = np.zeros(x.shape)
        for o, ((f, a, _, _), rot) in enumerate(zip(_TURBULENCE_OCTAVES, rotations, strict=True)):
            q = p @ rot
            sines = np.sin(f * q[..., 0] + 1.3 * o) * np.sin(f * q[..., 1] + 0.7)
            sines = sines * np.sin(f * q[..., 2] + 2.1 * o)
            total += a * (sines + 0.5 * np.sin(f * q.sum(axis=-1) / np.sqrt(3.0) + o))
        out[z0 : z0 + step] = np.clip(0.5 + 0.5 * total / 1.6, 0.0, 1.0)
    return _cube_volume(out, n)
