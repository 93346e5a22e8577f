"""Macrocell grids of a ZFP-compressed volume (kernels_cl/iso/macrocell.cl):
the value range of every block's dual cells (fine) and of 4^3 blocks (coarse),
which the traversal skips where they cannot hold the isovalue."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyopencl as cl
import pyopencl.array as cla

from .. import runtime
from .._arrays import resolve_queue
from .zfp import ZfpVolume, _stream_buffer

__all__ = ["PROFILES", "MacrocellGrids", "macrocell_grids", "range_bits"]

_SRC = "iso/macrocell.cl"
# the local size of the one-item-per-block (and per coarse cell) kernels
PROFILES = {"cpu": {"wg": 64}, "gpu": {"wg": 64}}


@dataclass
class MacrocellGrids:
    """Value ranges of the fine grid (one cell per ZFP block, dilated by the
    +x/+y/+z neighbour samples: the dual grid) and the coarse grid (4^3
    blocks). Each is a (Z, Y, X, 2) float32 array of (lo, hi); (+inf, -inf)
    where a block holds no dual cell. Device arrays when built with host=False."""

    fine: np.ndarray | cla.Array
    coarse: np.ndarray | cla.Array

    def active(self, isovalue: float) -> tuple[np.ndarray, np.ndarray]:
        """Host boolean masks (fine, coarse): the cells whose range holds `isovalue`."""
        f = self.fine if isinstance(self.fine, np.ndarray) else self.fine.get()
        c = self.coarse if isinstance(self.coarse, np.ndarray) else self.coarse.get()
        v = np.float32(isovalue)
        return (f[..., 0] <= v) & (v <= f[..., 1]), (c[..., 0] <= v) & (v <= c[..., 1])


def macrocell_grids(
    volume: ZfpVolume, *, queue: cl.CommandQueue | None = None, host: bool = True
) -> MacrocellGrids:
    """The fine and coarse macrocell grids of a compressed volume, built on the
    device from its stream (each block decoded once, kernels_cl/iso/macrocell.cl).
    Equal to clvis.reference.iso.macrocell.block_ranges / coarse_ranges of the decoded volume."""
    if not isinstance(volume, ZfpVolume):
        raise TypeError(f"volume: expected a clvis.zfp.ZfpVolume, got {type(volume).__name__}")
    q = resolve_queue(queue)
    nz, ny, nx = volume.shape
    if min(volume.shape) < 2:
        raise ValueError(f"volume: every axis needs at least 2 samples for a dual grid, got {volume.shape}")
    nbz, nby, nbx = (-(-n // 4) for n in volume.shape)
    ncz, ncy, ncx = (-(-n // 4) for n in (nbz, nby, nbx))
    nb, nc = nbx * nby * nbz, ncx * ncy * ncz
    wg = PROFILES[runtime.tuning_profile(q)]["wg"]
    faces = runtime.empty(q, (nb, 8, 2), np.float32, "block faces")
    fine = runtime.empty(q, (nbz, nby, nbx, 2), np.float32, "fine macrocells")
    coarse = runtime.empty(q, (ncz, ncy, ncx, 2), np.float32, "coarse macrocells")
    dims = (np.uint32(nx), np.uint32(ny), np.uint32(nz))
    k = runtime.get_kernel(q, _SRC, "block_faces", {})
    runtime.launch(
        q,
        k,
        *runtime.items(q, nb, wg),
        _stream_buffer(q, volume.stream),
        np.uint32(volume.rate),
        *dims,
        faces.base_data,
    )
    k = runtime.get_kernel(q, _SRC, "block_ranges", {})
    runtime.launch(q, k, *runtime.items(q, nb, wg), faces.base_data, *dims, fine.base_data)
    k = runtime.get_kernel(q, _SRC, "coarse_ranges", {})
    runtime.launch(
        q,
        k,
        *runtime.items(q, nc, wg),
        fine.base_data,
        np.uint32(nbx),
        np.uint32(nby),
        np.uint32(nbz),
        coarse.base_data,
    )
    if host:
        return MacrocellGrids(fine.get(), coarse.get())
    return MacrocellGrids(fine, coarse)


def range_bits(ranges: cla.Array, isovalue: float, *, queue: cl.CommandQueue | None = None) -> cla.Array:
    """The active bits of a device array of float32 ranges (..., 2) for one
    isovalue (kernels_cl/iso/macrocell.cl's range_bits): a uint32 device array
    of ceil(n / 32) words, bit j of word w set iff range 32 w + j holds it.
    How macro_traverse reads the macrocell grids; equal to
    clvis.reference.iso.macrocell.range_bits."""
    if (
        not isinstance(ranges, cla.Array)
        or ranges.dtype != np.float32
        or not ranges.shape
        or ranges.shape[-1] != 2
    ):
        raise TypeError("ranges: expected a float32 device array of shape (..., 2)")
    if not ranges.flags.c_contiguous or ranges.offset:
        raise ValueError("ranges: expected a contiguous device array at offset 0")
    q = resolve_queue(queue, ranges=ranges)
    n = ranges.size // 2
    words = -(-n // 32)
    bits = runtime.empty(q, max(words, 1), np.uint32, "macrocell bits")
    if words:
        k = runtime.get_kernel(q, _SRC, "range_bits", {})
        wg = PROFILES[runtime.tuning_profile(q)]["wg"]
        runtime.launch(
            q,
            k,
            *runtime.items(q, words, wg),
            runtime.arg(ranges),
            np.uint32(n),
            np.float32(isovalue),
            bits.base_data,
        )
    return bits
