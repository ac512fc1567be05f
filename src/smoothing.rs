//! Taubin smoothing of the decimated control mesh (G. Taubin, "A signal processing
//! approach to fair surface design", 1995): a low-pass filter on the vertex positions
//! that removes the field's small bumps without shrinking the surface the way plain
//! Laplacian smoothing does — or, with `μ = 0`, plain Laplacian smoothing of the regular
//! marching-cubes mesh (the steady surface, [`crate::pipeline::ReconstructOptions::steady`]):
//! there the field's lattice noise sits at the scale of a few edges, below Taubin's pass
//! band but well within what plain steps remove, and containment then keeps the centres
//! under what it shrank. There the inward moves can be weighted by how far the
//! neighbours' normals turn on a smoothed guidance copy
//! ([`SmoothOptions::feature_angle`]): the edges of resting water and the crests keep
//! their place while the faces' noise goes.
//!
//! **Input:** the decimated mesh (closed or with boundaries). **Output:** the same
//! triangles, vertices moved. Each step is two passes over every vertex `v` with
//! neighbours `n_1 … n_k` (the vertices it shares an edge with), each computed from the
//! positions of the pass before (Jacobi order: the result does not depend on the thread
//! count):
//! * `v ← v + λ (mean(n_i) − v)` (shrinks),
//! * `v ← v + μ (mean(n_i) − v)`, `μ < −λ` (inflates back; skipped when `μ = 0`).
//!
//! Positions are stepped in f32, the mesh's own precision (a step's rounding, about
//! 1e-7 of the coordinates, is far below any move that matters): the passes read half
//! the memory f64 would (figures in `docs/performance-log.md`, session 17).
//!
//! Low frequencies pass (below `k_PB = 1/λ + 1/μ` in Taubin's terms), high ones are damped
//! by `(1 − λk)(1 − μk)` per step. A vertex on a boundary edge or on an edge of more than
//! two triangles keeps its position.
//!
//! It runs between decimation and containment, on the control mesh: on the coarse mesh
//! each pass reaches further than it would after subdivision, containment then keeps
//! every centre under the smoothed surface, and a `.mseq` archive, which stores the
//! control mesh, stores the smoothed one. Measured in `docs/quality.md`: flatter faces
//! on every frame for a slightly larger distance to the particles.

use crate::mesh::{TriMesh, VertexTriangles};
use glam::Vec3;
use rayon::prelude::*;

/// Peak of Taubin smoothing per control-mesh triangle: the mesh (24 B), the vertices'
/// neighbour lists (≈ 14 B, and ≈ 14 B of vertex → triangle lists while they are built)
/// and two f32 copies of the positions (≈ 12 B), bytes. The inward bound adds the start
/// positions and normals (≈ 12 B), below the lists' building.
pub(crate) const BYTES_PER_INPUT_TRIANGLE: f64 = 60.0;

/// What feature weights ([`SmoothOptions::feature_angle`]) add per control-mesh
/// triangle while the steps run: a weight per neighbour-list entry (≈ 12 B) and the
/// guidance normals (≈ 6 B), bytes.
pub(crate) const FEATURE_BYTES_PER_INPUT_TRIANGLE: f64 = 18.0;

/// The vertices' neighbour lists ([`Rings`]) per triangle, bytes: what the pipeline
/// holds between smoothing and the shading normals when it hands them over.
pub(crate) const RINGS_BYTES_PER_TRIANGLE: f64 = 14.0;

/// Options of [`smooth`].
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[non_exhaustive]
pub struct SmoothOptions {
    /// Taubin steps (each a λ pass and a μ pass). Default 2; 0 leaves the mesh as it is.
    pub steps: u32,
    /// Shrinking weight `λ`, in (0, 1], or (0, 1) with a μ pass. Default 0.3.
    pub lambda: f32,
    /// Inflating weight `μ`, below `−λ`; 0 for plain Laplacian smoothing (no μ pass).
    /// Default −0.31.
    pub mu: f32,
    /// Farthest a vertex may move inwards, along its normal before smoothing, world
    /// units, or `None` for no bound. Default `None`. Plain steps shrink tips, thin
    /// sheets and small drops most; the bound keeps them where the field put them
    /// (and every particle centre under them), and leaves the small-scale noise, whose
    /// moves are far smaller, to the steps.
    pub max_inward: Option<f32>,
    /// Feature weights of the inward moves, degrees, or `None` for plain steps. Default
    /// `None`. Where a step would move a vertex inwards (against its normal on a
    /// *guidance* copy of the mesh, smoothed [`Self::feature_guide_steps`] plain steps),
    /// each neighbour `n` counts with `exp(−(θ / angle)²)`, `θ` the angle between the
    /// two vertices' guidance normals, and the move is `λ Σ w_n (n − v) / k` over the `k`
    /// neighbours: across an edge or a crest the move fades, on a gently curved face it
    /// is the plain one (outward moves always are). The edges of resting blocks and the
    /// crests stay where the field put them while the faces' noise goes. Plain Laplacian
    /// steps only (`μ = 0`).
    pub feature_angle: Option<f32>,
    /// Plain steps of the guidance copy whose normals give the feature weights: enough
    /// that the lattice's noise is gone from them, few enough that edges stay edges.
    /// Default 8.
    pub feature_guide_steps: u32,
}

impl Default for SmoothOptions {
    fn default() -> Self {
        SmoothOptions {
            steps: 2,
            lambda: 0.3,
            mu: -0.31,
            max_inward: None,
            feature_angle: None,
            feature_guide_steps: 8,
        }
    }
}

impl SmoothOptions {
    /// `steps` Taubin steps with the default weights.
    pub fn steps(steps: u32) -> Self {
        SmoothOptions {
            steps,
            ..Default::default()
        }
    }

    /// `steps` plain Laplacian steps: every vertex moved to the mean of its neighbours
    /// (`λ = 1`, no μ pass).
    pub fn laplacian(steps: u32) -> Self {
        SmoothOptions {
            steps,
            lambda: 1.0,
            mu: 0.0,
            ..Default::default()
        }
    }

    /// Checks the weights: `0 < λ < 1` and `−1 < μ < −λ` (Taubin), or `0 < λ ≤ 1` and
    /// `μ = 0` (Laplacian).
    pub fn validate(&self) -> crate::error::Result<()> {
        let (l, m) = (self.lambda, self.mu);
        let laplacian = m == 0.0;
        if !(l > 0.0 && (l < 1.0 || laplacian && l == 1.0)) {
            return Err(crate::error::Error::InvalidOption {
                option: "smooth.lambda",
                message: format!("must lie in (0, 1) ((0, 1] with μ = 0), got {l}"),
            });
        }
        if let Some(bound) = self.max_inward.filter(|b| !(b.is_finite() && *b >= 0.0)) {
            return Err(crate::error::Error::InvalidOption {
                option: "smooth.max_inward",
                message: format!("must be finite and >= 0 (world units), got {bound}"),
            });
        }
        if let Some(angle) = self.feature_angle {
            check_feature_angle(angle, if laplacian { "laplacian" } else { "taubin" }).map_err(
                |message| crate::error::Error::InvalidOption {
                    option: "smooth.feature_angle",
                    message,
                },
            )?;
        }
        if !(laplacian || m > -1.0 && m < -l) {
            return Err(crate::error::Error::InvalidOption {
                option: "smooth.mu",
                message: format!("must be 0 or lie in (−1, −λ) = (−1, {}), got {m}", -l),
            });
        }
        Ok(())
    }
}

/// Checks a feature angle ([`SmoothOptions::feature_angle`], degrees) for smoothing of
/// the kind `method` (`laplacian` or `taubin`): the message of the error.
pub(crate) fn check_feature_angle(angle: f32, method: &str) -> Result<(), String> {
    if !(angle.is_finite() && angle > 0.0 && angle <= 180.0) {
        return Err(format!("must lie in (0, 180] degrees, got {angle}"));
    }
    if method != "laplacian" {
        return Err(format!(
            "weights Laplacian steps only (the smoothing here is {method})"
        ));
    }
    Ok(())
}

/// What [`smooth`] did.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct SmoothStats {
    /// Vertices moved.
    pub vertices: usize,
    /// Vertices kept in place (on a boundary or non-manifold edge).
    pub fixed_vertices: usize,
    /// Mean distance a vertex moved, world units.
    pub mean_shift: f64,
    /// Largest distance a vertex moved, world units.
    pub max_shift: f64,
}

/// Smooths `mesh` in place by `options.steps` Taubin (or Laplacian) steps; clears its
/// normals.
/// Options must be valid ([`SmoothOptions::validate`]).
pub fn smooth(mesh: &mut TriMesh, options: &SmoothOptions) -> SmoothStats {
    smooth_keeping_rings(mesh, options).0
}

/// [`smooth`], and the vertices' rings it built (`None` when it had nothing to do): the
/// pipeline hands them to the shading normals when the triangles stay as they are
/// (containment only moves vertices), instead of building them again.
pub(crate) fn smooth_keeping_rings(
    mesh: &mut TriMesh,
    options: &SmoothOptions,
) -> (SmoothStats, Option<Rings>) {
    let mut stats = SmoothStats::default();
    if options.steps == 0 || mesh.positions.is_empty() {
        return (stats, None);
    }
    let rings = Rings::new(mesh);
    let mut current: Vec<Vec3> = mesh.positions.clone();
    let mut next = vec![Vec3::ZERO; current.len()];
    let passes: &[f32] = if options.mu == 0.0 {
        &[options.lambda]
    } else {
        &[options.lambda, options.mu]
    };
    // The bound's reference: each vertex's start (the f32 positions, which `current`
    // holds exactly) and its outward normal there.
    let start = options.max_inward.map(|bound| {
        mesh.compute_normals();
        (
            bound,
            mesh.positions.clone(),
            std::mem::take(&mut mesh.normals),
        )
    });
    let guide = options.feature_angle.map(|angle| {
        Guide::new(
            mesh,
            &rings,
            options.feature_guide_steps,
            angle,
            [&mut current, &mut next],
        )
    });
    for _ in 0..options.steps {
        for (pass, &weight) in passes.iter().enumerate() {
            // The bound after each step's last pass, in the same sweep.
            let bound = start.as_ref().filter(|_| pass + 1 == passes.len());
            next.par_iter_mut().enumerate().for_each(|(v, out)| {
                let mut p = match rings.of(v) {
                    Some(ring) => {
                        let x = current[v];
                        let k = ring.len() as f32;
                        let mut step = ring_mean(ring, &current) - x;
                        if let Some(guide) = guide.as_ref().filter(|g| step.dot(g.normals[v]) < 0.0)
                        {
                            step = ring
                                .iter()
                                .zip(guide.weights_of(&rings, v))
                                .map(|(&n, &w)| w * (current[n as usize] - x))
                                .sum::<Vec3>()
                                / k;
                        }
                        x + weight * step
                    }
                    None => current[v],
                };
                if let Some((bound, start, normals)) = bound {
                    let n = normals[v];
                    let inward = -(p - start[v]).dot(n);
                    if inward > *bound {
                        p += (inward - bound) * n;
                    }
                }
                *out = p;
            });
            std::mem::swap(&mut current, &mut next);
        }
    }
    drop((start, guide));
    drop(next);
    for (p, &new) in mesh.positions.iter_mut().zip(&current) {
        let shift = (new - *p).as_dvec3().length();
        *p = new;
        stats.mean_shift += shift;
        stats.max_shift = stats.max_shift.max(shift);
    }
    stats.fixed_vertices = rings.fixed.iter().filter(|&&fixed| fixed).count();
    stats.vertices = current.len() - stats.fixed_vertices;
    stats.mean_shift /= current.len() as f64;
    mesh.normals.clear();
    (stats, Some(rings))
}

/// The mean of the positions of `ring`'s vertices.
fn ring_mean(ring: &[u32], positions: &[Vec3]) -> Vec3 {
    ring.iter().map(|&n| positions[n as usize]).sum::<Vec3>() / ring.len() as f32
}

/// The feature weights' guidance ([`SmoothOptions::feature_angle`]): the vertex normals of
/// a copy of the mesh smoothed by plain steps, and a weight per neighbour-list entry.
struct Guide {
    normals: Vec<Vec3>,
    /// Aligned with [`Rings::neighbours`].
    weights: Vec<f32>,
}

impl Guide {
    /// Runs the guidance copy's `steps` plain steps in `buffers` (left holding the
    /// mesh's positions again) and weighs every neighbour by the angle `angle` (degrees).
    fn new(
        mesh: &mut TriMesh,
        rings: &Rings,
        steps: u32,
        angle: f32,
        buffers: [&mut Vec<Vec3>; 2],
    ) -> Guide {
        let [current, next] = buffers;
        for _ in 0..steps {
            next.par_iter_mut().enumerate().for_each(|(v, out)| {
                *out = rings
                    .of(v)
                    .map_or(current[v], |ring| ring_mean(ring, current));
            });
            std::mem::swap(current, next);
        }
        // The guidance copy's area-weighted normals, by the mesh's own code.
        std::mem::swap(&mut mesh.positions, current);
        mesh.compute_normals();
        let normals = std::mem::take(&mut mesh.normals);
        std::mem::swap(&mut mesh.positions, current);
        current.copy_from_slice(&mesh.positions);
        // Written in place in chunks of entries, each starting at the vertex whose list
        // holds its first entry.
        const CHUNK: usize = 1 << 16;
        let sigma = angle.to_radians();
        let mut weights = vec![0.0f32; rings.neighbours.len()];
        weights
            .par_chunks_mut(CHUNK)
            .enumerate()
            .for_each(|(c, out)| {
                let first = c * CHUNK;
                let mut v = rings.start.partition_point(|&s| s as usize <= first) - 1;
                for (e, w) in (first..).zip(out) {
                    while rings.start[v + 1] as usize <= e {
                        v += 1;
                    }
                    let u = rings.neighbours[e] as usize;
                    let theta = normals[v].dot(normals[u]).clamp(-1.0, 1.0).acos();
                    *w = (-(theta / sigma).powi(2)).exp();
                }
            });
        Guide { normals, weights }
    }

    /// The weights of `v`'s neighbours, in [`Rings::of`]'s order.
    fn weights_of(&self, rings: &Rings, v: usize) -> &[f32] {
        &self.weights[rings.start[v] as usize..rings.start[v + 1] as usize]
    }
}

/// Every vertex's edge neighbours (sorted, once each), or none for a vertex that keeps
/// its position.
pub(crate) struct Rings {
    /// `start[v]..start[v + 1]` indexes `neighbours`.
    start: Vec<u32>,
    neighbours: Vec<u32>,
    /// Per vertex: on a boundary or non-manifold edge, or on no triangle.
    fixed: Vec<bool>,
}

impl Rings {
    pub(crate) fn new(mesh: &TriMesh) -> Rings {
        const CHUNK: usize = 1 << 14;
        let n = mesh.positions.len();
        let triangles = VertexTriangles::new(mesh);
        // Per chunk of vertices, in order: their neighbours, list lengths and flags.
        let chunks: Vec<(Vec<u32>, Vec<u32>, Vec<bool>)> = (0..n.div_ceil(CHUNK))
            .into_par_iter()
            .map(|c| {
                let vertices = c * CHUNK..((c + 1) * CHUNK).min(n);
                let mut neighbours = Vec::with_capacity(3 * vertices.len());
                let mut lengths = Vec::with_capacity(vertices.len());
                let mut fixed = Vec::with_capacity(vertices.len());
                let mut listed = Vec::new();
                for v in vertices {
                    // Each triangle at v gives its two other vertices: an edge of two
                    // triangles is listed twice, a boundary edge once, a non-manifold
                    // edge more often.
                    listed.clear();
                    for &t in triangles.of(v as u32) {
                        let tri = mesh.triangles[t as usize];
                        listed.extend(tri.iter().copied().filter(|&u| u != v as u32));
                    }
                    listed.sort_unstable();
                    let before = neighbours.len();
                    let mut keep = !listed.is_empty();
                    for run in listed.chunk_by(|a, b| a == b) {
                        keep &= run.len() == 2;
                        neighbours.push(run[0]);
                    }
                    lengths.push((neighbours.len() - before) as u32);
                    fixed.push(!keep);
                }
                (neighbours, lengths, fixed)
            })
            .collect();
        drop(triangles);
        let mut rings = Rings {
            start: Vec::with_capacity(n + 1),
            neighbours: Vec::with_capacity(chunks.iter().map(|c| c.0.len()).sum()),
            fixed: Vec::with_capacity(n),
        };
        rings.start.push(0);
        for (neighbours, lengths, fixed) in chunks {
            rings.neighbours.extend_from_slice(&neighbours);
            let mut end = *rings.start.last().expect("starts at 0");
            rings.start.extend(lengths.iter().map(|&l| {
                end += l;
                end
            }));
            rings.fixed.extend_from_slice(&fixed);
        }
        rings
    }

    /// Vertices listed.
    pub(crate) fn vertices(&self) -> usize {
        self.fixed.len()
    }

    /// The neighbours of `v`, or `None` when it is on a boundary or non-manifold edge,
    /// or on no triangle.
    pub(crate) fn of(&self, v: usize) -> Option<&[u32]> {
        (!self.fixed[v])
            .then(|| &self.neighbours[self.start[v] as usize..self.start[v + 1] as usize])
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use glam::Vec3;

    /// A closed UV sphere of radius `radius` with `rings` × `segments` quads.
    fn uv_sphere(radius: f32, rings: u32, segments: u32) -> TriMesh {
        let mut positions = vec![Vec3::new(0.0, 0.0, radius)];
        for i in 1..rings {
            let theta = std::f32::consts::PI * i as f32 / rings as f32;
            for j in 0..segments {
                let phi = 2.0 * std::f32::consts::PI * j as f32 / segments as f32;
                positions.push(
                    radius
                        * Vec3::new(
                            theta.sin() * phi.cos(),
                            theta.sin() * phi.sin(),
                            theta.cos(),
                        ),
                );
            }
        }
        positions.push(Vec3::new(0.0, 0.0, -radius));
        let south = positions.len() as u32 - 1;
        let at = |i: u32, j: u32| 1 + (i - 1) * segments + j % segments;
        let mut triangles = Vec::new();
        for j in 0..segments {
            triangles.push([0, at(1, j), at(1, j + 1)]);
            triangles.push([south, at(rings - 1, j + 1), at(rings - 1, j)]);
        }
        for i in 1..rings - 1 {
            for j in 0..segments {
                let (a, b, c, d) = (at(i, j), at(i, j + 1), at(i + 1, j), at(i + 1, j + 1));
                triangles.push([a, c, b]);
                triangles.push([b, c, d]);
            }
        }
        TriMesh {
            positions,
            triangles,
            ..Default::default()
        }
    }

    fn radii(mesh: &TriMesh) -> (f64, f64) {
        let r: Vec<f64> = mesh.positions.iter().map(|p| p.length() as f64).collect();
        let mean = r.iter().sum::<f64>() / r.len() as f64;
        let rms = (r.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / r.len() as f64).sqrt();
        (mean, rms)
    }

    #[test]
    fn bumps_go_and_the_sphere_keeps_its_size() {
        let mut mesh = uv_sphere(1.0, 24, 48);
        // Every other vertex of each ring pushed out or in by 2 % (the same along the
        // meridians): the mean of a vertex's six neighbours is −1/3 of its own bump, a
        // frequency k = 4/3, which each step damps by (1 − λk)(1 − μk) = 0.848.
        for (i, p) in mesh.positions.iter_mut().enumerate() {
            *p *= if i % 2 == 0 { 1.02 } else { 0.98 };
        }
        let (mean_before, bumps_before) = radii(&mesh);
        let options = SmoothOptions::default();
        let stats = smooth(&mut mesh, &options);
        let (mean_after, bumps_after) = radii(&mesh);
        let k = 4.0 / 3.0;
        let damping = ((1.0 - options.lambda as f64 * k) * (1.0 - options.mu as f64 * k))
            .powi(options.steps as i32);
        assert!(
            (bumps_after / bumps_before - damping).abs() < 0.03,
            "{bumps_before} → {bumps_after}, expected × {damping}"
        );
        // Plain Laplacian smoothing with the same λ (no μ pass) shrinks it by about 2 %.
        assert!(
            (mean_after - mean_before).abs() < 0.004,
            "{mean_before} → {mean_after}"
        );
        assert_eq!(stats.fixed_vertices, 0);
        assert_eq!(stats.vertices, mesh.positions.len());
        assert!(
            stats.max_shift > 0.003
                && stats.max_shift < 0.02
                && stats.mean_shift <= stats.max_shift
        );
    }

    #[test]
    fn plain_laplacian_smoothing_would_shrink_it() {
        // The check above means something: one pass of λ alone shrinks the sphere.
        let mut mesh = uv_sphere(1.0, 24, 48);
        let (before, _) = radii(&mesh);
        let rings = Rings::new(&mesh);
        let current: Vec<glam::DVec3> = mesh.positions.iter().map(|p| p.as_dvec3()).collect();
        for (v, p) in mesh.positions.iter_mut().enumerate() {
            let ring = rings.of(v).unwrap();
            let mean = ring
                .iter()
                .map(|&n| current[n as usize])
                .sum::<glam::DVec3>()
                / ring.len() as f64;
            *p = (current[v] + 0.3 * (mean - current[v])).as_vec3();
        }
        let (after, _) = radii(&mesh);
        assert!(before - after > 0.002, "{before} → {after}");
    }

    #[test]
    fn boundary_vertices_stay_and_the_result_does_not_depend_on_threads() {
        let mut mesh = uv_sphere(1.0, 12, 24);
        // Open it: drop the triangles around the north pole.
        mesh.triangles.retain(|t| !t.contains(&0));
        for (i, p) in mesh.positions.iter_mut().enumerate() {
            *p *= 1.0 + 0.01 * ((i * 7919) % 13) as f32 / 13.0;
        }
        let rim: Vec<usize> = (1..=24).collect();
        let before = mesh.clone();
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let mut single = mesh.clone();
        let stats = one.install(|| smooth(&mut single, &SmoothOptions::default()));
        smooth(&mut mesh, &SmoothOptions::default());
        assert_eq!(mesh.positions, single.positions);
        for v in rim {
            assert_eq!(mesh.positions[v], before.positions[v], "rim vertex {v}");
        }
        // The pole (on no triangle now) and the 24 rim vertices.
        assert_eq!(stats.fixed_vertices, 25);
        assert_ne!(mesh.positions[30], before.positions[30]);
    }

    #[test]
    fn weights_are_checked() {
        assert!(SmoothOptions::default().validate().is_ok());
        for (lambda, mu) in [
            (0.0, -0.31),
            (1.0, -1.01),
            (0.3, -0.3),
            (0.3, -1.0),
            (0.3, 0.31),
            (1.0, -0.5),
            (1.01, 0.0),
            (0.0, 0.0),
        ] {
            let options = SmoothOptions {
                steps: 1,
                lambda,
                mu,
                ..Default::default()
            };
            assert!(options.validate().is_err(), "{lambda} {mu}");
        }
        assert!(SmoothOptions::laplacian(10).validate().is_ok());
        for (angle, options) in [
            (7.0, SmoothOptions::default()),
            (0.0, SmoothOptions::laplacian(10)),
            (f32::INFINITY, SmoothOptions::laplacian(10)),
            (181.0, SmoothOptions::laplacian(10)),
        ] {
            let options = SmoothOptions {
                feature_angle: Some(angle),
                ..options
            };
            assert!(options.validate().is_err(), "{angle} {options:?}");
        }
        let weighted = SmoothOptions {
            feature_angle: Some(7.0),
            ..SmoothOptions::laplacian(10)
        };
        assert!(weighted.validate().is_ok());
    }

    #[test]
    fn feature_weights_keep_a_crest_and_remove_the_faces_noise() {
        // A roof: two faces at 45° meeting in a crest along x = 12, normals up (+z),
        // with a checkerboard of bumps of 0.05 on its faces (0.05 from their neighbours'
        // mean along y).
        let (n, crest) = (24, 12);
        let roof = |i: u32| -(i as f32 - crest as f32).abs();
        let mesh = bumpy_grid(n, |i, j| {
            roof(i)
                + if i != crest && (i + j) % 2 == 0 {
                    0.05
                } else {
                    0.0
                }
        });
        let plain = SmoothOptions::laplacian(10);
        let weighted = SmoothOptions {
            feature_angle: Some(7.0),
            ..plain.clone()
        };
        let at = |i: u32, j: u32| (j * (n + 1) + i) as usize;
        // How far the crest sank, and the faces' bumps left, away from the fixed rim.
        let measure = |m: &TriMesh| {
            let sunk = (6..=n - 6)
                .map(|j| -m.positions[at(crest, j)].z)
                .fold(0.0f32, f32::max);
            let bumps = (6..=n - 6)
                .flat_map(|j| (4..=n - 4).map(move |i| (i, j)))
                .filter(|&(i, _)| i.abs_diff(crest) >= 6)
                .map(|(i, j)| {
                    // Along y the roof is level: what is left there is the bumps.
                    let z = |j: u32| m.positions[at(i, j)].z;
                    (z(j) - 0.5 * (z(j - 1) + z(j + 1))).abs()
                })
                .fold(0.0f32, f32::max);
            (sunk, bumps)
        };
        let mut plain_mesh = mesh.clone();
        smooth(&mut plain_mesh, &plain);
        let mut weighted_mesh = mesh.clone();
        smooth(&mut weighted_mesh, &weighted);
        let (plain_sunk, plain_bumps) = measure(&plain_mesh);
        let (sunk, bumps) = measure(&weighted_mesh);
        // Ten plain steps sink the crest by two edges; the weights keep it within a
        // hundredth, and the bumps of the faces go all the same, though not as far as
        // with plain steps (up moves weighted, down moves plain). Within the guidance's
        // reach of the crest (4 edges) its normals turn, and the bumps there stay.
        assert!(plain_sunk > 0.3, "plain steps: the crest sank {plain_sunk}");
        assert!(sunk < 0.1 * plain_sunk, "weighted: the crest sank {sunk}");
        assert!(plain_bumps < 0.005, "plain steps: bumps {plain_bumps}");
        assert!(bumps < 0.2 * 0.05, "weighted: bumps {bumps}");
        // No output depends on the thread count.
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let mut single = mesh.clone();
        one.install(|| smooth(&mut single, &weighted));
        assert_eq!(single.positions, weighted_mesh.positions);
    }

    /// A flat grid of `n × n` quads (two triangles each) in the z = 0 plane, vertex
    /// `(i, j)` lifted by `lift(i, j)`.
    pub(crate) fn bumpy_grid(n: u32, lift: impl Fn(u32, u32) -> f32) -> TriMesh {
        let mut positions = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                positions.push(Vec3::new(i as f32, j as f32, lift(i, j)));
            }
        }
        let at = |i: u32, j: u32| j * (n + 1) + i;
        let mut triangles = Vec::new();
        for j in 0..n {
            for i in 0..n {
                triangles.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
                triangles.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
            }
        }
        TriMesh {
            positions,
            triangles,
            ..Default::default()
        }
    }

    #[test]
    fn laplacian_steps_remove_lattice_noise_that_taubin_passes() {
        // A checkerboard of bumps: each plain step (λ = 1) maps it to −1/3 of itself
        // (four neighbours of the other colour, two of its own), each Taubin step to
        // 0.85 of itself. Measured away from the fixed rim.
        let n = 24;
        let mesh = bumpy_grid(n, |i, j| if (i + j) % 2 == 0 { 0.1 } else { 0.0 });
        let amplitude = |m: &TriMesh| {
            let z: Vec<f32> = (6..=n - 6)
                .flat_map(|j| (6..=n - 6).map(move |i| (i, j)))
                .map(|(i, j)| m.positions[(j * (n + 1) + i) as usize].z)
                .collect();
            let mean = z.iter().sum::<f32>() / z.len() as f32;
            z.iter().map(|v| (v - mean).abs()).fold(0.0f32, f32::max)
        };
        let before = amplitude(&mesh);
        let mut taubin = mesh.clone();
        smooth(&mut taubin, &SmoothOptions::default());
        let mut plain = mesh.clone();
        smooth(&mut plain, &SmoothOptions::laplacian(3));
        let (taubin, plain) = (amplitude(&taubin), amplitude(&plain));
        assert!((before - 0.05).abs() < 1e-3, "{before}");
        assert!(taubin > 0.6 * before, "Taubin: {before} → {taubin}");
        assert!(plain < 1.2 * before / 27.0, "Laplacian: {before} → {plain}");
    }
}
