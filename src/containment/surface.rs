//! The surface one Loop step makes of a control mesh, as points computed from the
//! control mesh (its triangles are the control triangles' children, never stored).

use crate::mesh::{TriMesh, VertexTriangles};
use glam::{DVec3, Vec3};
use rayon::prelude::*;

/// The surface one Loop step makes of a control mesh, without its triangles: every
/// control vertex's vertex point and every control triangle's three edge points (an edge
/// point is computed for both triangles of its edge, the same way, so the two copies are
/// equal bit for bit). Surface triangle `s` is child `s % 4` of control triangle `s / 4`.
pub(super) struct LoopSurface {
    /// Vertex points (one per control vertex), then edge points (three per control
    /// triangle, side `k` from corner `k` to `k + 1`).
    pub(super) points: Vec<Vec3>,
    pub(super) vertex_count: usize,
    /// With Loop's masks, or the control mesh itself (vertex points in place, edge points
    /// at the midpoints) when the surface is not subdivided.
    smooth: bool,
}

impl LoopSurface {
    pub(super) fn new(control: &TriMesh, tris: &VertexTriangles, smooth: bool) -> Self {
        let nv = control.positions.len();
        let mut surface = LoopSurface {
            points: vec![Vec3::ZERO; nv + 3 * control.triangles.len()],
            vertex_count: nv,
            smooth,
        };
        surface.update(control, tris, &vec![true; nv]);
        surface
    }

    /// Recomputes the points that depend on the vertices marked in `changed` or on their
    /// neighbours (every vertex point of a marked vertex, every edge point of a triangle
    /// with a marked corner: the marks must cover the one-rings of the moved vertices).
    pub(super) fn update(&mut self, control: &TriMesh, tris: &VertexTriangles, changed: &[bool]) {
        let nv = self.vertex_count;
        let (vertex_points, edge_points) = self.points.split_at_mut(nv);
        let smooth = self.smooth;
        let betas = crate::subdivision::loop_betas(&[64]);
        vertex_points
            .par_iter_mut()
            .enumerate()
            .filter(|(v, _)| changed[*v])
            .for_each(|(v, out)| {
                *out = vertex_point(control, tris, v as u32, smooth, &betas);
            });
        edge_points
            .par_chunks_mut(3)
            .enumerate()
            .filter(|(t, _)| control.triangles[*t].iter().any(|&v| changed[v as usize]))
            .for_each(|(t, out)| {
                for (k, e) in out.iter_mut().enumerate() {
                    *e = edge_point(control, tris, t as u32, k, smooth);
                }
            });
    }

    /// Point index of control triangle `t`'s edge point on side `k`.
    pub(super) fn edge(&self, t: u32, k: usize) -> u32 {
        (self.vertex_count + 3 * t as usize + k) as u32
    }

    /// Corner point indices of surface triangle `s`.
    pub(super) fn triangle(&self, control: &TriMesh, s: u32) -> [u32; 3] {
        let t = s >> 2;
        let tri = control.triangles[t as usize];
        let m = [0, 1, 2].map(|k| self.edge(t, k));
        crate::subdivision::children(tri, m)[(s & 3) as usize]
    }
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
    let mut across = tris
        .of(a)
        .iter()
        .filter(|&&u| u != t && control.triangles[u as usize].contains(&b));
    let d = match (smooth, across.next(), across.next()) {
        (true, Some(&u), None) => control.triangles[u as usize]
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
        let mut surface = LoopSurface::new(&control, &tris, true);
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
        let mut changed = vec![false; control.positions.len()];
        control.positions[3] += Vec3::splat(0.05);
        for t in &control.triangles {
            if t.contains(&3) {
                for &v in t {
                    changed[v as usize] = true;
                }
            }
        }
        surface.update(&control, &tris, &changed);
        check(&control, &surface);
    }
}
