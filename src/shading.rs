//! The shading normals: what a renderer lights. Area-weighted vertex normals of the final
//! surface, then, by option, smoothed over the mesh: each step sets every vertex's normal
//! to the normalised mean of its edge neighbours' (Jacobi order: the result does not
//! depend on the thread count; a vertex on a boundary or non-manifold edge keeps its
//! own).
//!
//! On an animation the surface's small-scale noise changes from frame to frame, and the
//! normals show it first: a highlight crawls where the positions barely move. A few steps
//! average the normals over a patch about `edge × √steps` wide (0.7 r × √3 ≈ 1.2 r at the
//! steady surface's cell), well below the scale of waves and droplets, and the flicker of
//! the written normals falls by about a fifth (`docs/quality.md`, "Steady in motion"). The
//! positions are not touched: a renderer that recomputes its own normals from the mesh
//! (Blender's importers by default; a `.mseq` decoder) sees the geometry's smoothness
//! alone.

use crate::mesh::TriMesh;
use crate::smoothing::Rings;
use glam::Vec3;
use rayon::prelude::*;

/// Peak of the normal smoothing per output triangle: the vertices' neighbour lists
/// (≈ 14 B, and ≈ 14 B of vertex → triangle lists while they are built) and a second copy
/// of the normals (≈ 6 B), bytes.
pub(crate) const BYTES_PER_TRIANGLE: f64 = 34.0;

/// Options of [`shading_normals`].
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[non_exhaustive]
pub struct ShadingOptions {
    /// Smoothing steps of the vertex normals (0: the area-weighted normals as they are).
    /// Default 0; the steady surface ([`crate::pipeline::ReconstructOptions::steady`])
    /// takes 3.
    pub normal_smoothing: u32,
}

impl ShadingOptions {
    /// Any step count is valid.
    pub fn validate(&self) -> crate::error::Result<()> {
        Ok(())
    }
}

/// Sets `mesh.normals` to its area-weighted vertex normals smoothed by
/// `options.normal_smoothing` steps.
pub fn shading_normals(mesh: &mut TriMesh, options: &ShadingOptions) {
    shading_normals_with(mesh, options, None);
}

/// [`shading_normals`] with the vertices' rings when they are at hand (built by the
/// smoothing of the same triangles; `None`: built here).
pub(crate) fn shading_normals_with(
    mesh: &mut TriMesh,
    options: &ShadingOptions,
    rings: Option<Rings>,
) {
    mesh.compute_normals();
    if options.normal_smoothing == 0 || mesh.positions.is_empty() {
        return;
    }
    let rings = rings.unwrap_or_else(|| Rings::new(mesh));
    debug_assert_eq!(rings.vertices(), mesh.positions.len());
    let mut current = std::mem::take(&mut mesh.normals);
    let mut next = vec![Vec3::ZERO; current.len()];
    for _ in 0..options.normal_smoothing {
        next.par_iter_mut().enumerate().for_each(|(v, out)| {
            *out = match rings.of(v) {
                Some(ring) => {
                    let sum = ring
                        .iter()
                        .map(|&n| current[n as usize].as_dvec3())
                        .sum::<glam::DVec3>();
                    let len = sum.length();
                    if len > 0.0 && len.is_finite() {
                        (sum / len).as_vec3()
                    } else {
                        current[v]
                    }
                }
                None => current[v],
            };
        });
        std::mem::swap(&mut current, &mut next);
    }
    mesh.normals = current;
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::smoothing::tests::bumpy_grid;

    fn mean_tilt(mesh: &TriMesh) -> f32 {
        // Interior vertices only (the rim keeps its normals).
        let n = (mesh.positions.len() as f64).sqrt() as u32 - 1;
        let mut sum = 0.0;
        let mut count = 0;
        for j in 2..n - 1 {
            for i in 2..n - 1 {
                sum += mesh.normals[(j * (n + 1) + i) as usize].angle_between(Vec3::Z);
                count += 1;
            }
        }
        sum / count as f32
    }

    #[test]
    fn smoothing_evens_out_the_normals_and_leaves_positions() {
        let mut mesh = bumpy_grid(16, |i, j| {
            0.3 * ((i * 7919 + j * 104729) % 13) as f32 / 13.0
        });
        let positions = mesh.positions.clone();
        shading_normals(&mut mesh, &ShadingOptions::default());
        let raw = mean_tilt(&mesh);
        assert!(raw > 0.05, "{raw}");
        let mut smoothed = mesh.clone();
        shading_normals(
            &mut smoothed,
            &ShadingOptions {
                normal_smoothing: 3,
            },
        );
        let after = mean_tilt(&smoothed);
        assert!(after < raw / 3.0, "{raw} → {after}");
        assert_eq!(smoothed.positions, positions);
        for n in &smoothed.normals {
            assert!((n.length() - 1.0).abs() < 1e-5);
        }
        // The same on one thread.
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let mut single = mesh.clone();
        one.install(|| {
            shading_normals(
                &mut single,
                &ShadingOptions {
                    normal_smoothing: 3,
                },
            )
        });
        assert_eq!(single.normals, smoothed.normals);
    }
}
