//! The frame codec: a triangle mesh to bytes and back.
//!
//! * Vertices are renumbered in order of first use by the triangle list (unreferenced
//!   vertices are dropped); triangles keep their order and corner order.
//! * Connectivity: for every triangle corner, `0` when it introduces the next new vertex,
//!   else `next − index` (≥ 1) as an unsigned LEB128 varint.
//! * Positions: quantized to the lattice `q = round(x / step)` with `step = 2·bound`, so
//!   each coordinate is within `bound` of the original; each vertex is predicted from the
//!   vertices before it — the parallelogram `a + b − c` across an edge of the triangle that
//!   introduces it (Touma & Gotsman 1998), else a corner of that triangle, else the
//!   previous vertex — and the zigzag-coded residual written as a varint.
//! * The two streams are concatenated (connectivity first) and compressed with zstd.
//!
//! Normals are not stored: decoders recompute area-weighted normals.

use crate::mesh::TriMesh;
use glam::Vec3;

fn put_varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

fn get_varint(bytes: &[u8], pos: &mut usize) -> Option<u64> {
    let mut v = 0u64;
    for shift in (0..64).step_by(7) {
        let b = *bytes.get(*pos)?;
        *pos += 1;
        v |= ((b & 0x7f) as u64) << shift;
        if b < 0x80 {
            return Some(v);
        }
    }
    None
}

fn zigzag(v: i64) -> u64 {
    ((v << 1) ^ (v >> 63)) as u64
}

fn unzigzag(v: u64) -> i64 {
    ((v >> 1) as i64) ^ -((v & 1) as i64)
}

/// The mesh reordered for coding: vertices in first-use order.
pub(crate) fn reorder(mesh: &TriMesh) -> TriMesh {
    let mut remap = vec![u32::MAX; mesh.positions.len()];
    let mut positions = Vec::with_capacity(mesh.positions.len());
    let triangles = mesh
        .triangles
        .iter()
        .map(|t| {
            t.map(|v| {
                if remap[v as usize] == u32::MAX {
                    remap[v as usize] = positions.len() as u32;
                    positions.push(mesh.positions[v as usize]);
                }
                remap[v as usize]
            })
        })
        .collect();
    TriMesh {
        positions,
        triangles,
        normals: Vec::new(),
    }
}

/// How a vertex is predicted from vertices introduced before it.
#[derive(Clone, Copy)]
enum Prediction {
    /// The first vertex: the origin.
    Origin,
    /// The previous vertex in order.
    Previous(u32),
    /// Another corner of the introducing triangle.
    Corner(u32),
    /// The parallelogram `a + b − c` across edge `ab` from the triangle `abc`.
    Parallelogram(u32, u32, u32),
}

impl Prediction {
    fn resolve(self, q: impl Fn(u32) -> [i64; 3]) -> [i64; 3] {
        match self {
            Prediction::Origin => [0; 3],
            Prediction::Previous(v) | Prediction::Corner(v) => q(v),
            Prediction::Parallelogram(a, b, c) => {
                let (a, b, c) = (q(a), q(b), q(c));
                [0, 1, 2].map(|k| a[k] + b[k] - c[k])
            }
        }
    }
}

/// For every vertex (in first-use order), how it is predicted: by the parallelogram rule
/// across an edge of its introducing triangle whose other triangle is already known,
/// else by a known corner of that triangle, else by the previous vertex.
fn prediction_plan(triangles: &[[u32; 3]], vertices: usize) -> Vec<Prediction> {
    let mut plan = Vec::with_capacity(vertices);
    // The last two triangles seen at every vertex: the neighbour across an edge (a, b) is
    // looked for among those of a and b (a bounded search that encoder and decoder
    // repeat identically; a miss falls back to the corner prediction).
    let mut recent: Vec<[u32; 2]> = vec![[u32::MAX; 2]; vertices];
    let opposite = |a: u32, b: u32, recent: &[[u32; 2]]| -> Option<u32> {
        recent[a as usize]
            .iter()
            .chain(&recent[b as usize])
            .filter(|&&t| t != u32::MAX)
            .find_map(|&t| {
                let tri = triangles[t as usize];
                (0..3)
                    .find(|&k| tri[k] == b && tri[(k + 1) % 3] == a)
                    .map(|k| tri[(k + 2) % 3])
            })
    };
    for (ti, t) in triangles.iter().enumerate() {
        for k in 0..3 {
            let v = t[k];
            if v as usize != plan.len() {
                continue;
            }
            let (a, b) = (t[(k + 1) % 3], t[(k + 2) % 3]);
            let known = |w: u32| (w as usize) < plan.len();
            let p = if known(a) && known(b) {
                // The neighbour across (a, b) holds the directed edge (b, a).
                match opposite(a, b, &recent) {
                    Some(c) => Prediction::Parallelogram(a, b, c),
                    None => Prediction::Corner(a),
                }
            } else if known(a) {
                Prediction::Corner(a)
            } else if known(b) {
                Prediction::Corner(b)
            } else if plan.is_empty() {
                Prediction::Origin
            } else {
                Prediction::Previous(plan.len() as u32 - 1)
            };
            plan.push(p);
        }
        for &v in t {
            let r = &mut recent[v as usize];
            *r = [ti as u32, r[0]];
        }
    }
    plan
}

fn predict(triangles: &[[u32; 3]], vertices: usize, q: impl Fn(u32) -> [i64; 3]) -> Vec<[i64; 3]> {
    prediction_plan(triangles, vertices)
        .into_iter()
        .map(|p| p.resolve(&q))
        .collect()
}

/// Encodes `mesh` (already in first-use order, see [`reorder`]) with quantization step
/// `step` (world units) and zstd `level`.
pub(crate) fn encode(mesh: &TriMesh, step: f64, level: i32) -> std::io::Result<Vec<u8>> {
    let mut raw = Vec::with_capacity(mesh.triangles.len() * 4 + mesh.positions.len() * 4);
    let mut next = 0u32;
    for t in &mesh.triangles {
        for &v in t {
            if v == next {
                put_varint(&mut raw, 0);
                next += 1;
            } else {
                put_varint(&mut raw, (next - v) as u64);
            }
        }
    }
    let quantized: Vec<[i64; 3]> = mesh
        .positions
        .iter()
        .map(|p| p.to_array().map(|c| (c as f64 / step).round() as i64))
        .collect();
    let predictions = predict(&mesh.triangles, mesh.positions.len(), |v| {
        quantized[v as usize]
    });
    for (q, pred) in quantized.iter().zip(&predictions) {
        for k in 0..3 {
            put_varint(&mut raw, zigzag(q[k] - pred[k]));
        }
    }
    zstd::bulk::compress(&raw, level)
}

/// Decodes a payload of `vertices` vertices and `triangles` triangles.
pub(crate) fn decode(
    payload: &[u8],
    vertices: usize,
    triangles: usize,
    step: f64,
) -> Result<TriMesh, String> {
    let capacity = triangles * 3 * 5 + vertices * 30 + 64;
    let raw = zstd::bulk::decompress(payload, capacity).map_err(|e| format!("zstd: {e}"))?;
    let mut pos = 0;
    let mut next = 0u32;
    let mut tris = Vec::with_capacity(triangles);
    for _ in 0..triangles {
        let mut t = [0u32; 3];
        for slot in &mut t {
            let d = get_varint(&raw, &mut pos).ok_or("connectivity stream ends early")?;
            *slot = if d == 0 {
                next += 1;
                next - 1
            } else {
                next.checked_sub(d as u32)
                    .ok_or("connectivity refers before the first vertex")?
            };
        }
        tris.push(t);
    }
    if next as usize != vertices {
        return Err(format!(
            "connectivity introduces {next} vertices, header says {vertices}"
        ));
    }
    // Residuals first, then predictions resolved in vertex order (each prediction reads
    // only vertices introduced before).
    let mut residuals = Vec::with_capacity(vertices);
    for _ in 0..vertices {
        let mut r = [0i64; 3];
        for slot in &mut r {
            *slot = unzigzag(get_varint(&raw, &mut pos).ok_or("position stream ends early")?);
        }
        residuals.push(r);
    }
    let mut quantized: Vec<[i64; 3]> = Vec::with_capacity(vertices);
    let plan = prediction_plan(&tris, vertices);
    for (v, r) in residuals.iter().enumerate() {
        let pred = plan[v].resolve(|w| quantized[w as usize]);
        quantized.push([0, 1, 2].map(|k| pred[k] + r[k]));
    }
    let positions: Vec<Vec3> = quantized
        .iter()
        .map(|q| Vec3::from_array(q.map(|c| (c as f64 * step) as f32)))
        .collect();
    if pos != raw.len() {
        return Err("trailing bytes after the position stream".into());
    }
    let mut mesh = TriMesh {
        positions,
        triangles: tris,
        normals: Vec::new(),
    };
    mesh.compute_normals();
    Ok(mesh)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn varints_and_zigzag_round_trip() {
        let mut out = Vec::new();
        let values = [0u64, 1, 127, 128, 300, u32::MAX as u64, u64::MAX];
        for v in values {
            put_varint(&mut out, v);
        }
        let mut pos = 0;
        for v in values {
            assert_eq!(get_varint(&out, &mut pos), Some(v));
        }
        for v in [0i64, -1, 1, -1000, 1 << 40, i64::MIN / 2] {
            assert_eq!(unzigzag(zigzag(v)), v);
        }
    }
}
