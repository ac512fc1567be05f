//! The whole reconstruction of one frame, stage by stage (Akinci et al. 2013, Fig. 2):
//!
//! 1. plan: one pass over the particles checks them and cuts the lattice into tiles under
//!    the memory budget ([`crate::tiles::plan_tiles`]);
//! 2. store: the particles held for the tiles, in memory or spilled to disk;
//! 3. tiles: isolated particles split off, the Solenthaler field ([`crate::field`]) and
//!    marching cubes ([`crate::marching_cubes`]), tile by tile, into a sink that
//!    stitches the pieces exactly, or decimates each as it comes
//!    ([`crate::decimation::TileDecimation`]);
//! 4. quadric decimation ([`crate::decimation`]), unless the tiles did it;
//! 5. Taubin smoothing of the decimated mesh ([`crate::smoothing`]);
//! 6. containment: every non-isolated particle centre pushed under the surface that
//!    subdivision will make ([`crate::containment`]);
//! 7. Loop subdivision ([`crate::subdivision`]);
//! 8. icospheres of radius `r` at the isolated particles ([`crate::isolated`]);
//! 9. area-weighted vertex normals;
//! 10. the particles' payload carried to the final vertices ([`crate::attributes`]).
//!
//! Every stage is timed; [`ReconstructionStats`] is the paper's Table 1 for one frame.

use crate::attributes::transfer;
use crate::cancel::CancelToken;
use crate::containment::{contain_centres, ContainmentOptions, ContainmentStats};
use crate::decimation::TileDecimation;
use crate::decimation::{decimate, DecimateOptions, DecimateStats};
use crate::error::Result;
use crate::field::{FieldOptions, FieldStats, Kernel};
use crate::io::particles::ParticleSource;
use crate::marching_cubes::MarchingCubesStats;
use crate::mesh::{SphereInstances, Surface};
use crate::neighbors::find_isolated;
use crate::smoothing::{smooth, SmoothOptions, SmoothStats};
use crate::subdivision::{subdivide, SubdivideOptions};
use crate::tiles::{
    output_bytes_per_triangle, plan_tiles, run_tiles, ParticleStore, StitchSink, TileOptions,
    TileSink, TileStats,
};
use glam::Vec3;
use std::time::Instant;

/// Fraction of the triangles the default decimation removes. Above the paper's 0.8: the
/// default anisotropic surface sits on the outer particles instead of inside them, so it
/// is larger and marching cubes gives it about 2 % more triangles; 0.81 keeps the default
/// output at most as large as the isotropic 0.8 surface on the shipped frames
/// (`docs/quality.md`).
pub const DEFAULT_DECIMATION: f32 = 0.81;

/// Error bound of the default decimation, multiples of the particle radius: no collapse
/// moves the surface by more than this (RMS distance to the original planes), so where
/// the fraction would take more (thin sheets and filaments of violent splashes),
/// decimation stops short of it. Unbounded, decimation collapses one-particle sheets into
/// fins that cross the surface elsewhere; particle centres then end up outside where no
/// local measure can tell (see [`crate::containment`]). On calm frames it does not bind:
/// dam break frame 25, the analytic sphere and box come out the same.
pub const DEFAULT_DECIMATION_ERROR: f32 = 0.1;

/// Options of the whole pipeline. [`Self::new`] gives meniscus's defaults,
/// [`Self::paper`] the pipeline of Akinci et al. 2013 exactly.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ReconstructOptions {
    /// Field parameters (particle radius, influence radius, cell size, thresholds).
    pub field: FieldOptions,
    /// Icosphere subdivision level for isolated particles, or `None` to keep isolated
    /// particles in the field like any other. Default `Some(2)` (320 triangles).
    pub isolated_sphere_level: Option<u32>,
    /// How the lattice is cut into tiles. Default: one tile.
    pub tiles: TileOptions,
    /// Quadric decimation, or `None` to skip it. Default: remove [`DEFAULT_DECIMATION`]
    /// of the triangles, no collapse beyond [`DEFAULT_DECIMATION_ERROR`].
    pub decimate: Option<DecimateOptions>,
    /// Taubin smoothing after decimation, or `None` to skip it. Default: 2 steps of
    /// λ 0.3, μ −0.31 ([`SmoothOptions::default`]).
    pub smooth: Option<SmoothOptions>,
    /// Loop subdivision steps after decimation. Default 1 (0 skips it).
    pub subdivide: SubdivideOptions,
    /// Loop subdivision steps left to whoever decodes the surface (a `.mseq` archive
    /// stores the control mesh and subdivides on decoding): not run here, but the
    /// containment stage measures the surface as it will be decoded. Default 0.
    pub deferred_subdivision: u32,
    /// Keeping every non-isolated particle centre under the surface after decimation and
    /// subdivision, or `None` to leave the surface as they made it. Default: at least
    /// 0.25 r deep.
    pub containment: Option<ContainmentOptions>,
}

impl ReconstructOptions {
    /// Field, marching cubes and isolated spheres only: no mesh post-processing.
    pub fn raw(particle_radius: f32) -> Self {
        ReconstructOptions {
            decimate: None,
            subdivide: SubdivideOptions { levels: 0 },
            ..Self::new(particle_radius)
        }
    }

    /// meniscus's defaults for particle radius `r` (world units): the paper's stages, with
    /// anisotropic kernels ([`Kernel::Anisotropic`]), decimation by
    /// [`DEFAULT_DECIMATION`] within [`DEFAULT_DECIMATION_ERROR`], Taubin smoothing
    /// ([`SmoothOptions::default`]), the coverage balls of [`FieldOptions::new`] and every
    /// non-isolated centre kept inside ([`ContainmentOptions::default`]).
    pub fn new(particle_radius: f32) -> Self {
        let mut field = FieldOptions::new(particle_radius);
        field.kernel = Kernel::Anisotropic;
        ReconstructOptions {
            field,
            decimate: Some(DecimateOptions {
                target_reduction: Some(DEFAULT_DECIMATION),
                max_error: Some(DEFAULT_DECIMATION_ERROR * particle_radius),
                ..Default::default()
            }),
            smooth: Some(SmoothOptions::default()),
            containment: Some(ContainmentOptions::default()),
            ..Self::paper(particle_radius)
        }
    }

    /// The pipeline of Akinci et al. 2013 exactly: the Solenthaler field with isotropic
    /// kernels and no coverage balls, decimation by 80 % without an error bound, no
    /// smoothing, one Loop step, icospheres of level 2 for isolated particles, no
    /// containment.
    pub fn paper(particle_radius: f32) -> Self {
        let mut field = FieldOptions::new(particle_radius);
        field.particle_coverage = 0.0;
        ReconstructOptions {
            field,
            isolated_sphere_level: Some(2),
            tiles: TileOptions::default(),
            decimate: Some(DecimateOptions::default()),
            smooth: None,
            subdivide: SubdivideOptions::default(),
            deferred_subdivision: 0,
            containment: None,
        }
    }
}

/// Time and output size of one stage.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct StageTiming {
    /// Stage name.
    pub stage: String,
    /// Wall time, seconds.
    pub seconds: f64,
    /// Triangles of the fluid surface after the stage (0 before marching cubes).
    pub triangles: usize,
    /// Peak resident memory of the process at the end of the stage (Linux), bytes.
    pub peak_rss_bytes: Option<u64>,
}

/// Everything measured while reconstructing one frame.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct ReconstructionStats {
    /// Input particles.
    pub particles: usize,
    /// Particles emitted as icospheres instead of entering the field.
    pub isolated_particles: usize,
    /// Field stage figures.
    pub field: FieldStats,
    /// Marching-cubes figures.
    pub marching_cubes: MarchingCubesStats,
    /// Tiling figures.
    pub tiles: TileStats,
    /// Decimation figures, when it ran.
    pub decimation: Option<DecimateStats>,
    /// Smoothing figures, when it ran.
    pub smoothing: Option<SmoothStats>,
    /// Containment figures, when it ran.
    pub containment: Option<ContainmentStats>,
    /// Triangles straight out of marching cubes.
    pub marching_cubes_triangles: usize,
    /// Per-stage wall times in pipeline order.
    pub stages: Vec<StageTiming>,
    /// Triangles of the final fluid surface.
    pub fluid_triangles: usize,
    /// Triangles of all isolated-particle spheres together.
    pub sphere_triangles: usize,
}

impl ReconstructionStats {
    /// Records a stage that took `seconds`.
    pub fn push_stage(&mut self, stage: &str, seconds: f64, triangles: usize) {
        self.stages.push(StageTiming {
            stage: stage.to_string(),
            seconds,
            triangles,
            peak_rss_bytes: peak_rss_bytes(),
        });
    }

    /// Sum of all stage times, seconds.
    pub fn total_seconds(&self) -> f64 {
        self.stages.iter().map(|s| s.seconds).sum()
    }

    /// A plain-text table of the stages (the paper's Table 1 for one frame).
    pub fn table(&self) -> String {
        let mut out = format!(
            "{:<18} {:>10} {:>12} {:>14}\n",
            "stage", "time [ms]", "triangles", "peak RSS [MiB]"
        );
        for s in &self.stages {
            let rss = s
                .peak_rss_bytes
                .map(|b| format!("{:.1}", b as f64 / (1 << 20) as f64))
                .unwrap_or_else(|| "-".into());
            out += &format!(
                "{:<18} {:>10.1} {:>12} {:>14}\n",
                s.stage,
                s.seconds * 1e3,
                s.triangles,
                rss
            );
        }
        out += &format!(
            "{:<18} {:>10.1} {:>12}\n",
            "total",
            self.total_seconds() * 1e3,
            self.fluid_triangles + self.sphere_triangles
        );
        out
    }
}

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
    let input = String::from("the particles given to reconstruct");
    crate::error::guard(
        move || input,
        || reconstruct_source_unguarded(source, options, progress, cancel),
    )
}

fn reconstruct_source_unguarded<S: ParticleSource>(
    source: S,
    options: &ReconstructOptions,
    progress: &dyn Fn(&str),
    cancel: &CancelToken,
) -> Result<(Surface, ReconstructionStats)> {
    options.field.validate()?;
    if let Some(smooth_options) = &options.smooth {
        smooth_options.validate()?;
    }
    let mut stats = ReconstructionStats {
        particles: source.particle_count(),
        ..Default::default()
    };
    let r = options.field.particle_radius;
    let layout = source.attribute_layout();

    // 1.–2. Plan the tiles and hold the particles for them.
    let clock = Instant::now();
    let decimating = options.decimate.as_ref();
    let plan = plan_tiles(
        &source,
        &options.field,
        &options.tiles,
        output_bytes_per_triangle(
            decimating.map(|d| d.target_reduction.unwrap_or(0.8)),
            options.smooth.is_some(),
            options.containment.is_some(),
            options.subdivide.levels,
        ),
        decimating.is_some(),
        cancel,
    )?;
    let store = ParticleStore::build(source, &plan, options.tiles.temp_dir.as_deref(), cancel)?;
    stats.tiles = TileStats {
        tile_blocks: plan.tile_blocks.unwrap_or(0) as u32,
        memory_budget_bytes: options.tiles.memory_budget_bytes,
        estimated_peak_bytes: plan.estimated_peak_bytes,
        kept_freed_memory: plan.kept_freed_memory,
        spill_bytes: store.spill_bytes(),
        spill_seconds: clock.elapsed().as_secs_f64(),
        tiles: plan.tile_count(),
        ..TileStats::default()
    };

    // 3. Isolated particles leave the field; field and marching cubes, tile by tile, into
    // a sink: decimated as they come when tiled, else stitched.
    let isolation_radius = options
        .isolated_sphere_level
        .map(|_| options.field.influence_radius_world() as f32);
    let on_tile = |tile: usize, tiles: usize| {
        if tiles > 1 {
            progress(&format!(
                "field + marching cubes, tile {}/{tiles}",
                tile + 1
            ))
        } else {
            progress("field + marching cubes")
        }
    };
    let run_into = |sink: &mut dyn TileSink, stats: &mut TileStats| {
        run_tiles(
            &store,
            &plan,
            &options.field,
            isolation_radius,
            sink,
            stats,
            cancel,
            &on_tile,
        )
    };
    let (mut fluid, tiles_run, tile_decimation) = match decimating.filter(|_| plan.is_tiled()) {
        Some(decimate_options) => {
            let mut sink = TileDecimation::new(decimate_options, r);
            let run = run_into(&mut sink, &mut stats.tiles)?;
            stats.marching_cubes.triangles = sink.marching_triangles();
            stats.tiles.stitch_seconds = sink.stitch_seconds;
            let (mesh, decimation, seconds) = sink.finish();
            stats.tiles.decimation_seconds = seconds;
            (mesh, run, Some(decimation))
        }
        None => {
            let mut sink = StitchSink::default();
            let run = run_into(&mut sink, &mut stats.tiles)?;
            let clock = Instant::now();
            let (mesh, marching_cubes, bytes) = sink.finish();
            stats.marching_cubes = marching_cubes;
            stats.tiles.surface_bytes = bytes;
            stats.tiles.stitch_seconds = clock.elapsed().as_secs_f64();
            (mesh, run, None)
        }
    };
    // The particles are needed again to keep their centres under the surface and to
    // carry their payload to it.
    let store = (!layout.is_empty() || options.containment.is_some()).then_some(store);
    let isolated_centers = tiles_run.isolated;
    stats.isolated_particles = isolated_centers.len();
    stats.field = tiles_run.field;
    let t = &stats.tiles;
    let untimed = clock.elapsed().as_secs_f64()
        - (t.spill_seconds
            + t.neighbour_seconds
            + t.kernel_seconds
            + t.field_seconds
            + t.marching_seconds
            + t.stitch_seconds
            + t.decimation_seconds);
    let kernels = t.kernel_seconds;
    let (neighbours, field, marching, stitching) = (
        t.spill_seconds + t.neighbour_seconds + untimed,
        t.field_seconds,
        t.marching_seconds,
        t.stitch_seconds,
    );
    stats.marching_cubes_triangles = stats.marching_cubes.triangles;
    stats.push_stage("neighbours", neighbours, 0);
    if options.field.kernel == crate::field::Kernel::Anisotropic {
        stats.push_stage("kernels", kernels, 0);
    }
    stats.push_stage("field", field, 0);
    stats.push_stage(
        "marching cubes",
        marching + stitching,
        stats.marching_cubes.triangles,
    );

    cancel.check()?;
    // 4. Decimation (already done tile by tile when the run was tiled).
    progress("decimation");
    if let Some(tile_decimation) = tile_decimation {
        stats.decimation = Some(tile_decimation);
        stats.push_stage(
            "decimation",
            stats.tiles.decimation_seconds,
            fluid.triangle_count(),
        );
    } else if let Some(decimate_options) = decimating {
        let clock = Instant::now();
        stats.decimation = Some(decimate(&mut fluid, decimate_options));
        stats.push_stage(
            "decimation",
            clock.elapsed().as_secs_f64(),
            fluid.triangle_count(),
        );
    }

    cancel.check()?;
    // 5. Smoothing.
    if let Some(smooth_options) = &options.smooth {
        progress("smoothing");
        let clock = Instant::now();
        stats.smoothing = Some(smooth(&mut fluid, smooth_options));
        stats.push_stage(
            "smoothing",
            clock.elapsed().as_secs_f64(),
            fluid.triangle_count(),
        );
    }

    cancel.check()?;
    // 6. Containment, on the surface as subdivision will make it.
    let levels = options.subdivide.levels;
    if let (Some(containment), Some(store)) = (&options.containment, &store) {
        progress("containment");
        let clock = Instant::now();
        let contained = contain_centres(
            &mut fluid,
            levels + options.deferred_subdivision,
            store,
            &isolated_centers,
            r,
            containment,
            containment.slab_triangles(options.tiles.memory_budget_bytes),
            cancel,
        )?;
        // The slabs' tables and lists leave holes in the heap that subdivision's large
        // arrays cannot fill.
        crate::allocator::release_freed_memory();
        stats.push_stage(
            "containment",
            clock.elapsed().as_secs_f64(),
            fluid.triangle_count(),
        );
        stats.containment = Some(contained);
    }

    cancel.check()?;
    // 7. Subdivision.
    progress("subdivision");
    if levels > 0 {
        let clock = Instant::now();
        subdivide(&mut fluid, &options.subdivide);
        stats.push_stage(
            "subdivision",
            clock.elapsed().as_secs_f64(),
            fluid.triangle_count(),
        );
    }

    cancel.check()?;
    // 8. Spheres.
    let clock = Instant::now();
    let mut spheres = match options.isolated_sphere_level {
        Some(level) if !isolated_centers.is_empty() => SphereInstances {
            template: crate::isolated::icosphere(level, r),
            centers: isolated_centers,
            attributes: Vec::new(),
        },
        _ => SphereInstances::default(),
    };
    stats.sphere_triangles = spheres.template.triangle_count() * spheres.centers.len();
    stats.push_stage(
        "spheres",
        clock.elapsed().as_secs_f64(),
        fluid.triangle_count(),
    );

    // 9. Normals.
    let clock = Instant::now();
    fluid.compute_normals();
    stats.fluid_triangles = fluid.triangle_count();
    stats.push_stage(
        "normals",
        clock.elapsed().as_secs_f64(),
        fluid.triangle_count(),
    );

    // 10. Attributes at the final vertices and the sphere centres.
    if let Some(store) = store {
        cancel.check()?;
        progress("attributes");
        let clock = Instant::now();
        let influence_radius = options.field.influence_radius_world();
        let sets = [fluid.positions.as_slice(), spheres.centers.as_slice()];
        let mut values = transfer(&store, &plan, &layout, &sets, influence_radius, cancel)?;
        spheres.attributes = values.pop().expect("one list per set");
        fluid.attributes = values.pop().expect("one list per set");
        drop(store);
        stats.push_stage(
            "attributes",
            clock.elapsed().as_secs_f64(),
            fluid.triangle_count(),
        );
    }

    Ok((Surface { fluid, spheres }, stats))
}

/// Peak resident memory of this process so far (Linux `VmHWM`), bytes.
pub fn peak_rss_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// Splits `positions` into (particles with a neighbour closer than `radius`, isolated
/// particle centres), both in input order.
pub fn split_isolated(positions: &[Vec3], radius: f32) -> (Vec<Vec3>, Vec<Vec3>) {
    let isolated = find_isolated(positions, radius);
    let mut kept = Vec::with_capacity(positions.len());
    let mut alone = Vec::new();
    for (p, lonely) in positions.iter().zip(isolated) {
        if lonely {
            alone.push(*p);
        } else {
            kept.push(*p);
        }
    }
    (kept, alone)
}
