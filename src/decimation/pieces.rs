//! Decimation piece by piece, so that the state follows the piece, not the mesh: regions
//! of a large mesh ([`decimate_by_regions`]) and the band around the seams of tiles that
//! were decimated on their own ([`decimate_band`], called by [`crate::tiles`]).
//!
//! A piece is taken out of the mesh ([`TriMesh::submesh`]), decimated by
//! [`super::decimate_locked`] with the vertices it shares with the rest of the mesh
//! locked, and put back ([`place_survivors`]): a locked survivor keeps its identity, the
//! piece's other survivors are new vertices.

use super::{bounds, decimate_locked, decimate_locked_walk, DecimateOptions, DecimateStats, Walk};
use crate::mesh::TriMesh;
use glam::{DVec3, Vec3};
use rayon::prelude::*;
use std::sync::atomic::{AtomicU32, Ordering};

/// Rings of triangles around the flagged vertices that [`decimate_band`] works on.
pub(crate) const BAND_RINGS: usize = 2;

/// A piece of a mesh, numbered on its own.
struct Piece {
    mesh: TriMesh,
    /// Mesh vertex of every piece vertex.
    global_of: Vec<u32>,
}

/// The output index of every vertex of a decimated piece (`remap` from
/// [`super::decimate_locked`]): first each surviving vertex `old` for which
/// `locked_index(old, positions)` gives an index (it may push to `positions`), in input
/// order; then the piece's other vertices, appended to `positions`.
pub(crate) fn place_survivors(
    piece: &TriMesh,
    remap: &[u32],
    mut locked_index: impl FnMut(usize, &mut Vec<Vec3>) -> Option<u32>,
    positions: &mut Vec<Vec3>,
) -> Vec<u32> {
    let mut output_of = vec![u32::MAX; piece.vertex_count()];
    for (old, &new) in remap.iter().enumerate() {
        if new != u32::MAX {
            if let Some(index) = locked_index(old, positions) {
                output_of[new as usize] = index;
            }
        }
    }
    for (new, p) in piece.positions.iter().enumerate() {
        if output_of[new] == u32::MAX {
            output_of[new] = positions.len() as u32;
            positions.push(*p);
        }
    }
    output_of
}

/// Whether a piecewise decimation reports where every input vertex went.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(crate) enum Remap {
    /// The new index of every input vertex (`u32::MAX` when it was removed).
    Keep,
    /// Nothing (an empty list): the caller needs no vertex identities.
    Drop,
}

/// Decimates region by region, seams and the `locked` vertices (indexed like the mesh's;
/// may be empty) locked, then the band around the seams until the whole mesh has
/// `target` triangles; the `locked` vertices never move and survive at their exact input
/// positions. Returns the stats and, with [`Remap::Keep`], the new index of every input
/// vertex (`u32::MAX` when it was removed; else an empty list). At most `in_flight`
/// regions are decimated at once (`usize::MAX`: all).
pub(super) fn decimate_by_regions(
    mesh: &mut TriMesh,
    options: &DecimateOptions,
    target: usize,
    locked: &[bool],
    remap: Remap,
    in_flight: usize,
) -> (DecimateStats, Vec<u32>) {
    let split = Regions::split(mesh, (options.region_triangles / 2).max(1));
    let mut stats = DecimateStats {
        triangles_before: mesh.triangle_count(),
        regions: split.count,
        ..Default::default()
    };
    // A region's vertices are numbered in order of first use by its triangles (what
    // [`TriMesh::submesh`] does), inside its own task: a vertex belongs to one region
    // only, so the tasks write disjoint entries of `local_of`.
    let local_of: Vec<AtomicU32> = (0..mesh.vertex_count())
        .map(|_| AtomicU32::new(u32::MAX))
        .collect();
    // Regions are decimated in parallel, one per task (each costs its candidates in
    // parallel too, but walks its collapses sequentially: `Walk::Sequential`), at most
    // `in_flight` at once (their state is the memory that grows with the thread count),
    // and placed in region order, so the output does not depend on the thread count.
    let in_flight = in_flight.max(1);
    let decimated: Vec<(Piece, DecimateStats, Vec<u32>)> = (0..split.count)
        .step_by(in_flight)
        .flat_map(|first| {
            (first..first.saturating_add(in_flight).min(split.count))
                .into_par_iter()
                .map(|r| split.triangles_of(r))
                .filter(|tris| !tris.is_empty())
                .map(|tris| decimate_region(mesh, tris, &local_of, &split.on_seam, locked, options))
                .collect::<Vec<_>>()
        })
        .collect();
    drop(local_of);
    let assembled = split.assemble(mesh, decimated, locked, remap, &mut stats);
    let (last, band_remap) = decimate_band(
        mesh,
        &assembled.at_seam,
        &assembled.locked,
        target,
        options.max_error,
        remap,
    );
    stats.add_work(&last);
    stats.triangles_after = last.triangles_after;
    let mut first = assembled.remap;
    for new in &mut first {
        if *new != u32::MAX {
            *new = band_remap[*new as usize];
        }
    }
    (stats, first)
}

/// What [`Regions::assemble`] gives: the flags of the joined mesh's vertices and where
/// the input vertices went.
struct Assembled {
    /// The vertices on a seam between regions.
    at_seam: Vec<bool>,
    /// The vertices locked by the caller (empty when none were).
    locked: Vec<bool>,
    /// The joined mesh's index of every input vertex (`u32::MAX`: removed); empty with
    /// [`Remap::Drop`].
    remap: Vec<u32>,
}

/// A mesh cut into regions: runs of vertices in Morton order of position (compact pieces
/// of surface). Triangles with all three vertices in one region are that region's; the
/// others are seam triangles, and their vertices stay locked until the seam band is
/// decimated.
struct Regions {
    count: usize,
    /// Every region's triangles (indices, 4 bytes each), grouped by region in mesh order:
    /// region `r` holds `grouped[start[r]..start[r + 1]]`.
    grouped: Vec<u32>,
    start: Vec<usize>,
    /// The seam triangles, in mesh order.
    seam_tris: Vec<u32>,
    /// Whether each mesh vertex is a corner of a seam triangle.
    on_seam: Vec<bool>,
}

impl Regions {
    /// Cuts `mesh` into regions of `region_vertices` vertices (a closed surface has about
    /// two triangles per vertex).
    fn split(mesh: &TriMesh, region_vertices: usize) -> Regions {
        let nv = mesh.vertex_count();
        let region_of = morton_regions(&mesh.positions, region_vertices);
        let count = nv.div_ceil(region_vertices);
        const SEAM: u32 = u32::MAX;
        let triangle_region: Vec<u32> = mesh
            .triangles
            .par_iter()
            .map(|tri| {
                let r = region_of[tri[0] as usize];
                if tri.iter().all(|&v| region_of[v as usize] == r) {
                    r
                } else {
                    SEAM
                }
            })
            .collect();
        drop(region_of);
        let mut start = vec![0usize; count + 1];
        let mut seam_tris = Vec::new();
        let mut on_seam = vec![false; nv];
        for (t, &r) in triangle_region.iter().enumerate() {
            if r == SEAM {
                seam_tris.push(t as u32);
                for &v in &mesh.triangles[t] {
                    on_seam[v as usize] = true;
                }
            } else {
                start[r as usize + 1] += 1;
            }
        }
        for r in 0..count {
            start[r + 1] += start[r];
        }
        let mut grouped = vec![0u32; start[count]];
        let mut fill = start.clone();
        for (t, &r) in triangle_region.iter().enumerate() {
            if r != SEAM {
                grouped[fill[r as usize]] = t as u32;
                fill[r as usize] += 1;
            }
        }
        Regions {
            count,
            grouped,
            start,
            seam_tris,
            on_seam,
        }
    }

    /// Region `r`'s triangles.
    fn triangles_of(&self, r: usize) -> &[u32] {
        &self.grouped[self.start[r]..self.start[r + 1]]
    }

    /// Replaces `mesh` by the decimated regions, in region order, then the seam triangles
    /// (the vertices on a seam or `locked` at their exact input positions).
    fn assemble(
        self,
        mesh: &mut TriMesh,
        decimated: Vec<(Piece, DecimateStats, Vec<u32>)>,
        locked: &[bool],
        remap: Remap,
        stats: &mut DecimateStats,
    ) -> Assembled {
        let Regions {
            grouped,
            start,
            seam_tris,
            on_seam,
            ..
        } = self;
        // The region lists are done with: freed before the output grows.
        drop((grouped, start));
        let is_locked = |g: usize| locked.get(g).is_some_and(|&l| l);
        let mut first = match remap {
            Remap::Keep => vec![u32::MAX; mesh.vertex_count()],
            Remap::Drop => Vec::new(),
        };
        let mut positions: Vec<Vec3> = Vec::new();
        let mut triangles: Vec<[u32; 3]> = Vec::new();
        // Output index of each seam or locked vertex, once placed.
        let mut fixed_index = vec![u32::MAX; mesh.vertex_count()];
        let mut place_fixed = |g: usize, positions: &mut Vec<Vec3>| -> u32 {
            if fixed_index[g] == u32::MAX {
                fixed_index[g] = positions.len() as u32;
                positions.push(mesh.positions[g]);
            }
            fixed_index[g]
        };
        for (piece, region_stats, region_remap) in decimated {
            stats.add_work(&region_stats);
            let output_of = place_survivors(
                &piece.mesh,
                &region_remap,
                |old, positions| {
                    let g = piece.global_of[old] as usize;
                    (on_seam[g] || is_locked(g)).then(|| place_fixed(g, positions))
                },
                &mut positions,
            );
            if remap == Remap::Keep {
                for (old, &new) in region_remap.iter().enumerate() {
                    if new != u32::MAX {
                        first[piece.global_of[old] as usize] = output_of[new as usize];
                    }
                }
            }
            triangles.extend(
                piece
                    .mesh
                    .triangles
                    .iter()
                    .map(|t| t.map(|v| output_of[v as usize])),
            );
        }
        for &t in &seam_tris {
            let tri = mesh.triangles[t as usize].map(|v| place_fixed(v as usize, &mut positions));
            triangles.push(tri);
        }
        *mesh = TriMesh {
            positions,
            triangles,
            normals: Vec::new(),
            attributes: Vec::new(),
        };
        let mut at_seam = vec![false; mesh.vertex_count()];
        let mut locked_here = if locked.is_empty() {
            Vec::new()
        } else {
            vec![false; mesh.vertex_count()]
        };
        for (g, &i) in fixed_index
            .iter()
            .enumerate()
            .filter(|(_, &i)| i != u32::MAX)
        {
            at_seam[i as usize] |= on_seam[g];
            if is_locked(g) {
                locked_here[i as usize] = true;
            }
            if remap == Remap::Keep {
                first[g] = i;
            }
        }
        Assembled {
            at_seam,
            locked: locked_here,
            remap: first,
        }
    }
}

/// Takes one region's triangles `tris` out of `mesh` (numbering its vertices in
/// `local_of`, which no other region shares) and decimates it to the options' fraction,
/// its seam vertices and the `extra_locked` ones (indexed like the mesh's) locked.
fn decimate_region(
    mesh: &TriMesh,
    tris: &[u32],
    local_of: &[AtomicU32],
    on_seam: &[bool],
    extra_locked: &[bool],
    options: &DecimateOptions,
) -> (Piece, DecimateStats, Vec<u32>) {
    let mut global_of: Vec<u32> = Vec::new();
    let triangles = tris
        .iter()
        .map(|&t| {
            mesh.triangles[t as usize].map(|v| {
                let slot = &local_of[v as usize];
                match slot.load(Ordering::Relaxed) {
                    u32::MAX => {
                        let local = global_of.len() as u32;
                        slot.store(local, Ordering::Relaxed);
                        global_of.push(v);
                        local
                    }
                    local => local,
                }
            })
        })
        .collect();
    let mut piece = Piece {
        mesh: TriMesh {
            positions: global_of
                .iter()
                .map(|&g| mesh.positions[g as usize])
                .collect(),
            triangles,
            normals: Vec::new(),
            attributes: Vec::new(),
        },
        global_of,
    };
    let locked: Vec<bool> = piece
        .global_of
        .iter()
        .map(|&g| on_seam[g as usize] || extra_locked.get(g as usize).is_some_and(|&l| l))
        .collect();
    let region_target = options.target_triangles(piece.mesh.triangle_count());
    let (stats, remap) = decimate_locked_walk(
        &mut piece.mesh,
        region_target,
        options.max_error,
        &locked,
        Walk::Sequential,
    );
    (piece, stats, remap)
}

/// Interleaves the bits of three 10-bit coordinates.
fn morton3(x: u32, y: u32, z: u32) -> u32 {
    fn spread(mut v: u32) -> u32 {
        v &= 0x3ff;
        v = (v | (v << 16)) & 0x0300_00ff;
        v = (v | (v << 8)) & 0x0300_f00f;
        v = (v | (v << 4)) & 0x030c_30c3;
        (v | (v << 2)) & 0x0924_9249
    }
    spread(x) | (spread(y) << 1) | (spread(z) << 2)
}

/// The Morton code of `p` on a 1024³ lattice over the cube of edge `extent` at `lo`.
fn morton_code(p: Vec3, lo: DVec3, extent: f64) -> u32 {
    let q = ((p.as_dvec3() - lo) / extent * 1023.0).clamp(DVec3::ZERO, DVec3::splat(1023.0));
    morton3(q.x as u32, q.y as u32, q.z as u32)
}

/// The region of every vertex: its rank in (Morton code of position, index) order,
/// divided by `region_vertices`.
fn morton_regions(positions: &[Vec3], region_vertices: usize) -> Vec<u32> {
    let (lo, hi) = bounds(positions);
    let extent = (hi - lo).max_element().max(f64::MIN_POSITIVE);
    // A vertex's rank in (Morton code, index) order, divided by the region size, is its
    // region. Only the ranks at region boundaries need a sort: codes are counted by their
    // top bits, each bucket's vertices take consecutive ranks, and a bucket that no
    // region boundary splits sends all of its vertices to one region.
    let codes: Vec<u32> = positions
        .par_iter()
        .map(|p| morton_code(*p, lo, extent))
        .collect();
    const BUCKET_SHIFT: u32 = 30 - 16;
    let mut bucket_start = vec![0usize; (1 << 16) + 1];
    for &code in &codes {
        bucket_start[(code >> BUCKET_SHIFT) as usize + 1] += 1;
    }
    for b in 0..1 << 16 {
        bucket_start[b + 1] += bucket_start[b];
    }
    let bucket_region = |b: usize| {
        let (first, end) = (bucket_start[b], bucket_start[b + 1]);
        (end > first && first / region_vertices == (end - 1) / region_vertices)
            .then_some((first / region_vertices) as u32)
    };
    const SPLIT: u32 = u32::MAX;
    let mut region_of: Vec<u32> = codes
        .par_iter()
        .map(|&code| bucket_region((code >> BUCKET_SHIFT) as usize).unwrap_or(SPLIT))
        .collect();
    let mut split: Vec<(u32, u32)> = codes
        .iter()
        .zip(0u32..)
        .filter(|&(_, v)| region_of[v as usize] == SPLIT)
        .map(|(&code, v)| (code, v))
        .collect();
    drop(codes);
    split.sort_unstable();
    let mut next_rank = 0;
    let mut bucket = usize::MAX;
    for &(code, v) in &split {
        let b = (code >> BUCKET_SHIFT) as usize;
        if b != bucket {
            (bucket, next_rank) = (b, bucket_start[b]);
        }
        region_of[v as usize] = (next_rank / region_vertices) as u32;
        next_rank += 1;
    }
    region_of
}

/// Decimates only the band of triangles around the `flagged` vertices (the triangles
/// within [`BAND_RINGS`] + 1 rings of one) until the whole mesh has
/// `target` triangles or the error bound stops it; the rest of the mesh is untouched and
/// the band's border and the `locked` vertices (indexed like the mesh's; may be empty) do
/// not move. Memory follows the band, not the mesh: this is the pass across tile seams
/// after each tile was decimated with its seam vertices locked ([`crate::tiles`]), and
/// across region seams. Unused vertices are removed; the order of the untouched triangles
/// and vertices is kept, the band's triangles come last. Returns the stats and, with
/// [`Remap::Keep`], the new index of every vertex (`u32::MAX`: removed).
pub(crate) fn decimate_band(
    mesh: &mut TriMesh,
    flagged: &[bool],
    locked: &[bool],
    target: usize,
    max_error: Option<f32>,
    remap: Remap,
) -> (DecimateStats, Vec<u32>) {
    let nv = mesh.vertex_count();
    let before = mesh.triangle_count();
    // The flagged vertices grown by `BAND_RINGS` rings.
    let mut near = flagged.to_vec();
    for _ in 0..BAND_RINGS {
        let mut grown = near.clone();
        for t in &mesh.triangles {
            if t.iter().any(|&v| near[v as usize]) {
                for &v in t {
                    grown[v as usize] = true;
                }
            }
        }
        near = grown;
    }
    let (band, rest): (Vec<[u32; 3]>, Vec<[u32; 3]>) = mesh
        .triangles
        .iter()
        .partition(|t| t.iter().any(|&v| near[v as usize]));
    drop(near);
    let stats = DecimateStats {
        triangles_before: before,
        triangles_after: before,
        ..Default::default()
    };
    if band.is_empty() || before <= target {
        let identity = match remap {
            Remap::Keep => (0..nv as u32).collect(),
            Remap::Drop => Vec::new(),
        };
        return (stats, identity);
    }
    // The band's border: vertices the rest also uses.
    let mut in_rest = vec![false; nv];
    for t in &rest {
        for &v in t {
            in_rest[v as usize] = true;
        }
    }
    let (band_mesh, global_of) = mesh.submesh(band.into_iter(), &mut vec![u32::MAX; nv]);
    let mut piece = Piece {
        mesh: band_mesh,
        global_of,
    };
    let fixed: Vec<bool> = piece
        .global_of
        .iter()
        .map(|&g| in_rest[g as usize] || locked.get(g as usize).is_some_and(|&l| l))
        .collect();
    let band_target = piece.mesh.triangle_count().saturating_sub(before - target);
    let (band_stats, band_remap) = decimate_locked(&mut piece.mesh, band_target, max_error, &fixed);
    let mut positions = std::mem::take(&mut mesh.positions);
    let output_of = place_survivors(
        &piece.mesh,
        &band_remap,
        |old, _| fixed[old].then(|| piece.global_of[old]),
        &mut positions,
    );
    // Where each vertex went before the unused ones are removed: the band's moved
    // vertices to their new index or nowhere, the others stay.
    let mut moved_to = Vec::new();
    if remap == Remap::Keep {
        moved_to = (0..nv as u32).collect();
        for (old, &new) in band_remap.iter().enumerate() {
            if !fixed[old] {
                moved_to[piece.global_of[old] as usize] = match new {
                    u32::MAX => u32::MAX,
                    new => output_of[new as usize],
                };
            }
        }
    }
    let mut triangles = rest;
    triangles.extend(
        piece
            .mesh
            .triangles
            .iter()
            .map(|t| t.map(|v| output_of[v as usize])),
    );
    *mesh = TriMesh {
        positions,
        triangles,
        normals: Vec::new(),
        attributes: Vec::new(),
    };
    let kept = mesh.remove_unused_vertices_mapped();
    for to in &mut moved_to {
        if *to != u32::MAX {
            *to = kept[*to as usize];
        }
    }
    let stats = DecimateStats {
        triangles_before: before,
        triangles_after: mesh.triangle_count(),
        ..band_stats
    };
    (stats, moved_to)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regions_are_runs_of_the_morton_order() {
        let mut rng = crate::test_rng::TestRng::new(5);
        let mut next = || rng.unit_f32();
        // A cloud, and a flat sheet whose codes crowd into few buckets; duplicated
        // positions share a code and are ranked by index.
        let cloud: Vec<Vec3> = (0..30_000)
            .map(|_| Vec3::new(next(), next(), next()))
            .collect();
        let mut sheet: Vec<Vec3> = (0..20_000)
            .map(|_| Vec3::new(next() * 1e-3, next() * 1e-3, 0.5))
            .collect();
        sheet.push(Vec3::splat(1.0));
        sheet.extend_from_within(..500);
        for positions in [cloud, sheet] {
            for region_vertices in [1, 7, 1000, 4096, 1 << 20] {
                let (lo, hi) = bounds(&positions);
                let extent = (hi - lo).max_element().max(f64::MIN_POSITIVE);
                let mut order: Vec<(u32, u32)> = (0..positions.len() as u32)
                    .map(|v| (morton_code(positions[v as usize], lo, extent), v))
                    .collect();
                order.sort_unstable();
                let mut expected = vec![0u32; positions.len()];
                for (rank, &(_, v)) in order.iter().enumerate() {
                    expected[v as usize] = (rank / region_vertices) as u32;
                }
                assert_eq!(
                    morton_regions(&positions, region_vertices),
                    expected,
                    "{region_vertices} vertices per region"
                );
            }
        }
    }
}
