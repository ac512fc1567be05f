#!/usr/bin/env bash
# Writes the seed corpora of the fuzz targets to fuzz/seeds/<target>/: tiny particle files
# in every format and variant the readers take (python3), and the meshes and archives the
# release binary reconstructs from one of them. Small on purpose (a few KB each): libFuzzer
# mutates small inputs much faster. Usage (from the repository root):
#   cargo build --release && fuzz/seed.sh [path/to/meniscus]
set -euo pipefail
cd "$(dirname "$0")"
BIN=${1:-${CARGO_TARGET_DIR:-../target}/release/meniscus}
OUT=seeds
rm -rf "$OUT"
mkdir -p "$OUT"/{particles_xyz,particles_ply,particles_bgeo,particles_vtk,particles_vtk_xml,mesh_ply,mesh_obj,mesh_gltf,mesh_vtk,archive,archive_payload,sequence_pvd}

python3 - "$OUT" <<'EOF'
import gzip, struct, sys
out = sys.argv[1]
# Two 3x3x3 blocks of particles (spacing 2r, r = 0.05) and one isolated particle, with a
# velocity and a density per particle.
pts = []
for ox in (0.0, 1.0):
    for i in range(3):
        for j in range(3):
            for k in range(3):
                pts.append((ox + 0.1 * i, 0.1 * j, 0.1 * k))
pts.append((0.5, 2.0, 0.5))
vel = [(0.1 * (n % 3), -0.2, 0.05 * n) for n in range(len(pts))]
dens = [1000.0 + n for n in range(len(pts))]
n = len(pts)
def w(name, data):
    with open(f"{out}/{name}", "wb") as f:
        f.write(data)
# .xyz: little-endian f32 triples.
w("particles_xyz/blocks.xyz", b"".join(struct.pack("<3f", *p) for p in pts))
w("particles_xyz/one.xyz", struct.pack("<3f", 1.0, 2.0, 3.0))
# PLY: ASCII and binary LE / BE, float and double, with attributes, and a face element.
head = lambda fmt, t: (f"ply\nformat {fmt} 1.0\ncomment seed\nelement vertex {n}\n"
    + "".join(f"property {t} {c}\n" for c in ("x", "y", "z"))
    + "property float vx\nproperty float vy\nproperty float vz\nproperty float density\nend_header\n").encode()
w("particles_ply/ascii.ply", head("ascii", "float") + "".join(
    f"{p[0]} {p[1]} {p[2]} {v[0]} {v[1]} {v[2]} {d}\n" for p, v, d in zip(pts, vel, dens)).encode())
for fmt, e, t, c in (("binary_little_endian", "<", "float", "f"), ("binary_big_endian", ">", "double", "d")):
    w(f"particles_ply/{fmt}.ply", head(fmt, t) + b"".join(
        struct.pack(e + "3" + c, *p) + struct.pack(e + "4f", *v, d) for p, v, d in zip(pts, vel, dens)))
w("particles_ply/faces.ply", b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0 1\n1 0 0 2\n0 1 0 3\n3 0 1 2\n")
# Legacy VTK: ASCII and BINARY (big-endian) POLYDATA with point data, an unstructured grid.
vhead = "# vtk DataFile Version 3.0\nseed\n{}\nDATASET POLYDATA\nPOINTS %d {}\n" % n
w("particles_vtk/ascii.vtk", (vhead.format("ASCII", "float") + "".join(f"{p[0]} {p[1]} {p[2]}\n" for p in pts)
    + f"VERTICES {n} {2 * n}\n" + "".join(f"1 {i}\n" for i in range(n))
    + f"POINT_DATA {n}\nSCALARS density float 1\nLOOKUP_TABLE default\n" + "".join(f"{d}\n" for d in dens)
    + "VECTORS velocity float\n" + "".join(f"{v[0]} {v[1]} {v[2]}\n" for v in vel)
    + f"FIELD extra 1\nid 1 {n} int\n" + " ".join(str(i) for i in range(n)) + "\n").encode())
w("particles_vtk/binary.vtk", vhead.format("BINARY", "double").encode()
    + b"".join(struct.pack(">3d", *p) for p in pts)
    + f"\nPOINT_DATA {n}\nVECTORS velocity float\n".encode() + b"".join(struct.pack(">3f", *v) for v in vel) + b"\n")
w("particles_vtk/grid.vtk", b"# vtk DataFile Version 2.0\ngrid\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS 2 float\n0 0 0 1 1 1\nCELLS 2 4\n1 0\n1 1\nCELL_TYPES 2\n1\n1\n")
# Classic BGEO version 5: P plus a vector, a float and an int attribute; plain and gzip.
b = b"BgeoV" + struct.pack(">9i", 5, n, 0, 0, 0, 3, 0, 0, 0)
for name, size, typ, default in ((b"v", 3, 5, b"\0" * 12), (b"density", 1, 0, b"\0" * 4), (b"id", 1, 1, b"\0" * 4)):
    b += struct.pack(">H", len(name)) + name + struct.pack(">Hi", size, typ) + default
for i, (p, v, d) in enumerate(zip(pts, vel, dens)):
    b += struct.pack(">4f", *p, 1.0) + struct.pack(">3f", *v) + struct.pack(">f", d) + struct.pack(">i", i)
w("particles_bgeo/plain.bgeo", b)
w("particles_bgeo/gzip.bgeo", gzip.compress(b, 6, mtime=0))
EOF

# VTK XML: the fixtures VTK's own writers made (tests/data/vtk_xml/make_fixtures.py), every
# data mode, compressor and header type, and two pieces with ascii data.
cp ../tests/data/vtk_xml/dd9_*.vt[up] "$OUT/particles_vtk_xml/"
printf '<?xml version="1.0"?>\n<VTKFile type="PolyData" version="0.1">\n<PolyData><Piece NumberOfPoints="2"><PointData><DataArray type="Float32" Name="m" format="ascii">0 1</DataArray></PointData><Points><DataArray type="Float64" NumberOfComponents="3" format="ascii">0 0 0 1 0 0</DataArray></Points></Piece><Piece NumberOfPoints="1"><PointData><DataArray type="Float32" Name="m" format="ascii">2</DataArray></PointData><Points><DataArray type="Float64" NumberOfComponents="3" format="ascii">2 0 0</DataArray></Points></Piece></PolyData></VTKFile>\n' >"$OUT/particles_vtk_xml/pieces.vtp"

# .pvd collections naming frame_0.vtu … frame_3.vtu (the files the sequence_pvd target
# puts beside its input): VTK's fixture (out of time order), entries without timesteps,
# one file listed twice, parts and groups, a comment and end tags written out.
cp ../tests/data/pvd/run.pvd "$OUT/sequence_pvd/"
pvd() { printf '<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n  <Collection>\n%b  </Collection>\n</VTKFile>\n' "$2" >"$OUT/sequence_pvd/$1"; }
pvd untimed.pvd '    <DataSet file="frame_2.vtu"/>\n    <DataSet file="frame_0.vtu"/>\n'
pvd twice.pvd '    <DataSet timestep="1e-3" part="1" file="frame_1.vtu"/>\n    <DataSet timestep="0.001" part="1" file="frame_1.vtu"/>\n    <DataSet timestep="-2" part="1" file="frame_3.vtu"/>\n'
pvd parts.pvd '    <!-- two parts of one time -->\n    <DataSet timestep="0" group="g" part="0" file="frame_0.vtu"></DataSet>\n    <DataSet timestep="0" group="g" part="1" file="frame_1.vtu"></DataSet>\n'

# Meshes and archives from the release binary: the fluid blocks plus an isolated-particle
# sphere, with the velocity as attribute where the format holds one.
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
in=$OUT/particles_ply/binary_little_endian.ply
r=(--particle-radius 0.05 --threads 1)
for m in m.ply m.vtk m.obj m.glb m.gltf; do
  "$BIN" reconstruct "$in" "${r[@]}" --attributes all --subdivide 0 -o "$work/$m" >/dev/null 2>&1
done
"$BIN" reconstruct "$in" "${r[@]}" --attributes all -o "$work/a.mseq" >/dev/null 2>&1
"$BIN" reconstruct "$in" "${r[@]}" --attributes none --subdivide 0 -o "$work/plain.mseq" >/dev/null 2>&1
cp "$work/m.ply" "$OUT/mesh_ply/"
cp "$work/m.vtk" "$OUT/mesh_vtk/"
cp "$work/m.obj" "$OUT/mesh_obj/"
cp "$work/m.glb" "$work/m.gltf" "$OUT/mesh_gltf/"
cp "$work/a.mseq" "$work/plain.mseq" "$OUT/archive/"
# archive_payload: each frame of those archives with its zstd sections decompressed, in
# the layout fuzz_targets/archive_payload.rs documents (needs the zstd command).
python3 - "$OUT" <<'EOF'
import struct, subprocess, sys
out = sys.argv[1]
unzstd = lambda b: subprocess.run(["zstd", "-d", "-c", "-q"], input=b, stdout=subprocess.PIPE, check=True).stdout
for name in ("a", "plain"):
    b = open(f"{out}/archive/{name}.mseq", "rb").read()
    pos = 16
    while b[pos:pos + 4] == b"FRAM":
        number, nv, nt, step, plen, crc, flags = struct.unpack_from("<qIIdQII", b, pos + 4)
        payload = b[pos + 48:pos + 48 + plen]
        head = struct.pack("<BII", 2 if flags else 1, nv, nt)
        if flags:
            (dlen,) = struct.unpack_from("<I", payload, 0)
            desc = payload[4:4 + dlen]
            (glen,) = struct.unpack_from("<Q", payload, 8 + dlen)
            geometry = unzstd(payload[16 + dlen:16 + dlen + glen])
            streams = unzstd(payload[16 + dlen + glen:])
            body = struct.pack("<H", dlen) + desc + struct.pack("<H", len(geometry)) + geometry + streams
        else:
            body = unzstd(payload)
        open(f"{out}/archive_payload/{name}-{number}.bin", "wb").write(head + body)
        pos += 48 + plen
EOF

# Hand-made small meshes in the variants the binary does not write.
printf 'ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz\nproperty double density\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0 0 0 1 1\n1 0 0 0 0 1 2\n1 1 0 0 0 1 3\n0 1 0 0 0 1 4\n4 0 1 2 3\n' >"$OUT/mesh_ply/quad.ply"
printf 'v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\nf 1 2 3\nf 1/1 3/1 4/1\nf -4//1 -3//1 -2//1\nf 1/1/1 2/1/1 3/1/1 4/1/1\n' >"$OUT/mesh_obj/forms.obj"
printf '# vtk DataFile Version 3.0\nquad\nASCII\nDATASET POLYDATA\nPOINTS 4 float\n0 0 0 1 0 0 1 1 0 0 1 0\nPOLYGONS 1 5\n4 0 1 2 3\nPOINT_DATA 4\nSCALARS density float 1\nLOOKUP_TABLE default\n1 2 3 4\n' >"$OUT/mesh_vtk/quad.vtk"
ls -l "$OUT"/*/
