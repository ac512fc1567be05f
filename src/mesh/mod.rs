//! The indexed triangle mesh shared by every stage, its normals, and topology validation.
//!
//! Invariants a [`TriMesh`] may carry (checked by [`validate`], not by construction):
//! triangles index existing vertices; a *closed 2-manifold* has every edge in exactly two
//! triangles and a single fan of triangles around every vertex; *consistent orientation*
//! means every edge is traversed once in each direction. Outward orientation is counter-
//! clockwise seen from outside (positive enclosed volume).

mod inside;
mod topology;

pub use topology::triangle_components;

pub use inside::InsideTest;
pub use topology::{validate, TopologyReport};

pub use crate::attributes::Attribute;
use glam::Vec3;
use rayon::prelude::*;

/// Fewest vertices per task of [`TriMesh::compute_normals`] (each task scans every
/// triangle).
const NORMALS_MIN_CHUNK: usize = 1 << 14;

/// Each vertex's triangles, in increasing order (a compressed list: offsets per vertex
/// into one array).
pub(crate) struct VertexTriangles {
    start: Vec<u32>,
    triangles: Vec<u32>,
}

impl VertexTriangles {
    /// The lists of `mesh`'s vertices.
    ///
    /// Counted and filled in parallel (atomic counters), then each list sorted, so the
    /// lists are the same whatever the thread count.
    pub(crate) fn new(mesh: &TriMesh) -> Self {
        use std::sync::atomic::{AtomicU32, Ordering::Relaxed};
        let nv = mesh.positions.len();
        let counts: Vec<AtomicU32> = (0..=nv).map(|_| AtomicU32::new(0)).collect();
        mesh.triangles.par_iter().for_each(|tri| {
            for &v in tri {
                counts[v as usize + 1].fetch_add(1, Relaxed);
            }
        });
        let mut start: Vec<u32> = counts.into_iter().map(AtomicU32::into_inner).collect();
        for i in 0..nv {
            start[i + 1] += start[i];
        }
        let fill: Vec<AtomicU32> = start[..nv].iter().map(|&s| AtomicU32::new(s)).collect();
        let slots: Vec<AtomicU32> = (0..start[nv]).map(|_| AtomicU32::new(0)).collect();
        mesh.triangles.par_iter().enumerate().for_each(|(t, tri)| {
            for &v in tri {
                let slot = fill[v as usize].fetch_add(1, Relaxed);
                slots[slot as usize].store(t as u32, Relaxed);
            }
        });
        drop(fill);
        let mut triangles: Vec<u32> = slots.into_iter().map(AtomicU32::into_inner).collect();
        // Sort each vertex's list, the vertices in chunks of about equal list lengths.
        const CHUNK: usize = 1 << 14;
        let mut lists = Vec::with_capacity(nv.div_ceil(CHUNK));
        let mut rest = &mut triangles[..];
        for first in (0..nv).step_by(CHUNK) {
            let last = (first + CHUNK).min(nv);
            let (chunk, tail) = rest.split_at_mut((start[last] - start[first]) as usize);
            lists.push((first..last, chunk));
            rest = tail;
        }
        lists.into_par_iter().for_each(|(vertices, chunk)| {
            let base = start[vertices.start];
            for v in vertices {
                chunk[(start[v] - base) as usize..(start[v + 1] - base) as usize].sort_unstable();
            }
        });
        VertexTriangles { start, triangles }
    }

    /// The triangles at vertex `v`.
    pub(crate) fn of(&self, v: u32) -> &[u32] {
        &self.triangles[self.start[v as usize] as usize..self.start[v as usize + 1] as usize]
    }
}

/// Bytes per triangle of a finished mesh with normals (12 for indices, half a vertex of
/// 24 for position and normal).
pub(crate) const MESH_BYTES_PER_TRIANGLE: f64 = 24.0;

/// An indexed triangle mesh. Positions are world units.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TriMesh {
    /// Vertex positions, world units.
    pub positions: Vec<Vec3>,
    /// Triangles as vertex indices, counter-clockwise seen from outside.
    pub triangles: Vec<[u32; 3]>,
    /// Unit vertex normals, one per vertex, or empty when not computed.
    pub normals: Vec<Vec3>,
    /// Per-vertex attributes carried from the particles ([`crate::attributes`]), one item
    /// per vertex each; empty when none were selected.
    pub attributes: Vec<Attribute>,
}

impl TriMesh {
    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    /// Number of vertices.
    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    /// Area-weighted unit vertex normals (each triangle adds its area times its unit normal
    /// to its three vertices), stored in [`TriMesh::normals`]. A vertex with no area around
    /// it gets +y.
    pub fn compute_normals(&mut self) {
        let chunk = self
            .positions
            .len()
            .div_ceil(rayon::current_num_threads())
            .max(NORMALS_MIN_CHUNK);
        self.compute_normals_in_chunks(chunk);
    }

    /// [`TriMesh::compute_normals`] with the vertices split into ranges of `chunk`, one task
    /// each. A task scans all triangles in order and adds those touching its range, so
    /// every vertex sums its triangles in triangle order whatever the split: the normals
    /// do not depend on `chunk` (nor on the thread count), bit for bit.
    fn compute_normals_in_chunks(&mut self, chunk: usize) {
        // Accumulated in place in f32 (cross products in f64): one array of the output's
        // size, not a second f64 one, since the fluid surface is the largest thing alive.
        let mut acc = vec![Vec3::ZERO; self.positions.len()];
        let (positions, triangles) = (&self.positions, &self.triangles);
        acc.par_chunks_mut(chunk.max(1))
            .enumerate()
            .for_each(|(k, out)| {
                let lo = (k * chunk) as u32;
                let hi = lo + out.len() as u32;
                for t in triangles {
                    if t.iter().all(|&i| i < lo || i >= hi) {
                        continue;
                    }
                    let [a, b, c] = t.map(|i| positions[i as usize].as_dvec3());
                    // The cross product is twice the area times the unit normal.
                    let n = (b - a).cross(c - a).as_vec3();
                    for &i in t {
                        if (lo..hi).contains(&i) {
                            out[(i - lo) as usize] += n;
                        }
                    }
                }
            });
        acc.par_iter_mut().for_each(|n| {
            let len = n.length();
            *n = if len > 0.0 && len.is_finite() {
                *n / len
            } else {
                Vec3::Y
            };
        });
        self.normals = acc;
    }

    /// Signed enclosed volume (world units cubed), positive for an outward-oriented closed
    /// mesh. Meaningful only for closed meshes.
    pub fn signed_volume(&self) -> f64 {
        self.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| self.positions[i as usize].as_dvec3());
                a.dot(b.cross(c)) / 6.0
            })
            .sum()
    }

    /// Total surface area (world units squared).
    pub fn area(&self) -> f64 {
        self.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| self.positions[i as usize].as_dvec3());
                0.5 * (b - a).cross(c - a).length()
            })
            .sum()
    }

    /// Removes the vertices no triangle uses, keeping the order of the others (and their
    /// normals, when the mesh has them).
    pub fn remove_unused_vertices(&mut self) {
        self.remove_unused_vertices_mapped();
    }

    /// [`TriMesh::remove_unused_vertices`], returning the new index of every old vertex
    /// (`u32::MAX` for a removed one).
    pub(crate) fn remove_unused_vertices_mapped(&mut self) -> Vec<u32> {
        let mut new_index = vec![u32::MAX; self.positions.len()];
        for t in &self.triangles {
            for &v in t {
                new_index[v as usize] = 0;
            }
        }
        let has_normals = self.normals.len() == self.positions.len();
        let mut kept = 0;
        for (v, index) in new_index.iter_mut().enumerate() {
            if *index != u32::MAX {
                *index = kept as u32;
                self.positions[kept] = self.positions[v];
                if has_normals {
                    self.normals[kept] = self.normals[v];
                }
                for a in &mut self.attributes {
                    let k = a.components;
                    a.values.copy_within(v * k..(v + 1) * k, kept * k);
                }
                kept += 1;
            }
        }
        self.positions.truncate(kept);
        if has_normals {
            self.normals.truncate(kept);
        }
        for a in &mut self.attributes {
            a.values.truncate(kept * a.components);
        }
        for t in &mut self.triangles {
            for v in t.iter_mut() {
                *v = new_index[*v as usize];
            }
        }
        new_index
    }

    /// `triangles` (of this mesh) as a mesh of their own, vertices numbered in order of
    /// first use, with the index here of each of its vertices. `scratch` has one entry
    /// per vertex of this mesh, all `u32::MAX`, and is left that way.
    pub(crate) fn submesh(
        &self,
        triangles: impl Iterator<Item = [u32; 3]>,
        scratch: &mut [u32],
    ) -> (TriMesh, Vec<u32>) {
        let mut piece = TriMesh::default();
        let mut index_here: Vec<u32> = Vec::new();
        piece.triangles = triangles
            .map(|t| {
                t.map(|v| {
                    if scratch[v as usize] == u32::MAX {
                        scratch[v as usize] = index_here.len() as u32;
                        index_here.push(v);
                        piece.positions.push(self.positions[v as usize]);
                    }
                    scratch[v as usize]
                })
            })
            .collect();
        for &g in &index_here {
            scratch[g as usize] = u32::MAX;
        }
        (piece, index_here)
    }

    /// Appends another mesh (its vertices and triangles, re-indexed). Normals are kept only
    /// when both meshes have them; attributes only when both have the same ones (names
    /// and components, in the same order), or when this mesh is empty.
    pub fn append(&mut self, other: &TriMesh) {
        let same_attributes = self.attributes.len() == other.attributes.len()
            && self
                .attributes
                .iter()
                .zip(&other.attributes)
                .all(|(a, b)| a.name == b.name && a.components == b.components);
        if self.positions.is_empty() {
            self.attributes = other.attributes.clone();
        } else if same_attributes {
            for (a, b) in self.attributes.iter_mut().zip(&other.attributes) {
                a.values.extend_from_slice(&b.values);
            }
        } else {
            self.attributes.clear();
        }
        let offset = self.positions.len() as u32;
        let keep_normals = self.normals.len() == self.positions.len()
            && other.normals.len() == other.positions.len();
        self.positions.extend_from_slice(&other.positions);
        self.triangles
            .extend(other.triangles.iter().map(|t| t.map(|i| i + offset)));
        if keep_normals {
            self.normals.extend_from_slice(&other.normals);
        } else {
            self.normals.clear();
        }
    }
}

/// Isolated particles rendered as instances of one icosphere.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SphereInstances {
    /// The sphere, centred at the origin, radius = particle radius (world units).
    pub template: TriMesh,
    /// One centre per isolated particle, world units.
    pub centers: Vec<Vec3>,
    /// One factor per centre by which the template is scaled about that centre (the
    /// particle's radius over the template's: `r_i / r`), finite and > 0; empty when every
    /// instance has the template's size (scale 1).
    pub scales: Vec<f32>,
    /// Per-instance attributes (one item per centre: the value of its particle); empty
    /// when none were selected.
    pub attributes: Vec<Attribute>,
}

impl SphereInstances {
    /// Checks [`SphereInstances::scales`]: empty, or one finite factor > 0 per centre.
    /// Writers call it before writing anything; the message says what is wrong.
    pub(crate) fn check_scales(&self) -> Result<(), String> {
        if self.scales.is_empty() {
            return Ok(());
        }
        if self.scales.len() != self.centers.len() {
            return Err(format!(
                "the sphere instances have {} scales for {} centres (one per centre, or none)",
                self.scales.len(),
                self.centers.len()
            ));
        }
        match self
            .scales
            .iter()
            .position(|s| !(s.is_finite() && *s > 0.0))
        {
            Some(k) => Err(format!(
                "sphere instance {k} has the scale {}; a scale must be a finite number > 0",
                self.scales[k]
            )),
            None => Ok(()),
        }
    }

    /// The scale of instance `k` (1 when the instances carry no scales).
    pub(crate) fn scale(&self, k: usize) -> f32 {
        debug_assert!(
            self.scales.is_empty() || self.scales.len() == self.centers.len(),
            "{} scales for {} centres",
            self.scales.len(),
            self.centers.len()
        );
        self.scales.get(k).copied().unwrap_or(1.0)
    }

    /// Template vertex `v` placed as instance `k`: scaled by the instance's scale (an
    /// exact no-op at scale 1) and moved to its centre.
    pub(crate) fn vertex(&self, k: usize, v: usize) -> Vec3 {
        self.template.positions[v] * self.scale(k) + self.centers[k]
    }

    /// The instances merged into one mesh (template scaled by each instance's scale and
    /// translated to its centre; normals as the template's; every vertex of a sphere
    /// takes its instance's attribute values).
    pub fn merged(&self) -> TriMesh {
        let mut out = TriMesh::default();
        for (i, c) in self.centers.iter().enumerate() {
            let mut s = self.template.clone();
            let scale = self.scale(i);
            for p in &mut s.positions {
                *p = *p * scale + *c;
            }
            s.attributes = self
                .attributes
                .iter()
                .map(|a| Attribute {
                    name: a.name.clone(),
                    components: a.components,
                    values: a.item(i).repeat(s.positions.len()),
                })
                .collect();
            out.append(&s);
        }
        out
    }
}

/// The result of a reconstruction: the fluid surface plus the isolated-particle spheres.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Surface {
    /// The fluid surface extracted from the field (after any post-processing).
    pub fluid: TriMesh,
    /// Icospheres standing for isolated particles (empty when disabled or none).
    pub spheres: SphereInstances,
}

impl Surface {
    /// Fluid surface and spheres merged into one mesh (for formats without instancing).
    pub fn merged(&self) -> TriMesh {
        let mut out = self.fluid.clone();
        if !self.spheres.centers.is_empty() {
            out.append(&self.spheres.merged());
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vertex_triangle_lists_hold_each_vertex_triangles_in_order_on_any_pool() {
        // Vertices renumbered so that lists cross the chunks, and one vertex on no triangle.
        let mesh = crate::isolated::icosphere(6, 1.0);
        let n = mesh.positions.len() as u32 + 1;
        let perm = |v: u32| (v * 7 + 5) % n;
        assert_ne!(n % 7, 0);
        let mesh = TriMesh {
            positions: vec![Vec3::ZERO; n as usize],
            triangles: mesh.triangles.iter().map(|t| t.map(perm)).collect(),
            ..TriMesh::default()
        };
        let mut expected = vec![Vec::new(); n as usize];
        for (t, tri) in mesh.triangles.iter().enumerate() {
            for &v in tri {
                expected[v as usize].push(t as u32);
            }
        }
        assert!(
            expected.iter().any(Vec::is_empty),
            "a vertex on no triangle"
        );
        for threads in [1, 3] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let lists = pool.install(|| VertexTriangles::new(&mesh));
            for (v, want) in expected.iter().enumerate() {
                assert_eq!(
                    lists.of(v as u32),
                    &want[..],
                    "vertex {v}, {threads} threads"
                );
            }
        }
    }

    #[test]
    fn normals_do_not_depend_on_the_split_of_the_vertices() {
        let mut mesh = crate::isolated::icosphere(4, 1.0);
        for (i, p) in mesh.positions.iter_mut().enumerate() {
            *p *= 1.0 + 0.01 * ((i * 7919 % 97) as f32 / 97.0);
        }
        // Shuffle the vertex numbers so that triangles straddle the ranges (a bijection:
        // 2562 vertices, coprime to 11).
        let n = mesh.positions.len() as u32;
        assert_ne!(n % 11, 0);
        let perm = |v: u32| (v * 11 + 3) % n;
        let mut shuffled = TriMesh {
            positions: vec![Vec3::ZERO; n as usize],
            triangles: mesh.triangles.iter().map(|t| t.map(perm)).collect(),
            normals: Vec::new(),
            attributes: Vec::new(),
        };
        for v in 0..n {
            shuffled.positions[perm(v) as usize] = mesh.positions[v as usize];
        }
        shuffled.compute_normals_in_chunks(usize::MAX);
        let whole = shuffled.normals.clone();
        for chunk in [1, 7, 100, 1000] {
            shuffled.compute_normals_in_chunks(chunk);
            let same = whole
                .iter()
                .zip(&shuffled.normals)
                .all(|(a, b)| a.to_array().map(f32::to_bits) == b.to_array().map(f32::to_bits));
            assert!(same, "chunk {chunk}");
        }
        // Outward on the sphere.
        for (p, nrm) in shuffled.positions.iter().zip(&whole) {
            assert!(p.normalize().dot(*nrm) > 0.9);
        }
    }
}
