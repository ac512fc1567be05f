//! A surface as a list of parts (the fluid mesh, the instanced isolated spheres) that
//! share one vertex numbering, for the writers of formats without instancing (PLY, OBJ,
//! legacy VTK): nothing is merged or copied first. Binary data goes out in chunks of
//! [`CHUNK_BYTES`] ([`write_chunked`], also used by the glTF writer), so writing adds no
//! more than that to the memory peak.
//!
//! Attributes ([`Shared`]) are written when every non-empty part has them (same name and
//! components): PLY as float vertex properties, VTK as point-data arrays beside the
//! normals; OBJ has no place for them.

use crate::attributes::Attribute;
use crate::mesh::{SphereInstances, TriMesh};
use glam::Vec3;
use std::io::{Result, Write};

/// A piece of the written surface.
#[derive(Clone, Copy)]
pub(super) enum Part<'a> {
    /// A mesh as it is.
    Mesh(&'a TriMesh),
    /// Every instance of a sphere, as if merged (instance after instance, each scaled by
    /// its scale).
    Spheres(&'a SphereInstances),
}

impl Part<'_> {
    pub(super) fn vertex_count(&self) -> usize {
        match self {
            Part::Mesh(m) => m.vertex_count(),
            Part::Spheres(s) => s.template.vertex_count() * s.centers.len(),
        }
    }
    pub(super) fn triangle_count(&self) -> usize {
        match self {
            Part::Mesh(m) => m.triangle_count(),
            Part::Spheres(s) => s.template.triangle_count() * s.centers.len(),
        }
    }
    /// True when every vertex has a normal.
    pub(super) fn has_normals(&self) -> bool {
        let m = match self {
            Part::Mesh(m) => m,
            Part::Spheres(s) => &s.template,
        };
        m.normals.len() == m.positions.len()
    }
    pub(super) fn position(&self, i: usize) -> Vec3 {
        match self {
            Part::Mesh(m) => m.positions[i],
            Part::Spheres(s) => {
                let n = s.template.vertex_count();
                s.vertex(i / n, i % n)
            }
        }
    }
    pub(super) fn normal(&self, i: usize) -> Vec3 {
        match self {
            Part::Mesh(m) => m.normals[i],
            Part::Spheres(s) => s.template.normals[i % s.template.vertex_count()],
        }
    }
    /// The part's attributes (per vertex for a mesh, per instance for spheres).
    fn attributes(&self) -> &[Attribute] {
        match self {
            Part::Mesh(m) => &m.attributes,
            Part::Spheres(s) => &s.attributes,
        }
    }
    /// The values of attribute `k` at vertex `i`.
    fn attribute_item(&self, k: usize, i: usize) -> &[f32] {
        match self {
            Part::Mesh(m) => m.attributes[k].item(i),
            Part::Spheres(s) => s.attributes[k].item(i / s.template.vertex_count()),
        }
    }
    pub(super) fn triangle(&self, j: usize) -> [u32; 3] {
        match self {
            Part::Mesh(m) => m.triangles[j],
            Part::Spheres(s) => {
                let n = s.template.triangle_count();
                let base = (j / n * s.template.vertex_count()) as u32;
                s.template.triangles[j % n].map(|v| v + base)
            }
        }
    }
}

/// The attributes written for a list of parts: those every part with vertices has (same
/// name and components), in the order of the first such part.
pub(super) struct Shared<'a> {
    /// Name and components of each written attribute.
    pub list: Vec<&'a Attribute>,
    /// For each part, the index in its own attributes of each written attribute.
    index: Vec<Vec<usize>>,
}

impl<'a> Shared<'a> {
    /// Chooses the attributes of `parts`; `dropped` receives the names of the others.
    pub(super) fn new(parts: &[Part<'a>], dropped: &mut Vec<String>) -> Self {
        let filled: Vec<&Part<'a>> = parts.iter().filter(|p| p.vertex_count() > 0).collect();
        let find = |p: &Part<'a>, a: &Attribute| {
            p.attributes()
                .iter()
                .position(|b| b.name == a.name && b.components == a.components)
        };
        let mut list = Vec::new();
        if let Some(first) = filled.first() {
            let first: &[Attribute] = match **first {
                Part::Mesh(m) => &m.attributes,
                Part::Spheres(s) => &s.attributes,
            };
            for a in first {
                if filled.iter().all(|p| find(p, a).is_some()) {
                    list.push(a);
                }
            }
        }
        for p in parts {
            for a in p.attributes() {
                let kept = list
                    .iter()
                    .any(|b| b.name == a.name && b.components == a.components);
                if !kept && !dropped.contains(&a.name) {
                    dropped.push(a.name.clone());
                }
            }
        }
        let index = parts
            .iter()
            .map(|p| {
                list.iter()
                    .map(|a| find(p, a).unwrap_or(usize::MAX))
                    .collect()
            })
            .collect();
        Shared { list, index }
    }

    /// Appends the little-endian or big-endian bytes of every written attribute at vertex
    /// `i` of part `p` (all attributes, item-major), or only attribute `only`.
    pub(super) fn encode(
        &self,
        parts: &[Part],
        p: usize,
        i: usize,
        only: Option<usize>,
        big: bool,
        buf: &mut Vec<u8>,
    ) {
        for (k, &own) in self.index[p].iter().enumerate() {
            if only.is_some_and(|o| o != k) {
                continue;
            }
            for v in parts[p].attribute_item(own, i) {
                buf.extend_from_slice(&if big {
                    v.to_be_bytes()
                } else {
                    v.to_le_bytes()
                });
            }
        }
    }
}

/// Bytes encoded before each write.
pub(super) const CHUNK_BYTES: usize = 1 << 20;

/// Vertices and triangles of all parts.
pub(super) fn counts(parts: &[Part]) -> (usize, usize) {
    parts.iter().fold((0, 0), |(v, t), m| {
        (v + m.vertex_count(), t + m.triangle_count())
    })
}

/// Encodes `items` with `encode` into chunks and writes them.
pub(super) fn write_chunked<T>(
    w: &mut impl Write,
    items: impl Iterator<Item = T>,
    mut encode: impl FnMut(&mut Vec<u8>, T),
) -> Result<()> {
    let mut buf = Vec::with_capacity(CHUNK_BYTES + 64);
    for item in items {
        encode(&mut buf, item);
        if buf.len() >= CHUNK_BYTES {
            w.write_all(&buf)?;
            buf.clear();
        }
    }
    w.write_all(&buf)
}

/// Items encoded per task of [`write_chunked_par`].
const PAR_CHUNK_ITEMS: usize = 1 << 15;

/// [`write_chunked`] over the items `0..n`, encoded on every thread a window of a few
/// chunks per thread at a time and written in order: the same bytes, and no more than
/// the window (a few MiB) added to the memory peak.
pub(super) fn write_chunked_par(
    w: &mut impl Write,
    n: usize,
    encode: impl Fn(&mut Vec<u8>, usize) + Sync,
) -> Result<()> {
    use rayon::prelude::*;
    let window = PAR_CHUNK_ITEMS * 4 * rayon::current_num_threads();
    for first in (0..n).step_by(window) {
        let last = (first + window).min(n);
        let chunks: Vec<Vec<u8>> = (first..last)
            .step_by(PAR_CHUNK_ITEMS)
            .collect::<Vec<_>>()
            .into_par_iter()
            .map(|start| {
                let mut buf = Vec::new();
                for i in start..(start + PAR_CHUNK_ITEMS).min(last) {
                    encode(&mut buf, i);
                }
                buf
            })
            .collect();
        for chunk in &chunks {
            w.write_all(chunk)?;
        }
    }
    Ok(())
}

/// The triangles of all parts, with vertex indices offset to the shared numbering.
pub(super) fn all_triangles<'a>(parts: &'a [Part<'a>]) -> impl Iterator<Item = [u32; 3]> + 'a {
    let mut base = 0u32;
    parts.iter().flat_map(move |m| {
        let b = base;
        base += m.vertex_count() as u32;
        (0..m.triangle_count()).map(move |j| m.triangle(j).map(|i| i + b))
    })
}

/// The positions of all parts, in the shared numbering.
pub(super) fn all_positions<'a>(parts: &'a [Part<'a>]) -> impl Iterator<Item = Vec3> + 'a {
    parts
        .iter()
        .flat_map(|m| (0..m.vertex_count()).map(move |i| m.position(i)))
}

/// The normals of all parts, in the shared numbering.
pub(super) fn all_normals<'a>(parts: &'a [Part<'a>]) -> impl Iterator<Item = Vec3> + 'a {
    parts
        .iter()
        .flat_map(|m| (0..m.vertex_count()).map(move |i| m.normal(i)))
}
