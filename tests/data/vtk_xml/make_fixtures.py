"""Writes the VTK XML test fixtures with VTK's own writers (pip install vtk; VTK 9.x).

Usage, from the repository root:
    python tests/data/vtk_xml/make_fixtures.py [OUT_DIR] [LEGACY.vtk [COUNT]]

Every fixture holds the first COUNT (default 40) particles of the legacy file (default
datasets/double_dambreak/ParticleData_Fluid_9.vtk) with its velocity, plus an Int32 `id`
(the index) and a Float64 `density` (1000 + index / 8). The names say what each one is:
<dataset>_<data mode>_<compressor>_<header type>_<point type>[_be].<vtu|vtp> (_be:
big-endian); the block size is
64 bytes, so that compressed arrays span several blocks. `frame9_appended_zlib.vtu` is the whole
frame (its velocity, no cells), as the CLI test compares it with the legacy file.
"""
import os
import sys

import vtk
from vtk.util import numpy_support as ns

out = sys.argv[1] if len(sys.argv) > 1 else os.path.dirname(os.path.abspath(__file__))
legacy = sys.argv[2] if len(sys.argv) > 2 else "datasets/double_dambreak/ParticleData_Fluid_9.vtk"
count = int(sys.argv[3]) if len(sys.argv) > 3 else 40

reader = vtk.vtkPolyDataReader()
reader.SetFileName(legacy)
reader.Update()
frame = reader.GetOutput()


def dataset(n, polydata, double, extra, cells=True):
    """The first n particles as PolyData (one vertex each) or an UnstructuredGrid (one
    VTK_VERTEX cell each, or none)."""
    pts = ns.vtk_to_numpy(frame.GetPoints().GetData())[:n].copy()
    points = vtk.vtkPoints()
    points.SetData(ns.numpy_to_vtk(pts.astype("f8" if double else "f4"), deep=1))
    velocity = ns.numpy_to_vtk(ns.vtk_to_numpy(frame.GetPointData().GetArray("velocity"))[:n].copy(), deep=1)
    velocity.SetName("velocity")
    arrays = [velocity]
    if extra:
        import numpy as np
        ids = ns.numpy_to_vtk(np.arange(n, dtype="i4"), deep=1)
        ids.SetName("id")
        density = ns.numpy_to_vtk(1000.0 + np.arange(n, dtype="f8") / 8, deep=1)
        density.SetName("density")
        arrays += [ids, density]
    if polydata:
        d = vtk.vtkPolyData()
        cells = vtk.vtkCellArray()
        for i in range(n):
            cells.InsertNextCell(1)
            cells.InsertCellPoint(i)
        d.SetPoints(points)
        d.SetVerts(cells)
    else:
        d = vtk.vtkUnstructuredGrid()
        d.SetPoints(points)
        for i in range(n if cells else 0):
            d.InsertNextCell(vtk.VTK_VERTEX, 1, [i])
    for a in arrays:
        d.GetPointData().AddArray(a)
    return d


def write(name, d, polydata, mode, compressor, header64, block=64, big=False):
    w = vtk.vtkXMLPolyDataWriter() if polydata else vtk.vtkXMLUnstructuredGridWriter()
    w.SetInputData(d)
    w.SetFileName(os.path.join(out, name))
    {"ascii": w.SetDataModeToAscii, "binary": w.SetDataModeToBinary}.get(mode, w.SetDataModeToAppended)()
    w.SetEncodeAppendedData(1 if mode == "appended64" else 0)
    {"none": w.SetCompressorTypeToNone, "zlib": w.SetCompressorTypeToZLib,
     "lz4": w.SetCompressorTypeToLZ4}[compressor]()
    w.SetHeaderTypeToUInt64() if header64 else w.SetHeaderTypeToUInt32()
    w.SetByteOrderToBigEndian() if big else w.SetByteOrderToLittleEndian()
    if block:
        w.SetBlockSize(block)
    assert w.Write() == 1, name


# (data mode, compressor, UInt64 headers, Float64 points, PolyData[, big-endian])
variants = [
    ("ascii", "none", False, False, True),
    ("ascii", "none", True, True, False),
    ("binary", "none", False, True, False),
    ("binary", "zlib", True, False, True),
    ("binary", "lz4", False, False, False),
    ("appended", "none", True, False, False),
    ("appended", "zlib", False, True, True),
    ("appended", "lz4", True, True, False),
    ("appended64", "none", False, False, True),
    ("appended64", "zlib", True, False, False),
    ("appended64", "lz4", False, True, True),
    ("binary", "zlib", False, True, False, True),
    ("appended", "none", True, False, True, True),
]
for mode, compressor, header64, double, polydata, *big in variants:
    big = bool(big and big[0])
    name = "dd9_%s_%s_%s_%s%s.%s" % (mode, compressor, "u64" if header64 else "u32",
                                     "f64" if double else "f32", "_be" if big else "",
                                     "vtp" if polydata else "vtu")
    write(name, dataset(count, polydata, double, True), polydata, mode, compressor, header64,
          big=big)
if len(sys.argv) <= 1 or "--frame" in sys.argv:
    n = frame.GetNumberOfPoints()
    # No cells: the points and the velocity are what is compared, and the file stays small.
    write("frame9_appended_zlib.vtu", dataset(n, False, False, False, cells=False), False,
          "appended", "zlib", True, block=0)
