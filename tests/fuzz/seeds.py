"""Seed files for the fuzzer, made here (and the third-party files of
tests/data): every format clvis reads, with the reader each goes to.

A seed is (format, reader, path). Formats: ply, las, laz, npy, npz, nii,
nii.gz, hdr and img (Analyze and NIfTI-1 pairs), mgh, mgz, raw, vdb, e57
(with pye57), vti, vtr, vtk (volumes and point sets), vtp, vtu, vts (with vtk),
pcd, xyz, pts, txt, csv. Readers:
points (read_points), volume (read_volume), vdb (read_vdb), gaussians
(Gaussians.load).
"""

from __future__ import annotations

import base64
import gzip
import struct
import zlib
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


def _vti(path: Path, data: np.ndarray, encoding: str) -> None:
    """A .vti of (Z, Y, X) `data` as VTK's XML writer lays it out: inline
    ascii, base64 binary (a UInt32 byte count, then the bytes) or zlib blocks
    (its block header and the blocks base64-encoded apart), or raw appended
    (the byte count and bytes after <AppendedData>'s '_')."""
    nz, ny, nx = data.shape
    raw = data.astype("<f4").tobytes()
    comp = ""
    if encoding == "ascii":
        body = " ".join(f"{v:.6g}" for v in data.ravel())
    elif encoding == "binary":
        body = base64.b64encode(np.array([len(raw)], "<u4").tobytes() + raw).decode()
    elif encoding in ("appended", "appended64"):  # raw appended data, VTK's and ParaView's default
        body = ""
    else:
        comp = ' compressor="vtkZLibDataCompressor"'
        blocks = [raw[i : i + 256] for i in range(0, len(raw), 256)]
        zs = [zlib.compress(b) for b in blocks]
        head = np.array([len(blocks), 256, len(blocks[-1]) % 256, *map(len, zs)], "<u4").tobytes()
        body = base64.b64encode(head).decode() + base64.b64encode(b"".join(zs)).decode()
        encoding = "binary"
    tail = ""
    if encoding == "appended64":  # base64 appended zlib blocks (EncodeAppendedData on)
        comp = ' compressor="vtkZLibDataCompressor"'
        zs = [zlib.compress(raw[i : i + 256]) for i in range(0, len(raw), 256)]
        head = np.array([len(zs), 256, len(raw) % 256, *map(len, zs)], "<u4").tobytes()
        encoding = 'appended" offset="0'
        tail = (
            '<AppendedData encoding="base64">\n _'
            + (base64.b64encode(head) + base64.b64encode(b"".join(zs))).decode()
            + "\n</AppendedData>"
        )
    if encoding == "appended":
        encoding = 'appended" offset="0'
        tail = '<AppendedData encoding="raw">\n _'
    text = (
        f'<?xml version="1.0"?>\n<VTKFile type="ImageData" version="0.1" byte_order="LittleEndian" '
        f'header_type="UInt32"{comp}>\n<ImageData WholeExtent="0 {nx - 1} 0 {ny - 1} 0 {nz - 1}" '
        f'Origin="1 2 3" Spacing="0.5 1 2">\n<Piece Extent="0 {nx - 1} 0 {ny - 1} 0 {nz - 1}">'
        f'<PointData Scalars="density">\n<DataArray type="Float32" Name="density" format="{encoding}">'
        f"\n{body}\n</DataArray>\n</PointData><CellData></CellData></Piece></ImageData>{tail}"
    ).encode()
    if tail.endswith("_"):
        text += np.array([len(raw)], "<u4").tobytes() + raw + b"\n</AppendedData>"
    path.write_bytes(text + b"</VTKFile>\n")


def _vtr(path: Path, mode: str, cells: bool) -> None:
    """A .vtr (XML RectilinearGrid) of evenly spaced coordinates as VTK's
    writer makes it, in `mode` (Ascii, Binary: zlib, Appended: raw), its
    samples a point array, or with `cells` a cell array."""
    import vtk
    from vtk.util import numpy_support

    g = vtk.vtkRectilinearGrid()
    g.SetDimensions(4, 3, 2)
    for axis, c in zip("XYZ", (np.arange(4.0), np.arange(3.0) * 2, np.arange(2.0) * 0.5), strict=True):
        getattr(g, f"Set{axis}Coordinates")(numpy_support.numpy_to_vtk(c, deep=True))
    a = numpy_support.numpy_to_vtk(np.arange(6.0 if cells else 24.0, dtype=np.float32), deep=True)
    a.SetName("v")
    (g.GetCellData() if cells else g.GetPointData()).SetScalars(a)
    w = vtk.vtkXMLRectilinearGridWriter()
    w.SetFileName(str(path))
    w.SetInputData(g)
    getattr(w, f"SetDataModeTo{mode}")()
    if mode == "Appended":
        w.SetCompressorTypeToNone()
        w.EncodeAppendedDataOff()
    assert w.Write() == 1


def vtk_point_set(path: Path, n: int, mode: str = "binary", seed: int = 6) -> None:
    """A VTK point set of n points (RGB colours, a float scalar, a velocity,
    a vertex each and a triangle), written by VTK's own writers: a .vtp, a
    .vtu (the same cells, and a cell array) or a .vts (the points as a grid
    of n/6 x 3 x 2 where 6 divides n, else n x 1 x 1, and a cell array) in
    `mode` ascii, binary, zlib (binary, compressed), appended (raw) or
    appended64 (base64, LZ4); a legacy .vtk POLYDATA in ascii, binary or
    binary42 (file version 4.2)."""
    import vtk
    from vtk.util import numpy_support

    def array(values: np.ndarray, name: str):
        a = numpy_support.numpy_to_vtk(np.ascontiguousarray(values), deep=True)
        a.SetName(name)
        return a

    rng = np.random.default_rng(seed)
    pts = vtk.vtkPoints()
    pts.SetData(numpy_support.numpy_to_vtk(rng.normal(0, 5, (n, 3)), deep=True))
    pd = vtk.vtkPolyData()
    pd.SetPoints(pts)
    verts, polys = vtk.vtkCellArray(), vtk.vtkCellArray()
    for i in range(n):
        verts.InsertNextCell(1, [i])
    polys.InsertNextCell(3, [0, 1, 2])
    pd.SetVerts(verts)
    pd.SetPolys(polys)
    pd.GetPointData().SetScalars(array(rng.integers(0, 256, (n, 3)).astype(np.uint8), "RGB"))
    pd.GetPointData().AddArray(array(rng.random(n).astype(np.float32), "temperature"))
    pd.GetPointData().AddArray(array(rng.normal(size=(n, 3)).astype(np.float32), "velocity"))
    grid = pd
    if path.suffix == ".vtu":
        grid = vtk.vtkUnstructuredGrid()
        grid.SetPoints(pts)
        grid.Allocate(n + 1)
        for i in range(n):
            grid.InsertNextCell(vtk.VTK_VERTEX, 1, [i])
        grid.InsertNextCell(vtk.VTK_TRIANGLE, 3, [0, 1, 2])
    elif path.suffix == ".vts":
        grid = vtk.vtkStructuredGrid()
        grid.SetDimensions(*((n // 6, 3, 2) if n % 6 == 0 else (n, 1, 1)))
        grid.SetPoints(pts)
    if grid is not pd:
        grid.GetPointData().ShallowCopy(pd.GetPointData())
        grid.GetCellData().AddArray(array(np.arange(grid.GetNumberOfCells(), dtype=np.float64), "cell"))
    if path.suffix in (".vtp", ".vtu", ".vts"):
        w = getattr(
            vtk,
            {".vtp": "vtkXMLPolyDataWriter", ".vtu": "vtkXMLUnstructuredGridWriter"}.get(
                path.suffix, "vtkXMLStructuredGridWriter"
            ),
        )()
        w.SetDataModeToAscii() if mode == "ascii" else w.SetDataModeToBinary()
        if mode.startswith("appended"):
            w.SetDataModeToAppended()
        w.SetEncodeAppendedData(mode == "appended64")
        w.SetCompressorTypeToLZ4() if mode == "appended64" else w.SetCompressorTypeToNone()
        if mode == "zlib":
            w.SetCompressorTypeToZLib()
    else:
        w = vtk.vtkPolyDataWriter()
        w.SetFileTypeToASCII() if mode == "ascii" else w.SetFileTypeToBinary()
        if mode == "binary42":
            w.SetFileVersion(42)
    w.SetFileName(str(path))
    w.SetInputData(grid)
    if w.Write() != 1:
        raise OSError(f"VTK could not write {path}")


def _pcd(path: Path, n: int, binary: bool, seed: int = 7) -> None:
    """A PCD v0.7 file as PCL writes it: x y z, rgb packed in a float, intensity."""
    rng = np.random.default_rng(seed)
    rec = np.zeros(n, [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("rgb", "<u4"), ("intensity", "<f4")])
    for c in "xyz":
        rec[c] = rng.normal(0, 5, n)
    rec["rgb"] = rng.integers(0, 1 << 24, n)
    rec["intensity"] = rng.random(n)
    head = (
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z rgb intensity\n"
        f"SIZE 4 4 4 4 4\nTYPE F F F U F\nCOUNT 1 1 1 1 1\nWIDTH {n}\nHEIGHT 1\n"
        f"VIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {'binary' if binary else 'ascii'}\n"
    )
    if binary:
        path.write_bytes(head.encode() + rec.tobytes())
    else:
        rows = "".join(
            f"{r['x']:.5f} {r['y']:.5f} {r['z']:.5f} {r['rgb']} {r['intensity']:.4f}\n" for r in rec
        )
        path.write_text(head + rows)


def companion(path: Path) -> Path | None:
    """The other file of a two-file seed (an Analyze pair's .img beside its
    .hdr, and the reverse), which a mutant of it needs beside it; or None."""
    other = {".hdr": ".img", ".img": ".hdr"}.get(path.suffix)
    return None if other is None else path.with_suffix(other)


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
    vol = rng.random((5, 4, 6)).astype(np.float32)
    for enc in ("ascii", "binary", "zlib", "appended", "appended64"):
        _vti(out / f"vol-{enc}.vti", vol, enc)
        add("vti", "volume", out / f"vol-{enc}.vti")
    if (DATA / "pyvista_uniform.vtk").is_file():  # legacy binary, cell data and a field first
        add("vtk", "volume", DATA / "pyvista_uniform.vtk")
    (out / "ascii.vtk").write_text(
        "# vtk DataFile Version 3.0\nclvis seed\nASCII\nDATASET STRUCTURED_POINTS\nDIMENSIONS 3 2 2\n"
        "SPACING 1 1 2\nORIGIN 0 0 0\nPOINT_DATA 12\nSCALARS v float 1\nLOOKUP_TABLE default\n"
        + " ".join(str(v) for v in range(12))
        + "\n"
    )
    add("vtk", "volume", out / "ascii.vtk")
    for name, head in (("rect-ascii.vtk", "ASCII"), ("rect-binary.vtk", "BINARY")):
        # a RECTILINEAR_GRID as VTK writes it (evenly spaced coordinates: a volume)
        coords = {"X": np.arange(3.0), "Y": np.arange(2.0) * 2, "Z": np.arange(2.0) * 0.5}
        body = b"".join(
            f"{k}_COORDINATES {len(c)} float\n".encode()
            + (" ".join(f"{v:g}" for v in c).encode() if head == "ASCII" else c.astype(">f4").tobytes())
            + b"\n"
            for k, c in coords.items()
        )
        samples = np.arange(12, dtype=np.float32)
        text = " ".join(f"{v:g}" for v in samples).encode()
        data = text if head == "ASCII" else samples.astype(">f4").tobytes()
        (out / name).write_bytes(
            f"# vtk DataFile Version 3.0\nclvis seed\n{head}\n".encode()
            + b"DATASET RECTILINEAR_GRID\nDIMENSIONS 3 2 2\n"
            + body
            + b"POINT_DATA 12\nSCALARS v float 1\nLOOKUP_TABLE default\n"
            + data
            + b"\n"
        )
        add("vtk", "volume", out / name)
    for name, head in (("fields-ascii.vtk", "ASCII"), ("fields-binary.vtk", "BINARY")):
        # point data as FIELD arrays (as VTK writes all but the scalars), cell data as SCALARS and FIELD
        def block(a: np.ndarray, head: str = head) -> bytes:
            return (
                " ".join(f"{v:g}" for v in a.ravel()).encode() if head == "ASCII" else a.tobytes()
            ) + b"\n"

        (out / name).write_bytes(
            f"# vtk DataFile Version 3.0\nclvis seed\n{head}\n".encode()
            + b"DATASET STRUCTURED_POINTS\nDIMENSIONS 3 2 2\nSPACING 1 1 2\nORIGIN 0 0 0\n"
            + b"POINT_DATA 12\nFIELD FieldData 2\nf 1 12 float\n"
            + block(np.arange(12, dtype=">f4"))
            + b"g 3 12 short\n"
            + block(np.arange(36, dtype=">i2"))
            + b"CELL_DATA 2\nSCALARS c double\nLOOKUP_TABLE default\n"
            + block(np.array([1.5, -2.0], ">f8"))
            + b"FIELD FieldData 1\nd 1 2 int\n"
            + block(np.array([7, 8], ">i4"))
        )
        add("vtk", "volume", out / name)
    (out / "cells-only.vtk").write_text(  # cell data only: the volume is a sample a cell
        "# vtk DataFile Version 3.0\nclvis seed\nASCII\nDATASET STRUCTURED_POINTS\nDIMENSIONS 3 3 2\n"
        "SPACING 1 1 1\nORIGIN 0 0 0\nCELL_DATA 4\nFIELD FieldData 1\nc 1 4 float\n1 2 3 4\n"
    )
    add("vtk", "volume", out / "cells-only.vtk")
    try:
        import vtk  # noqa: F401
    except ImportError:
        pass
    else:  # point sets as VTK's own writers make them: .vtp in each data mode, .vtu, .vts, legacy POLYDATA
        for mode in ("ascii", "binary", "zlib", "appended", "appended64"):
            vtk_point_set(out / f"cloud-{mode}.vtp", 24, mode)
            add("vtp", "points", out / f"cloud-{mode}.vtp")
        for suffix, modes in (("vtu", ("appended", "zlib")), ("vts", ("appended64", "ascii"))):
            for mode in modes:  # pyvista's mesh.save writes these most often
                vtk_point_set(out / f"cloud-{mode}.{suffix}", 24, mode)
                add(suffix, "points", out / f"cloud-{mode}.{suffix}")
        for mode in ("ascii", "binary", "binary42"):
            vtk_point_set(out / f"cloud-{mode}.vtk", 24, mode)
            add("vtk", "points", out / f"cloud-{mode}.vtk")
        for mode, cells in (("Appended", False), ("Binary", True), ("Ascii", False)):
            _vtr(out / f"vol-{mode.lower()}.vtr", mode, cells)  # pyvista's RectilinearGrid.save("x.vtr")
            add("vtr", "volume", out / f"vol-{mode.lower()}.vtr")
    _pcd(out / "cloud-ascii.pcd", 20, binary=False)
    add("pcd", "points", out / "cloud-ascii.pcd")
    _pcd(out / "cloud-binary.pcd", 40, binary=True)
    add("pcd", "points", out / "cloud-binary.pcd")
    try:
        import pypcd4
    except ImportError:
        pass
    else:  # LZF-compressed (binary_compressed), as pypcd4 and PCL write it; compressible values
        xyz = rng.integers(0, 8, (60, 3)).astype(np.float32)
        pc = pypcd4.PointCloud.from_xyzrgb_points(np.c_[xyz, np.tile(np.float32(1e-39), (60, 1))])
        pc.save(out / "cloud-lzf.pcd", encoding=pypcd4.Encoding.BINARY_COMPRESSED)
        add("pcd", "points", out / "cloud-lzf.pcd")
    pts = rng.normal(0, 10, (25, 3)) + [635000.0, 848000.0, 400.0]
    cols = rng.integers(0, 256, (25, 3))
    np.savetxt(out / "scan.xyz", np.c_[pts, cols], fmt=["%.3f"] * 3 + ["%d"] * 3)
    add("xyz", "points", out / "scan.xyz")
    with open(out / "scan.pts", "w") as f:  # Leica PTS: the count, then x y z intensity r g b
        f.write(f"{len(pts)}\n")
        np.savetxt(f, np.c_[pts, rng.integers(-2048, 2048, 25), cols], fmt=["%.3f"] * 3 + ["%d"] * 4)
    add("pts", "points", out / "scan.pts")
    np.savetxt(out / "scan.txt", pts, fmt="%.3f")
    add("txt", "points", out / "scan.txt")
    np.savetxt(
        out / "scan.csv",
        np.c_[pts, rng.random(25)],
        fmt="%.4f",
        delimiter=",",
        header="X,Y,Z,Intensity",
        comments="",
    )
    add("csv", "points", out / "scan.csv")
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
        # Analyze and NIfTI-1 pairs: the header and the data file each mutated,
        # the other copied beside the case (companion)
        nibabel.save(nibabel.AnalyzeImage(data, np.diag([0.5, 1.0, 2.0, 1.0])), out / "ana.hdr")
        nibabel.save(nibabel.Nifti1Pair(data, np.eye(4)), out / "pair.hdr")
        for name in ("ana", "pair"):
            add("hdr", "volume", out / f"{name}.hdr")
            add("img", "volume", out / f"{name}.img")
        nibabel.save(nibabel.MGHImage(data, np.eye(4)), out / "vol.mgh")
        add("mgh", "volume", out / "vol.mgh")
        nibabel.save(nibabel.MGHImage(data, np.eye(4)), out / "vol.mgz")
        add("mgz", "volume", out / "vol.mgz")
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
        # written by OpenVDB: 124 active tiles, blosc-compressed (tests/data/make_openvdb_small.py)
        add("vdb", "vdb", DATA / "openvdb_tiles.vdb")
        # a file tinyvdb fails on (a frustum map): its linear grid read from clvis's walk alone
        add("vdb", "vdb", DATA / "openvdb_frustum.vdb")
    try:
        import pye57
    except ImportError:
        pass
    else:
        _e57(pye57, out / "scan.e57", 200)
        add("e57", "points", out / "scan.e57")
        _e57(pye57, out / "two.e57", 40, scans=2, invalid=True)
        add("e57", "points", out / "two.e57")
    return seeds


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
