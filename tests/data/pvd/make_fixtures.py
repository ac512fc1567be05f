"""Writes the .pvd test fixtures with VTK's own writer (pip install vtk; VTK 9.x).

Usage, from the repository root:
    python tests/data/pvd/make_fixtures.py [OUT_DIR]

Three frames `frame_0.vtu`, `frame_1.vtu`, `frame_2.vtu` (vtkXMLUnstructuredGridWriter,
its defaults: appended raw, zlib) hold the first 40, 60 and 80 particles of
datasets/double_dambreak/ParticleData_Fluid_9.vtk with their velocity, and `run.pvd`
lists them as ParaView does (`<DataSet timestep=".." group="" part="0" file=".."/>`),
but not in time order (frame 2's entry first), so that a reader must sort by timestep.
"""
import os
import sys

import vtk
from vtk.util import numpy_support as ns

out = sys.argv[1] if len(sys.argv) > 1 else os.path.dirname(os.path.abspath(__file__))
reader = vtk.vtkPolyDataReader()
reader.SetFileName("datasets/double_dambreak/ParticleData_Fluid_9.vtk")
reader.Update()
frame = reader.GetOutput()
positions = ns.vtk_to_numpy(frame.GetPoints().GetData())
velocities = ns.vtk_to_numpy(frame.GetPointData().GetArray("velocity"))

times = {0: 0.0, 1: 0.05, 2: 0.1}
for k, n in enumerate([40, 60, 80]):
    grid = vtk.vtkUnstructuredGrid()
    points = vtk.vtkPoints()
    points.SetData(ns.numpy_to_vtk(positions[:n].copy(), deep=1))
    grid.SetPoints(points)
    velocity = ns.numpy_to_vtk(velocities[:n].copy(), deep=1)
    velocity.SetName("velocity")
    grid.GetPointData().AddArray(velocity)
    w = vtk.vtkXMLUnstructuredGridWriter()
    w.SetInputData(grid)
    w.SetFileName(os.path.join(out, f"frame_{k}.vtu"))
    assert w.Write() == 1

entries = "".join(
    f'    <DataSet timestep="{times[k]}" group="" part="0" file="frame_{k}.vtu"/>\n'
    for k in [2, 0, 1]
)
with open(os.path.join(out, "run.pvd"), "w") as f:
    f.write(
        '<?xml version="1.0"?>\n'
        '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">\n'
        "  <Collection>\n" + entries + "  </Collection>\n</VTKFile>\n"
    )
