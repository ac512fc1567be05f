//! Tiled reconstruction equals the untiled one bit for bit, for every shipped frame,
//! several tile sizes (including tiles smaller than the influence radius) and thread
//! counts.

mod support;

use glam::Vec3;
use meniscus::field::{FieldOptions, Kernel};
use meniscus::mesh::Surface;
use meniscus::pipeline::{reconstruct, ReconstructOptions, ReconstructionStats};
use meniscus::tiles::TileOptions;
use support::{in_pool, shipped_frames, xyz};

/// Field, marching cubes and isolated particles only (no post-processing), tiled or not.
struct Run {
    surface: Surface,
    stats: ReconstructionStats,
}

fn run(positions: &[Vec3], options: &FieldOptions, tile: Option<u32>, threads: usize) -> Run {
    let mut field = options.clone();
    let mut options = ReconstructOptions::raw(field.particle_radius);
    std::mem::swap(&mut options.field, &mut field);
    options.tiles = tile.map_or_else(TileOptions::default, TileOptions::tile_size);
    in_pool(threads, || {
        let (surface, stats) = reconstruct(positions, &options).unwrap();
        Run { surface, stats }
    })
}

fn assert_same(a: &Run, b: &Run, what: &str) {
    let (a_mesh, b_mesh) = (&a.surface.fluid, &b.surface.fluid);
    assert_eq!(
        a_mesh.triangles.len(),
        b_mesh.triangles.len(),
        "{what}: triangle count"
    );
    assert!(
        a_mesh.triangles == b_mesh.triangles,
        "{what}: triangles differ"
    );
    assert!(
        a_mesh.positions.len() == b_mesh.positions.len()
            && a_mesh
                .positions
                .iter()
                .zip(&b_mesh.positions)
                .all(|(p, q)| p.to_array().map(f32::to_bits) == q.to_array().map(f32::to_bits)),
        "{what}: vertex positions differ"
    );
    assert_eq!(
        a.surface.spheres.centers, b.surface.spheres.centers,
        "{what}: isolated particles"
    );
}

#[test]
fn tiled_runs_equal_the_untiled_run_on_every_frame() {
    let frames: Vec<(String, f32)> = shipped_frames()
        .into_iter()
        .chain(
            ["sphere", "box", "droplets", "sheet"]
                .iter()
                .map(|n| (format!("analytic/{n}.xyz"), 0.025)),
        )
        .collect();
    for (rel, r) in frames {
        let positions = xyz(&rel);
        let options = FieldOptions::new(r);
        let whole = run(&positions, &options, None, 2);
        assert!(whole.surface.fluid.triangles.len() > 1000, "{rel}");
        let sizes: &[u32] = if positions.len() < 10_000 {
            &[16, 40]
        } else {
            &[32, 64]
        };
        for &tile in sizes {
            assert_same(
                &whole,
                &run(&positions, &options, Some(tile), 2),
                &format!("{rel}, tile {tile}"),
            );
        }
    }
}

#[test]
fn anisotropic_tiled_runs_equal_the_untiled_run_for_any_thread_count() {
    // The kernels of a tile's particles come from its own ghost zone: the same neighbours
    // in the same order as in the whole scene, so the same ellipsoids, the same field.
    for (rel, r, tiles) in [
        ("dambreak_small/ParticleData_Fluid_25.xyz", 0.012, [24, 64]),
        ("dambreak_small/ParticleData_Fluid_45.xyz", 0.012, [32, 48]),
        ("double_dambreak/ParticleData_Fluid_9.xyz", 0.025, [16, 40]),
        ("analytic/sphere.xyz", 0.025, [16, 24]),
        ("analytic/sheet.xyz", 0.025, [8, 16]),
    ] {
        let positions = xyz(rel);
        let mut options = FieldOptions::new(r);
        options.kernel = Kernel::Anisotropic;
        let whole = run(&positions, &options, None, 2);
        assert!(whole.surface.fluid.triangles.len() > 1000, "{rel}");
        assert_same(
            &whole,
            &run(&positions, &options, None, 1),
            &format!("{rel}, 1 thread"),
        );
        for tile in tiles {
            let tiled = run(&positions, &options, Some(tile), 3);
            assert!(
                tiled.stats.tiles.tiles > 1,
                "{rel}: {:?}",
                tiled.stats.tiles
            );
            assert_same(&whole, &tiled, &format!("{rel}, anisotropic, tile {tile}"));
        }
        // And the kernels make a different surface from the isotropic one.
        let isotropic = run(&positions, &FieldOptions::new(r), None, 2);
        assert!(isotropic.surface.fluid.positions != whole.surface.fluid.positions);
    }
}

#[test]
fn tiles_smaller_than_the_influence_radius_and_any_thread_count() {
    // R = 8r at h = r/2 is 16 cells = 2 blocks, so one-block tiles are half of R.
    let positions = xyz("analytic/sheet.xyz");
    let mut options = FieldOptions::new(0.025);
    options.cell_size = 0.5;
    options.influence_radius = 8.0;
    let whole = run(&positions, &options, None, 1);
    assert!(whole.stats.tiles.tiles == 1);
    let small = run(&positions, &options, Some(8), 3);
    assert!(small.stats.tiles.tiles > 50, "{:?}", small.stats.tiles);
    assert_same(&whole, &small, "tile 8 cells, R = 16 cells");
    assert_same(
        &whole,
        &run(&positions, &options, Some(40), 2),
        "tile 40 cells, R = 16 cells",
    );
}

#[test]
fn particles_on_tile_boundaries_and_lattice_planes() {
    // A slab of particles whose coordinates are exact multiples of the cell size, with
    // planes of particles lying exactly on block and tile boundaries (8 and 16 cells).
    let r = 0.5f32;
    let h = r; // cell size 1 r
    let mut positions = Vec::new();
    for k in -6..=6 {
        for j in -8..=8 {
            for i in -10..=10 {
                positions.push(Vec3::new(
                    i as f32 * 2.0 * h,
                    j as f32 * 2.0 * h,
                    k as f32 * 2.0 * h,
                ));
            }
        }
    }
    // A second body: a column right at +16 cells, touching tile planes.
    for j in 0..10 {
        positions.push(Vec3::new(16.0 * h, j as f32 * 2.0 * h + 20.0 * h, 16.0 * h));
    }
    let options = FieldOptions::new(r);
    let whole = run(&positions, &options, None, 2);
    let report = meniscus::mesh::validate(&whole.surface.fluid);
    assert!(report.is_closed_manifold(), "{report:?}");
    for tile in [8, 16, 32] {
        assert_same(
            &whole,
            &run(&positions, &options, Some(tile), 2),
            &format!("lattice scene, tile {tile}"),
        );
    }
}
