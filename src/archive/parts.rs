//! Closed control meshes stored in parts, so that one frame decodes on every core.
//!
//! The traversal that decodes a mesh's connectivity ([`super::codec`]) is sequential: each
//! gate depends on the ones before it. A closed control mesh of at least two
//! [`PART_TRIANGLES`] is therefore cut into slabs along the longest axis of its triangle
//! centroids, each holding about [`PART_TRIANGLES`] triangles, and each slab is coded as a
//! mesh of its own. A vertex shared by several slabs is coded in each (its parallelogram
//! predictions need it) and listed as a *copy* of its first occurrence in the slabs after
//! the first. The decoder runs the fused traversal and Loop step of [`super::fused`] on
//! every slab in parallel, then pairs the sides left open at the cuts, folds each copy's
//! valence and neighbour sum into its original and writes the subdivided mesh: control
//! vertices in slab order (copies left out), the edge points of each slab, then those of
//! the cut edges. A closed mesh stored whole is written the same way, as one part
//! ([`decode_streams_subdivided`]).
//!
//! The result is the Loop subdivision of the stored control mesh (the same vertices and
//! triangles as [`crate::subdivision::subdivide`] of the decoded mesh, up to their order
//! and the last bit of vertex points, whose neighbour sums are added in another order).
//! The cost is the copies and the restarted traversals: on the six shipped
//! `dambreak_small` frames (two parts each) the archive is 1.9 % larger (4096-triangle
//! parts: 8.6 %), and one frame decodes about 1.7 times as fast on two cores.

use super::codec::{get_varint, put_varint, read_count, unzigzag, zigzag, HalfEdges};
use super::fused::{edge_point, traverse, State};
use crate::mesh::TriMesh;
use crate::subdivision::{children, loop_betas};
use glam::Vec3;
use rayon::prelude::*;
use std::mem::MaybeUninit;

/// Control triangles per part: a mesh of `n` triangles has `n / PART_TRIANGLES` parts
/// (at least one) of equal size.
pub(crate) const PART_TRIANGLES: usize = 8192;
/// Most parts a frame may have.
const MAX_PARTS: usize = 1 << 16;
const NONE: u32 = u32::MAX;
/// Marks an edge number in `side_edge` as a cut edge's.
const CUT: u32 = 1 << 31;

/// Parts for a closed control mesh of `triangles` triangles (1: stored whole).
pub(crate) fn part_count(triangles: usize) -> usize {
    (triangles / PART_TRIANGLES).clamp(1, MAX_PARTS)
}

/// A vertex that a later part codes again: (its number in that part, the earlier part
/// that has it first, its number there).
type SeamCopy = (u32, u32, u32);

/// Appends `mesh` (closed, consistently oriented) in `parts` parts to `out`:
/// `varint(parts) (varint(V) varint(T) streams)×parts`, then for every part after the
/// first `varint(copies)` and per copy, by increasing number, `varint(number − previous
/// number) varint(part − 1 − earlier part) zigzag(number there − previous number
/// there)`. Returns the vertex order of the decoded control mesh (each part's own
/// vertices in part order): decoded vertex `i` is `mesh` vertex `order[i]`.
pub(crate) fn encode_parts(mesh: &TriMesh, parts: usize, step: f64, out: &mut Vec<u8>) -> Vec<u32> {
    let n = mesh.triangles.len();
    let (lo, hi) = mesh.positions.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), &p| (lo.min(p), hi.max(p)),
    );
    let extent = hi - lo;
    let axis = if extent.x >= extent.y && extent.x >= extent.z {
        0
    } else if extent.y >= extent.z {
        1
    } else {
        2
    };
    // Sorted by the sum of the corners' coordinates along the axis, ties by number: the
    // sum as order-preserving bits above the triangle number.
    let mut order: Vec<u64> = mesh
        .triangles
        .iter()
        .enumerate()
        .map(|(t, tri)| {
            let key: f32 = tri.iter().map(|&v| mesh.positions[v as usize][axis]).sum();
            let bits = key.to_bits();
            let ordered = if bits >> 31 == 1 {
                !bits
            } else {
                bits | 1 << 31
            };
            (ordered as u64) << 32 | t as u64
        })
        .collect();
    order.sort_unstable();
    put_varint(out, parts as u64);
    // First (part, number) of every mesh vertex, and each part's copies.
    let mut first: Vec<(u32, u32)> = vec![(NONE, 0); mesh.positions.len()];
    let mut copies: Vec<Vec<SeamCopy>> = vec![Vec::new(); parts];
    let mut local = vec![NONE; mesh.positions.len()];
    let mut streams = Vec::new();
    let mut decoded_order = Vec::with_capacity(mesh.positions.len());
    for p in 0..parts {
        let mut tris: Vec<u32> = order[p * n / parts..(p + 1) * n / parts]
            .iter()
            .map(|&k| k as u32)
            .collect();
        tris.sort_unstable();
        let (piece, original) =
            mesh.submesh(tris.iter().map(|&t| mesh.triangles[t as usize]), &mut local);
        streams.clear();
        let numbering = HalfEdges::of(&piece).encode(&piece, step, &mut streams);
        put_varint(out, numbering.len() as u64);
        put_varint(out, piece.triangles.len() as u64);
        out.extend_from_slice(&streams);
        for (k, &v) in numbering.iter().enumerate() {
            let v = original[v as usize] as usize;
            if first[v].0 == NONE {
                first[v] = (p as u32, k as u32);
                decoded_order.push(v as u32);
            } else {
                copies[p].push((k as u32, first[v].0, first[v].1));
            }
        }
    }
    for (p, list) in copies.iter().enumerate().skip(1) {
        put_varint(out, list.len() as u64);
        let (mut previous, mut previous_there) = (0u32, 0u32);
        for &(k, q, l) in list {
            put_varint(out, (k - previous) as u64);
            put_varint(out, (p as u32 - 1 - q) as u64);
            put_varint(out, zigzag(l as i64 - previous_there as i64));
            (previous, previous_there) = (k, l);
        }
    }
    decoded_order
}

/// Decodes the streams at `raw[*pos..]` of a closed, consistently oriented mesh of
/// `vertices` vertices and `triangles` triangles stored whole and returns its Loop
/// subdivision (one step), written as a mesh of one part. Moves `pos` past the streams.
pub(crate) fn decode_streams_subdivided(
    raw: &[u8],
    pos: &mut usize,
    vertices: usize,
    triangles: usize,
    step: f64,
) -> Result<TriMesh, String> {
    let st = traverse(raw, pos, vertices, triangles, step)?;
    if st.edge_points.len() * 2 != triangles * 3 {
        return Err("the mesh stored as closed has sides without a partner".into());
    }
    let numbers = Numbers {
        global: vec![(0..vertices as u32).collect()],
        base: vec![0],
        home: (0..vertices as u32).map(|k| (0, k)).collect(),
    };
    Ok(write_subdivision(&[st], &numbers, &[], triangles))
}

/// Decodes what [`encode_parts`] wrote at `raw[*pos..]` (a closed mesh of `vertices`
/// vertices and `triangles` triangles in all) and returns its Loop subdivision (one
/// step). Moves `pos` past it.
pub(crate) fn decode_parts_subdivided(
    raw: &[u8],
    pos: &mut usize,
    vertices: usize,
    triangles: usize,
    step: f64,
) -> Result<TriMesh, String> {
    let (spans, copies) = read_layout(raw, pos, triangles)?;
    let mut states: Vec<State> = spans
        .par_iter()
        .enumerate()
        .map(|(p, span)| {
            traverse(
                raw,
                &mut { span.start },
                span.vertices,
                span.triangles,
                step,
            )
            .map_err(|e| format!("part {p}: {e}"))
        })
        .collect::<Result<_, _>>()?;
    let numbers = number_vertices(&states, &copies, vertices)?;
    for (p, list) in copies.iter().enumerate() {
        for &(k, q, l) in list {
            let (n, sum) = (states[p].valence[k as usize], states[p].sum[k as usize]);
            let original = &mut states[q as usize];
            original.valence[l as usize] += n;
            original.sum[l as usize] += sum;
        }
    }
    let cut_points = pair_cuts(&mut states, &numbers)?;
    let inner: usize = states.iter().map(|s| s.edge_points.len()).sum();
    if (inner + cut_points.len()) * 2 != triangles * 3 {
        return Err("the mesh stored as closed has sides without a partner".into());
    }
    Ok(write_subdivision(&states, &numbers, &cut_points, triangles))
}

/// Where a part's streams start in the raw frame, and its counts.
struct Span {
    start: usize,
    vertices: usize,
    triangles: usize,
}

/// Reads the part count, each part's counts (skipping its streams) and the copy lists.
fn read_layout(
    raw: &[u8],
    pos: &mut usize,
    triangles: usize,
) -> Result<(Vec<Span>, Vec<Vec<SeamCopy>>), String> {
    let parts = read_count(raw, pos, "part count", MAX_PARTS as u64)?;
    if parts == 0 {
        return Err("a mesh in parts has no part".into());
    }
    let mut spans: Vec<Span> = Vec::with_capacity(parts);
    let mut total_triangles = 0usize;
    for p in 0..parts {
        let t_limit = (triangles - total_triangles) as u64;
        let v = read_count(raw, pos, &format!("part {p} vertex count"), 3 * t_limit)?;
        let t = read_count(raw, pos, &format!("part {p} triangle count"), t_limit)?;
        spans.push(Span {
            start: *pos,
            vertices: v,
            triangles: t,
        });
        total_triangles += t;
        super::codec::split_streams(raw, pos).map_err(|e| format!("part {p}: {e}"))?;
    }
    if total_triangles != triangles {
        return Err(format!(
            "parts hold {total_triangles} triangles, header says {triangles}"
        ));
    }
    let mut copies: Vec<Vec<SeamCopy>> = vec![Vec::new(); parts];
    for p in 1..parts {
        let count = read_count(raw, pos, "copy count", spans[p].vertices as u64)?;
        let (mut previous, mut previous_there) = (0u64, 0i64);
        for i in 0..count {
            let k = get_varint(raw, pos).ok_or("copy list cut off")?;
            let back = get_varint(raw, pos).ok_or("copy list cut off")?;
            let there = get_varint(raw, pos).ok_or("copy list cut off")?;
            let (Some(k), Some(there)) = (
                previous.checked_add(k),
                previous_there.checked_add(unzigzag(there)),
            ) else {
                return Err(format!("part {p}: copy {i} is out of range"));
            };
            if (i > 0 && k == previous) || k >= spans[p].vertices as u64 || back >= p as u64 {
                return Err(format!("part {p}: copy {i} is out of range"));
            }
            let q = p - 1 - back as usize;
            if there < 0 || there >= spans[q].vertices as i64 {
                return Err(format!("part {p}: copy {i} refers past part {q}"));
            }
            copies[p].push((k as u32, q as u32, there as u32));
            (previous, previous_there) = (k, there);
        }
    }
    Ok((spans, copies))
}

/// The global numbering of the control vertices: each part's own vertices in order
/// (part `p`'s from `base[p]` on), copies taking their original's number.
struct Numbers {
    /// Per part, the global number of each of its vertices.
    global: Vec<Vec<u32>>,
    base: Vec<u32>,
    /// Per global vertex, its part and number there (where its valence and sum gather).
    home: Vec<(u32, u32)>,
}

impl Numbers {
    /// True when vertex `k` of part `p` is that part's own (not a copy).
    fn own(&self, p: usize, k: usize) -> bool {
        self.global[p][k] >= self.base[p]
    }
}

/// Numbers the control vertices of the decoded parts; checks that every copy names an
/// original at the same lattice position and that the parts hold `vertices` in all.
fn number_vertices(
    states: &[State],
    copies: &[Vec<SeamCopy>],
    vertices: usize,
) -> Result<Numbers, String> {
    let mut numbers = Numbers {
        global: Vec::with_capacity(states.len()),
        base: Vec::with_capacity(states.len()),
        home: Vec::with_capacity(vertices),
    };
    for (p, st) in states.iter().enumerate() {
        let base = numbers.home.len() as u32;
        let mut ids = Vec::with_capacity(st.positions.len());
        let mut list = copies[p].iter().peekable();
        for k in 0..st.positions.len() as u32 {
            let Some(&(_, q, l)) = list.next_if(|c| c.0 == k) else {
                ids.push(numbers.home.len() as u32);
                numbers.home.push((p as u32, k));
                continue;
            };
            let (q, l) = (q as usize, l as usize);
            if !numbers.own(q, l) || st.quantized[k as usize] != states[q].quantized[l] {
                return Err(format!(
                    "part {p}: copy of vertex {l} of part {q} does not match it"
                ));
            }
            ids.push(numbers.global[q][l]);
        }
        numbers.global.push(ids);
        numbers.base.push(base);
    }
    if numbers.home.len() != vertices {
        return Err(format!(
            "parts hold {} distinct vertices, header says {vertices}",
            numbers.home.len()
        ));
    }
    Ok(numbers)
}

/// Pairs the sides the parts left open (the cut edges) by their global ends: makes each
/// cut edge's point, numbers it in the sides' `side_edge` (marked [`CUT`]) and adds its
/// ends to each other's neighbourhood at their home. Returns the cut edges' points.
fn pair_cuts(states: &mut [State], numbers: &Numbers) -> Result<Vec<Vec3>, String> {
    // (smaller end, larger end, the side's first end, part, side), global ends.
    let mut open: Vec<(u32, u32, u32, u32, u32)> = Vec::new();
    for (p, st) in states.iter().enumerate() {
        for side in st.unpaired_sides() {
            let [a, b, _] = side_corners(st, side).map(|v| numbers.global[p][v as usize]);
            open.push((a.min(b), a.max(b), a, p as u32, side));
        }
    }
    open.sort_unstable();
    let unpaired = || "the mesh stored as closed has sides without a partner".to_string();
    let mut cut_points: Vec<Vec3> = Vec::with_capacity(open.len() / 2);
    for pair in open.chunks(2) {
        let [(lo, hi, first, p, s), (lo2, hi2, first2, p2, t)] = *pair else {
            return Err(unpaired());
        };
        if (lo, hi) != (lo2, hi2) || first == first2 {
            return Err(unpaired());
        }
        let [a, b, c] = side_corners(&states[p as usize], s);
        let [.., d] = side_corners(&states[p2 as usize], t);
        let st = &states[p as usize];
        let (pa, pb, pc) = (st.position(a), st.position(b), st.position(c));
        let pd = states[p2 as usize].position(d);
        let e = cut_points.len() as u32;
        cut_points.push(edge_point(pa, pb, first == lo, pc, pd));
        for (part, side) in [(p, s), (p2, t)] {
            states[part as usize].side_edge[side as usize / 3][side as usize % 3] = CUT | e;
        }
        let other_end = if first == lo { hi } else { lo };
        for (v, other) in [(first, pb), (other_end, pa)] {
            let (q, l) = numbers.home[v as usize];
            states[q as usize].add_neighbour(l, other);
        }
    }
    Ok(cut_points)
}

/// The corners of side `3t + k` of a part: from corner `k` to `k + 1`, then the apex.
fn side_corners(st: &State, side: u32) -> [u32; 3] {
    let (t, k) = (side as usize / 3, side as usize % 3);
    let tri = st.triangles[t];
    [tri[k], tri[(k + 1) % 3], tri[(k + 2) % 3]]
}

/// One part's slices of the subdivided mesh's outputs, written by [`PartOutput::write`].
struct PartOutput<'a> {
    part: usize,
    state: &'a State<'a>,
    /// The part's own control vertices' vertex points.
    vertices: &'a mut [MaybeUninit<Vec3>],
    /// The edge points of its edges (its cut edges' are written apart).
    edge_points: &'a mut [MaybeUninit<Vec3>],
    /// Four children per triangle.
    triangles: &'a mut [MaybeUninit<[u32; 3]>],
    /// The number of its first edge point in the subdivided mesh.
    edge_base: u32,
}

impl PartOutput<'_> {
    /// Writes the part's slices (edge points of cut edges numbered from `cut_base`);
    /// returns whether it filled each exactly.
    fn write(self, numbers: &Numbers, beta: &[f64], cut_base: u32) -> bool {
        let (p, st) = (self.part, self.state);
        let own = (0..st.positions.len()).filter(|&k| numbers.own(p, k));
        let mut vertex_count = 0;
        for (out, k) in self.vertices.iter_mut().zip(own) {
            out.write(st.vertex_point(k, beta));
            vertex_count += 1;
        }
        for (out, e) in self.edge_points.iter_mut().zip(&st.edge_points) {
            out.write(*e);
        }
        let ids = &numbers.global[p];
        let mut triangle_count = 0;
        for ((out, tri), sides) in self
            .triangles
            .chunks_exact_mut(4)
            .zip(&st.triangles)
            .zip(&st.side_edge)
        {
            let m = sides.map(|e| {
                if e & CUT != 0 {
                    cut_base + (e & !CUT)
                } else {
                    self.edge_base + e
                }
            });
            for (slot, child) in out
                .iter_mut()
                .zip(children(tri.map(|v| ids[v as usize]), m))
            {
                slot.write(child);
            }
            triangle_count += 4;
        }
        vertex_count == self.vertices.len()
            && self.edge_points.len() == st.edge_points.len()
            && triangle_count == self.triangles.len()
    }
}

/// The subdivided mesh, part by part in parallel: control vertices (each part's own, in
/// part order), the edge points of each part, then those of the cut edges.
fn write_subdivision(
    states: &[State],
    numbers: &Numbers,
    cut_points: &[Vec3],
    triangles: usize,
) -> TriMesh {
    let max_valence = states
        .iter()
        .flat_map(|s| s.valence.iter().copied())
        .max()
        .unwrap_or(0);
    let beta = loop_betas(&[max_valence]);
    let vertices = numbers.home.len();
    let inner: usize = states.iter().map(|s| s.edge_points.len()).sum();
    let nv = vertices as u32;
    let cut_base = nv + inner as u32;
    // The outputs are written slot by slot by the parts in parallel, without zeroing them
    // first (a serial pass over the whole output before the parallel one); every slot is
    // written exactly once, which is counted before the lengths are set.
    let vertex_total = vertices + inner + cut_points.len();
    let mut positions: Vec<Vec3> = Vec::with_capacity(vertex_total);
    let mut fine: Vec<[u32; 3]> = Vec::with_capacity(triangles * 4);
    {
        let (vertex_out, edge_out) =
            positions.spare_capacity_mut()[..vertex_total].split_at_mut(vertices);
        let (edge_out, cut_out) = edge_out.split_at_mut(inner);
        for (out, p) in cut_out.iter_mut().zip(cut_points) {
            out.write(*p);
        }
        // Each part's slices of the outputs.
        let mut jobs = Vec::with_capacity(states.len());
        let (mut vrest, mut erest, mut trest) = (
            vertex_out,
            edge_out,
            &mut fine.spare_capacity_mut()[..triangles * 4],
        );
        let mut edge_base = nv;
        for (p, st) in states.iter().enumerate() {
            let own_end = numbers.base.get(p + 1).copied().unwrap_or(nv);
            let own = (own_end - numbers.base[p]) as usize;
            let (v, vr) = std::mem::take(&mut vrest).split_at_mut(own);
            let (e, er) = std::mem::take(&mut erest).split_at_mut(st.edge_points.len());
            let (t, tr) = std::mem::take(&mut trest).split_at_mut(st.triangles.len() * 4);
            (vrest, erest, trest) = (vr, er, tr);
            jobs.push(PartOutput {
                part: p,
                state: st,
                vertices: v,
                edge_points: e,
                triangles: t,
                edge_base,
            });
            edge_base += st.edge_points.len() as u32;
        }
        let covered = vrest.is_empty() && erest.is_empty() && trest.is_empty();
        let complete = jobs
            .into_par_iter()
            .map(|job| job.write(numbers, &beta, cut_base))
            .all(|filled| filled);
        assert!(covered && complete, "every output slot is written");
    }
    // SAFETY: every slot of both outputs was written (asserted above: each part filled
    // its slices exactly, and the slices cover the outputs).
    unsafe {
        positions.set_len(vertex_total);
        fine.set_len(triangles * 4);
    }
    TriMesh {
        positions,
        triangles: fine,
        normals: Vec::new(),
        attributes: Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::archive::codec::{decode_streams, encode_streams};
    use crate::isolated::icosphere;
    use crate::subdivision::{subdivide, SubdivideOptions};

    /// Vertices sorted by position (they are far apart) and triangles in those ranks,
    /// corners rotated to start at the smallest, sorted.
    fn canonical(m: &TriMesh) -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let mut order: Vec<u32> = (0..m.positions.len() as u32).collect();
        let key = |v: u32| m.positions[v as usize].to_array();
        order.sort_by(|&a, &b| key(a).partial_cmp(&key(b)).unwrap());
        let mut rank = vec![0u32; order.len()];
        for (i, &v) in order.iter().enumerate() {
            rank[v as usize] = i as u32;
        }
        let mut tris: Vec<[u32; 3]> = m
            .triangles
            .iter()
            .map(|t| {
                let r = t.map(|v| rank[v as usize]);
                let k = (0..3).min_by_key(|&k| r[k]).unwrap();
                [r[k], r[(k + 1) % 3], r[(k + 2) % 3]]
            })
            .collect();
        tris.sort_unstable();
        (
            order.iter().map(|&v| m.positions[v as usize]).collect(),
            tris,
        )
    }

    fn test_mesh() -> TriMesh {
        // A fine sphere with one vertex pulled out, and a second, small component.
        let mut mesh = icosphere(5, 1.0);
        mesh.positions[40] *= 1.2;
        let mut second = icosphere(1, 0.3);
        for p in &mut second.positions {
            *p += Vec3::new(1.8, 0.1, 0.0);
        }
        mesh.append(&second);
        mesh
    }

    /// `mesh` (closed, oriented) coded whole, its vertex and triangle counts, and the
    /// general Loop step of the decoded mesh: what the fused decoders must give.
    fn coded_with_loop_step(mesh: &TriMesh, step: f64) -> (Vec<u8>, usize, usize, TriMesh) {
        let mut raw = Vec::new();
        let coded = encode_streams(mesh, step, &mut raw);
        assert!(coded.closed_oriented);
        let (nv, nt) = (coded.vertices as usize, coded.triangles as usize);
        let mut expected = decode_streams(&raw, &mut 0, nv, nt, step).unwrap();
        subdivide(&mut expected, &SubdivideOptions { levels: 1 });
        (raw, nv, nt, expected)
    }

    #[test]
    fn parts_decode_to_the_loop_step_of_the_whole_mesh() {
        let mesh = test_mesh();
        let step = 1e-4;
        let (_, nv, nt, expected) = coded_with_loop_step(&mesh, step);
        let (expected_positions, expected_triangles) = canonical(&expected);
        // Two parts, several, and thin slabs whose vertices lie in three parts.
        for parts in [1, 2, 5, 60] {
            let mut raw = Vec::new();
            encode_parts(&mesh, parts, step, &mut raw);
            let mut pos = 0;
            let back = decode_parts_subdivided(&raw, &mut pos, nv, nt, step).unwrap();
            assert_eq!(pos, raw.len());
            let (positions, triangles) = canonical(&back);
            assert_eq!(triangles, expected_triangles, "{parts} parts");
            for (a, b) in positions.iter().zip(&expected_positions) {
                assert!(
                    (*a - *b).abs().max_element() <= 1e-6,
                    "{parts} parts: {a} vs {b}"
                );
            }
        }
    }

    #[test]
    fn damaged_parts_are_errors_not_panics() {
        let mesh = test_mesh();
        let step = 1e-4;
        let mut raw = Vec::new();
        encode_parts(&mesh, 5, step, &mut raw);
        let (nv, nt) = (mesh.positions.len(), mesh.triangles.len());
        assert!(decode_parts_subdivided(&raw, &mut 0, nv, nt, step).is_ok());
        // Wrong counts.
        assert!(decode_parts_subdivided(&raw, &mut 0, nv + 1, nt, step).is_err());
        assert!(decode_parts_subdivided(&raw, &mut 0, nv, nt - 1, step).is_err());
        // Every byte of the copy tables (the last ones) and a sample of the rest, changed.
        let tail = raw.len().saturating_sub(600);
        for i in (0..tail).step_by(97).chain(tail..raw.len()) {
            for delta in [1u8, 0x80] {
                let mut bad = raw.clone();
                bad[i] = bad[i].wrapping_add(delta);
                let _ = decode_parts_subdivided(&bad, &mut 0, nv, nt, step);
            }
        }
        // Cut off.
        assert!(decode_parts_subdivided(&raw[..raw.len() - 1], &mut 0, nv, nt, step).is_err());
    }

    #[test]
    fn the_fused_step_is_loop_subdivision_of_the_decoded_mesh() {
        // Two closed components (valences 5 and 6, one vertex pulled out) so that the
        // traversal starts twice.
        let mut mesh = icosphere(2, 1.0);
        mesh.positions[7] *= 1.4;
        let mut second = icosphere(1, 0.5);
        for p in &mut second.positions {
            *p += Vec3::new(3.0, 0.0, 0.0);
        }
        mesh.append(&second);
        let step = 1e-4;
        let (raw, nv, nt, generic) = coded_with_loop_step(&mesh, step);
        let mut pos = 0;
        let fused = decode_streams_subdivided(&raw, &mut pos, nv, nt, step).unwrap();
        assert_eq!(pos, raw.len());
        // Same control vertices and children; edge points may be numbered differently.
        assert_eq!(fused.vertex_count(), generic.vertex_count());
        assert_eq!(fused.triangle_count(), generic.triangle_count());
        for v in 0..nv {
            let d = (fused.positions[v] - generic.positions[v])
                .abs()
                .max_element();
            assert!(d <= 1e-6, "vertex point {v} differs by {d}");
        }
        let key = |m: &TriMesh, t: usize| {
            m.triangles[t].map(|v| {
                m.positions[v as usize]
                    .to_array()
                    .map(|c| (c as f64 * 1e5).round() as i64)
            })
        };
        for t in 0..nt * 4 {
            assert_eq!(key(&fused, t), key(&generic, t), "child triangle {t}");
        }
        // An open mesh is not flagged closed.
        let mut open = mesh.clone();
        open.triangles.pop();
        assert!(!encode_streams(&open, step, &mut Vec::new()).closed_oriented);
    }
}
