"""The Gaussians container shared by the gauss family, and their records on
the device (``kernels_cl/gauss/gaussians.cl``: :func:`gaussian_records`
uploads them and builds the records the march kernel reads with their boxes;
:func:`gather_records` puts the records in the BVH's leaf order).

A Gaussian i is a density  opacity_i * exp(-1/2 (x - mu_i)^T Sigma_i^-1 (x - mu_i))
(peak 1 at its mean, not normalised), with Sigma_i = R_i diag(scales_i)^2 R_i^T:
``scales`` are the standard deviations along the Gaussian's own axes, which are
the columns of ``rotations[i]``. ``values`` is the scalar a transfer function
maps to a colour (and an opacity factor); optional ``colors`` (N, 3) uint8 rgb
give each Gaussian its own colour instead (renderers then take only the
opacity factor from the transfer function).
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pyopencl as cl
import pyopencl.array as cla

from .. import runtime
from ..errors import DataError

__all__ = ["GAUSSIAN_DTYPE", "PROFILES", "Gaussians", "gather_records", "gaussian_records"]

# One record of gaussians.cl (kernels_cl/include/clvis/gauss.h): what march.cl reads.
GAUSSIAN_DTYPE = np.dtype(
    [("mean", np.float32, 3), ("value", np.float32), ("w", np.float32, 9), ("opacity", np.float32)]
)
# work-items per group of gaussians.cl's one-item-per-Gaussian kernels
PROFILES = {"cpu": {"item_wg": 64}, "gpu": {"item_wg": 64}}


def _real(name: str, x, shape_tail: tuple, n: int | None) -> np.ndarray:
    if isinstance(x, (str, bytes)) or x is None:
        raise TypeError(f"{name}: expected an array, got {type(x).__name__}")
    a = np.asarray(x)
    if a.dtype == bool or not (np.issubdtype(a.dtype, np.floating) or np.issubdtype(a.dtype, np.integer)):
        raise TypeError(f"{name}: expected real numbers, got dtype {a.dtype}")
    if a.ndim != 1 + len(shape_tail) or tuple(a.shape[1:]) != shape_tail:
        want = "(N" + "".join(f", {s}" for s in shape_tail) + ")"
        raise ValueError(f"{name}: expected shape {want}, got {a.shape}")
    if n is not None and a.shape[0] != n:
        raise ValueError(f"{name}: {a.shape[0]} rows, but there are {n} Gaussians")
    a = np.ascontiguousarray(a, dtype=np.float32)
    if a.size and not np.isfinite(a).all():
        bad = int(np.flatnonzero(~np.isfinite(a.reshape(len(a), -1)).all(axis=1))[0])
        raise DataError(f"{name}: row {bad} is not finite (NaN or Inf)")
    return a


def _colors(x, n: int) -> np.ndarray:
    """(N, 3) uint8 from integer rgb(a) in 0..255 as is, or floats in [0, 1] scaled by 255 and rounded."""
    if isinstance(x, (str, bytes)):
        raise TypeError(f"colors: expected an array, got {type(x).__name__}")
    a = np.asarray(x)
    if a.ndim != 2 or a.shape[1] not in (3, 4):
        raise ValueError(f"colors: expected shape (N, 3) or (N, 4), got {a.shape}")
    if a.shape[0] != n:
        raise ValueError(f"colors: {a.shape[0]} rows, but there are {n} Gaussians")
    a = a[:, :3]
    if a.dtype == np.uint8:
        return np.ascontiguousarray(a)
    if a.dtype == bool or not (np.issubdtype(a.dtype, np.floating) or np.issubdtype(a.dtype, np.integer)):
        raise TypeError(f"colors: expected integers in 0..255 or floats in [0, 1], got dtype {a.dtype}")
    if np.issubdtype(a.dtype, np.integer):
        if a.size and ((a < 0) | (a > 255)).any():
            raise DataError("colors: integer colours must lie in 0..255")
        return a.astype(np.uint8)
    if a.size and not (np.isfinite(a).all() and (a >= 0).all() and (a <= 1).all()):
        raise DataError("colors: float colours must lie in [0, 1]")
    return np.rint(a.astype(np.float64) * 255).astype(np.uint8)


class Gaussians:
    """N anisotropic 3-D Gaussians.

    Parameters
    ----------
    means : (N, 3) world positions (float32).
    scales : (N, 3) standard deviations along the local axes, >= 0 (world units).
        A zero scale is a flat (degenerate) Gaussian; renderers clamp it (see
        ``clvis.gauss.render``).
    rotations : (N, 3, 3), optional; columns are the local axes (orthonormal
        within 1e-3). Identity when omitted.
    values : (N,), optional scalar per Gaussian (0 when omitted).
    opacities : (N,), optional, in [0, 1] (1 when omitted).
    colors : (N, 3) or (N, 4), optional: each Gaussian's own rgb, integers in
        0..255 or floats in [0, 1] (alpha dropped; stored as (N, 3) uint8). None: the
        transfer function colours them by value.
    """

    def __init__(
        self,
        means: npt.ArrayLike,
        scales: npt.ArrayLike,
        rotations: npt.ArrayLike | None = None,
        values: npt.ArrayLike | None = None,
        opacities: npt.ArrayLike | None = None,
        colors: npt.ArrayLike | None = None,
    ) -> None:
        self.means = _real("means", means, (3,), None)
        n = len(self.means)
        self.scales = _real("scales", scales, (3,), n)
        if n and (self.scales < 0).any():
            raise DataError(
                f"scales: row {int(np.flatnonzero((self.scales < 0).any(axis=1))[0])} is negative"
            )
        if rotations is None:
            self.rotations = np.ascontiguousarray(np.broadcast_to(np.eye(3, dtype=np.float32), (n, 3, 3)))
        else:
            self.rotations = _real("rotations", rotations, (3, 3), n)
            if n:
                r = self.rotations.astype(np.float64)
                err = np.abs(np.einsum("nji,njk->nik", r, r) - np.eye(3)).max(axis=(1, 2))
                if (err > 1e-3).any():
                    raise DataError(
                        f"rotations: matrix {int(np.flatnonzero(err > 1e-3)[0])} is not "
                        "orthonormal (R^T R differs from I by more than 1e-3)"
                    )
        self.values = np.zeros(n, np.float32) if values is None else _real("values", values, (), n)
        self.opacities = np.ones(n, np.float32) if opacities is None else _real("opacities", opacities, (), n)
        if n and ((self.opacities < 0) | (self.opacities > 1)).any():
            raise DataError("opacities: values must lie in [0, 1]")
        self.colors = None if colors is None else _colors(colors, n)

    def __len__(self) -> int:
        return len(self.means)

    @property
    def n(self) -> int:
        return len(self.means)

    @property
    def covariances(self) -> np.ndarray:
        """(N, 3, 3) float32: R diag(scales)^2 R^T."""
        r = self.rotations.astype(np.float64)
        s2 = self.scales.astype(np.float64) ** 2
        return np.einsum("nij,nj,nkj->nik", r, s2, r).astype(np.float32)

    @property
    def nbytes(self) -> int:
        return sum(
            a.nbytes
            for a in (self.means, self.scales, self.rotations, self.values, self.opacities, self.colors)
            if a is not None
        )

    def bounds(self, cutoff: float = 3.0) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi) float64 of the boxes holding every Gaussian's `cutoff`-sigma ellipsoid."""
        if not self.n:
            return np.zeros(3), np.zeros(3)
        half = cutoff * np.sqrt(
            np.einsum(
                "nij,nj->ni", self.rotations.astype(np.float64) ** 2, self.scales.astype(np.float64) ** 2
            )
        )
        m = self.means.astype(np.float64)
        return (m - half).min(axis=0), (m + half).max(axis=0)

    def subset(self, index: npt.ArrayLike | slice) -> Gaussians:
        pick = index if isinstance(index, slice) else np.asarray(index)
        return Gaussians(
            self.means[pick],
            self.scales[pick],
            self.rotations[pick],
            self.values[pick],
            self.opacities[pick],
            None if self.colors is None else self.colors[pick],
        )

    @staticmethod
    def concatenate(parts: Iterable[Gaussians]) -> Gaussians:
        """One Gaussians of all `parts`, in order. Colours are kept when every
        part has them; parts without colours among parts with them: ValueError
        (there is no colour to give them)."""
        parts = list(parts)
        if not parts:
            return Gaussians(np.zeros((0, 3)), np.zeros((0, 3)))
        cat = np.concatenate
        have = [p.colors is not None for p in parts]
        if any(have) and not all(have):
            raise ValueError("parts: some have colours and some do not")
        return Gaussians(
            cat([p.means for p in parts]),
            cat([p.scales for p in parts]),
            cat([p.rotations for p in parts]),
            cat([p.values for p in parts]),
            cat([p.opacities for p in parts]),
            cat([p.colors for p in parts]) if all(have) else None,
        )

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write a .npz (means, scales, rotations, values, opacities, and colors
        when present) and return its path: `path`, with ``.npz`` added when it
        has not that suffix (as np.savez names it; :meth:`load` finds it by
        either name). A 3DGS splat name (.ply, .splat, .spz) is refused: this
        is not that format."""
        from ..io.files import write_replacing

        suffix = Path(os.fspath(path)).suffix.lower()
        if suffix in (".ply", ".splat", ".spz"):
            raise ValueError(
                f"path: Gaussians.save writes a NumPy .npz archive, not a {suffix} splat file; "
                f"got {os.fspath(path)!r}"
            )

        extra: dict[str, Any] = {} if self.colors is None else {"colors": self.colors}
        arrays = dict(
            means=self.means,
            scales=self.scales,
            rotations=self.rotations,
            values=self.values,
            opacities=self.opacities,
            **extra,
        )
        target = os.fspath(path)
        if not target.endswith(".npz"):  # as np.savez names it
            target += ".npz"
        # atomic: a failed overwrite keeps the previous file
        write_replacing(target, lambda f: np.savez(f, **arrays))
        return Path(target)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> Gaussians:
        """Read a .npz written by :meth:`save`; DataError naming the file when malformed."""
        from ..io import load_npz

        path = Path(path)
        if not path.exists() and path.suffix != ".npz" and Path(f"{path}.npz").exists():
            path = Path(f"{path}.npz")  # what save(path) wrote
        z = load_npz(path)
        missing = [k for k in ("means", "scales") if k not in z]
        if missing:
            raise DataError(f"{path}: not a Gaussians file (missing {', '.join(missing)})")
        get = {k: z[k] for k in ("means", "scales", "rotations", "values", "opacities", "colors") if k in z}
        try:
            return cls(**get)
        except (TypeError, ValueError) as e:
            raise DataError(f"{path}: {e}") from None

    def __repr__(self) -> str:
        return f"Gaussians(n={self.n})"


def _items(queue: cl.CommandQueue, n: int) -> tuple[int, int]:
    return runtime.items(queue, n, PROFILES[runtime.tuning_profile(queue)]["item_wg"])


def gaussian_records(
    queue: cl.CommandQueue, gaussians: Gaussians, cutoff: float
) -> tuple[cla.Array, cla.Array, cl.Event | None]:
    """`gaussians` uploaded and turned into records (GAUSSIAN_DTYPE, as bytes)
    and world boxes at `cutoff` standard deviations (float32 (N, 6)), in the
    Gaussians' order, by gaussians.cl's gaussian_records: (records, boxes, the
    event of the launch, None for no Gaussians). Both arrays hold at least one
    element."""
    n = gaussians.n
    m = max(n, 1)
    arrays = {}
    for name, a in (
        ("means", gaussians.means),
        ("scales", gaussians.scales),
        ("rotations", gaussians.rotations),
        ("values", gaussians.values),
        ("opacities", gaussians.opacities),
    ):
        d = runtime.empty(queue, (m,) + a.shape[1:], np.float32, f"Gaussian {name}")
        if n:
            d.set(a, queue=queue)
        arrays[name] = d
    records = runtime.empty(queue, m * GAUSSIAN_DTYPE.itemsize, np.uint8, "Gaussian records")
    boxes = runtime.empty(queue, (m, 6), np.float32, "Gaussian boxes")
    last = None
    if n:
        kr = runtime.get_kernel(queue, "gauss/gaussians.cl", "gaussian_records", {}, runtime.EXACT_FP)
        last = runtime.launch(
            queue,
            kr,
            *_items(queue, n),
            *(arrays[k].base_data for k in ("means", "scales", "rotations", "values", "opacities")),
            np.uint32(n),
            np.float32(cutoff),
            records.base_data,
            boxes.base_data,
        )
    return records, boxes, last


def gather_records(queue: cl.CommandQueue, records: cla.Array, order: cla.Array, n: int) -> cla.Array:
    """The first `n` records in the order `order` (uint32 (n,), the BVH's leaf
    order), by gaussians.cl's gather_records; at least one record long."""
    out = runtime.empty(queue, max(n, 1) * GAUSSIAN_DTYPE.itemsize, np.uint8, "Gaussian records (BVH order)")
    if n:
        kg = runtime.get_kernel(queue, "gauss/gaussians.cl", "gather_records", {}, runtime.EXACT_FP)
        runtime.launch(
            queue,
            kg,
            *_items(queue, n),
            records.base_data,
            order.base_data,
            np.uint32(n),
            out.base_data,
        )
    return out
