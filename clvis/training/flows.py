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
"""

from __future__ import annotations

import numpy as np

FLOWS = ("convection", "lorenz", "jet", "ring")


def _result(pos: np.ndarray, vel: np.ndarray, temp: np.ndarray) -> dict:
    return {
        "positions": pos.astype(np.float32),
        "velocity": vel.astype(np.float32),
        "attributes": {"temperature": temp.astype(np.float32)},
    }


def flow(kind: str, n: int, seed: int) -> dict:
    """`n` particles of flow `kind` (one of FLOWS) from `seed`."""
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

        for _ in range(400):  # onto the attractor
            s = s + dt * f(s + dt / 2 * f(s))
        out = np.empty((steps, m, 3))
        for i in range(steps):
            s = s + dt * f(s + dt / 2 * f(s))
            out[i] = s
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
    raise ValueError(f"flow: expected one of {FLOWS}, got {kind!r}")
