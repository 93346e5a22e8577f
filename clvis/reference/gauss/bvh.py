"""NumPy reference of clvis.gauss.bvh: the LBVH the device builds, and a
checker of the tree invariants.

The hierarchy is built top-down here, not with Karras's per-node searches:
a node covering sorted positions [first, last] splits where the (code, index)
keys of first and last first differ (the highest set bit of their xor); the
left child [first, g] is internal node g (or leaf g when first == g) and the
right child [g + 1, last] internal node g + 1 (or leaf g + 1), the root node
0. That is Karras's (HPG 2012) tree and numbering; the device reaches the same
tree bottom-up (Apetrei 2014's order), so the two must agree field for field.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from ..morton import morton_codes as _point_codes

__all__ = ["BVH_LEAF", "BVH_NODE_DTYPE", "BVH_NONE", "build_bvh", "check_bvh", "morton_codes"]

BVH_NODE_DTYPE = np.dtype([("lo", "<f4", (3,)), ("left", "<u4"), ("hi", "<f4", (3,)), ("right", "<u4")])
BVH_LEAF = np.uint32(0x80000000)
BVH_NONE = np.uint32(0xFFFFFFFF)


def morton_codes(boxes: npt.ArrayLike) -> np.ndarray:
    """30-bit Morton codes of the centres (lo + hi) * 0.5 (float32) over their
    bounding box (clvis.reference.morton.morton_codes's quantization)."""
    b = np.asarray(boxes, np.float32).reshape(-1, 6)
    centres = (b[:, :3] + b[:, 3:]) * np.float32(0.5)
    return _point_codes(centres)


def _bit_length(x: np.ndarray) -> np.ndarray:
    """Bit length of each uint64 (exact: each 32-bit half goes through float64)."""
    hi = (x >> np.uint64(32)).astype(np.float64)
    lo = (x & np.uint64(0xFFFFFFFF)).astype(np.float64)
    return np.where(hi > 0, 32 + np.frexp(hi)[1], np.frexp(lo)[1]).astype(np.uint64)


def _union(llo, lhi, rlo, rhi):
    """Exact union; ties (-0.0 vs +0.0) keep the left child's value."""
    return np.where(rlo < llo, rlo, llo), np.where(rhi > lhi, rhi, lhi)


def build_bvh(boxes: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(nodes, order, leaf_boxes) of the LBVH over boxes, float32 (N, 6):
    nodes a BVH_NODE_DTYPE array (N - 1 nodes; 1 for N == 1; 0 for N == 0),
    order uint32 (stable argsort of the codes), leaf_boxes = boxes[order]."""
    b = np.ascontiguousarray(boxes, np.float32).reshape(-1, 6)
    n = b.shape[0]
    codes = morton_codes(b)
    order = np.argsort(codes, kind="stable").astype(np.uint32)
    leaf_boxes = b[order]
    if n == 0:
        return np.zeros(0, BVH_NODE_DTYPE), order, leaf_boxes
    nodes = np.zeros(max(n - 1, 1), BVH_NODE_DTYPE)
    if n == 1:
        nodes["lo"][0], nodes["hi"][0] = b[0, :3], b[0, 3:]
        nodes["left"][0], nodes["right"][0] = BVH_LEAF, BVH_NONE
        return nodes, order, leaf_boxes
    # distinct keys: (code, sorted position)
    keys = (codes[order].astype(np.uint64) << np.uint64(32)) | np.arange(n, dtype=np.uint64)
    first, last, idx = np.array([0]), np.array([n - 1]), np.array([0])
    levels = []
    while idx.size:
        top = _bit_length(keys[first] ^ keys[last]) - np.uint64(1)
        boundary = (keys[last] >> top) << top  # the prefix, then the first bit of last
        g = np.searchsorted(keys, boundary, side="left") - 1
        left = np.where(g == first, BVH_LEAF | g.astype(np.uint32), g.astype(np.uint32))
        right = np.where(g + 1 == last, BVH_LEAF | (g + 1).astype(np.uint32), (g + 1).astype(np.uint32))
        nodes["left"][idx], nodes["right"][idx] = left, right
        levels.append((idx, left, right))
        li, ri = g > first, g + 1 < last
        first, last, idx = (
            np.concatenate([first[li], g[ri] + 1]),
            np.concatenate([g[li], last[ri]]),
            np.concatenate([g[li], g[ri] + 1]),
        )
    for idx, left, right in reversed(levels):
        (llo, lhi), (rlo, rhi) = _child_boxes(nodes, leaf_boxes, left), _child_boxes(nodes, leaf_boxes, right)
        nodes["lo"][idx], nodes["hi"][idx] = _union(llo, lhi, rlo, rhi)
    return nodes, order, leaf_boxes


def _child_boxes(nodes, leaf_boxes, child):
    leaf = (child & BVH_LEAF) != 0
    k = (child & ~BVH_LEAF).astype(np.int64)
    lo = np.where(leaf[:, None], leaf_boxes[np.where(leaf, k, 0), :3], nodes["lo"][np.where(leaf, 0, k)])
    hi = np.where(leaf[:, None], leaf_boxes[np.where(leaf, k, 0), 3:], nodes["hi"][np.where(leaf, 0, k)])
    return lo, hi


def check_bvh(nodes: np.ndarray, order: np.ndarray, leaf_boxes: np.ndarray, boxes: npt.ArrayLike) -> None:
    """Assert the LBVH invariants; AssertionError saying which one fails.

    order is a permutation and leaf_boxes[j] == boxes[order[j]]; from the root
    every internal node and every leaf is reached exactly once (so no cycle,
    no orphan); every node's box contains its children's boxes.
    """
    boxes = np.asarray(boxes, np.float32).reshape(-1, 6)
    nodes, order = np.asarray(nodes), np.asarray(order)
    leaf_boxes = np.asarray(leaf_boxes).reshape(-1, 6)
    n = boxes.shape[0]
    assert nodes.dtype == BVH_NODE_DTYPE, f"nodes: dtype {nodes.dtype}, expected {BVH_NODE_DTYPE}"
    assert order.shape == (n,), f"order: shape {order.shape}, expected ({n},)"
    assert np.array_equal(np.sort(order.astype(np.int64)), np.arange(n)), (
        "order is not a permutation of 0..n-1"
    )
    assert leaf_boxes.shape == (n, 6), f"leaf_boxes: shape {leaf_boxes.shape}, expected ({n}, 6)"
    bad = np.flatnonzero((leaf_boxes.view(np.uint32) != boxes[order].view(np.uint32)).any(axis=1))
    assert bad.size == 0, f"leaf_boxes[{bad[0]}] != boxes[order[{bad[0]}]]"
    if n == 0:
        assert nodes.shape == (0,), f"0 boxes but {nodes.shape[0]} nodes"
        return
    if n == 1:
        assert nodes.shape == (1,), f"1 box but {nodes.shape[0]} nodes"
        assert nodes["left"][0] == BVH_LEAF and nodes["right"][0] == BVH_NONE, (
            f"1-box tree: children {nodes['left'][0]:#x}, {nodes['right'][0]:#x}; expected LEAF|0, NONE"
        )
        assert (nodes["lo"][0] <= boxes[0, :3]).all() and (nodes["hi"][0] >= boxes[0, 3:]).all(), (
            "1-box tree: the node's box does not contain the box"
        )
        return
    m = n - 1
    assert nodes.shape == (m,), f"{n} boxes need {m} internal nodes, got {nodes.shape[0]}"
    seen_node = np.zeros(m, np.int64)
    seen_leaf = np.zeros(n, np.int64)
    seen_node[0] = 1
    frontier = np.array([0])
    while frontier.size:
        nxt, contain = [], []
        for side in ("left", "right"):
            c = nodes[side][frontier]
            assert (c != BVH_NONE).all(), (
                f"node {frontier[np.argmax(c == BVH_NONE)]}: {side} child is NONE in a tree of {n} boxes"
            )
            leaf = (c & BVH_LEAF) != 0
            k = (c & ~BVH_LEAF).astype(np.int64)
            for is_leaf, size, kind in ((True, n, "leaf"), (False, m, "internal node")):
                sel = leaf == is_leaf
                ks, ps = k[sel], frontier[sel]
                out = ks >= size
                assert not out.any(), f"node {ps[out][0]}: {side} child {kind} {ks[out][0]} out of range"
                np.add.at(seen_leaf if is_leaf else seen_node, ks, 1)
                if not is_leaf:
                    nxt.append(ks)
                contain.append(
                    (
                        side,
                        kind,
                        ps,
                        ks,
                        leaf_boxes[ks, :3] if is_leaf else nodes["lo"][ks],
                        leaf_boxes[ks, 3:] if is_leaf else nodes["hi"][ks],
                    )
                )
        twice = np.flatnonzero(seen_node > 1)
        assert twice.size == 0, f"internal node {twice[0]} is reached more than once"
        twice = np.flatnonzero(seen_leaf > 1)
        assert twice.size == 0, f"leaf {twice[0]} is reached more than once"
        for side, kind, ps, ks, clo, chi in contain:
            ok = (nodes["lo"][ps] <= clo).all(axis=1) & (nodes["hi"][ps] >= chi).all(axis=1)
            assert ok.all(), (
                f"node {ps[~ok][0]}'s box does not contain its {side} child ({kind} {ks[~ok][0]})"
            )
        frontier = np.concatenate(nxt)
    missing = np.flatnonzero(seen_node == 0)
    assert missing.size == 0, f"internal node {missing[0]} is not reached from the root"
    missing = np.flatnonzero(seen_leaf == 0)
    assert missing.size == 0, f"leaf {missing[0]} is not reached from the root"
