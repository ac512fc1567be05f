//! The decimation state: positions and quadrics in the unit-box frame, triangles and
//! their reference normals, vertex → triangle lists, flags, and the candidates of a pass
//! (with the reuse of what the previous pass learnt, see the module docs of [`super`]).

use super::candidate::Candidate;
use super::placement::place_candidates_at;
use super::quadric::{Plane, Quadric};
use super::tri_list::TriList;
use super::{bounds, DecimateStats, Frame, Reuse, CHUNK_TRIANGLES};
use crate::mesh::TriMesh;
use glam::{DVec3, Vec3};
use rayon::prelude::*;

/// The decimation state, in unit-box coordinates.
pub(super) struct State {
    pub(super) pos: Vec<DVec3>,
    pub(super) quadric: Vec<Quadric>,
    pub(super) tris: Vec<[u32; 3]>,
    /// Unit normal of every triangle in the input (zero for a degenerate one): a
    /// triangle may never turn far from it, however many collapses touch it.
    pub(super) reference_normal: Vec<Vec3>,
    pub(super) tri_alive: Vec<bool>,
    pub(super) vert_tris: Vec<TriList>,
    pub(super) locked: Vec<bool>,
    pub(super) alive: Vec<bool>,
    /// Pass in which the vertex last moved (each vertex moves at most once per pass).
    pub(super) touched: Vec<u32>,
    /// Clock of the last collapse that changed the vertex's closed one-ring (0: none).
    pub(super) stamp: Vec<u32>,
    /// The clock: the stamp of the last collapse, and what a refusal is marked with.
    /// Starts at 1 ([`Mark::NONE`] is 0).
    pub(super) clock: u32,
    pub(super) reuse: Reuse,
    /// Chunk owning the vertex during the parallel walk of a pass.
    pub(super) owner: Vec<u32>,
}

impl State {
    /// The state of `mesh` (whose positions, triangles and normals it takes), in its
    /// unit-box frame, with the `extra_locked` vertices locked too; counts the vertices
    /// locked by boundaries and non-manifold edges in `stats.refused_boundary`.
    pub(super) fn from_mesh(
        mesh: &mut TriMesh,
        extra_locked: &[bool],
        stats: &mut DecimateStats,
    ) -> (State, Frame) {
        let (lo, hi) = bounds(&mesh.positions);
        let frame = Frame {
            centre: (lo + hi) * 0.5,
            scale: ((hi - lo).max_element() * 0.5).max(f64::MIN_POSITIVE),
        };
        mesh.normals = Vec::new();
        let mut s = State::new(
            std::mem::take(&mut mesh.positions),
            std::mem::take(&mut mesh.triangles),
            frame.centre,
            frame.scale,
        );
        stats.refused_boundary = s
            .locked
            .iter()
            .enumerate()
            .filter(|&(v, &l)| l && !extra_locked.get(v).is_some_and(|&e| e))
            .count();
        for (locked, &extra) in s.locked.iter_mut().zip(extra_locked) {
            *locked |= extra;
        }
        (s, frame)
    }

    /// The candidates of pass `pass`: every live interior edge once (as the directed side
    /// u → v, u < v), in mesh order, per chunk. An edge of the same triangle among the
    /// `previous` pass's candidates keeps its cost and placement when neither end moved in
    /// that pass (they are a function of the two ends' positions and quadrics alone); the
    /// others are costed, in parallel. The tail of a decimation costs few edges anew: its
    /// passes make few collapses.
    pub(super) fn candidates(
        &self,
        mut previous: Vec<Vec<Candidate>>,
        pass: u32,
    ) -> Vec<Vec<Candidate>> {
        let moved_last_pass = |w: u32| self.touched[w as usize] + 1 == pass;
        // Each chunk's old list is dropped as its new one is made: no more memory than one
        // list.
        previous.resize_with(self.tris.len().div_ceil(CHUNK_TRIANGLES), Vec::new);
        self.tris
            .par_chunks(CHUNK_TRIANGLES)
            .zip(self.tri_alive.par_chunks(CHUNK_TRIANGLES))
            .zip(previous)
            .enumerate()
            .map(|(chunk, ((tris, alive), old))| {
                let first = (chunk * CHUNK_TRIANGLES) as u32;
                let mut out = Vec::with_capacity(tris.len() * 3 / 2);
                // Where the candidates to cost are in `out`.
                let mut fresh = Vec::with_capacity(out.capacity());
                let mut o = 0;
                for (i, (tri, _)) in tris.iter().zip(alive).enumerate().filter(|(_, (_, a))| **a) {
                    let t = first + i as u32;
                    while o < old.len() && old[o].triangle < t {
                        o += 1;
                    }
                    for k in 0..3 {
                        let (u, v) = (tri[k], tri[(k + 1) % 3]);
                        if u >= v || self.locked[u as usize] || self.locked[v as usize] {
                            continue;
                        }
                        let unmoved = !moved_last_pass(u) && !moved_last_pass(v);
                        let kept = if self.reuse == Reuse::Yes && unmoved {
                            old[o..]
                                .iter()
                                .take_while(|c| c.triangle == t)
                                .find(|c| c.u == u && c.v == v)
                        } else {
                            None
                        };
                        match kept {
                            Some(c) => out.push(c.carried()),
                            None => {
                                fresh.push(out.len() as u32);
                                out.push(Candidate::edge(t, u, v));
                            }
                        }
                    }
                }
                drop(old);
                place_candidates_at(&self.pos, &self.quadric, &mut out, &fresh);
                out
            })
            .collect()
    }

    /// Writes the surviving triangles back to `mesh` in order, their vertices in order of
    /// first use and in world units; returns the new index of every vertex (`u32::MAX`
    /// when it was removed).
    pub(super) fn compact_into(self, mesh: &mut TriMesh, frame: Frame) -> Vec<u32> {
        let mut remap = vec![u32::MAX; self.pos.len()];
        let mut positions = Vec::new();
        let mut triangles = Vec::with_capacity(self.tri_alive.iter().filter(|a| **a).count());
        for (tri, _) in self.tris.iter().zip(&self.tri_alive).filter(|(_, a)| **a) {
            triangles.push(tri.map(|v| {
                if remap[v as usize] == u32::MAX {
                    remap[v as usize] = positions.len() as u32;
                    positions.push((self.pos[v as usize] * frame.scale + frame.centre).as_vec3());
                }
                remap[v as usize]
            }));
        }
        *mesh = TriMesh {
            positions,
            triangles,
            normals: Vec::new(),
            attributes: Vec::new(),
        };
        remap
    }

    /// Builds the state in parallel; `positions` are world units, rescaled by
    /// `(p - centre) / scale`.
    fn new(positions: Vec<Vec3>, tris: Vec<[u32; 3]>, centre: DVec3, scale: f64) -> State {
        let nv = positions.len();
        let pos: Vec<DVec3> = positions
            .par_iter()
            .map(|p| (p.as_dvec3() - centre) / scale)
            .collect();
        drop(positions);
        // Per triangle: its unit normal and its weighted plane, computed once.
        let (reference_normal, tri_plane): (Vec<Vec3>, Vec<Plane>) = tris
            .par_iter()
            .map(|t| {
                let [a, b, c] = t.map(|v| pos[v as usize]);
                (
                    (b - a).cross(c - a).normalize_or_zero().as_vec3(),
                    Plane::from_triangle(a, b, c),
                )
            })
            .unzip();
        // Vertex → triangles, through a counting sort (triangles in increasing order).
        let mut start = vec![0u32; nv + 1];
        for tri in &tris {
            for &v in tri {
                start[v as usize + 1] += 1;
            }
        }
        for i in 0..nv {
            start[i + 1] += start[i];
        }
        let mut flat = vec![0u32; start[nv] as usize];
        let mut fill = start.clone();
        for (t, tri) in tris.iter().enumerate() {
            for &v in tri {
                flat[fill[v as usize] as usize] = t as u32;
                fill[v as usize] += 1;
            }
        }
        drop(fill);
        let vert_tris: Vec<TriList> = (0..nv)
            .into_par_iter()
            .map(|v| TriList::from_slice(&flat[start[v] as usize..start[v + 1] as usize]))
            .collect();
        drop(flat);
        drop(start);
        // Quadrics, summed per vertex over its triangles in increasing order
        // (deterministic); edges with one or more than two triangles lock their endpoints:
        // around a vertex every neighbour appears on exactly two of its triangles when all
        // its edges are shared by two triangles.
        let (quadric, locked): (Vec<Quadric>, Vec<bool>) = (0..nv)
            .into_par_iter()
            .map_init(Vec::new, |scratch: &mut Vec<u32>, v| {
                let mut q = Quadric::default();
                scratch.clear();
                for &t in &vert_tris[v] {
                    q += Quadric::from_plane(&tri_plane[t as usize]);
                    let tri = tris[t as usize];
                    scratch.extend(tri.iter().copied().filter(|&w| w as usize != v));
                }
                scratch.sort_unstable();
                let locked = scratch.chunk_by(|a, b| a == b).any(|run| run.len() != 2);
                (q, locked)
            })
            .unzip();
        State {
            pos,
            quadric,
            tri_alive: vec![true; tris.len()],
            tris,
            reference_normal,
            vert_tris,
            locked,
            alive: vec![true; nv],
            touched: vec![0; nv],
            stamp: vec![0; nv],
            clock: 1,
            reuse: Reuse::Yes,
            owner: vec![u32::MAX; nv],
        }
    }

    /// Every live vertex goes to the chunk of its lowest-numbered live triangle.
    pub(super) fn assign_owners(&mut self) {
        let vert_tris = &self.vert_tris;
        self.owner.par_iter_mut().enumerate().for_each(|(v, o)| {
            *o = vert_tris[v]
                .iter()
                .min()
                .map_or(u32::MAX, |&t| (t as usize / CHUNK_TRIANGLES) as u32);
        });
    }
}
