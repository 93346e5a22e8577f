"""Writes tests/data/openvdb_small.vdb with the OpenVDB library itself
(Debian's python3-openvdb 10.0.1: ``apt install python3-openvdb``, run with
/usr/bin/python3; clvis does not depend on it). Three float grids:

- "surface": OpenVDB's narrow-band level set of a sphere, radius 16 voxels
  centred at (60, 61, 62), voxel size 1, half width 2 (12,790 active voxels
  in 94 leaves, all in one 16^3 node: tinyvdb 0.9's own voxel list returns
  8,534 of them);
- "density": a fog ball, 1 - r / 12 over a 24^3 block at index (-30, 4, 9),
  voxel size 0.25, saved as half floats (7,208 active voxels);
- "block": 0.5 over a 160^3 block at index (0, 0, 0), but (i + 2 j + 3 k)
  mod 7 / 7 + 0.25 where i, j, k >= 140 (counted from 140); OpenVDB stores
  the uniform part as active tiles (a 128^3 one of a 32^3 node, 8^3 ones of
  16^3 nodes), which tinyvdb 0.9 does not read (4,096,000 active voxels,
  27 leaves).

The tests check what read_vdb returns against these formulas.

Also tests/data/openvdb_tiles.vdb, a fuzzing seed of active tiles: "tiles",
0.5 over a 40^3 block at index (0, 0, 0) but (i + 2 j + 3 k) mod 5 / 5 in
its first 8^3 (124 8^3 tiles and one leaf, blosc-compressed).

And tests/data/openvdb_instance.vdb (instance grids),
tests/data/openvdb_half_inactive.vdb (half floats with inactive values other
than the background), tests/data/openvdb_half_subnormal.vdb,
tests/data/openvdb_frustum.vdb and tests/data/openvdb_fog.vdb (a grid of
class "fog volume"), described where they are written below. Each run writes new UUIDs: regenerate only the
files a change needs."""

import numpy as np
import pyopenvdb as vdb

surface = vdb.createLevelSetSphere(radius=16.0, center=(60.0, 61.0, 62.0), voxelSize=1.0, halfWidth=2.0)
surface.name = "surface"
i, j, k = np.mgrid[:24, :24, :24]
r = np.sqrt((i - 11.5) ** 2 + (j - 11.5) ** 2 + (k - 11.5) ** 2)
density = vdb.FloatGrid()
density.copyFromArray(np.clip(1 - r / 12, 0, 1).astype(np.float32), ijk=(-30, 4, 9), tolerance=0.0)
density.name = "density"
density.transform = vdb.createLinearTransform(voxelSize=0.25)
density.saveFloatAsHalf = True
b = np.full((160, 160, 160), 0.5, np.float32)
i, j, k = np.mgrid[:20, :20, :20]
b[140:, 140:, 140:] = (i + 2 * j + 3 * k) % 7 / 7 + 0.25
block = vdb.FloatGrid()
block.copyFromArray(b, ijk=(0, 0, 0), tolerance=0.0)
block.name = "block"
vdb.write("openvdb_small.vdb", grids=[surface, density, block])

t = np.full((40, 40, 40), 0.5, np.float32)
i, j, k = np.mgrid[:8, :8, :8]
t[:8, :8, :8] = (i + 2 * j + 3 * k) % 5 / 5
tiles = vdb.FloatGrid()
tiles.copyFromArray(t, ijk=(0, 0, 0), tolerance=0.0)
tiles.name = "tiles"
vdb.write("openvdb_tiles.vdb", grids=[tiles])

# tests/data/openvdb_instance.vdb: "orig", "inst" (an instance of "orig": the
# two grids share one tree, which OpenVDB writes once, "inst" storing only its
# transform: voxel size 0.5, translation (1, 2, 3)) and "other"
orig = vdb.FloatGrid()
orig.fill((-16, 0, 0), (-1, 15, 15), 0.5)  # eight active 8^3 tiles
acc = orig.getAccessor()
for i, j, k in np.ndindex(5, 4, 3):
    acc.setValueOn((3 + i, 4 + j, 5 + k), (i + 2 * j + 3 * k) % 11 / 11)
orig.name = "orig"
inst = orig.copy()  # shares orig's tree
inst.transform = vdb.createLinearTransform(voxelSize=0.5)
inst.transform.translate((1.0, 2.0, 3.0))
inst.name = "inst"
other = vdb.FloatGrid()
other.getAccessor().setValueOn((-1, -2, -3), 7.0)
other.name = "other"
vdb.write("openvdb_instance.vdb", grids=[orig, inst, other])

# tests/data/openvdb_half_inactive.vdb: "half", saved as half floats, whose
# nodes store an inactive value other than the background (6.0; OpenVDB
# writes it as a float, not a half): a 16^3 node of two active 8^3 tiles
# (5.0 at (0, 0, 0) and (8, 0, 0)) and two inactive ones (6.0), a leaf of 64
# active voxels (1.5 over (40..43, 0..3, 0..3)) and 8 inactive ones (6.0),
# then a leaf of 27 (2.5 over (60..62, 0..2, 0..2))
half = vdb.FloatGrid()
half.fill((16, 0, 0), (31, 7, 7), 6.0, False)
half.fill((0, 0, 0), (15, 7, 7), 5.0)
half.fill((40, 0, 0), (43, 3, 3), 1.5)
half.fill((44, 4, 4), (45, 5, 5), 6.0, False)
half.fill((60, 0, 0), (62, 2, 2), 2.5)
half.name = "half"
half.saveFloatAsHalf = True
vdb.write("openvdb_half_inactive.vdb", grids=[half])

# tests/data/openvdb_half_subnormal.vdb: "tiny", saved as half floats, whose
# values are half floats' subnormals and normals: voxel (i, j, 0) for i, j in
# 0..7 holds (1 + i + 8 j) * 2^-24 (half's smallest subnormal times 1..64),
# voxel (i, j, 1) the negated value times 2^10 (normal halves up to 2^-8)
tiny = vdb.FloatGrid()
acc = tiny.getAccessor()
for i, j in np.ndindex(8, 8):
    acc.setValueOn((i, j, 0), float((1 + i + 8 * j) * 2.0**-24))
    acc.setValueOn((i, j, 1), float(-(1 + i + 8 * j) * 2.0**-14))
tiny.name = "tiny"
tiny.saveFloatAsHalf = True
vdb.write("openvdb_half_subnormal.vdb", grids=[tiny])

# tests/data/openvdb_frustum.vdb: "linear", (i + 8 j + 64 k) mod 7 + 1 over the
# 8^3 leaf at the origin, beside "frustum", a grid of 2.0 under a frustum map
# (which tinyvdb 0.9 cannot parse, failing the whole file, and clvis does not
# read): the linear grid is read from clvis's walk alone
i, j, k = np.mgrid[:8, :8, :8]
linear = vdb.FloatGrid()
linear.copyFromArray(((i + 8 * j + 64 * k) % 7 + 1).astype(np.float32), ijk=(0, 0, 0), tolerance=0.0)
linear.name = "linear"
frustum = vdb.FloatGrid()
frustum.copyFromArray(np.full((8, 8, 8), 2.0, np.float32), tolerance=0.0)
frustum.name = "frustum"
frustum.transform = vdb.createFrustumTransform(xyzMin=(0, 0, 0), xyzMax=(8, 8, 8), taper=0.5, depth=4.0)
vdb.write("openvdb_frustum.vdb", grids=[linear, frustum])

# tests/data/openvdb_fog.vdb: "density", a fog ball 1 - r / 10 over a 20^3
# block at the origin (4,224 active voxels), its class "fog volume" (what
# OpenVDB's sdf-to-fog conversion and fog exporters set): clvis gauss draws
# such a grid as a fog
i, j, k = np.mgrid[:20, :20, :20]
r = np.sqrt((i - 9.5) ** 2 + (j - 9.5) ** 2 + (k - 9.5) ** 2)
fog = vdb.FloatGrid()
fog.copyFromArray(np.clip(1 - r / 10, 0, 1).astype(np.float32), ijk=(0, 0, 0), tolerance=0.0)
fog.name = "density"
fog.gridClass = vdb.GridClass.FOG_VOLUME
vdb.write("openvdb_fog.vdb", grids=[fog])
