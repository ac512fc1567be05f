//! The frame codec: a triangle mesh to bytes and back.
//!
//! **Connectivity** is coded along a depth-first traversal over shared edges. Every coded
//! triangle pushes its edges as *gates* on a stack; popping a gate `(x, y)` writes one
//! flag — whether an uncoded triangle lies across it (holding the directed edge `(y, x)`)
//! — and, if so, that triangle's third vertex: `0` for the next new vertex, else
//! `next − index` as a varint. When the stack runs empty, the first uncoded triangle in
//! input order starts a new traversal with its three vertices. Any triangle list round
//! trips (non-manifold or inconsistently oriented parts simply start new traversals);
//! triangles come back in traversal order with their corners rotated, vertices numbered in
//! order of first use (unreferenced vertices are dropped).
//!
//! **Positions** are quantized to the lattice `q = round(x / step)`, `step = 2·bound`, so
//! every coordinate is within `bound` of the original. A vertex introduced across a gate
//! is predicted by the parallelogram `x + y − z` of the gate's triangle `(x, y, z)`
//! (Touma & Gotsman 1998); a vertex of a traversal's first triangle by a known corner of
//! it, else by the previous vertex. Residuals are zigzag varints.
//!
//! Three streams (flags, vertex codes, residuals), each prefixed by its byte length as a
//! varint, compressed together with zstd. Normals are not stored: decoders recompute
//! area-weighted normals.

use crate::mesh::TriMesh;
use glam::Vec3;

pub(crate) fn put_varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

#[inline]
pub(crate) fn get_varint(bytes: &[u8], pos: &mut usize) -> Option<u64> {
    // One byte is the common case (flags, vertex codes, most residuals).
    let first = *bytes.get(*pos)?;
    if first < 0x80 {
        *pos += 1;
        return Some(first as u64);
    }
    get_varint_long(bytes, pos)
}

fn get_varint_long(bytes: &[u8], pos: &mut usize) -> Option<u64> {
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

pub(crate) fn zigzag(v: i64) -> u64 {
    ((v << 1) ^ (v >> 63)) as u64
}

pub(crate) fn unzigzag(v: u64) -> i64 {
    ((v >> 1) as i64) ^ -((v & 1) as i64)
}

/// How a vertex is predicted from vertices introduced before it.
#[derive(Clone, Copy)]
pub(crate) enum Prediction {
    Origin,
    Vertex(u32),
    Parallelogram(u32, u32, u32),
}

impl Prediction {
    /// The predicted lattice coordinates. Predictions and residuals are computed modulo
    /// 2^64 (wrapping) on both sides: exact for every coordinate, and a damaged stream
    /// decodes to some coordinates instead of overflowing.
    pub(crate) fn resolve(self, q: &[[i64; 3]]) -> [i64; 3] {
        match self {
            Prediction::Origin => [0; 3],
            Prediction::Vertex(v) => q[v as usize],
            Prediction::Parallelogram(a, b, c) => {
                let (a, b, c) = (q[a as usize], q[b as usize], q[c as usize]);
                [0, 1, 2].map(|k| a[k].wrapping_add(b[k]).wrapping_sub(c[k]))
            }
        }
    }
}

/// The shared bookkeeping of encoder and decoder: new vertex numbers and predictions.
pub(crate) struct Numbering {
    pub(crate) next: u32,
    pub(crate) plan: Vec<Prediction>,
}

impl Numbering {
    /// The prediction of a traversal's first-triangle corner: a known corner, else the
    /// previous vertex.
    pub(crate) fn root_prediction(&self, known_corner: Option<u32>) -> Prediction {
        match known_corner {
            Some(v) => Prediction::Vertex(v),
            None if self.next == 0 => Prediction::Origin,
            None => Prediction::Vertex(self.next - 1),
        }
    }
}

/// A gate: directed edge `(x, y)` of a coded triangle whose third vertex is `z` (new ids).
pub(crate) type Gate = [u32; 3];

pub(crate) fn push_gates(stack: &mut Vec<Gate>, t: [u32; 3], skip_first: bool) {
    // Pushed in reverse so that the triangle's first edge is explored first.
    for k in (0..3).rev() {
        if skip_first && k == 0 {
            continue;
        }
        stack.push([t[k], t[(k + 1) % 3], t[(k + 2) % 3]]);
    }
}

/// The position stream: the vertices of `mesh` in decoded order (`old_of_new`),
/// quantized with `step`, each as the zigzag varints of its residual to its prediction
/// in `plan`.
fn position_residuals(
    mesh: &TriMesh,
    step: f64,
    old_of_new: &[u32],
    plan: &[Prediction],
) -> Vec<u8> {
    let quantized: Vec<[i64; 3]> = old_of_new
        .iter()
        .map(|&v| {
            mesh.positions[v as usize]
                .to_array()
                .map(|c| (c as f64 / step).round() as i64)
        })
        .collect();
    let mut residuals = Vec::with_capacity(quantized.len() * 4);
    for (v, q) in quantized.iter().enumerate() {
        let pred = plan[v].resolve(&quantized);
        for k in 0..3 {
            put_varint(&mut residuals, zigzag(q[k].wrapping_sub(pred[k])));
        }
    }
    residuals
}

/// Version-1 payload: the three streams of `mesh` (quantization step `step`, world
/// units) compressed with zstd `level`. Returns the payload and the vertex and triangle
/// counts it holds.
pub(crate) fn encode_v1(
    mesh: &TriMesh,
    step: f64,
    level: i32,
) -> std::io::Result<(Vec<u8>, u32, u32)> {
    let mut raw = Vec::new();
    let coded = encode_streams(mesh, step, &mut raw);
    Ok((
        zstd::bulk::compress(&raw, level)?,
        coded.vertices,
        coded.triangles,
    ))
}

/// What [`encode_streams`] wrote, and what Loop subdivision of it will make.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct CodedMesh {
    /// Vertices coded (the referenced ones).
    pub vertices: u32,
    /// Triangles coded.
    pub triangles: u32,
    /// Distinct undirected edges.
    pub edges: u64,
    /// True when no triangle repeats a corner and no two triangles have the same three
    /// vertices: then one Loop step makes exactly `vertices + edges` vertices and
    /// `2 edges + 3 triangles` edges, and the result has the same property.
    pub loop_countable: bool,
    /// True when every edge has exactly two sides running in opposite directions (a
    /// closed, consistently oriented 2-manifold) and the mesh is `loop_countable`.
    pub closed_oriented: bool,
}

/// Appends the flag, vertex-code and residual streams of `mesh` (positions quantized
/// with step `step`, world units), each prefixed with its byte length, to `out`.
pub(crate) fn encode_streams(mesh: &TriMesh, step: f64, out: &mut Vec<u8>) -> CodedMesh {
    let half_edges = HalfEdges::of(mesh);
    half_edges.encode(mesh, step, out);
    half_edges.report(mesh)
}

/// Half-edge `h = 3t + k` of `tris`: from corner `k` to corner `k + 1` of triangle `t`.
fn half_edge(tris: &[[u32; 3]], h: usize) -> (u32, u32) {
    let t = tris[h / 3];
    (t[h % 3], t[(h % 3 + 1) % 3])
}

/// The half-edges of a mesh bucketed by the smaller vertex of their edge (a counting
/// sort, ascending `h` within a bucket), so the half-edges of one edge are found among a
/// handful of entries: bucket `v` is `bucket[start[v]..start[v + 1]]`. Built once per
/// mesh for both its shape report and its coding.
pub(crate) struct HalfEdges {
    start: Vec<u32>,
    bucket: Vec<u32>,
}

impl HalfEdges {
    pub(crate) fn of(mesh: &TriMesh) -> HalfEdges {
        let tris = &mesh.triangles;
        let n = tris.len();
        let mut start = vec![0u32; mesh.positions.len() + 1];
        for h in 0..3 * n {
            let (a, b) = half_edge(tris, h);
            start[a.min(b) as usize + 1] += 1;
        }
        for v in 0..mesh.positions.len() {
            start[v + 1] += start[v];
        }
        let mut fill = start.clone();
        let mut bucket = vec![0u32; 3 * n];
        for h in 0..3 * n {
            let (a, b) = half_edge(tris, h);
            let slot = &mut fill[a.min(b) as usize];
            bucket[*slot as usize] = h as u32;
            *slot += 1;
        }
        HalfEdges { start, bucket }
    }

    /// Appends the streams of `mesh` (the mesh these half-edges are of) to `out`, as
    /// [`encode_streams`] describes; returns the vertex order of the streams: decoded
    /// vertex `i` is `mesh` vertex `order[i]`.
    pub(crate) fn encode(&self, mesh: &TriMesh, step: f64, out: &mut Vec<u8>) -> Vec<u32> {
        let tris = &mesh.triangles;
        let n = tris.len();
        let mut coded = vec![false; n];
        let mut new_id = vec![u32::MAX; mesh.positions.len()];
        let mut old_of_new: Vec<u32> = Vec::new();
        let mut numbering = Numbering {
            next: 0,
            plan: Vec::new(),
        };
        let (mut flags, mut codes) = (Vec::with_capacity(2 * n), Vec::with_capacity(2 * n));
        let mut emit = |v: u32,
                        prediction: Prediction,
                        numbering: &mut Numbering,
                        codes: &mut Vec<u8>|
         -> u32 {
            let id = new_id[v as usize];
            if id == u32::MAX {
                new_id[v as usize] = numbering.next;
                old_of_new.push(v);
                numbering.plan.push(prediction);
                numbering.next += 1;
                put_varint(codes, 0);
                numbering.next - 1
            } else {
                put_varint(codes, (numbering.next - id) as u64);
                id
            }
        };
        // The stack holds gates in new ids, and in parallel their half-edges.
        let mut stack: Vec<Gate> = Vec::new();
        let mut gate_edge: Vec<u32> = Vec::new();
        let (mut done, mut cursor) = (0usize, 0usize);
        while done < n {
            if stack.is_empty() {
                while coded[cursor] {
                    cursor += 1;
                }
                let t = tris[cursor];
                coded[cursor] = true;
                done += 1;
                let mut ids = [0u32; 3];
                for k in 0..3 {
                    let known = (0..k).map(|j| ids[j]).next();
                    let p = numbering.root_prediction(known);
                    ids[k] = emit(t[k], p, &mut numbering, &mut codes);
                }
                push_gates(&mut stack, ids, false);
                for k in (0..3).rev() {
                    gate_edge.push((3 * cursor + k) as u32);
                }
                continue;
            }
            let [x, y, z] = stack.pop().expect("non-empty");
            let h = gate_edge.pop().expect("parallel to the stack") as usize;
            let (ox, oy) = half_edge(tris, h);
            let low = ox.min(oy) as usize;
            let found = self.bucket[self.start[low] as usize..self.start[low + 1] as usize]
                .iter()
                .copied()
                .find(|&e| half_edge(tris, e as usize) == (oy, ox) && !coded[e as usize / 3]);
            let Some(e) = found else {
                flags.push(0);
                continue;
            };
            flags.push(1);
            let t = e as usize / 3;
            coded[t] = true;
            done += 1;
            // The triangle holds (oy, ox) at corner k = e % 3; its third corner follows.
            let k = e as usize % 3;
            let ow = tris[t][(k + 2) % 3];
            let w = emit(
                ow,
                Prediction::Parallelogram(x, y, z),
                &mut numbering,
                &mut codes,
            );
            push_gates(&mut stack, [y, x, w], true);
            // Gates (w, y) and (x, w) in push order: half-edges k+2 then k+1 of t.
            gate_edge.push((3 * t + (k + 2) % 3) as u32);
            gate_edge.push((3 * t + (k + 1) % 3) as u32);
        }
        let residuals = position_residuals(mesh, step, &old_of_new, &numbering.plan);
        out.reserve(flags.len() + codes.len() + residuals.len() + 16);
        for stream in [&flags, &codes, &residuals] {
            put_varint(out, stream.len() as u64);
            out.extend_from_slice(stream);
        }
        old_of_new
    }

    /// What [`encode_streams`] reports for `mesh`: its counts and shape, without coding
    /// it.
    pub(crate) fn report(&self, mesh: &TriMesh) -> CodedMesh {
        let tris = &mesh.triangles;
        // Edges and the conditions of exact Loop counts, from the buckets: the sides of one
        // undirected edge share a bucket.
        let mut edges = 0u64;
        let mut loop_countable = tris
            .iter()
            .all(|t| t[0] != t[1] && t[1] != t[2] && t[2] != t[0]);
        let mut closed_oriented = loop_countable;
        // Per half-edge of the bucket: (larger vertex, apex); per edge: (larger vertex,
        // sides, sides running from the smaller vertex).
        let mut seen: Vec<(u32, u32)> = Vec::new();
        let mut edge_sides: Vec<(u32, u32, u32)> = Vec::new();
        for v in 0..mesh.positions.len() {
            seen.clear();
            edge_sides.clear();
            for &h in &self.bucket[self.start[v] as usize..self.start[v + 1] as usize] {
                let (a, b) = half_edge(tris, h as usize);
                let other = a.max(b);
                let opposite = tris[h as usize / 3][(h as usize % 3 + 2) % 3];
                if seen.iter().any(|&(o, w)| o == other && w == opposite) {
                    loop_countable = false;
                }
                seen.push((other, opposite));
                let forward = (a < b) as u32;
                match edge_sides.iter_mut().find(|e| e.0 == other) {
                    Some(e) => {
                        e.1 += 1;
                        e.2 += forward;
                    }
                    None => {
                        edges += 1;
                        edge_sides.push((other, 1, forward));
                    }
                }
            }
            closed_oriented &= edge_sides.iter().all(|&(_, n, f)| n == 2 && f == 1);
        }
        let mut used = vec![false; mesh.positions.len()];
        for &v in tris.iter().flatten() {
            used[v as usize] = true;
        }
        CodedMesh {
            vertices: used.iter().filter(|&&u| u).count() as u32,
            triangles: tris.len() as u32,
            edges,
            loop_countable,
            closed_oriented: closed_oriented && loop_countable,
        }
    }
}

/// Reads a count no larger than `limit` (what the header or an earlier count allows).
pub(crate) fn read_count(
    raw: &[u8],
    pos: &mut usize,
    what: &str,
    limit: u64,
) -> Result<usize, String> {
    let v = get_varint(raw, pos).ok_or(format!("{what} missing"))?;
    if v > limit {
        return Err(format!("{what} {v} exceeds the frame's {limit}"));
    }
    Ok(v as usize)
}

/// Decodes a version-1 payload of `vertices` vertices and `triangles` triangles. No
/// normals.
pub(crate) fn decode_v1(
    payload: &[u8],
    vertices: usize,
    triangles: usize,
    step: f64,
) -> Result<TriMesh, String> {
    let raw = decompress(payload, raw_capacity(vertices, triangles))?;
    let mut pos = 0;
    let mesh = decode_streams(&raw, &mut pos, vertices, triangles, step)?;
    if pos != raw.len() {
        return Err("trailing bytes after the streams".into());
    }
    Ok(mesh)
}

/// An upper bound of the stream bytes of a mesh (varints of at most 5 bytes per vertex
/// code and 10 per coordinate residual).
pub(crate) fn raw_capacity(vertices: usize, triangles: usize) -> usize {
    triangles
        .saturating_mul(8)
        .saturating_add(vertices.saturating_mul(30))
        .saturating_add(64)
}

/// The most bytes one byte of zstd frame decompresses to (a block of at most 128 KiB
/// needs at least a 3-byte header and a byte of content): a bound on the decompressed
/// size from the bytes present, whatever a header claims.
const ZSTD_MAX_RATIO: usize = 1 << 16;

/// Checks counts of a mesh against the `bytes` of streams left to code it, before
/// anything is sized by them: every vertex has three position residuals of at least a
/// byte, every triangle at least one flag or vertex-code byte.
pub(crate) fn check_counts(vertices: usize, triangles: usize, bytes: usize) -> Result<(), String> {
    if vertices > bytes / 3 || triangles > bytes {
        return Err(format!(
            "{vertices} vertices and {triangles} triangles cannot fit in the {bytes} bytes that code them"
        ));
    }
    Ok(())
}

/// zstd decompression of at most `capacity` bytes. The buffer is sized by the frame's
/// content size when the frame states it, and each thread keeps its decompression context
/// (creating one costs about as much as decompressing a small frame).
pub(crate) fn decompress(payload: &[u8], capacity: usize) -> Result<Vec<u8>, String> {
    thread_local! {
        static CONTEXT: std::cell::RefCell<Option<zstd::bulk::Decompressor<'static>>> =
            const { std::cell::RefCell::new(None) };
    }
    let capacity = capacity.min(
        payload
            .len()
            .saturating_mul(ZSTD_MAX_RATIO)
            .saturating_add(1024),
    );
    let size = match zstd::zstd_safe::get_frame_content_size(payload) {
        Ok(Some(n)) if n > capacity as u64 => {
            return Err(format!(
                "zstd: content of {n} bytes exceeds the frame's {capacity}"
            ))
        }
        Ok(Some(n)) => n as usize,
        _ => capacity,
    };
    CONTEXT.with(|context| {
        let mut context = context.borrow_mut();
        let decompressor = match context.as_mut() {
            Some(d) => d,
            None => {
                context.insert(zstd::bulk::Decompressor::new().map_err(|e| format!("zstd: {e}"))?)
            }
        };
        decompressor
            .decompress(payload, size)
            .map_err(|e| format!("zstd: {e}"))
    })
}

/// The flag, vertex-code and residual streams at `raw[*pos..]`; moves `pos` past them.
pub(crate) fn split_streams<'a>(raw: &'a [u8], pos: &mut usize) -> Result<[&'a [u8]; 3], String> {
    let mut streams: [&[u8]; 3] = [&[]; 3];
    for (k, name) in ["flag", "vertex code", "position"].iter().enumerate() {
        let len = get_varint(raw, pos).ok_or(format!("{name} stream length missing"))? as usize;
        streams[k] = raw
            .get(*pos..pos.saturating_add(len))
            .ok_or(format!("{name} stream cut off"))?;
        *pos += len;
    }
    Ok(streams)
}

/// Reads the streams [`encode_streams`] wrote at `raw[*pos..]` (a mesh of `vertices`
/// vertices and `triangles` triangles) and moves `pos` past them. No normals.
pub(crate) fn decode_streams(
    raw: &[u8],
    pos: &mut usize,
    vertices: usize,
    triangles: usize,
    step: f64,
) -> Result<TriMesh, String> {
    let [flags, codes, residual_bytes] = split_streams(raw, pos)?;
    check_counts(vertices, 0, residual_bytes.len())?;
    check_counts(0, triangles, flags.len() + codes.len())?;
    let (mut fpos, mut cpos) = (0usize, 0usize);
    let mut numbering = Numbering {
        next: 0,
        plan: Vec::with_capacity(vertices),
    };
    let mut read = |prediction: Prediction, numbering: &mut Numbering| -> Result<u32, String> {
        let d = get_varint(codes, &mut cpos).ok_or("vertex code stream ends early")?;
        if d == 0 {
            numbering.plan.push(prediction);
            numbering.next += 1;
            Ok(numbering.next - 1)
        } else {
            numbering
                .next
                .checked_sub(d as u32)
                .ok_or_else(|| "vertex code refers before the first vertex".to_string())
        }
    };
    let mut tris: Vec<[u32; 3]> = Vec::with_capacity(triangles);
    let mut stack: Vec<Gate> = Vec::new();
    while tris.len() < triangles {
        match stack.pop() {
            None => {
                let mut ids = [0u32; 3];
                for k in 0..3 {
                    let known = (0..k).map(|j| ids[j]).next();
                    let p = numbering.root_prediction(known);
                    ids[k] = read(p, &mut numbering)?;
                }
                tris.push(ids);
                push_gates(&mut stack, ids, false);
            }
            Some([x, y, z]) => {
                let flag = *flags.get(fpos).ok_or("flag stream ends early")?;
                fpos += 1;
                if flag == 0 {
                    continue;
                }
                let w = read(Prediction::Parallelogram(x, y, z), &mut numbering)?;
                let ids = [y, x, w];
                tris.push(ids);
                push_gates(&mut stack, ids, true);
            }
        }
    }
    if numbering.next as usize != vertices {
        return Err(format!(
            "connectivity introduces {} vertices, header says {vertices}",
            numbering.next
        ));
    }
    let mut quantized: Vec<[i64; 3]> = Vec::with_capacity(vertices);
    let mut rpos = 0;
    for v in 0..vertices {
        let pred = numbering.plan[v].resolve(&quantized);
        let mut q = [0i64; 3];
        for k in 0..3 {
            let d = get_varint(residual_bytes, &mut rpos).ok_or("position stream ends early")?;
            q[k] = pred[k].wrapping_add(unzigzag(d));
        }
        quantized.push(q);
    }
    let positions = quantized
        .iter()
        .map(|q| Vec3::from_array(q.map(|c| (c as f64 * step) as f32)))
        .collect();
    Ok(TriMesh {
        positions,
        triangles: tris,
        normals: Vec::new(),
        attributes: Vec::new(),
    })
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

    #[test]
    fn any_triangle_soup_round_trips() {
        // Non-manifold edge (three triangles on 0-1), a flipped triangle, a repeated
        // vertex, an isolated triangle and an unreferenced vertex.
        let positions: Vec<Vec3> = (0..9)
            .map(|i| Vec3::new(i as f32, (i * i % 5) as f32, (i % 3) as f32))
            .collect();
        let triangles = vec![
            [0, 1, 2],
            [1, 0, 3],
            [0, 1, 4],
            [2, 1, 3],
            [3, 3, 4],
            [6, 7, 8],
        ];
        let mesh = TriMesh {
            positions: positions.clone(),
            triangles: triangles.clone(),
            normals: vec![],
            attributes: Vec::new(),
        };
        let (payload, nv, nt) = encode_v1(&mesh, 0.01, 3).unwrap();
        assert_eq!((nv, nt), (8, 6));
        let back = decode_v1(&payload, nv as usize, nt as usize, 0.01).unwrap();
        let canon = |m: &TriMesh| {
            let mut set: Vec<[[i64; 3]; 3]> = m
                .triangles
                .iter()
                .map(|t| {
                    let c = t.map(|v| {
                        m.positions[v as usize]
                            .to_array()
                            .map(|x| (x * 100.0).round() as i64)
                    });
                    (0..3)
                        .map(|r| [c[r], c[(r + 1) % 3], c[(r + 2) % 3]])
                        .min()
                        .unwrap()
                })
                .collect();
            set.sort();
            set
        };
        assert_eq!(canon(&back), canon(&mesh));
    }
}
