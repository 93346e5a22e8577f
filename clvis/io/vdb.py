"""The checks an OpenVDB file passes before tinyvdb reads it: tinyvdb sizes
its allocations by the counts the file declares (string lengths, metadata
entries, grid descriptors, the root node's tile and child counts, a
compressed block's byte count) before it finds the file too short for them:
4 changed bytes of a 1.5 MB file made it reserve 1.7 GB, one changed mask
word of a 1 MB file 8.6 GB. :func:`check_vdb` walks the header, the grid
descriptors and each grid's metadata, transform and tree, node by node, and
refuses counts the bytes after them cannot hold (DataError naming the file).

The layout (OpenVDB file format, version 222 and later):

- header: magic (int64 0x56444220), file version (uint32), library major and
  minor (uint32 each), a grid-offsets flag (uint8), the UUID (36 ASCII bytes);
  file metadata (below); the grid count (uint32);
- per grid: name, type and instance-parent strings (uint32 length + bytes),
  then the grid, block and end offsets (int64 each); an instance (a grid
  sharing the tree of the earlier grid its instance parent names) stores only
  its compression flags, metadata and transform, and a block offset of 0;
- at a grid's offset: its compression flags (uint32: 1 zip, 2 active mask,
  4 blosc), its metadata (a count, then per entry a name and a type string
  and a uint32-sized value), its transform (a type name string, then the
  map's doubles), the buffer count (uint32), the root's background value,
  tile count and child count (uint32); a tile takes 3 int32 + a value + an
  active byte, a child 3 int32 and then its node;
- the topology of a Tree_<type>_5_4_3, depth first: an internal node of
  32^3 (then 16^3) entries stores its child mask and value mask (4096, then
  512 bytes each) and its values (below), then the nodes its child mask
  names; a leaf (8^3) its value mask (64 bytes);
- the buffers: per leaf, in the same order, its value mask again (tinyvdb
  keeps the topology's, OpenVDB reads this one: they must agree) and its 512
  values (a bool leaf: 3 int32 and a 64-byte bit mask);
- values: a metadata byte (0-6), up to two inactive values (of the tree's
  type, half floats or not), a selection mask
  (metadata 3-5), then all the node's values, or only the active ones (the
  value mask's count) under the active-mask flag unless the metadata is 6;
  compressed (zip, blosc) as an int64 byte count and the bytes (a count <= 0:
  exactly the values' raw bytes follow), else raw. A grid type ending in
  _HalfFloat stores a float as 2 bytes, and nothing for a node without values.

The walk follows tinyvdb's reader where OpenVDB's is more lenient (tinyvdb
is what reads the file next); a tree of another value type or configuration
is checked to the root node only.
"""

from __future__ import annotations

import mmap
import os
import struct
import zlib
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..errors import DataError

__all__ = ["GridLeaves", "check_vdb", "vdb_grids", "vdb_leaves"]

_MAGIC = 0x56444220
# doubles each map type stores after its name
_MAP_DOUBLES = {
    "ScaleTranslateMap": 18,
    "UniformScaleTranslateMap": 18,
    "ScaleMap": 15,
    "UniformScaleMap": 15,
    "TranslationMap": 3,
    "AffineMap": 16,
}
# bytes of one value of the tree's type (Tree_<type>_5_4_3)
_VALUE_BYTES = {"float": 4, "double": 8, "int32": 4, "int64": 8, "bool": 1, "vec3s": 12, "vec3d": 24}
_CHILD_MIN = 12 + 2 * 4096  # origin, then the 32^3 node's child and value masks
_ZIP, _ACTIVE_MASK, _BLOSC = 1, 2, 4
_LOG2DIMS = ["5", "4", "3"]  # the tree configuration walked (OpenVDB's standard one)
# log2 of the voxels a child of each internal level spans a side: a 32^3
# node's children are 16^3 nodes of 8^3 leaves (2^7), a 16^3 node's leaves 2^3
_CHILD_SPAN = [4 + 3, 3]


_CODECS: list[str | None] = [None, "zip", "blosc"]  # a leaf_blocks row's codec


@dataclass(frozen=True)
class _Values:
    """A node's values as stored (decoded by :func:`_decode`)."""

    block: bytes  # the bytes
    count: int  # values they hold
    codec: str | None  # "zip", "blosc", None (raw)
    half: bool  # 2-byte half floats, else 4-byte floats
    what: str  # where they are, for an error


@dataclass(frozen=True)
class _TileBlock:
    """One node's active tiles: their origins, side (log2) and where their
    values are in the node's stored values (decoded on demand)."""

    origins: np.ndarray  # (t, 3) int64
    log2: int
    picks: np.ndarray  # (t,) indices into the decoded values
    values: _Values


@dataclass(frozen=True)
class GridLeaves:
    """A walked grid's leaves, in file order (the order of its leaf buffers),
    and its active tiles.

    active: the active voxels the leaves' value masks hold; origins: (L, 3)
    int64 index coordinates (i, j, k) of each leaf's first voxel; masks: (L,
    64) uint8, each leaf's value mask as stored (bit n = voxel (i, j, k) =
    origin + (n >> 6, (n >> 3) & 7, n & 7)).

    Active tiles (a float grid's; none for other types): a region of one
    value stored above the leaves, e.g. a fog volume's uniform inside.
    tile_origins (T, 3) int64 (i, j, k) of each tile's first voxel,
    tile_log2 (T,) its side: 2^3 (a 16^3 node's entry), 2^7 (a 32^3 node's)
    or 2^12 (the root's); :meth:`tile_values` decodes their values.

    parent: for an instance grid (one OpenVDB wrote sharing the tree of an
    earlier grid: it stores only its metadata and transform), the index of
    the grid whose tree (these leaves and tiles) it is; else None."""

    path: Path
    active: int
    origins: np.ndarray
    masks: np.ndarray
    tile_blocks: tuple[_TileBlock, ...] = ()
    parent: int | None = None  # an instance grid: the index of the grid whose tree it shares
    # a half-float grid's nodes that store inactive values other than the
    # background (value metadata 2, 4, 5), which tinyvdb 0.9 cannot read
    half_inactive: int = 0
    half: bool = False  # a float grid saved as half floats
    # a float grid's leaf values as stored: per leaf (start byte, bytes, values, codec)
    leaf_blocks: np.ndarray | None = None
    transform: dict | None = None  # its map, as tinyvdb's VDBGrid.transform gives it
    grid_class: str | None = None  # its metadata's "class": "level set", "fog volume", ...
    background: float = 0.0  # a float grid's background value (a level set's: its narrow band's outside)

    def leaf_values(self) -> np.ndarray:
        """(L, 512) float32: a float grid's leaf values, decoded from the file
        (VDB order: value n at (n >> 6, (n >> 3) & 7, n & 7) from the leaf's
        origin; where only the active values are stored, the inactive ones
        are 0)."""
        if self.leaf_blocks is None:
            raise ValueError("leaf_values: not a float grid")
        out = np.zeros((len(self), 512), np.float32)
        if not len(out):
            return out
        active = np.unpackbits(self.masks, axis=1, bitorder="little").view(bool)
        with open(self.path, "rb") as f, mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as data:
            for k, (start, nbytes, count, codec) in enumerate(self.leaf_blocks.tolist()):
                stored = _Values(
                    bytes(data[start : start + nbytes]),
                    count,
                    _CODECS[codec],
                    self.half,
                    f"the leaf values at byte {start}",
                )
                values = _decode(self.path, stored)
                if count == 512:
                    out[k] = values
                else:  # the active ones, as many as the value mask's bits (the walk's count)
                    out[k, active[k]] = values
        return out

    def __len__(self) -> int:
        return len(self.origins)

    @property
    def tile_origins(self) -> np.ndarray:
        if not self.tile_blocks:
            return np.zeros((0, 3), np.int64)
        return np.concatenate([b.origins for b in self.tile_blocks])

    @property
    def tile_log2(self) -> np.ndarray:
        return np.array([b.log2 for b in self.tile_blocks for _ in range(len(b.origins))], np.int64)

    @property
    def tile_leaves(self) -> int:
        """The 8^3 leaves the active tiles cover."""
        return sum(len(b.origins) << 3 * (b.log2 - 3) for b in self.tile_blocks)

    def tile_values(self) -> np.ndarray:
        """(T,) float32: each active tile's value, decoded from the node
        values it is stored among (OpenVDB's codecs: zlib, blosc; half
        floats widened). A block that does not decode to what its node
        declares is a DataError."""
        if not self.tile_blocks:
            return np.zeros(0, np.float32)
        return np.concatenate([_decode(self.path, b.values)[b.picks] for b in self.tile_blocks])


class _Reader:
    def __init__(self, path: Path, data, end: int) -> None:
        self.path, self.data, self.pos, self.end = path, data, 0, end

    def need(self, n: int, what: str) -> None:
        if n < 0 or self.pos + n > self.end:
            raise DataError(
                f"{self.path}: malformed VDB file: {what} at byte {self.pos} declares {n} bytes, "
                f"{max(self.end - self.pos, 0)} remain"
            )

    def take(self, fmt: str, what: str):
        n = struct.calcsize(fmt)
        self.need(n, what)
        out = struct.unpack_from(fmt, self.data, self.pos)
        self.pos += n
        return out if len(out) > 1 else out[0]

    def string(self, what: str) -> str:
        n = self.take("<I", what)
        self.need(n, what)
        s = self.data[self.pos : self.pos + n].decode("latin1")
        self.pos += n
        return s

    def metadata(self, what: str) -> dict[str, str]:
        """Skip a metadata block; its entries of type string (e.g. a grid's
        "class": "level set", "fog volume")."""
        count = self.take("<I", f"{what} count")
        # each entry: two strings (4 bytes each at least) and a sized value (4)
        self.need(12 * count, f"{count} {what} entries")
        strings = {}
        for _ in range(count):
            name = self.string(f"{what} name")
            kind = self.string(f"{what} type")
            n = self.take("<I", f"{what} value")
            self.need(n, f"{what} value")
            if kind == "string" and n <= 256:
                strings[name] = self.data[self.pos : self.pos + n].decode("latin1")
            self.pos += n
        return strings

    def mask(self, nbytes: int, what: str) -> int:
        """Skip a node mask of `nbytes`; the bits it sets."""
        self.need(nbytes, what)
        on = int.from_bytes(self.data[self.pos : self.pos + nbytes], "little").bit_count()
        self.pos += nbytes
        return on


def check_vdb(path: str | Path) -> list[tuple[int, int] | None]:
    """Refuse (DataError) an OpenVDB file whose counts the file cannot hold.

    Returns, per grid in file order, (the active voxels its leaves' value
    masks hold, what a reader of leaf voxels must return; its leaves), or
    None for a grid not walked to its leaves (another value type or tree
    configuration, a file version before 222)."""
    return [None if g is None else (g.active, len(g)) for g in vdb_leaves(path)]


def vdb_leaves(path: str | Path) -> list[GridLeaves | None]:
    """:func:`check_vdb`'s walk, returning each walked grid's leaves (their
    origins and value masks, GridLeaves), None for a grid not walked."""
    return [leaves for _, _, leaves in vdb_grids(path)]


def vdb_grids(path: str | Path) -> list[tuple[str, str, GridLeaves | None]]:
    """:func:`vdb_leaves` with each grid's name (without the suffix OpenVDB
    gives a repeated name) and type name: (name, type, leaves or None)."""
    p = Path(path)
    with open(p, "rb") as f:
        size = os.fstat(f.fileno()).st_size
        if size == 0:
            raise DataError(f"{p}: not an OpenVDB file (empty)")
        with mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as data:
            return _check(p, data, size)


def _check(p: Path, data, size: int) -> list[tuple[str, str, GridLeaves | None]]:
    r = _Reader(p, data, size)
    magic = r.take("<q", "magic")
    if magic != _MAGIC:
        raise DataError(f"{p}: not an OpenVDB file (magic {magic:#x})")
    version = r.take("<I", "file version")
    if version < 222:
        return []  # older layouts: tinyvdb's own checks
    r.take("<II", "library version")
    r.take("<B", "grid offsets flag")
    r.need(36, "UUID")
    r.pos += 36
    r.metadata("file metadata")
    n_grids = r.take("<I", "grid count")
    r.need(36 * n_grids, f"{n_grids} grid descriptors")
    out: list[GridLeaves | None] = []
    names: list[str] = []
    kinds: list[str] = []
    for i in range(n_grids):
        names.append(r.string("grid name"))
        kind = r.string("grid type")
        kinds.append(kind)
        parent = r.string("instance parent")
        grid_pos, block_pos, end_pos = r.take("<qqq", "grid offsets")
        # an instance (a grid sharing an earlier grid's tree) stores no tree:
        # its block offset is 0 and its tree is its parent's
        if not 0 <= grid_pos <= (grid_pos if parent else block_pos) <= end_pos <= size:
            raise DataError(
                f"{p}: malformed VDB file: grid offsets {grid_pos}, {block_pos}, {end_pos} "
                f"outside the file's {size} bytes"
            )
        if parent:
            if parent not in names[:i]:
                raise DataError(
                    f"{p}: malformed VDB file: grid {names[i]!r} is an instance of grid {parent!r}, "
                    "which no grid before it is"
                )
            j = names.index(parent)
            if kinds[j] != kind:
                raise DataError(
                    f"{p}: malformed VDB file: grid {names[i]!r} ({kind}) is an instance of grid "
                    f"{parent!r}, a {kinds[j]}"
                )
            shared = out[j]
            root = j if shared is None or shared.parent is None else shared.parent
            own = _Reader(p, data, end_pos)  # its own compression flags, metadata and transform
            own.pos = grid_pos
            own.take("<I", "grid compression flags")
            own_meta = own.metadata("grid metadata")
            transform = _read_map(own)
            out.append(
                None
                if shared is None
                else replace(shared, parent=root, transform=transform, grid_class=own_meta.get("class"))
            )
        else:
            out.append(_check_root(p, data, end_pos, kind, grid_pos))
        r.pos = end_pos  # the next descriptor follows the grid
    # a repeated name is written with a suffix: "\x1e" and a number
    return [(n.split("\x1e")[0], k, g) for n, k, g in zip(names, kinds, out, strict=True)]


def _read_map(r: _Reader) -> dict | None:
    """A grid's transform (its map's type name and doubles) as tinyvdb gives
    it: {"type", "voxel_size", "translation"} or {"type": "affine",
    "matrix"}; None for a map of another type (not skipped)."""
    map_type = r.string("transform type")
    n = _MAP_DOUBLES.get(map_type)
    if n is None:
        return None
    r.need(8 * n, f"{map_type} values")
    d = struct.unpack_from(f"<{n}d", r.data, r.pos)
    r.pos += 8 * n
    if map_type == "AffineMap":  # the 4x4 matrix, row by row, translation in the last row
        return {"type": "affine", "matrix": [list(d[i : i + 4]) for i in range(0, 16, 4)]}
    if map_type == "TranslationMap":
        return {"type": "translation", "voxel_size": (1.0, 1.0, 1.0), "translation": d[0:3]}
    # the scale (signed), then the voxel size (its absolute value), ...
    if n == 18:  # (Uniform)ScaleTranslateMap: the translation first
        return {"type": "scale_translate", "scale": d[3:6], "voxel_size": d[6:9], "translation": d[0:3]}
    return {"type": "scale", "scale": d[0:3], "voxel_size": d[3:6], "translation": (0.0, 0.0, 0.0)}


def _check_root(p: Path, data, end: int, kind: str, grid_pos: int) -> GridLeaves | None:
    """Check a grid; its leaves, None where not walked."""
    half = kind.endswith("_HalfFloat")  # floats saved as half floats
    parts = kind.removesuffix("_HalfFloat").split("_")
    value_bytes = _VALUE_BYTES.get(parts[1]) if len(parts) > 1 and parts[0] == "Tree" else None
    if value_bytes is None:
        return None  # a tree type clvis does not read: tinyvdb's checks
    r = _Reader(p, data, end)
    r.pos = grid_pos
    compression = r.take("<I", "grid compression flags")
    meta = r.metadata("grid metadata")
    transform = _read_map(r)
    if transform is None:
        return None  # a map clvis refuses later, by name
    r.take("<I", "buffer count")
    r.need(value_bytes, "background value")
    background = struct.unpack_from("<f", data, r.pos)[0] if parts[1] == "float" else 0.0  # never as half
    r.pos += value_bytes
    tiles, children = r.take("<II", "root tile and child counts")
    need = tiles * (12 + value_bytes + 1) + children * _CHILD_MIN
    if need > end - r.pos:
        raise DataError(
            f"{p}: malformed VDB file: the root node of the grid at byte {grid_pos} declares "
            f"{tiles} tiles and {children} children (at least {need} bytes); the grid has "
            f"{end - r.pos} bytes after them"
        )
    if parts[2:] != _LOG2DIMS:
        return None  # another tree configuration: tinyvdb's checks
    tree = _Tree(r, compression, value_bytes, half and parts[1] == "float", parts[1] == "float")
    for _ in range(tiles):  # origin, value (never as half), active byte
        origin = r.take("<3i", "root tile origin")
        value = struct.unpack_from("<f", data, r.pos)[0] if tree.want_tiles else 0.0  # in the need above
        r.pos += value_bytes
        if r.take("<B", "root tile active flag") and tree.want_tiles:
            block = struct.pack("<f", value)
            tree.tiles.append(
                _TileBlock(
                    np.array([origin], np.int64),
                    12,
                    np.zeros(1, np.int64),
                    _Values(block, 1, None, False, "a root tile"),
                )
            )
    for _ in range(children):
        origin = r.take("<3i", "root child origin")
        tree.internal(0, np.array(origin, np.int64))
    active = 0
    blocks: list[tuple[int, int, int, int]] = []  # a float grid's leaf values: start, bytes, count, codec
    for leaf in tree.leaves:
        at = r.pos
        r.need(64, "leaf buffer value mask")
        if data[at : at + 64] != data[leaf : leaf + 64]:
            raise DataError(
                f"{p}: malformed VDB file: the leaf value mask at byte {at} differs from its "
                f"topology's at byte {leaf}"
            )
        r.pos += 64
        on = int.from_bytes(data[leaf : leaf + 64], "little").bit_count()
        active += on
        if parts[1] == "bool":  # origin, then the values as a bit mask
            r.need(12 + 64, "bool leaf buffer")
            r.pos += 12 + 64
        else:
            count, start, nbytes, codec = tree.values(3, on)
            if tree.want_tiles:  # a float grid
                blocks.append((start, nbytes, count, _CODECS.index(codec)))
    masks = np.frombuffer(b"".join(tree.masks), np.uint8).reshape(-1, 64)
    origins = np.concatenate(tree.origins) if tree.origins else np.zeros((0, 3), np.int64)
    return GridLeaves(
        p,
        active,
        origins,
        masks,
        tuple(tree.tiles),
        half_inactive=tree.half_inactive,
        half=tree.half,
        leaf_blocks=np.array(blocks, np.int64).reshape(-1, 4) if tree.want_tiles else None,
        transform=transform,
        grid_class=meta.get("class"),
        background=float(background),
    )


class _Tree:
    """Walks a 5-4-3 tree's nodes as tinyvdb reads them, checking each against
    the bytes left before tinyvdb would allocate what it declares."""

    def __init__(
        self, r: _Reader, compression: int, value_bytes: int, half: bool, tiles: bool = False
    ) -> None:
        self.r, self.compression, self.value_bytes, self.half = r, compression, value_bytes, half
        self.want_tiles = tiles  # a float tree: its active tiles kept
        self.half_inactive = 0  # half-float nodes storing inactive values (tinyvdb 0.9 misreads them)
        self.tiles: list[_TileBlock] = []
        self.leaves: list[int] = []  # where each leaf's topology value mask is
        self.origins: list[np.ndarray] = []  # their origins, (n, 3) per 16^3 node
        self.masks: list[bytes] = []  # their value masks, 64 bytes each, per 16^3 node

    def internal(self, level: int, origin: np.ndarray) -> None:
        r, log2 = self.r, int(_LOG2DIMS[level])
        nbytes = (1 << 3 * log2) // 8
        at = r.pos
        children = r.mask(nbytes, f"{1 << log2}^3 node child mask")
        # the children, in the order their nodes follow: ascending bit n, at
        # local (n >> 2 log2, (n >> log2) & (2^log2 - 1), n & (2^log2 - 1))
        bits = _bits(r.data, at, nbytes)
        side = (1 << log2) - 1
        local = np.stack([bits >> 2 * log2, (bits >> log2) & side, bits & side], axis=1)
        child_origins = origin + (local.astype(np.int64) << _CHILD_SPAN[level])
        at = r.pos
        on = r.mask(nbytes, f"{1 << log2}^3 node value mask")
        stored = self.values(log2, on)
        if on and self.want_tiles:  # active tiles: value-mask entries that are not children
            on_bits = _bits(r.data, at, nbytes)
            tile = np.setdiff1d(on_bits, bits, assume_unique=True)
            if len(tile):
                count, start, size, codec = stored
                tl = np.stack([tile >> 2 * log2, (tile >> log2) & side, tile & side], axis=1).astype(np.int64)
                self.tiles.append(
                    _TileBlock(
                        origin + (tl << _CHILD_SPAN[level]),
                        _CHILD_SPAN[level],
                        tile if count == 1 << 3 * log2 else np.searchsorted(on_bits, tile),
                        _Values(
                            bytes(r.data[start : start + size]),
                            count,
                            codec,
                            self.half,
                            f"the {1 << log2}^3 node values at byte {at + nbytes}",
                        ),
                    )
                )
        if level == 0:
            for o in child_origins:
                self.internal(1, o)
        else:  # each child a leaf, its topology its value mask
            r.need(64 * children, f"{children} leaf value masks")
            self.leaves.extend(range(r.pos, r.pos + 64 * children, 64))
            self.origins.append(child_origins)
            self.masks.append(bytes(r.data[r.pos : r.pos + 64 * children]))
            r.pos += 64 * children

    def values(self, log2: int, active: int) -> tuple[int, int, int, str | None]:
        """A node's values: metadata, inactive values, selection mask, the
        values. Returns where its values are: (the values stored, the byte
        where they start, their bytes there, "zip", "blosc" or None for raw)."""
        r, n = self.r, 1 << 3 * log2
        what = f"{1 << log2}^3 node values"
        at = r.pos
        meta = r.take("<B", f"{what}' metadata")
        if meta > 6:
            raise DataError(f"{r.path}: malformed VDB file: {what}' metadata {meta} at byte {at} (0 to 6)")
        # the inactive values are stored whole, as the tree's type, even in a
        # grid saved as half floats (OpenVDB writes them truncated to half
        # precision but as floats); the values after them as half floats
        inactive = {2: 1, 4: 1, 5: 2}.get(meta, 0)
        if inactive and self.half:
            self.half_inactive += 1
        r.need(inactive * self.value_bytes, f"{what}' inactive values")
        r.pos += inactive * self.value_bytes
        value_bytes = 2 if self.half else self.value_bytes
        if meta in (3, 4, 5):
            r.mask(n // 8, f"{what}' selection mask")
        count = active if self.compression & _ACTIVE_MASK and meta != 6 else n
        raw = count * value_bytes
        if self.half and count == 0:
            return 0, r.pos, 0, None  # nothing stored, not even a compressed size
        if self.compression & (_ZIP | _BLOSC):
            at = r.pos
            stored = r.take("<q", f"{what}' compressed size")
            if stored <= 0 and -stored != raw:
                raise DataError(
                    f"{r.path}: malformed VDB file: {what} at byte {at} store {-stored} raw bytes "
                    f"for {count} values of {value_bytes} bytes"
                )
            r.need(abs(stored), f"{what}' compressed block")
            r.pos += abs(stored)
            codec = None if stored <= 0 else "blosc" if self.compression & _BLOSC else "zip"
            return count, r.pos - abs(stored), abs(stored), codec
        r.need(raw, what)
        r.pos += raw
        return count, r.pos - raw, raw, None


def _decode(path: Path, b: _Values) -> np.ndarray:
    """The float values a node's values block stores, as float32."""
    raw = b.count * (2 if b.half else 4)
    try:
        if b.codec == "zip":
            out = zlib.decompressobj().decompress(b.block, raw + 1)  # never more than the values take
        elif b.codec == "blosc":
            # blosc's header: the bytes it decompresses to (at 4), its own size (at 12)
            if len(b.block) < 16 or struct.unpack_from("<I", b.block, 4)[0] != raw:
                raise ValueError(f"a blosc block not of {raw} bytes")
            if struct.unpack_from("<I", b.block, 12)[0] != len(b.block):
                raise ValueError(f"a blosc block of {len(b.block)} bytes stating another size")
            blosc = _blosc(path)
            try:
                out = blosc.decompress(b.block)
            except Exception as e:  # blosc_extension.error, an Exception of its own
                raise ValueError(f"blosc: {e}") from None
        else:
            out = b.block
    except (zlib.error, ValueError, RuntimeError) as e:  # blosc: ValueError, RuntimeError
        raise DataError(f"{path}: malformed VDB file: {b.what}: {e}") from None
    if len(out) != raw:
        raise DataError(f"{path}: malformed VDB file: {b.what}: {len(out)} bytes for {b.count} values")
    return np.frombuffer(out, "<f2" if b.half else "<f4").astype(np.float32)


def _bits(data, at: int, nbytes: int) -> np.ndarray:
    """The set bits of the mask of `nbytes` at byte `at`, ascending."""
    return np.flatnonzero(
        np.unpackbits(np.frombuffer(bytes(data[at : at + nbytes]), np.uint8), bitorder="little")
    )


def _blosc(path: Path):
    try:
        import blosc
    except ImportError:
        raise ImportError(
            f"{path}: its active tiles or half-float leaves are blosc-compressed, which needs "
            "the blosc package: "
            'pip install ".[vdb]" in a clvis checkout (or pip install blosc)'
        ) from None
    return blosc
