//! The whole reconstruction of one frame, stage by stage (Akinci et al. 2013, Fig. 2):
//!
//! 1. plan: one pass over the particles checks them and cuts the lattice into tiles under
//!    the memory budget (`tiles::plan_tiles`);
//! 2. store: the particles held for the tiles, in memory or spilled to disk;
//! 3. tiles: isolated particles split off, the field ([`crate::field`]: anisotropic
//!    kernels by default, the paper's isotropic Solenthaler field with `paper`) and
//!    marching cubes ([`crate::marching_cubes`]), tile by tile, into a sink that
//!    stitches the pieces exactly, or decimates each as it comes
//!    (`tiles::TileDecimation`);
//! 4. quadric decimation ([`crate::decimation`]), unless the tiles did it;
//! 5. Taubin smoothing of the decimated mesh ([`crate::smoothing`]);
//! 6. containment: every non-isolated particle centre pushed under the surface that
//!    subdivision will make ([`crate::containment`]);
//! 7. Loop subdivision ([`crate::subdivision`]);
//! 8. icospheres of radius `r` at the isolated particles ([`crate::isolated`]);
//! 9. the shading normals: area-weighted vertex normals, smoothed by option
//!    ([`crate::shading`]);
//! 10. the particles' payload carried to the final vertices ([`crate::attributes`]).
//!
//! Every stage is timed; [`ReconstructionStats`] is the paper's Table 1 for one frame.

use crate::cancel::CancelToken;
use crate::containment::{contain_centres, ContainmentInput};
use crate::decimation::{decimate, DecimateStats};
use crate::error::Result;
use crate::field::Sizes;
use crate::io::particles::ParticleSource;
use crate::mesh::{SphereInstances, Surface, TriMesh};
use crate::radius::ParticleRadii;
use crate::shading::shading_normals_with;
use crate::smoothing::smooth_keeping_rings;
use crate::subdivision::subdivide;
use crate::tiles::{
    plan_tiles, run_tiles, Isolated, ParticleStore, StitchSink, TileDecimation, TilePlan, TileSink,
    TileStats,
};
use crate::transfer::transfer;
use glam::Vec3;
use std::time::Instant;

mod options;
mod stats;
pub use options::{
    ReconstructOptions, DEFAULT_DECIMATION, DEFAULT_DECIMATION_ERROR, STEADY_CELL_SIZE,
    STEADY_FEATURE_ANGLE, STEADY_ISO_OFFSET, STEADY_MAX_INWARD, STEADY_NORMAL_SMOOTHING,
    STEADY_SMOOTHING_STEPS,
};
use stats::Recorder;
pub use stats::{peak_rss_bytes, ReconstructionStats, StageTiming};

/// Reconstructs the surface of one frame of particles (world units).
pub fn reconstruct(
    positions: &[Vec3],
    options: &ReconstructOptions,
) -> Result<(Surface, ReconstructionStats)> {
    reconstruct_source(positions, options, &|_| {}, &CancelToken::new())
}

/// [`reconstruct`] from any [`ParticleSource`], carrying its payload (the attributes it
/// holds, e.g. [`crate::io::particles::Particles`] after
/// [`crate::io::particles::Particles::select`]) to the surface. `progress` is told what the
/// run is doing ("tile 3/8", "decimation", ...); `cancel` stops it between tiles and
/// stages with [`crate::Error::Interrupted`]. A tiled run reads the source twice and
/// drops it before the first tile, so a mapped `.xyz` file or an owned `Vec` is never
/// held during the field stage.
pub fn reconstruct_source<S: ParticleSource>(
    source: S,
    options: &ReconstructOptions,
    progress: &dyn Fn(&str),
    cancel: &CancelToken,
) -> Result<(Surface, ReconstructionStats)> {
    reconstruct_sized(source, None, options, progress, cancel)
}

/// [`reconstruct_source`] for particles of several sizes: `radii` holds each particle's
/// radius (world units, input order; see `docs/radius.md`). Every length of the options
/// stays a multiple of the reference radius `options.field.particle_radius` (the cell
/// size, the influence radius, the decimation's bound); each particle's influence
/// radius, kernel, coverage ball, containment depth and isolated sphere follow its own
/// radius. Radii all equal to the reference radius give [`reconstruct_source`]'s surface
/// bit for bit. `None`: every particle has the reference radius.
pub fn reconstruct_sized<S: ParticleSource>(
    source: S,
    radii: Option<ParticleRadii>,
    options: &ReconstructOptions,
    progress: &dyn Fn(&str),
    cancel: &CancelToken,
) -> Result<(Surface, ReconstructionStats)> {
    let input = String::from("the particles given to reconstruct");
    crate::error::guard(
        move || input,
        || reconstruct_source_unguarded(source, radii, options, progress, cancel),
    )
}

/// Each particle's radius as a multiple of the reference radius `reference`, and the
/// largest; `None` when every radius is the reference (the plain run). Checks the count.
fn radius_ratios(
    radii: Option<ParticleRadii>,
    particles: usize,
    reference: f32,
) -> Result<Option<(Vec<f32>, f32)>> {
    let Some(radii) = radii else {
        return Ok(None);
    };
    radii.check("the particles given to reconstruct".as_ref(), particles)?;
    if radii.values.iter().all(|&v| v == reference) {
        return Ok(None);
    }
    // The radii become the ratios in place: the column is held once.
    let mut ratios = radii.values;
    for v in &mut ratios {
        *v /= reference;
    }
    let largest = ratios.iter().copied().fold(1.0f32, f32::max);
    Ok(Some((ratios, largest)))
}

/// The stage list.
fn reconstruct_source_unguarded<S: ParticleSource>(
    source: S,
    radii: Option<ParticleRadii>,
    options: &ReconstructOptions,
    progress: &dyn Fn(&str),
    cancel: &CancelToken,
) -> Result<(Surface, ReconstructionStats)> {
    options.validate()?;
    let ratios = radius_ratios(
        radii,
        source.particle_count(),
        options.field.particle_radius,
    )?;
    let sizes = ratios.as_ref().map(|(ratios, largest)| Sizes {
        ratios,
        largest: *largest,
    });
    let mut run = Recorder::new(source.particle_count(), progress, cancel);
    let layout = source.attribute_layout();
    let carries_payload = !layout.is_empty();
    // 1.–2. Plan the tiles and hold the particles for them.
    let (plan, store) = plan_and_store(source, sizes, options, &mut run)?;
    // 3. Isolated particles, field and marching cubes, tile by tile.
    let Tiles {
        mut fluid,
        isolated,
        decimated,
    } = march_tiles(&plan, &store, sizes, options, &mut run)?;
    // The particles are needed again to keep their centres under the surface and to
    // carry their payload to it.
    let store = (carries_payload || options.containment.is_some()).then_some(store);
    // 4. Decimation (already done tile by tile when the run was tiled).
    decimation_stage(&mut fluid, decimated, options, &mut run)?;
    // 5. Smoothing. Its vertex rings serve the shading normals too when no stage
    // between changes the triangles (containment only moves vertices).
    let mut rings = None;
    // How far the surface moved from the marching-cubes one, which encloses every centre
    // with coverage balls: not bounded once decimation has moved it.
    let encloses = options.decimate.is_none() && options.field.particle_coverage > 0.0;
    let mut moved_from_marched = encloses.then_some(0.0f32);
    if let Some(smooth_options) = &options.smooth {
        run.stage("smoothing", &mut fluid, |fluid, stats| {
            let (smoothed, built) = smooth_keeping_rings(fluid, smooth_options);
            if let Some(moved) = &mut moved_from_marched {
                // With an inward bound, what moved the surface off the centres: the moves
                // along it (the rest of the largest shift) slide the surface over itself.
                let shift = smoothed.max_shift as f32;
                *moved = smooth_options.max_inward.map_or(shift, |b| b.min(shift));
            }
            stats.smoothing = Some(smoothed);
            rings = built.filter(|_| options.keeps_rings());
            Ok(())
        })?;
    }
    // 6. Containment, on the surface as subdivision will make it.
    if let (Some(containment), Some(store)) = (&options.containment, &store) {
        run.stage("containment", &mut fluid, |fluid, stats| {
            let input = ContainmentInput {
                farthest_outside: moved_from_marched,
                levels: options.subdivide.levels + options.deferred_subdivision,
                centres: store,
                isolated: &isolated.centres,
                particle_radius: options.field.particle_radius,
                sizes,
                slab_triangles: containment.slab_triangles(options.tiles.memory_budget_bytes),
            };
            let contained = contain_centres(fluid, &input, containment, cancel)?;
            // The slabs' tables and lists leave holes in the heap that subdivision's large
            // arrays cannot fill.
            crate::allocator::release_freed_memory();
            stats.containment = Some(contained);
            Ok(())
        })?;
    }
    // 7. Subdivision.
    if options.subdivide.levels > 0 {
        run.stage("subdivision", &mut fluid, |fluid, _| {
            subdivide(fluid, &options.subdivide);
            Ok(())
        })?;
    }
    // 8. Spheres.
    let mut spheres = run.stage("spheres", &mut fluid, |_, stats| {
        let spheres = sphere_instances(isolated, sizes, options);
        stats.sphere_triangles = spheres.template.triangle_count() * spheres.centers.len();
        Ok(spheres)
    })?;
    // 9. Normals.
    run.stage("normals", &mut fluid, |fluid, stats| {
        shading_normals_with(fluid, &options.shading, rings.take());
        stats.fluid_triangles = fluid.triangle_count();
        Ok(())
    })?;
    // 10. Attributes at the final vertices and the sphere centres.
    if let Some(store) = store.filter(|_| carries_payload) {
        run.stage("attributes", &mut fluid, |fluid, _| {
            let sets = [fluid.positions.as_slice(), spheres.centers.as_slice()];
            let influence_radius = options.field.influence_radius_world();
            let mut values = transfer(&store, &plan, &layout, &sets, influence_radius, cancel)?;
            spheres.attributes = values.pop().expect("one list per set");
            fluid.attributes = values.pop().expect("one list per set");
            Ok(())
        })?;
    }
    Ok((Surface { fluid, spheres }, run.stats))
}

/// Stages 1–2: one pass over the source checks the particles and plans the tiles under
/// the memory budget; the store then holds the particles for the tiles (the source
/// itself, or a spill file on disk).
fn plan_and_store<S: ParticleSource>(
    source: S,
    sizes: Option<Sizes<'_>>,
    options: &ReconstructOptions,
    run: &mut Recorder,
) -> Result<(TilePlan, ParticleStore<S>)> {
    let clock = Instant::now();
    let plan = plan_tiles(
        &source,
        &options.field,
        sizes,
        &options.tiles,
        options.post_processing_cost(),
        options.decimate.is_some(),
        run.cancel(),
    )?;
    let store = ParticleStore::build(
        source,
        &plan,
        options.tiles.temp_dir.as_deref(),
        run.cancel(),
    )?;
    run.stats.tiles = TileStats {
        tile_blocks: plan.tile_blocks.unwrap_or(0) as u32,
        memory_budget_bytes: options.tiles.memory_budget_bytes,
        estimated_peak_bytes: plan.estimated_peak_bytes,
        kept_freed_memory: plan.kept_freed_memory,
        spill_bytes: store.spill_bytes(),
        spill_seconds: clock.elapsed().as_secs_f64(),
        tiles: plan.tile_count(),
        ..TileStats::default()
    };
    Ok((plan, store))
}

/// What the tiles made.
struct Tiles {
    /// The surface: marching cubes stitched, or decimated tile by tile.
    fluid: TriMesh,
    /// The isolated particles, in input order.
    isolated: Isolated,
    /// The decimation's figures when the tiles decimated their pieces.
    decimated: Option<DecimateStats>,
}

/// Stage 3: isolated particles split off, field and marching cubes tile by tile, into a
/// sink: decimated as they come when tiled and decimating, else stitched. Records the
/// neighbours, kernels, field and marching-cubes stages.
fn march_tiles<S: ParticleSource>(
    plan: &TilePlan,
    store: &ParticleStore<S>,
    sizes: Option<Sizes<'_>>,
    options: &ReconstructOptions,
    run: &mut Recorder,
) -> Result<Tiles> {
    let clock = Instant::now();
    let (cancel, progress) = (run.cancel(), run.progress_callback());
    let isolation_radius = options
        .isolated_sphere_level
        .map(|_| options.field.influence_radius_world() as f32);
    let on_tile = |tile: usize, tiles: usize| match tiles {
        1 => progress("field + marching cubes"),
        _ => progress(&format!(
            "field + marching cubes, tile {}/{tiles}",
            tile + 1
        )),
    };
    let mut tile_stats = std::mem::take(&mut run.stats.tiles);
    let run_into = |sink: &mut dyn TileSink, stats: &mut TileStats| {
        run_tiles(
            store,
            plan,
            &options.field,
            sizes,
            isolation_radius,
            sink,
            stats,
            cancel,
            &on_tile,
        )
    };
    let decimating = options.decimate.as_ref().filter(|_| plan.is_tiled());
    let (fluid, tiles_run, decimated) = match decimating {
        Some(decimate_options) => {
            let mut sink = TileDecimation::new(
                decimate_options,
                options.field.particle_radius,
                plan.spare_bytes,
            );
            let tiles_run = run_into(&mut sink, &mut tile_stats)?;
            run.stats.marching_cubes.triangles = sink.marching_triangles();
            tile_stats.stitch_seconds = sink.stitch_seconds;
            let (mesh, decimation, seconds) = sink.finish();
            tile_stats.decimation_seconds = seconds;
            (mesh, tiles_run, Some(decimation))
        }
        None => {
            let mut sink = StitchSink::default();
            let tiles_run = run_into(&mut sink, &mut tile_stats)?;
            let clock = Instant::now();
            let (mesh, marching_cubes, bytes) = sink.finish();
            run.stats.marching_cubes = marching_cubes;
            tile_stats.surface_bytes = bytes;
            tile_stats.stitch_seconds = clock.elapsed().as_secs_f64();
            (mesh, tiles_run, None)
        }
    };
    let stats = &mut run.stats;
    stats.tiles = tile_stats;
    stats.isolated_particles = tiles_run.isolated.centres.len();
    stats.field = tiles_run.field;
    stats.marching_cubes_triangles = stats.marching_cubes.triangles;
    let kernels = options.field.kernel == crate::field::Kernel::Anisotropic;
    let elapsed = stats.tiles.spill_seconds + clock.elapsed().as_secs_f64();
    for (stage, seconds) in stats.tiles.stage_seconds(elapsed, kernels) {
        let triangles = match stage {
            "marching cubes" => stats.marching_cubes.triangles,
            _ => 0,
        };
        stats.push_stage(stage, seconds, triangles);
    }
    Ok(Tiles {
        fluid,
        isolated: tiles_run.isolated,
        decimated,
    })
}

/// Stage 4: quadric decimation of the stitched surface, or the figures of the tiles'.
fn decimation_stage(
    fluid: &mut TriMesh,
    decimated: Option<DecimateStats>,
    options: &ReconstructOptions,
    run: &mut Recorder,
) -> Result<()> {
    match (decimated, &options.decimate) {
        (Some(decimated), _) => {
            run.check()?;
            let seconds = run.stats.tiles.decimation_seconds;
            run.stats.decimation = Some(decimated);
            run.stats
                .push_stage("decimation", seconds, fluid.triangle_count());
            Ok(())
        }
        (None, Some(decimate_options)) => run.stage("decimation", fluid, |fluid, stats| {
            stats.decimation = Some(decimate(fluid, decimate_options));
            Ok(())
        }),
        (None, None) => Ok(()),
    }
}

/// Stage 8: one icosphere of radius `r` per isolated particle (none without spheres),
/// scaled to each particle's own radius when they differ.
fn sphere_instances(
    isolated: Isolated,
    sizes: Option<Sizes<'_>>,
    options: &ReconstructOptions,
) -> SphereInstances {
    match options.isolated_sphere_level {
        Some(level) if !isolated.centres.is_empty() => SphereInstances {
            template: crate::isolated::icosphere(level, options.field.particle_radius),
            scales: match sizes {
                Some(s) => isolated
                    .indices
                    .iter()
                    .map(|&i| s.ratios[i as usize])
                    .collect(),
                None => Vec::new(),
            },
            centers: isolated.centres,
            attributes: Vec::new(),
        },
        _ => SphereInstances::default(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::particles::read_particles;
    use crate::isolated::split_isolated;
    use crate::shading::shading_normals;

    #[test]
    fn raw_is_the_marching_cubes_surface_of_the_field_alone() {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/datasets/double_dambreak/ParticleData_Fluid_9.xyz"
        );
        let positions = read_particles(path.as_ref(), None).unwrap().positions;
        let options = ReconstructOptions::raw(0.025);
        let (surface, stats) = reconstruct(&positions, &options).unwrap();
        let stages: Vec<&str> = stats.stages.iter().map(|s| s.stage.as_str()).collect();
        assert_eq!(
            stages,
            [
                "neighbours",
                "kernels",
                "field",
                "marching cubes",
                "spheres",
                "normals"
            ]
        );
        assert!(stats.decimation.is_none() && stats.smoothing.is_none());
        assert!(stats.containment.is_none());
        // The documented entries, field then marching cubes, on the particles that are
        // not isolated: the same surface, bit for bit.
        let radius = options.field.influence_radius_world() as f32;
        let (kept, alone) = split_isolated(&positions, radius);
        assert!(!alone.is_empty());
        assert_eq!(surface.spheres.centers, alone);
        let (field, _) = crate::field::compute_field(&kept, &options.field).unwrap();
        let (mesh, _) = crate::marching_cubes::extract_surface(&field);
        assert_eq!(surface.fluid.triangles, mesh.triangles);
        assert_eq!(surface.fluid.positions, mesh.positions);
        assert_eq!(stats.fluid_triangles, stats.marching_cubes_triangles);
    }

    #[test]
    fn the_shading_normals_from_the_smoothings_rings_are_those_of_fresh_ones() {
        // The steady surface hands the smoothing's rings to the shading normals across
        // containment (which moves vertices, not triangles): the normals are the ones
        // the public entry computes from the output mesh alone, bit for bit.
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/datasets/double_dambreak/ParticleData_Fluid_9.xyz"
        );
        let positions = read_particles(path.as_ref(), None).unwrap().positions;
        let options = ReconstructOptions::steady(0.025);
        assert!(options.keeps_rings());
        let (surface, stats) = reconstruct(&positions, &options).unwrap();
        assert!(stats.containment.as_ref().unwrap().moved_vertices > 0);
        let mut fresh = surface.fluid.clone();
        shading_normals(&mut fresh, &options.shading);
        assert!(!fresh.normals.is_empty());
        assert_eq!(fresh.normals, surface.fluid.normals);
        // Subdivision changes the triangles: the rings are not kept.
        let mut subdivided = options.clone();
        subdivided.subdivide.levels = 1;
        assert!(!subdivided.keeps_rings());
    }
}
