"""Particle flows of other geometries than the hurricane, for NARVis's
held-out suite (``clvis eval narvis``): closed forms with deterministic
seeds, each a dict like ``datasets.hurricane``'s (positions (n, 3) float32,
velocity (n, 3) float32, attributes with a "temperature").

- "convection": Rayleigh–Bénard cells (steady roll flow in a 4 x 4 x 1 box,
  hot rising plumes at the cell corners, temperature from the conduction
  profile and the cells' perturbation);
- "lorenz": points along trajectories of the Lorenz attractor (sigma 10,
  rho 28, beta 8/3), velocity its vector field, temperature its z;
- "jet": a round buoyant jet along z that spreads linearly and slows with
  height, a slight swirl, temperature its centreline excess;
- "ring": a vortex ring (torus of radius 3, a Gaussian core), velocity its
  rotation about the core plus its self-induced drift along z.

NARVis's *training* flows (TRAIN_FLOWS; none of them is a family of the
held-out suite, which keeps the four above and the hurricane through an
unseen colormap):

- "abc": the Arnold–Beltrami–Childress flow in a 2 pi box (random A, B, C),
  points uniform, the scalar a random mix of its components;
- "abc-lines": particles along trajectories of the ABC flow (thin curves,
  as attractor trajectories are), the scalar the time along each;
- "taylor-green": Taylor–Green vortex cells in a 2 pi x 2 pi x pi box, the
  scalar its pressure;
- "double-gyre": the periodically driven double gyre in a slab (time as the
  third axis), the scalar its stream function;
- "burgers": a Burgers vortex (swirl, radial inflow, axial stretching),
  points denser in its core, the scalar its vorticity;
- "vortices": 2-5 tilted Rankine vortex tubes of random strengths, the scalar
  the distance to the nearest core;
- "turbulence": a random-Fourier divergence-free field (energy ~ k^-5/3),
  points clustered by a random scalar field which also colours them;
- "attractors": points along trajectories of a chaotic attractor other than
  Lorenz's, drawn per scene from Rössler's, Thomas's, Aizawa's and
  Halvorsen's with jittered parameters (thin curves in sheets and lobes),
  velocity its vector field, the scalar one coordinate or the time along
  each trajectory (issue 21 §3's "attractor trajectories"; the held-out
  Lorenz attractor is none of them).

Three more geometries, in neither list (PROBE_FLOWS): never trained on
and not in the suite, so that a change tuned on the suite can still be
checked on flows it never scored (``python bench/narvis_unseen.py``; keep
them out of TRAIN_FLOWS):

- "street": a von Kármán vortex street (alternating vortices of a smoothed
  core along x in a slab, a uniform stream), the scalar each vortex's sign
  and strength;
- "hill": Hill's spherical vortex in a uniform stream (its interior
  solution inside the unit sphere, a dipole outside), points denser inside,
  the scalar its stream-function-like interior weight;
- "shear": a Kelvin–Helmholtz shear layer rolled up into billows (tanh
  profile, periodic roll-ups along x), the scalar the layer's tanh.
"""

from __future__ import annotations

import numpy as np

FLOWS = ("convection", "lorenz", "jet", "ring")
TRAIN_FLOWS = (
    "abc",
    "abc-lines",
    "taylor-green",
    "double-gyre",
    "burgers",
    "vortices",
    "turbulence",
    "attractors",
)
#: flows in neither FLOWS nor TRAIN_FLOWS (bench/narvis_unseen.py)
PROBE_FLOWS = ("street", "hill", "shear")


def _trajectories(f, s: np.ndarray, dt: float, settle: int, steps: int) -> np.ndarray:
    """(steps, m, 3): the m points `s` moved by midpoint steps of dt along
    f, after `settle` steps onto the attractor."""
    for _ in range(settle):
        s = s + dt * f(s + dt / 2 * f(s))
    out = np.empty((steps, *s.shape))
    for i in range(steps):
        s = s + dt * f(s + dt / 2 * f(s))
        out[i] = s
    return out


def _result(pos: np.ndarray, vel: np.ndarray, temp: np.ndarray) -> dict:
    return {
        "positions": pos.astype(np.float32),
        "velocity": vel.astype(np.float32),
        "attributes": {"temperature": temp.astype(np.float32)},
    }


def flow(kind: str, n: int, seed: int) -> dict:
    """`n` particles of flow `kind` (one of FLOWS or TRAIN_FLOWS) from `seed`."""
    if not isinstance(n, int) or n < 16:
        raise ValueError(f"n: expected an int >= 16, got {n!r}")
    rng = np.random.default_rng(seed)
    if kind == "convection":
        a = rng.uniform(0.8, 1.2)
        x, y, z = rng.uniform(0, 4, n), rng.uniform(0, 4, n), rng.uniform(0, 1, n)
        u = a * np.sin(np.pi * x) * np.cos(np.pi * z)
        v = a * np.sin(np.pi * y) * np.cos(np.pi * z)
        w = -a * (np.cos(np.pi * x) + np.cos(np.pi * y)) * np.sin(np.pi * z)
        t = 1 - z - 0.25 * (np.cos(np.pi * x) + np.cos(np.pi * y)) * np.sin(np.pi * z)
        return _result(np.stack([x, y, z], 1), np.stack([u, v, w], 1), t)
    if kind == "lorenz":
        m = max(n // 200, 1)
        steps = -(-n // m)
        s = rng.normal(size=(m, 3)) * 5 + (0, 0, 25)
        dt = 0.005

        def f(q):
            return np.stack(
                [
                    10 * (q[:, 1] - q[:, 0]),
                    q[:, 0] * (28 - q[:, 2]) - q[:, 1],
                    q[:, 0] * q[:, 1] - 8 / 3 * q[:, 2],
                ],
                1,
            )

        out = _trajectories(f, s, dt, 400, steps)
        pos = out.reshape(-1, 3)[:n] + rng.normal(scale=0.05, size=(n, 3))
        return _result(pos, f(pos), pos[:, 2])
    if kind == "jet":
        z = rng.uniform(0, 10, n) ** 1.2 / 10**0.2
        width = 0.3 + rng.uniform(0.1, 0.2) * z
        r = np.abs(rng.normal(size=n)) * width
        th = rng.uniform(0, 2 * np.pi, n)
        profile = np.exp(-((r / width) ** 2) / 2)
        w = 8 * profile / (1 + 0.3 * z)
        ur, ut = 0.1 * w * r / width, rng.uniform(0.5, 1.5) * profile
        c, s_ = np.cos(th), np.sin(th)
        pos = np.stack([r * c, r * s_, z], 1)
        vel = np.stack([ur * c - ut * s_, ur * s_ + ut * c, w], 1)
        return _result(pos, vel, profile / (1 + 0.2 * z))
    if kind == "ring":
        big = 3.0
        core = rng.uniform(0.4, 0.8)
        phi = rng.uniform(0, 2 * np.pi, n)  # around the ring
        rho = np.abs(rng.normal(size=n)) * core  # from the core
        psi = rng.uniform(0, 2 * np.pi, n)  # around the core
        rad = big + rho * np.cos(psi)
        pos = np.stack([rad * np.cos(phi), rad * np.sin(phi), rho * np.sin(psi)], 1)
        swirl = 3 * (1 - np.exp(-((rho / core) ** 2))) / np.maximum(rho / core, 1e-3)
        # rotation about the core: tangent of psi in the (radial, z) plane
        ur, uz = -swirl * np.sin(psi), swirl * np.cos(psi) + 1.0
        vel = np.stack([ur * np.cos(phi), ur * np.sin(phi), uz], 1)
        return _result(pos, vel, np.exp(-((rho / core) ** 2)))
    if kind in TRAIN_FLOWS:
        return _train_flow(kind, n, rng)
    if kind in PROBE_FLOWS:
        return _probe_flow(kind, n, rng)
    raise ValueError(f"flow: expected one of {FLOWS + TRAIN_FLOWS + PROBE_FLOWS}, got {kind!r}")


def _probe_flow(kind: str, n: int, rng: np.random.Generator) -> dict:
    """The flows of PROBE_FLOWS (see the module docstring)."""
    if kind == "street":
        x, y, z = rng.uniform(0, 8, n), rng.normal(0, 0.8, n), rng.uniform(0, 1, n)
        u, v, temp = np.ones(n), np.zeros(n), np.zeros(n)
        for k in range(8):  # alternating vortices, staggered across the wake
            sign = (-1) ** k
            dx, dy = x - (k + 0.5), y - 0.35 * sign
            r2 = dx**2 + dy**2 + 0.05
            g = sign * (1 - np.exp(-r2 / 0.08)) / r2  # a Lamb-Oseen-like smoothed core
            u, v = u - g * dy, v + g * dx
            temp = temp + sign * np.exp(-r2 / 0.15)
        w = 0.2 * np.sin(2 * np.pi * z)
        return _result(np.stack([x, y, z], 1), np.stack([u, v, w], 1), temp)
    if kind == "hill":
        q = rng.normal(size=(n, 3))
        q /= np.maximum(np.linalg.norm(q, axis=1, keepdims=True), 1e-12)
        pos = q * (1.2 * rng.uniform(0, 1.6, n) ** 0.7)[:, None]
        x, y, z = pos.T
        rho2 = x**2 + y**2
        r2 = rho2 + z**2
        inside = r2 < 1
        far = np.maximum(r2, 1) ** 2.5
        uz = np.where(inside, 1.5 * (1 - 2 * rho2 - z**2), 1 - (2 * z**2 - rho2) / (2 * far))
        ur = np.where(inside, 1.5 * z, 1.5 * z / far)
        rho = np.sqrt(rho2) + 1e-9
        vel = np.stack([ur * x / rho, ur * y / rho, uz], 1)
        return _result(pos, vel, np.where(inside, 1 - r2, 0.0) + 0.1 * z)
    # "shear"
    x, y, zeta = rng.uniform(0, 6, n), rng.uniform(0, 3, n), rng.normal(0, 0.6, n)
    phase = np.pi * x  # a billow every 2 units along x
    z = zeta + 0.4 * np.sin(phase + 2 * zeta) * np.exp(-(zeta**2))
    u = np.tanh(2 * z) + 0.5 * np.cos(phase) * np.exp(-(z**2))
    w = 0.5 * np.sin(phase) * np.exp(-(z**2))
    v = 0.05 * np.sin(2 * np.pi * y / 3)
    return _result(np.stack([x, y, z], 1), np.stack([u, v, w], 1), np.tanh(2 * z))


def _abc(q: np.ndarray, a: float, b: float, c: float) -> np.ndarray:
    x, y, z = q[:, 0], q[:, 1], q[:, 2]
    return np.stack(
        [a * np.sin(z) + c * np.cos(y), b * np.sin(x) + a * np.cos(z), c * np.sin(y) + b * np.cos(x)], 1
    )


def _fourier(rng: np.random.Generator, modes: int, kmax: float, solenoidal: bool):
    """A random smooth field: `modes` waves of wave numbers up to `kmax`
    (amplitude ~ k^-11/6, energy ~ k^-5/3); solenoidal: a vector field
    (each wave's amplitude across its wave vector), else a scalar one."""
    k = rng.normal(size=(modes, 3))
    k /= np.linalg.norm(k, axis=1, keepdims=True)
    mag = np.exp(rng.uniform(0, np.log(kmax), modes))
    k *= mag[:, None]
    amp = mag ** (-11 / 6)
    ph = rng.uniform(0, 2 * np.pi, modes)
    if solenoidal:
        a = np.cross(k, rng.normal(size=(modes, 3)))
        a *= (amp / np.maximum(np.linalg.norm(a, axis=1), 1e-9))[:, None]
    else:
        a = amp[:, None]

    def field(q: np.ndarray) -> np.ndarray:
        out = np.zeros((len(q), a.shape[1]))
        for j in range(modes):
            out += np.sin(q @ k[j] + ph[j])[:, None] * a[j]
        return out if solenoidal else out[:, 0]

    return field


def _attractor(rng: np.random.Generator):
    """(vector field, start point, time step) of a chaotic attractor other
    than Lorenz's, its parameters jittered a little around a chaotic set."""
    which = int(rng.integers(0, 4))
    j = rng.uniform(0.97, 1.03, 3)
    if which == 0:  # Rössler
        a, b, c = 0.2 * j[0], 0.2 * j[1], 5.7 * j[2]

        def rossler(q):
            return np.stack([-q[:, 1] - q[:, 2], q[:, 0] + a * q[:, 1], b + q[:, 2] * (q[:, 0] - c)], 1)

        return rossler, (1.0, 1.0, 0.0), 0.02
    if which == 1:  # Thomas
        b = 0.208 * j[0]

        def thomas(q):
            return np.sin(q[:, [1, 2, 0]]) - b * q

        return thomas, (0.1, 0.0, 0.0), 0.05
    if which == 2:  # Aizawa
        a, b, c, d, e, ff = 0.95 * j[0], 0.7 * j[1], 0.6 * j[2], 3.5, 0.25, 0.1

        def aizawa(q):
            x, y, z = q[:, 0], q[:, 1], q[:, 2]
            return np.stack(
                [
                    (z - b) * x - d * y,
                    d * x + (z - b) * y,
                    c + a * z - z**3 / 3 - (x**2 + y**2) * (1 + e * z) + ff * z * x**3,
                ],
                1,
            )

        return aizawa, (0.1, 0.0, 0.0), 0.01
    a = 1.89 * j[0]  # Halvorsen

    def halvorsen(q):
        x, y, z = q[:, 0], q[:, 1], q[:, 2]
        return np.stack(
            [-a * x - 4 * y - 4 * z - y**2, -a * y - 4 * z - 4 * x - z**2, -a * z - 4 * x - 4 * y - x**2], 1
        )

    return halvorsen, (-1.0, 0.0, 0.0), 0.005


def _train_flow(kind: str, n: int, rng: np.random.Generator) -> dict:
    if kind == "attractors":
        f, start, dt = _attractor(rng)
        m = max(n // int(rng.integers(150, 600)), 1)
        steps = -(-n // m)
        s = np.asarray(start, np.float64) + rng.normal(scale=0.1, size=(m, 3))
        out = _trajectories(f, s, dt, 2000, steps)
        pos = out.reshape(-1, 3)[:n]
        pos = pos + rng.normal(scale=0.002 * float(np.ptp(pos, axis=0).max()), size=(n, 3))
        col = int(rng.integers(0, 4))
        scalar = np.repeat(np.arange(steps, dtype=np.float64), m)[:n] if col == 3 else pos[:, col]
        return _result(pos, f(pos), scalar)
    if kind == "abc":
        a, b, c = rng.uniform(0.3, 1.5, 3)
        pos = rng.uniform(0, 2 * np.pi, (n, 3))
        vel = _abc(pos, a, b, c)
        return _result(pos, vel, vel @ rng.normal(size=3))
    if kind == "abc-lines":
        a, b, c = rng.uniform(0.5, 1.5, 3)
        m = max(n // int(rng.integers(150, 600)), 1)
        steps = -(-n // m)
        s = rng.uniform(0, 2 * np.pi, (m, 3))
        dt = float(rng.uniform(0.01, 0.03))
        out = np.empty((steps, m, 3))
        for i in range(steps):
            s = s + dt * _abc(s + dt / 2 * _abc(s, a, b, c), a, b, c)
            out[i] = s
        pos = np.mod(out.reshape(-1, 3)[:n] + rng.normal(scale=0.01, size=(n, 3)), 2 * np.pi)
        t = np.repeat(np.arange(steps, dtype=np.float64), m)[:n]
        return _result(pos, _abc(pos, a, b, c), t)
    if kind == "taylor-green":
        pos = rng.uniform(0, 1, (n, 3)) * (2 * np.pi, 2 * np.pi, np.pi)
        x, y, z = pos.T
        vel = np.stack([np.sin(x) * np.cos(y) * np.cos(z), -np.cos(x) * np.sin(y) * np.cos(z), 0 * x], 1)
        p = (np.cos(2 * x) + np.cos(2 * y)) * (np.cos(2 * z) + 2) / 16
        return _result(pos, vel, p)
    if kind == "double-gyre":
        amp, eps, om = rng.uniform(0.1, 0.3), rng.uniform(0.1, 0.3), rng.uniform(0.4, 0.8)
        x, y = rng.uniform(0, 2, n), rng.uniform(0, 1, n)
        tt = rng.uniform(0, 10, n)
        f = eps * np.sin(om * tt) * x**2 + (1 - 2 * eps * np.sin(om * tt)) * x
        df = 2 * eps * np.sin(om * tt) * x + 1 - 2 * eps * np.sin(om * tt)
        psi = amp * np.sin(np.pi * f) * np.sin(np.pi * y)
        u = -np.pi * amp * np.sin(np.pi * f) * np.cos(np.pi * y)
        v = np.pi * amp * np.cos(np.pi * f) * np.sin(np.pi * y) * df
        pos = np.stack([x, y, tt * 0.1], 1)
        return _result(pos, np.stack([u, v, 0.1 * np.ones(n)], 1), psi)
    if kind == "burgers":
        a, delta, gam = rng.uniform(0.2, 0.6), rng.uniform(0.3, 0.7), rng.uniform(5, 15)
        r = np.abs(rng.normal(size=n)) * delta * rng.uniform(1.5, 3)
        th = rng.uniform(0, 2 * np.pi, n)
        z = rng.uniform(-2, 2, n)
        ut = gam / (2 * np.pi * np.maximum(r, 1e-3)) * (1 - np.exp(-((r / delta) ** 2)))
        ur = -a * r
        c, s_ = np.cos(th), np.sin(th)
        pos = np.stack([r * c, r * s_, z], 1)
        vel = np.stack([ur * c - ut * s_, ur * s_ + ut * c, 2 * a * z], 1)
        return _result(pos, vel, np.exp(-((r / delta) ** 2)))
    if kind == "vortices":
        k = int(rng.integers(2, 6))
        centres = rng.uniform(-3, 3, (k, 3)) * (1, 1, 0)
        axes = rng.normal(size=(k, 3)) * (0.3, 0.3, 1)
        axes /= np.linalg.norm(axes, axis=1, keepdims=True)
        cores, gams = rng.uniform(0.3, 0.8, k), rng.uniform(-10, 10, k)
        pos = rng.uniform(-4, 4, (n, 3))
        vel = np.zeros((n, 3))
        near = np.full(n, np.inf)
        for c0, ax, rc, g in zip(centres, axes, cores, gams, strict=True):
            d = pos - c0
            radial = d - (d @ ax)[:, None] * ax
            r = np.linalg.norm(radial, axis=1)
            ut = np.where(r < rc, g * r / (2 * np.pi * rc**2), g / (2 * np.pi * np.maximum(r, 1e-9)))
            tang = np.cross(ax, radial) / np.maximum(r, 1e-9)[:, None]
            vel += ut[:, None] * tang
            near = np.minimum(near, r)
        return _result(pos, vel, near)
    # turbulence
    vfield = _fourier(rng, 48, 6.0, True)
    sfield = _fourier(rng, 24, 3.0, False)
    cand = rng.uniform(-np.pi, np.pi, (3 * n, 3))
    sv = sfield(cand)
    keep = rng.uniform(size=3 * n) < 0.2 + 0.8 * (sv - sv.min()) / max(np.ptp(sv), 1e-9)
    pos = cand[keep][:n]
    if len(pos) < n:  # top up uniformly
        pos = np.concatenate([pos, rng.uniform(-np.pi, np.pi, (n - len(pos), 3))])
    return _result(pos, vfield(pos), sfield(pos))
