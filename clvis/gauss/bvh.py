"""A linear BVH over axis-aligned boxes, built on the device.

Karras's binary radix tree (HPG 2012) over the 30-bit Morton codes of the box
centres, with Karras's node numbering: the acceleration structure of the
Gaussian ray marcher. Every step runs on the device; the host reads one small
array (the bounds, which also flag bad rows).

1. ``bvh_bounds``: the union box of the centres (the Morton grid), the union
   of the boxes, and the first bad row;
2. ``bvh_morton``: the code of each centre, quantized over that grid exactly
   as :func:`clvis.morton_order` does (10 bits per axis);
3. :func:`clvis.radix_sort` of (codes, iota): stable, so equal codes keep
   index order (the tie-break of Karras's delta);
4. ``bvh_gather``: the leaf boxes in sorted order;
5. ``bvh_build``: one work-item per leaf climbs the tree bottom-up (Apetrei
   2014's agglomerative order, which yields Karras's tree without his
   per-node searches); the second to reach a node writes it, its box the
   exact min/max union of its children's. Siblings meet through an atomic
   exchange; nobody waits.

The node layout, shared with the traversal kernels, is documented in
``kernels_cl/include/clvis/bvh.h`` (:data:`BVH_NODE_DTYPE` here); the kernels'
ABI in ``kernels_cl/gauss/bvh.cl``; the NumPy definition of the result in
``clvis.reference.gauss.bvh``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pyopencl as cl
import pyopencl.array as cla

from .. import morton, runtime
from .._arrays import check_array, resolve_queue, to_device
from .._keys import key_f32_inverse
from ..errors import DataError, DeviceError
from ..primitives import radix_sort

__all__ = ["BVH", "BVH_LEAF", "BVH_NODE_DTYPE", "BVH_NONE", "build_bvh"]

# clvis_bvh_node of clvis/bvh.h: 32 bytes
BVH_NODE_DTYPE = np.dtype([("lo", "<f4", (3,)), ("left", "<u4"), ("hi", "<f4", (3,)), ("right", "<u4")])
BVH_LEAF = np.uint32(0x80000000)  # child & LEAF: a leaf; child & ~LEAF = sorted position
BVH_NONE = np.uint32(0xFFFFFFFF)  # no child (the right child of a 1-primitive tree)
MAX_BOXES = 2**31 - 1  # child words keep the top bit for LEAF

_KERNEL = "gauss/bvh.cl"
# item_wg: the fixed local size (a driver-chosen one makes PoCL compile a
# work-group function per global size). bounds_groups: work-groups of the
# bounds reduction per compute unit; bounds_contiguous: each of its items walks
# one contiguous range of rows (streams on CPUs), else the items interleave
# (coalesced on GPUs).
PROFILES = {
    "cpu": {"item_wg": 64, "bounds_groups": 4, "bounds_contiguous": True},
    "gpu": {"item_wg": 256, "bounds_groups": 8, "bounds_contiguous": False},
}


def _wg(queue) -> int:
    return runtime.local_size(queue, PROFILES[runtime.tuning_profile(queue)]["item_wg"])


def _items(queue, n: int) -> tuple[int, int]:
    """(global, local) sizes for one work-item per element of n."""
    return runtime.items(queue, n, PROFILES[runtime.tuning_profile(queue)]["item_wg"])


def _kernel(queue, name: str):
    return runtime.get_kernel(queue, _KERNEL, name, {})


class BVH:
    """A device LBVH over n boxes (see the module docstring and clvis/bvh.h).

    n: the number of boxes. nodes: device array of :data:`BVH_NODE_DTYPE`,
    n - 1 internal nodes (root = node 0), one node for n == 1, none for n == 0.
    order: device uint32 (n,), the primitive at each sorted position (leaf j
    is box order[j]). leaf_boxes: device float32 (n, 6), leaf_boxes[j] =
    boxes[order[j]]. codes: device uint32 (n,), the sorted Morton codes.
    bounds: host (lo, hi) float32 (3,) each, the union of the boxes (+inf, -inf
    for n == 0). centre_bounds: host (lo, hi), the union box of the centres
    (the Morton grid). events: (first, last) of the build's commands, for
    :attr:`build_seconds`. The build does not wait for its last kernels.
    """

    def __init__(
        self,
        queue: cl.CommandQueue,
        n: int,
        nodes: cla.Array,
        order: cla.Array,
        leaf_boxes: cla.Array,
        codes: cla.Array,
        bounds: tuple[np.ndarray, np.ndarray],
        centre_bounds: tuple[np.ndarray, np.ndarray],
        events: tuple[cl.Event, cl.Event],
    ):
        self.queue = queue
        self.n = n
        self.nodes = nodes
        self.order = order
        self.leaf_boxes = leaf_boxes
        self.codes = codes
        self.bounds = bounds
        self.centre_bounds = centre_bounds
        self.events = events

    @property
    def build_seconds(self) -> float | None:
        """Device time of the build (event profiling; waits for the build to
        finish). None on a queue made without profiling."""
        return runtime.seconds(*self.events)

    @property
    def nbytes(self) -> int:
        """Device bytes held: nodes, order, leaf boxes and codes."""
        return int(self.nodes.nbytes + self.order.nbytes + self.leaf_boxes.nbytes + self.codes.nbytes)

    def get(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Host copies (nodes, order, leaf_boxes)."""
        return self.nodes.get(), self.order.get(), self.leaf_boxes.get()

    def __repr__(self) -> str:
        return f"BVH(n={self.n}, nodes={self.nodes.shape[0]}, nbytes={self.nbytes})"  # does not wait


def _read_bounds(queue, bd, n: int):
    """Run bvh_bounds; (centre lo, centre hi, box lo, box hi), or DataError on a bad row."""
    res = runtime.fill(queue, runtime.empty(queue, 16, np.uint32, "BVH bounds"), 0xFFFFFFFF)
    prof = PROFILES[runtime.tuning_profile(queue)]
    wg = _wg(queue)
    groups = max(1, min(prof["bounds_groups"] * runtime.capabilities(queue).compute_units, -(-n // wg)))
    items = groups * wg
    chunk = -(-n // items) if prof["bounds_contiguous"] else 1
    runtime.launch(
        queue,
        _kernel(queue, "bvh_bounds"),
        items,
        wg,
        bd.base_data,
        np.uint32(n),
        np.uint32(chunk),
        res.base_data,
    )
    r = res.get(queue=queue)
    if r[12] != 0xFFFFFFFF:
        row = int(r[12])
        raise DataError(
            f"boxes: row {row} is not a valid box (NaN or infinite values, lo > hi on an "
            "axis, or lo + hi overflows float32)"
        )
    clo, chi = key_f32_inverse(r[0:3]), key_f32_inverse(~r[3:6])
    blo, bhi = key_f32_inverse(r[6:9]), key_f32_inverse(~r[9:12])
    return clo, chi, blo, bhi


def build_bvh(boxes: Any, *, queue: cl.CommandQueue | None = None) -> BVH:
    """Build an LBVH over axis-aligned boxes on the device.

    boxes: float32 (N, 6), row i = (lo x, y, z, hi x, y, z), numpy or a
    ``pyopencl.array.Array`` (then nothing goes through the host but the
    bounds). Every value finite, lo <= hi. Returns a :class:`BVH` whose arrays
    are on the device. DataError names the first bad row; N >= 2^31 raises
    DeviceError.
    """
    queue = resolve_queue(queue, boxes=boxes)
    shape = getattr(boxes, "shape", None)
    if shape is not None and len(shape) == 2 and shape[0] > MAX_BOXES:  # before any copy
        raise DeviceError(
            f"boxes: {shape[0]} boxes; at most 2^31 - 1 (child words keep the top bit for leaves)"
        )
    b = check_array("boxes", boxes, dtypes=[np.float32], ndim=2)
    if b.shape[1] != 6:
        raise ValueError(f"boxes: expected shape (N, 6) = lo xyz, hi xyz; got {tuple(b.shape)}")
    n = int(b.shape[0])
    e = runtime.empty
    first = runtime.marker(queue)
    if n == 0:
        empty3 = (np.full(3, np.inf, np.float32), np.full(3, -np.inf, np.float32))
        return BVH(
            queue,
            0,
            e(queue, 0, BVH_NODE_DTYPE, "BVH nodes"),
            e(queue, 0, np.uint32, "BVH order"),
            e(queue, (0, 6), np.float32, "BVH leaf boxes"),
            e(queue, 0, np.uint32, "BVH codes"),
            empty3,
            empty3,
            (first, runtime.marker(queue)),
        )
    bd = to_device(queue, "boxes", b)
    clo, chi, blo, bhi = _read_bounds(queue, bd, n)
    # -0.0 -> +0.0 (which zero an item keeps depends on the rows it saw): the
    # same codes, and bounds that do not depend on how rows fell to items
    clo, chi, blo, bhi = (a + np.float32(0) for a in (clo, chi, blo, bhi))
    scale = morton.scale(clo, chi)

    codes = e(queue, n, np.uint32, "BVH Morton codes")
    iota = e(queue, n, np.uint32, "BVH order")
    runtime.launch(
        queue,
        _kernel(queue, "bvh_morton"),
        *_items(queue, n),
        bd.base_data,
        np.uint32(n),
        *clo,
        *scale,
        codes.base_data,
        iota.base_data,
    )
    # codes < 2^30 by construction; all 32 bits cost no extra pass at 4 or 8
    # bits a pass, and skip key_bits's check (a host read)
    codes, order = radix_sort(codes, iota, queue=queue)

    leaf_boxes = e(queue, (n, 6), np.float32, "BVH leaf boxes")
    runtime.launch(
        queue,
        _kernel(queue, "bvh_gather"),
        *_items(queue, n),
        bd.base_data,
        order.base_data,
        np.uint32(n),
        leaf_boxes.base_data,
    )
    nodes = e(queue, max(n - 1, 1), BVH_NODE_DTYPE, "BVH nodes")
    meet = runtime.fill(queue, e(queue, max(n - 1, 1), np.uint32, "BVH meeting words"), 0xFFFFFFFF)
    last = runtime.launch(
        queue,
        _kernel(queue, "bvh_build"),
        *_items(queue, n),
        codes.base_data,
        leaf_boxes.base_data,
        np.uint32(n),
        nodes.base_data,
        meet.base_data,
    )
    return BVH(queue, n, nodes, order, leaf_boxes, codes, (blo, bhi), (clo, chi), (first, last))
