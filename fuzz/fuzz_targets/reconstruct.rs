//! The whole reconstruction (`pipeline::reconstruct_sized`) of a small random particle
//! set: up to 48 particles on a lattice of half-radius steps, each with its own radius
//! (2^-3 to 2^3 times the reference, so some frames break the plausible spread and must
//! be refused), up to two attributes of 1 or 3 components, and the pipeline's options
//! picked by the input (the still or the steady preset; kernel, decimation, smoothing,
//! containment, subdivision, tiles),
//! under a memory budget. The run must return a surface whose every coordinate and
//! attribute value is finite and whose triangles index its vertices, or a typed error;
//! never a panic (caught as `Error::Internal`), an abort, a hang or memory past the RSS
//! limit.
//!
//! Input layout: byte 0 the count, byte 1 the option bits, byte 2 the attribute count
//! and their components, then per particle 3 position bytes and one radius byte, then
//! the attributes' values (one byte each, scaled), missing bytes read as zero.
#![no_main]

use glam::Vec3;
use libfuzzer_sys::fuzz_target;
use meniscus::attributes::Attribute;
use meniscus::field::Kernel;
use meniscus::io::particles::Particles;
use meniscus::pipeline::{reconstruct_sized, ReconstructOptions};
use meniscus::radius::ParticleRadii;
use meniscus::{CancelToken, Error};

/// The reference radius, world units.
const R: f32 = 0.1;

fuzz_target!(|data: &[u8]| {
    let byte = |k: usize| data.get(k).copied().unwrap_or(0);
    let count = 1 + byte(0) as usize % 48;
    let bits = byte(1);
    let attribute_bits = byte(2);
    let mut at = 3;
    let mut positions = Vec::with_capacity(count);
    let mut radii = Vec::with_capacity(count);
    for _ in 0..count {
        // 0 to 31 half-radius steps per axis: a frame of a few particles across.
        let c = |b: u8| (b % 32) as f32 * 0.5 * R;
        positions.push(Vec3::new(c(byte(at)), c(byte(at + 1)), c(byte(at + 2))));
        radii.push(R * 2f32.powf((byte(at + 3) as f32 - 128.0) / 43.0));
        at += 4;
    }
    let mut attributes = Vec::new();
    for k in 0..(attribute_bits % 3) as usize {
        let components = if attribute_bits & (8 << k) != 0 { 3 } else { 1 };
        let values = (0..count * components)
            .map(|i| (byte(at + i) as f32 - 128.0) * 0.25)
            .collect();
        at += count * components;
        attributes.push(Attribute {
            name: format!("a{k}"),
            components,
            values,
        });
    }
    // The top bit starts from the steady surface (a sequence's default: finer cell, plain
    // Laplacian steps with an inward bound, smoothed shading normals), the others change
    // either preset.
    let mut options = match bits & 128 != 0 {
        true => ReconstructOptions::steady(R),
        false => ReconstructOptions::new(R),
    };
    if bits & 1 != 0 {
        options.field.kernel = Kernel::Anisotropic;
    }
    if bits & 2 != 0 {
        options.decimate = None;
    }
    if bits & 4 != 0 {
        options.smooth = None;
    }
    if bits & 8 != 0 {
        options.containment = None;
    }
    options.subdivide.levels = ((bits >> 4) & 1) as u32;
    options.tiles.tile_size_cells = (bits & 32 != 0).then_some(16);
    options.tiles.memory_budget_bytes = Some(1 << 30);
    let uniform = bits & 64 != 0;
    let radii = (!uniform).then(|| ParticleRadii {
        attribute: "pscale".into(),
        values: radii,
    });
    let particles = Particles {
        positions,
        attributes,
    };
    let width: Vec<usize> = particles.attributes.iter().map(|a| a.components).collect();
    match reconstruct_sized(particles, radii, &options, &|_| {}, &CancelToken::new()) {
        Ok((surface, _)) => {
            let fluid = &surface.fluid;
            let n = fluid.positions.len() as u32;
            assert!(
                fluid.positions.iter().all(|p| p.is_finite()),
                "a vertex is not finite"
            );
            assert!(
                fluid.triangles.iter().flatten().all(|&v| v < n),
                "a triangle index is out of range"
            );
            assert!(
                fluid.normals.iter().all(|v| v.is_finite()),
                "a normal is not finite"
            );
            for a in fluid.attributes.iter().chain(&surface.spheres.attributes) {
                assert!(
                    a.values.iter().all(|v| v.is_finite()),
                    "attribute {} is not finite",
                    a.name
                );
            }
            for (a, w) in fluid.attributes.iter().zip(&width) {
                assert_eq!(
                    a.values.len(),
                    n as usize * w,
                    "attribute {} per vertex",
                    a.name
                );
            }
            let spheres = &surface.spheres;
            assert!(spheres.centers.iter().all(|p| p.is_finite()));
            assert!(spheres.scales.is_empty() || spheres.scales.len() == spheres.centers.len());
            assert!(spheres.scales.iter().all(|s| s.is_finite() && *s > 0.0));
        }
        Err(e @ Error::Internal { .. }) => panic!("{e}"),
        Err(e @ (Error::InvalidRadius { .. } | Error::MemoryBudget { .. })) => {
            let _ = e.to_string();
        }
        Err(e) => panic!("unexpected error for a valid frame: {e}"),
    }
});
