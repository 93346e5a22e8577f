"""Writes tests/data/openvdb_small.vdb with the OpenVDB library itself
(Debian's python3-openvdb 10.0.1: ``apt install python3-openvdb``, run with
/usr/bin/python3; clvis does not depend on it). Two float grids:

- "surface": OpenVDB's narrow-band level set of a sphere, radius 16 voxels
  centred at (60, 61, 62), voxel size 1, half width 2 (12,790 active voxels
  in 94 leaves, all in one 16^3 node: tinyvdb 0.9's own voxel list returns
  8,534 of them);
- "density": a fog ball, 1 - r / 12 over a 24^3 block at index (-30, 4, 9),
  voxel size 0.25, saved as half floats (7,208 active voxels).

The tests check what read_vdb returns against these formulas."""

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
vdb.write("openvdb_small.vdb", grids=[surface, density])
