//! Decoding and one Loop step in a single pass, for closed, consistently oriented meshes
//! (what the pipeline stores).
//!
//! The traversal that decodes the connectivity already knows most edges: a gate popped
//! with flag 1 is the edge between its triangle and the one decoded across it. A gate
//! popped with flag 0 lies on an edge whose other side is, or will be, popped with flag 0
//! too; it waits in a short list at its smaller vertex until its partner comes. Positions
//! are decoded as their vertices are introduced, so each edge point
//! `3/8 (a + b) + 1/8 (c + d)` is made as soon as its edge is paired, and each vertex
//! gathers its valence and neighbour sum on the way; Loop's vertex mask is one pass at the
//! end ([`super::parts`] writes the subdivided mesh, of one part or several). The result is [`crate::subdivision::subdivide`]'s (edge points are bit for bit the
//! same; vertex points can differ in the last bit, since the neighbour sums are added in
//! another order), with the edge points numbered in order of pairing.

use super::codec::{get_varint, push_gates, split_streams, unzigzag, Gate, Prediction};
use glam::{DVec3, Vec3};

const NONE: u32 = u32::MAX;

/// The decoder's state: the control mesh so far and the subdivision gathered from it.
pub(crate) struct State<'a> {
    codes: &'a [u8],
    cpos: usize,
    residuals: &'a [u8],
    rpos: usize,
    step: f64,
    pub(crate) quantized: Vec<[i64; 3]>,
    /// Control positions as decoded (f32; widened to f64 for the masks).
    pub(crate) positions: Vec<Vec3>,
    pub(crate) valence: Vec<u32>,
    pub(crate) sum: Vec<DVec3>,
    /// Sides waiting for their partner: the head of a list per smaller vertex, and the
    /// entries (larger vertex, side, its apex, next entry).
    waiting_head: Vec<u32>,
    waiting: Vec<[u32; 4]>,
    pub(crate) triangles: Vec<[u32; 3]>,
    pub(crate) side_edge: Vec<[u32; 3]>,
    pub(crate) edge_points: Vec<Vec3>,
}

impl State<'_> {
    /// Loop's vertex point of control vertex `v` once its valence and neighbour sum are
    /// complete (`beta` from [`crate::subdivision::loop_betas`]).
    pub(crate) fn vertex_point(&self, v: usize, beta: &[f64]) -> Vec3 {
        let (p, n) = (self.positions[v].as_dvec3(), self.valence[v]);
        let (nf, b) = (n as f64, beta[n as usize]);
        ((1.0 - nf * b) * p + b * self.sum[v]).as_vec3()
    }

    /// The sides still waiting for a partner (boundary sides), in order of vertex and
    /// list position.
    pub(crate) fn unpaired_sides(&self) -> Vec<u32> {
        let mut sides = Vec::new();
        for &head in &self.waiting_head {
            let mut entry = head;
            while entry != NONE {
                let [_, side, _, next] = self.waiting[entry as usize];
                sides.push(side);
                entry = next;
            }
        }
        sides
    }

    /// Reads a vertex code; a new vertex gets its position from the residual stream.
    fn vertex(&mut self, prediction: Prediction) -> Result<u32, String> {
        let d = get_varint(self.codes, &mut self.cpos).ok_or("vertex code stream ends early")?;
        let next = self.quantized.len() as u32;
        if d != 0 {
            return next
                .checked_sub(d as u32)
                .ok_or_else(|| "vertex code refers before the first vertex".to_string());
        }
        let pred = prediction.resolve(&self.quantized);
        let mut q = [0i64; 3];
        for k in 0..3 {
            let r =
                get_varint(self.residuals, &mut self.rpos).ok_or("position stream ends early")?;
            q[k] = pred[k].wrapping_add(unzigzag(r));
        }
        self.quantized.push(q);
        let p = Vec3::from_array(q.map(|c| (c as f64 * self.step) as f32));
        self.positions.push(p);
        self.valence.push(0);
        self.sum.push(DVec3::ZERO);
        self.waiting_head.push(NONE);
        Ok(next)
    }

    /// Sides `s` (from `a` to `b`, apex `c`) and `t` (from `b` to `a`, apex `d`) are the
    /// two sides of one edge: number it, make its edge point, add each end to the
    /// other's neighbourhood.
    fn pair(&mut self, s: u32, t: u32, [a, b, c, d]: [u32; 4]) {
        let e = self.edge_points.len() as u32;
        self.side_edge[s as usize / 3][s as usize % 3] = e;
        self.side_edge[t as usize / 3][t as usize % 3] = e;
        let (pa, pb) = (self.position(a), self.position(b));
        let (pc, pd) = (self.position(c), self.position(d));
        self.edge_points.push(edge_point(pa, pb, a < b, pc, pd));
        self.add_neighbour(a, pb);
        self.add_neighbour(b, pa);
    }

    /// Control vertex `v`'s position, widened for the masks.
    #[inline]
    pub(crate) fn position(&self, v: u32) -> DVec3 {
        self.positions[v as usize].as_dvec3()
    }

    /// Counts `other` (a position) among vertex `v`'s neighbours.
    #[inline]
    pub(crate) fn add_neighbour(&mut self, v: u32, other: DVec3) {
        self.sum[v as usize] += other;
        self.valence[v as usize] += 1;
    }

    /// A side (gate `[a, b, c]`: from `a` to `b`, apex `c`) whose gate found no triangle
    /// across: pair it with its waiting partner, or wait for it.
    fn meet(&mut self, side: u32, [a, b, c]: Gate) {
        let (lo, hi) = (a.min(b), a.max(b));
        let mut previous = NONE;
        let mut entry = self.waiting_head[lo as usize];
        while entry != NONE {
            let [other, partner, apex, next] = self.waiting[entry as usize];
            if other == hi {
                if previous == NONE {
                    self.waiting_head[lo as usize] = next;
                } else {
                    self.waiting[previous as usize][3] = next;
                }
                self.pair(side, partner, [a, b, c, apex]);
                return;
            }
            previous = entry;
            entry = next;
        }
        self.waiting
            .push([hi, side, c, self.waiting_head[lo as usize]]);
        self.waiting_head[lo as usize] = self.waiting.len() as u32 - 1;
    }
}

/// Loop's edge point `3/8 (a + b) + 1/8 (c + d)` of edge `(a, b)` with apexes `c` and
/// `d`; the ends are added as the general subdivision adds them, smaller vertex first
/// (`a_first`: `a` is the smaller).
#[inline]
pub(crate) fn edge_point(pa: DVec3, pb: DVec3, a_first: bool, pc: DVec3, pd: DVec3) -> Vec3 {
    let ends = if a_first { pa + pb } else { pb + pa };
    (0.375 * ends + 0.125 * (pc + pd)).as_vec3()
}

/// Runs the traversal of the streams at `raw[*pos..]` (a mesh of `vertices` vertices and
/// `triangles` triangles), pairing every edge whose two sides it meets; moves `pos` past
/// the streams. Sides left waiting lie on the boundary (of a part of a closed mesh).
pub(crate) fn traverse<'a>(
    raw: &'a [u8],
    pos: &mut usize,
    vertices: usize,
    triangles: usize,
    step: f64,
) -> Result<State<'a>, String> {
    let [flags, codes, residuals] = split_streams(raw, pos)?;
    super::codec::check_counts(vertices, 0, residuals.len())?;
    super::codec::check_counts(0, triangles, flags.len() + codes.len())?;
    let mut st = State {
        codes,
        cpos: 0,
        residuals,
        rpos: 0,
        step,
        quantized: Vec::with_capacity(vertices),
        positions: Vec::with_capacity(vertices),
        valence: Vec::with_capacity(vertices),
        sum: Vec::with_capacity(vertices),
        waiting_head: Vec::with_capacity(vertices),
        // At most one entry per side popped with flag 0, about one per triangle.
        waiting: Vec::with_capacity(triangles + 16),
        triangles: Vec::with_capacity(triangles),
        side_edge: Vec::with_capacity(triangles),
        edge_points: Vec::with_capacity(triangles * 3 / 2),
    };
    // Gates with the side they stand for (3 t + k: corner k to k + 1 of triangle t).
    let mut stack: Vec<Gate> = Vec::with_capacity(64);
    let mut stack_sides: Vec<u32> = Vec::with_capacity(64);
    let mut fpos = 0usize;
    while st.triangles.len() < triangles {
        let t = st.triangles.len() as u32;
        match stack.pop() {
            None => {
                let mut ids = [0u32; 3];
                for k in 0..3 {
                    let known = if k > 0 { Some(ids[0]) } else { None };
                    let next = st.quantized.len() as u32;
                    let p = match known {
                        Some(v) => Prediction::Vertex(v),
                        None if next == 0 => Prediction::Origin,
                        None => Prediction::Vertex(next - 1),
                    };
                    ids[k] = st.vertex(p)?;
                }
                st.triangles.push(ids);
                st.side_edge.push([NONE; 3]);
                push_gates(&mut stack, ids, false);
                stack_sides.extend([3 * t + 2, 3 * t + 1, 3 * t]);
            }
            Some([x, y, z]) => {
                let side = stack_sides.pop().expect("parallel to the stack");
                let flag = *flags.get(fpos).ok_or("flag stream ends early")?;
                fpos += 1;
                if flag == 0 {
                    st.meet(side, [x, y, z]);
                    continue;
                }
                let w = st.vertex(Prediction::Parallelogram(x, y, z))?;
                let ids = [y, x, w];
                st.triangles.push(ids);
                st.side_edge.push([NONE; 3]);
                st.pair(side, 3 * t, [x, y, z, w]);
                push_gates(&mut stack, ids, true);
                stack_sides.extend([3 * t + 2, 3 * t + 1]);
            }
        }
    }
    // Gates left when the last triangle came: their triangles across are all decoded.
    while let (Some(side), Some(gate)) = (stack_sides.pop(), stack.pop()) {
        st.meet(side, gate);
    }
    if st.quantized.len() != vertices {
        return Err(format!(
            "connectivity introduces {} vertices, header says {vertices}",
            st.quantized.len()
        ));
    }
    Ok(st)
}
