"""Seed files for the fuzzer, made here (and the third-party files of
tests/data): every format clvis reads, with the reader each goes to.

A seed is (format, reader, path). Formats: ply, las, laz, npy, npz, nii,
nii.gz, raw, vdb, e57 (with pye57), pcd, xyz, csv, vti, vtk. Readers: points
(read_points), volume (read_volume), vdb (read_vdb), gaussians (Gaussians.load).
"""

from __future__ import annotations

import gzip
import struct
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parents[1] / "data"


def _cloud(n, seed=0):
    from clvis.io import PointCloud

    rng = np.random.default_rng(seed)
    return PointCloud(
        rng.normal(0, 10, (n, 3)),
        colors=rng.integers(0, 256, (n, 4), dtype=np.uint8),
        attributes={"intensity": rng.random(n).astype(np.float32)},
        radius=rng.random(n),
        origin=(1e5, 2.0, 0.5),
    )


def _las(path, n, point_format, seed=0, extra=False):
    import laspy

    rng = np.random.default_rng(seed)
    header = laspy.LasHeader(point_format=point_format, version="1.2" if point_format < 6 else "1.4")
    header.scales = [0.001] * 3
    header.offsets = [500000.0, 0.0, 0.0]
    las = laspy.LasData(header)
    if extra:
        las.add_extra_dims([laspy.ExtraBytesParams("a", "f4"), laspy.ExtraBytesParams("b", "u1")])
    las.x = 500000 + rng.random(n) * 100
    las.y = rng.random(n) * 100
    las.z = rng.random(n) * 10
    las.intensity = rng.integers(0, 65536, n)
    if "gps_time" in las.point_format.dimension_names:
        las.gps_time = np.arange(n) * 0.5
    if "red" in las.point_format.dimension_names:
        las.red, las.green, las.blue = rng.integers(0, 65536, (3, n)).astype(np.uint16)
    las.write(str(path))
    return las.header.offset_to_point_data


def _s(text):
    b = text.encode()
    return struct.pack("<I", len(b)) + b


def _vdb(tmp: Path, path: Path, n=60, seed=1):
    """A float grid written by tinyvdb from a minimal hand-made OpenVDB file."""
    import tinyvdb

    vs = np.array([1.0, 1.0, 1.0])
    transform = _s("ScaleTranslateMap") + b"".join(
        struct.pack("<3d", *v) for v in (np.zeros(3), vs, vs, 1 / vs, 1 / vs**2, 0.5 / vs)
    )
    out = struct.pack("<qIIIB", 0x56444220, 224, 11, 0, 1) + b"0EA4B2C5-0F55-4B24-9C25-5CFD16E1E1CE"
    out += struct.pack("<II", 0, 1)
    body = struct.pack("<II", 0, 0) + transform + struct.pack("<I", 1) + struct.pack("<f", 0)
    body += struct.pack("<ii", 0, 0)
    out += _s("density") + _s("Tree_float_5_4_3") + _s("")
    pos = len(out) + 24
    out += struct.pack("<qqq", pos, pos + len(body), pos + len(body)) + body
    template = tmp / f"template-{path.stem}.vdb"
    template.write_bytes(out)
    rng = np.random.default_rng(seed)
    ijk = np.unique(rng.integers(-10, 20, (n, 3)), axis=0).astype(np.int32)
    vals = rng.random(len(ijk)).astype(np.float32)
    with tinyvdb.open(str(template)) as f:
        f.read_grids()
        f.extend_grid_from_sparse(0, ijk.tobytes(), vals.tobytes(), "density")
        f.save(str(path))
    template.unlink()


def _vdb_tree(tmp: Path, path: Path, compression=None, clusters=4, seed=7):
    """A float grid whose tree has several nodes at each level: `clusters`
    32^3 nodes (more where a cluster straddles a boundary), 4 16^3 nodes in
    each, 6 leaves in each of those; tinyvdb writes it raw, or with
    `compression` (tinyvdb.COMPRESS_*): 4 clusters raw are 2-4 MB, 20 zipped
    with the active mask 1 MB."""
    import tinyvdb

    _vdb(tmp, path, n=20, seed=seed)
    rng = np.random.default_rng(seed)
    pts = []
    for c5 in rng.integers(-12000, 12000, (clusters, 3)):
        for c4 in rng.integers(-1500, 1500, (4, 3)):
            for leaf in rng.integers(-60, 60, (6, 3)):
                pts.append(c5 + c4 + leaf + rng.integers(0, 8, (20, 3)))
    ijk = np.unique(np.concatenate(pts), axis=0).astype(np.int32)
    vals = rng.random(len(ijk)).astype(np.float32)
    with tinyvdb.open(str(path)) as f:
        f.read_grids()
        f.extend_grid_from_sparse(0, ijk.tobytes(), vals.tobytes(), "density")
        f.save(str(path), **({} if compression is None else {"compression": compression}))


def make_seeds(out: Path) -> list[tuple[str, str, Path]]:
    """Write the seeds into `out`; [(format, reader, path)]. Formats whose
    optional package is missing are left out."""
    from clvis.gauss import Gaussians
    from clvis.io import save_npz, write_ply

    out.mkdir(parents=True, exist_ok=True)
    seeds: list[tuple[str, str, Path]] = []

    def add(fmt, reader, path):
        seeds.append((fmt, reader, Path(path)))

    write_ply(out / "bin.ply", _cloud(12))
    add("ply", "points", out / "bin.ply")
    write_ply(out / "txt.ply", _cloud(6, seed=1), text=True)
    add("ply", "points", out / "txt.ply")
    for name in ("pyvista_ant.ply",):
        if (DATA / name).is_file():
            add("ply", "points", DATA / name)
    np.save(out / "arr.npy", np.random.default_rng(2).normal(size=(20, 3)).astype(np.float32))
    add("npy", "points", out / "arr.npy")
    rec = np.zeros(8, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("red", "u1"), ("i", "<f8")])
    np.save(out / "rec.npy", rec)
    add("npy", "points", out / "rec.npy")
    save_npz(out / "cloud.npz", _cloud(10, seed=3))
    add("npz", "points", out / "cloud.npz")
    rng = np.random.default_rng(4)
    Gaussians(rng.normal(size=(5, 3)), rng.random((5, 3))).save(out / "gauss.npz")
    add("npz", "gaussians", out / "gauss.npz")
    np.savez_compressed(out / "deflated.npz", positions=rng.normal(size=(30, 3)))
    add("npz", "points", out / "deflated.npz")
    np.save(out / "vol.npy", rng.random((4, 5, 6)))
    add("npy", "volume", out / "vol.npy")
    (out / "vol_6x5x4_uint16.raw").write_bytes(rng.integers(0, 65535, 120, dtype=np.uint16).tobytes())
    add("raw", "volume", out / "vol_6x5x4_uint16.raw")
    try:
        import laspy  # noqa: F401
        import lazrs  # noqa: F401
    except ImportError:
        pass
    else:
        _las(out / "las0.las", 30, 0)
        add("las", "points", out / "las0.las")
        _las(out / "las3.las", 30, 3)
        add("las", "points", out / "las3.las")
        _las(out / "eb.las", 20, 6, extra=True)
        add("las", "points", out / "eb.las")
        for pf, n in ((1, 60), (3, 60), (6, 80), (7, 60), (8, 60), (3, 3000)):
            _las(out / f"laz{pf}-{n}.laz", n, pf, seed=pf)
            add("laz", "points", out / f"laz{pf}-{n}.laz")
        for name in ("laspy_simple.laz", "laspy_simple.copc.laz"):
            if (DATA / name).is_file():
                add("laz", "points", DATA / name)
    try:
        import nibabel
    except ImportError:
        pass
    else:
        data = rng.random((6, 5, 4)).astype(np.float32)
        nibabel.save(nibabel.Nifti1Image(data, np.eye(4)), out / "vol.nii")
        add("nii", "volume", out / "vol.nii")
        img = nibabel.Nifti1Image(rng.integers(0, 200, (5, 4, 3, 1)).astype(np.int16), np.eye(4))
        img.header.extensions.append(nibabel.nifti1.Nifti1Extension(6, b"a comment for the fuzzer"))
        nibabel.save(img, out / "ext4d.nii")
        add("nii", "volume", out / "ext4d.nii")
        nibabel.save(nibabel.Nifti2Image(data, np.eye(4)), out / "vol2.nii")
        add("nii", "volume", out / "vol2.nii")
        (out / "volz.nii.gz").write_bytes(gzip.compress((out / "vol.nii").read_bytes()))
        add("nii.gz", "volume", out / "volz.nii.gz")
    try:
        import tinyvdb  # noqa: F401
    except ImportError:
        pass
    else:
        _vdb(out, out / "grid.vdb")
        add("vdb", "vdb", out / "grid.vdb")
        _vdb(out, out / "grid2.vdb", n=400, seed=2)
        add("vdb", "vdb", out / "grid2.vdb")
        # internal nodes and leaves of several kinds, zipped with the active mask
        _vdb_tree(out, out / "tree.vdb", compression=tinyvdb.COMPRESS_ZIP | tinyvdb.COMPRESS_ACTIVE_MASK)
        add("vdb", "vdb", out / "tree.vdb")
    try:
        import pye57
    except ImportError:
        pass
    else:
        _e57(pye57, out / "scan.e57", 200)
        add("e57", "points", out / "scan.e57")
        _e57(pye57, out / "two.e57", 40, scans=2, invalid=True)
        add("e57", "points", out / "two.e57")
    _text_seeds(out, add)
    return seeds


def _text_seeds(out: Path, add) -> None:
    """PCD (ASCII and binary), text clouds (.xyz, .csv) and VTK image data
    (.vti in ascii, base64 and zlib-compressed base64; legacy .vtk ASCII and
    pyvista's binary file)."""
    import base64
    import zlib

    rng = np.random.default_rng(7)
    n = 12

    def pcd_header(fields, sizes, types, data):
        return (
            "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\n"
            f"FIELDS {' '.join(fields)}\nSIZE {' '.join(sizes)}\nTYPE {' '.join(types)}\n"
            f"COUNT {' '.join(['1'] * len(fields))}\nWIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\n"
            f"POINTS {n}\nDATA {data}\n"
        ).encode()

    rec = np.zeros(n, [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("rgb", "<u4"), ("intensity", "<u2")])
    for k in ("x", "y", "z"):
        rec[k] = rng.normal(0, 10, n)
    rec["rgb"] = rng.integers(0, 1 << 24, n)
    rec["intensity"] = rng.integers(0, 65536, n)
    fields = ["x", "y", "z", "rgb", "intensity"]
    (out / "bin.pcd").write_bytes(
        pcd_header(fields, ["4"] * 4 + ["2"], ["F"] * 3 + ["U", "U"], "binary") + rec.tobytes()
    )
    add("pcd", "points", out / "bin.pcd")
    body = "".join(f"{r['x']:.6g} {r['y']:.6g} {r['z']:.6g} {r['rgb']} {r['intensity']}\n" for r in rec)
    (out / "txt.pcd").write_bytes(
        pcd_header(fields, ["4"] * 4 + ["2"], ["F"] * 3 + ["U", "U"], "ascii") + body.encode()
    )
    add("pcd", "points", out / "txt.pcd")
    xyz = "x y z r g b intensity\n" + "".join(
        f"{r['x']:.6g} {r['y']:.6g} {r['z']:.6g} {r['rgb'] & 255} {r['rgb'] >> 8 & 255} {r['rgb'] >> 16} "
        f"{r['intensity']}\n"
        for r in rec
    )
    (out / "cloud.xyz").write_text(xyz)
    add("xyz", "points", out / "cloud.xyz")
    (out / "cloud.csv").write_text(xyz.replace(" ", ","))
    add("csv", "points", out / "cloud.csv")

    vol = rng.random((3, 4, 5)).astype(np.float32)
    raw = vol.tobytes()
    for encoding in ("ascii", "binary", "zlib"):
        comp = ""
        if encoding == "ascii":
            data = " ".join(f"{v:.6g}" for v in vol.ravel())
        elif encoding == "binary":
            data = base64.b64encode(np.array([len(raw)], "<u4").tobytes() + raw).decode()
        else:  # zlib blocks of 64 bytes, header and data encoded separately (VTK's layout)
            comp = ' compressor="vtkZLibDataCompressor"'
            blocks = [raw[i : i + 64] for i in range(0, len(raw), 64)]
            zs = [zlib.compress(b) for b in blocks]
            head = np.array([len(blocks), 64, len(blocks[-1]) % 64, *map(len, zs)], "<u4").tobytes()
            data = base64.b64encode(head).decode() + base64.b64encode(b"".join(zs)).decode()
        fmt = "ascii" if encoding == "ascii" else "binary"
        (out / f"{encoding}.vti").write_text(
            f'<?xml version="1.0"?>\n<VTKFile type="ImageData" version="0.1" byte_order="LittleEndian" '
            f'header_type="UInt32"{comp}>\n'
            '<ImageData WholeExtent="0 4 0 3 0 2" Origin="5 6 7" Spacing="1 2 3">\n'
            '<Piece Extent="0 4 0 3 0 2"><PointData Scalars="v">\n'
            f'<DataArray type="Float32" Name="v" format="{fmt}">\n{data}\n</DataArray>\n'
            "</PointData><CellData></CellData></Piece></ImageData></VTKFile>\n"
        )
        add("vti", "volume", out / f"{encoding}.vti")
    (out / "ascii.vtk").write_text(
        "# vtk DataFile Version 3.0\nclvis fuzz seed\nASCII\nDATASET STRUCTURED_POINTS\n"
        "DIMENSIONS 5 4 3\nORIGIN 0 0 0\nSPACING 1 1 1\nPOINT_DATA 60\nSCALARS v float 1\n"
        "LOOKUP_TABLE default\n" + " ".join(f"{v:.6g}" for v in vol.ravel()) + "\n"
    )
    add("vtk", "volume", out / "ascii.vtk")
    if (DATA / "pyvista_uniform.vtk").is_file():
        add("vtk", "volume", DATA / "pyvista_uniform.vtk")


def _e57(pye57, path: Path, n: int, scans: int = 1, invalid: bool = False, seed: int = 5) -> None:
    """An E57 file of `scans` scans of n points: georeferenced x, y, z,
    intensity and colours (and an invalid-state field)."""
    rng = np.random.default_rng(seed)
    f = pye57.E57(str(path), mode="w")
    for _ in range(scans):
        s = {
            "cartesianX": 5e5 + rng.random(n) * 10,
            "cartesianY": rng.random(n) * 10,
            "cartesianZ": rng.random(n),
            "intensity": rng.random(n).astype(np.float32),
            **{k: rng.integers(0, 256, n).astype(np.uint8) for k in ("colorRed", "colorGreen", "colorBlue")},
        }
        if invalid:
            s["cartesianInvalidState"] = (np.arange(n) % 7 == 0).astype(np.int8)
        f.write_scan_raw(s)
    f.close()


def suffix(fmt: str) -> str:
    return "." + fmt
