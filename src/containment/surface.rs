//! The surface one Loop step makes of a control mesh, as points computed from the
//! control mesh (its triangles are the control triangles' children, never stored).

use crate::mesh::{TriMesh, VertexTriangles};
use glam::{DVec3, Vec3};
use rayon::prelude::*;

/// The surface one Loop step makes of a part of a control mesh, without its triangles:
/// the vertex point of every corner of the chosen control triangles and every chosen
/// triangle's three edge points (an edge point is computed for both triangles of its
/// edge, the same way, so two copies are equal bit for bit). Surface triangle `s` is child
/// `s % 4` of control triangle `s / 4`. Points are numbered in the order of the whole
/// mesh's (vertex points by control vertex, then edge points by control triangle and
/// side), so that ties between equally near points break the same way in any part.
pub(super) struct LoopSurface {
    /// Vertex points (one per control vertex of [`Self::vertex_ids`]), then edge points
    /// (three per control triangle of [`Self::cut_ids`], side `k` from corner `k` to
    /// `k + 1`).
    pub(super) points: Vec<Vec3>,
    /// Control vertices with a vertex point, ascending.
    pub(super) vertex_ids: Vec<u32>,
    /// Control triangles of the part, ascending.
    pub(super) triangle_ids: Vec<u32>,
    /// Those of them cut into four children, with edge points, ascending (all of them
    /// with [`Step::Loop`]).
    cut_ids: Vec<u32>,
    slots: Slots,
}

/// Control vertex → its vertex point and control triangle → its place in a part
/// ([`ABSENT`] when not in it): tables the size of the whole control mesh, passed from
/// one part to the next (`Default`: empty, to take a table's place meanwhile).
#[derive(Default)]
pub(super) struct Slots {
    vertex: Vec<u32>,
    triangle: Vec<u32>,
}

impl Slots {
    pub(super) fn new(control: &TriMesh) -> Self {
        Slots {
            vertex: vec![ABSENT; control.positions.len()],
            triangle: vec![ABSENT; control.triangles.len()],
        }
    }
}

/// The surface measured, from the control mesh.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Step {
    /// One Loop step: vertex and edge points by Loop's masks, four children per control
    /// triangle.
    Loop,
    /// The control mesh itself (nothing subdivides it): a triangle with a side longer
    /// than `split` (world units) cut into four children at its edge midpoints, so that
    /// the surface has points between its far-apart vertices; the others whole (surface
    /// triangle `4t` is control triangle `t`), their corners their only points. On a fine
    /// mesh (the steady surface's) a quarter of the triangles and a seventh of the points
    /// of cutting every triangle, the same surface. `split` 0 cuts every triangle.
    Flat { split: f32 },
}

impl Step {
    /// How far from its first corner (the control position) any point of a control
    /// triangle's surface lies at most, when no edge of the control mesh is longer than
    /// `longest_edge`: cut or whole, its corners and edge midpoints lie within the longest
    /// edge at that corner; a Loop vertex point lies in the hull of its vertex's one-ring
    /// and an edge point in the hull of the edge's two triangles, so within two edges.
    /// A hair more, against rounding.
    pub(super) fn spread(self, longest_edge: f64) -> f64 {
        let edges = match self {
            Step::Loop => 2.0,
            Step::Flat { .. } => 1.0,
        };
        edges * longest_edge * (1.0 + 1e-4)
    }
}

/// Slot of a vertex or triangle not in the part.
const ABSENT: u32 = u32::MAX;
/// Slot of a triangle of the part measured whole ([`Step::Flat`]).
const WHOLE: u32 = u32::MAX - 1;

impl LoopSurface {
    /// The one-step surface over control triangles `triangle_ids` (ascending), made as
    /// `step` says. Loop's masks read the whole control mesh: a point is the same in
    /// every part that holds it. `slots` come from [`Slots::new`] or
    /// [`Self::into_slots`].
    pub(super) fn new(
        control: &TriMesh,
        tris: &VertexTriangles,
        triangle_ids: Vec<u32>,
        step: Step,
        mut slots: Slots,
    ) -> Self {
        let smooth = step == Step::Loop;
        let cut_ids: Vec<u32> = match step {
            Step::Loop => triangle_ids.clone(),
            Step::Flat { split } => {
                let split2 = split * split;
                let long = |t: u32| {
                    let [a, b, c] =
                        control.triangles[t as usize].map(|v| control.positions[v as usize]);
                    a.distance_squared(b) > split2
                        || b.distance_squared(c) > split2
                        || c.distance_squared(a) > split2
                };
                triangle_ids
                    .par_iter()
                    .copied()
                    .filter(|&t| long(t))
                    .collect()
            }
        };
        for &t in &triangle_ids {
            slots.triangle[t as usize] = WHOLE;
        }
        for (k, &t) in cut_ids.iter().enumerate() {
            slots.triangle[t as usize] = k as u32;
        }
        // The corners, ascending: sorted when the part is small, else marked and read off
        // the table in order.
        let vertex_ids: Vec<u32> = if 8 * triangle_ids.len() < control.positions.len() {
            let mut ids: Vec<u32> = triangle_ids
                .iter()
                .flat_map(|&t| control.triangles[t as usize])
                .collect();
            ids.par_sort_unstable();
            ids.dedup();
            ids
        } else {
            for &t in &triangle_ids {
                for v in control.triangles[t as usize] {
                    slots.vertex[v as usize] = 0;
                }
            }
            (0..control.positions.len() as u32)
                .filter(|&v| slots.vertex[v as usize] != ABSENT)
                .collect()
        };
        for (k, &v) in vertex_ids.iter().enumerate() {
            slots.vertex[v as usize] = k as u32;
        }
        let betas = crate::subdivision::loop_betas(&[64]);
        let mut points = vec![Vec3::ZERO; vertex_ids.len() + 3 * cut_ids.len()];
        let (vertex_points, edge_points) = points.split_at_mut(vertex_ids.len());
        vertex_points
            .par_iter_mut()
            .zip(&vertex_ids)
            .for_each(|(out, &v)| *out = vertex_point(control, tris, v, smooth, &betas));
        edge_points
            .par_chunks_mut(3)
            .zip(&cut_ids)
            .for_each(|(out, &t)| {
                for (k, e) in out.iter_mut().enumerate() {
                    *e = edge_point(control, tris, t, k, smooth);
                }
            });
        LoopSurface {
            points,
            vertex_ids,
            triangle_ids,
            cut_ids,
            slots,
        }
    }

    /// The slot tables, emptied, for the next part.
    pub(super) fn into_slots(self) -> Slots {
        let mut slots = self.slots;
        for &v in &self.vertex_ids {
            slots.vertex[v as usize] = ABSENT;
        }
        for &t in &self.triangle_ids {
            slots.triangle[t as usize] = ABSENT;
        }
        slots
    }

    /// Point index of control vertex `v`'s vertex point (`v` must be a corner of a
    /// triangle of the part).
    pub(super) fn vertex(&self, v: u32) -> u32 {
        let i = self.slots.vertex[v as usize];
        debug_assert!(i != ABSENT, "control vertex {v} outside the part");
        i
    }

    /// Point index of control triangle `t`'s edge point on side `k` (`t` must be in the
    /// part).
    pub(super) fn edge(&self, t: u32, k: usize) -> u32 {
        let slot = self.slots.triangle[t as usize];
        debug_assert!(slot != ABSENT, "control triangle {t} outside the part");
        debug_assert!(slot != WHOLE, "control triangle {t} is not cut");
        (self.vertex_ids.len() + 3 * slot as usize + k) as u32
    }

    /// Corner point indices of surface triangle `s`.
    pub(super) fn triangle(&self, control: &TriMesh, s: u32) -> [u32; 3] {
        let t = s >> 2;
        let tri = control.triangles[t as usize].map(|v| self.vertex(v));
        if self.whole(t) {
            debug_assert_eq!(s & 3, 0, "control triangle {t} is measured whole");
            return tri;
        }
        let m = [0, 1, 2].map(|k| self.edge(t, k));
        crate::subdivision::children(tri, m)[(s & 3) as usize]
    }

    /// Whether control triangle `t` (of the part) is measured whole, not cut.
    fn whole(&self, t: u32) -> bool {
        self.slots.triangle[t as usize] == WHOLE
    }

    /// Surface triangles over control triangle `t` (of the part): its four children, or
    /// itself when measured whole.
    pub(super) fn children(&self, t: u32) -> std::ops::Range<u32> {
        if self.whole(t) {
            4 * t..4 * t + 1
        } else {
            4 * t..4 * t + 4
        }
    }

    /// Points of control triangle `t`'s surface: its corners' vertex points and, when it
    /// is cut, its edge points.
    pub(super) fn points_of(&self, control: &TriMesh, t: u32) -> impl Iterator<Item = u32> + '_ {
        let corners = control.triangles[t as usize].map(|v| self.vertex(v));
        let sides = if self.whole(t) { 0 } else { 3 };
        corners
            .into_iter()
            .chain((0..sides).map(move |k| self.edge(t, k)))
    }

    /// The control vertex of vertex point `i`, or the control triangle and side of edge
    /// point `i`.
    pub(super) fn owner(&self, i: u32) -> Owner {
        let nv = self.vertex_ids.len() as u32;
        if i < nv {
            Owner::Vertex(self.vertex_ids[i as usize])
        } else {
            let e = i - nv;
            Owner::Edge(self.cut_ids[(e / 3) as usize], (e % 3) as usize)
        }
    }
}

/// What a point of the one-step surface is computed from.
pub(super) enum Owner {
    /// The vertex point of this control vertex.
    Vertex(u32),
    /// The edge point of this control triangle's side.
    Edge(u32, usize),
}

/// Loop's vertex point of control vertex `v` (interior mask; the vertex itself when not
/// `smooth`, or when its fan is not a closed ring).
fn vertex_point(
    control: &TriMesh,
    tris: &VertexTriangles,
    v: u32,
    smooth: bool,
    betas: &[f64],
) -> Vec3 {
    let x = control.positions[v as usize];
    let fan = tris.of(v);
    if !smooth || fan.len() < 3 {
        return x;
    }
    // In a closed fan every neighbour follows v in exactly one triangle.
    let mut sum = DVec3::ZERO;
    for &t in fan {
        let tri = control.triangles[t as usize];
        let k = tri.iter().position(|&w| w == v).expect("v is a corner");
        sum += control.positions[tri[(k + 1) % 3] as usize].as_dvec3();
    }
    let n = fan.len();
    let beta = if n < betas.len() {
        betas[n]
    } else {
        crate::subdivision::loop_betas(&[n as u32])[n]
    };
    ((1.0 - n as f64 * beta) * x.as_dvec3() + beta * sum).as_vec3()
}

/// Loop's edge point on side `k` of control triangle `t`: `3/8 (a + b) + 1/8 (c + d)`
/// with `d` the far corner of the triangle across the side (the midpoint when not
/// `smooth` or when the side has not exactly one triangle across). Summed in vertex-index
/// order, so both triangles of the edge compute the same bits.
fn edge_point(control: &TriMesh, tris: &VertexTriangles, t: u32, k: usize, smooth: bool) -> Vec3 {
    let tri = control.triangles[t as usize];
    let (a, b, c) = (tri[k], tri[(k + 1) % 3], tri[(k + 2) % 3]);
    let x = |v: u32| control.positions[v as usize].as_dvec3();
    let pair = |u: u32, w: u32| if u < w { x(u) + x(w) } else { x(w) + x(u) };
    if !smooth {
        // The control mesh itself: no need to look for the triangle across.
        return (0.5 * pair(a, b)).as_vec3();
    }
    let mut across = tris
        .of(a)
        .iter()
        .filter(|&&u| u != t && control.triangles[u as usize].contains(&b));
    let d = match (across.next(), across.next()) {
        (Some(&u), None) => control.triangles[u as usize]
            .into_iter()
            .find(|&w| w != a && w != b),
        _ => None,
    };
    match d {
        Some(d) => (0.375 * pair(a, b) + 0.125 * pair(c, d)).as_vec3(),
        None => (0.5 * pair(a, b)).as_vec3(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::isolated::icosphere;

    /// The one-step surface measured is Loop's subdivision: every triangle's corners as
    /// `subdivide` makes them (to f32 rounding), after moving a few vertices too.
    #[test]
    fn loop_surface_is_the_subdivision() {
        let mut control = icosphere(2, 1.0);
        for (i, p) in control.positions.iter_mut().enumerate() {
            *p *= 1.0 + 0.1 * ((i * 7 % 5) as f32 / 5.0);
        }
        let tris = VertexTriangles::new(&control);
        let all = |control: &TriMesh| (0..control.triangles.len() as u32).collect();
        let one_step = |control: &TriMesh, ids: Vec<u32>| {
            LoopSurface::new(control, &tris, ids, Step::Loop, Slots::new(control))
        };
        let surface = one_step(&control, all(&control));
        let check = |control: &TriMesh, surface: &LoopSurface| {
            let mut expected = control.clone();
            crate::subdivision::subdivide(
                &mut expected,
                &crate::subdivision::SubdivideOptions { levels: 1 },
            );
            for s in 0..expected.triangles.len() as u32 {
                let want = expected.triangles[s as usize].map(|v| expected.positions[v as usize]);
                let got = surface
                    .triangle(control, s)
                    .map(|i| surface.points[i as usize]);
                for (w, g) in want.iter().zip(&got) {
                    assert!((*w - *g).length() < 1e-6, "triangle {s}: {w} against {g}");
                }
            }
        };
        check(&control, &surface);
        control.positions[3] += Vec3::splat(0.05);
        check(&control, &one_step(&control, all(&control)));
        // A part holds the same points as the whole.
        let part: Vec<u32> = (0..control.triangles.len() as u32).step_by(3).collect();
        let whole = one_step(&control, all(&control));
        let some = one_step(&control, part.clone());
        for &t in &part {
            for s in 4 * t..4 * t + 4 {
                let [a, b] =
                    [&whole, &some].map(|x| x.triangle(&control, s).map(|i| x.points[i as usize]));
                assert_eq!(a, b, "surface triangle {s}");
            }
        }
    }

    /// Every point of a control triangle's surface lies within [`Step::spread`] of its
    /// first corner, for Loop's step and the flat one, on a mesh with vertices moved far
    /// apart (what [`super::super::measure`]'s confirmation relies on to skip triangles
    /// by their first corner).
    #[test]
    fn every_point_of_a_triangle_lies_within_the_spread_of_its_first_corner() {
        let mut control = icosphere(2, 1.0);
        for (i, p) in control.positions.iter_mut().enumerate() {
            *p *= 1.0 + 0.8 * ((i * 7 % 5) as f32 / 5.0);
        }
        let tris = VertexTriangles::new(&control);
        let longest = super::super::measure::longest_edge(&control) as f64;
        for step in [
            Step::Loop,
            Step::Flat { split: 0.0 },
            Step::Flat { split: 0.3 },
        ] {
            let all = (0..control.triangles.len() as u32).collect();
            let surface = LoopSurface::new(&control, &tris, all, step, Slots::new(&control));
            let spread = step.spread(longest);
            let mut farthest = 0.0f64;
            for t in 0..control.triangles.len() as u32 {
                let corner = control.positions[control.triangles[t as usize][0] as usize];
                for i in surface.points_of(&control, t) {
                    let d = surface.points[i as usize].distance(corner) as f64;
                    assert!(d <= spread, "{step:?}: triangle {t}, {d} > {spread}");
                    farthest = farthest.max(d);
                }
            }
            // The bound is not loose by more than the edges it counts.
            assert!(farthest > 0.4 * spread, "{step:?}: {farthest} of {spread}");
        }
    }
}
