//! The `meniscus` command line: argument parsing, progress display and reports. All
//! reconstruction logic lives in the library.

use clap::{Args, Parser, Subcommand};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use meniscus::io::mesh::MeshWriteOptions;
use meniscus::io::particles::ParticleFormat;
use meniscus::job::{peak_rss_bytes, plan_frames, run_frames, FrameReport, JobOptions};
use meniscus::pipeline::ReconstructOptions;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

#[derive(Parser)]
#[command(
    name = "meniscus",
    version,
    about = "Surface reconstruction for particle-based fluids (Akinci et al. 2013 pipeline)"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Reconstruct the surface of one particle file or a `{}` sequence of them.
    Reconstruct(ReconstructArgs),
}

#[derive(Args)]
struct ReconstructArgs {
    /// Particle file (.xyz, .vtk, .ply, .bgeo), or a pattern with `{}` for the frame number.
    input: String,
    /// Output mesh (.glb, .gltf, .ply, .obj, .vtk); a pattern with `{}` for sequences.
    #[arg(short, long)]
    output: String,
    /// Particle radius r, world units (half the rest spacing).
    #[arg(short = 'r', long)]
    particle_radius: f32,
    /// Influence radius R, multiples of r.
    #[arg(long, default_value_t = 4.0)]
    influence_radius: f32,
    /// Marching-cubes cell size h, multiples of r.
    #[arg(short = 'c', long, default_value_t = 1.0)]
    cell_size: f32,
    /// Lower eigenvalue threshold t_low of the Solenthaler concavity factor.
    #[arg(long, default_value_t = 0.4)]
    t_low: f32,
    /// Upper eigenvalue threshold t_high of the Solenthaler concavity factor.
    #[arg(long, default_value_t = 3.5)]
    t_high: f32,
    /// Icosphere subdivision level for isolated particles (no neighbour within R), or
    /// `off` to leave them in the field.
    #[arg(long, default_value = "2")]
    isolated_spheres: String,
    /// Input format, overriding the extension (xyz, vtk, ply, bgeo).
    #[arg(long)]
    input_format: Option<ParticleFormat>,
    /// First frame of a sequence (inclusive).
    #[arg(long, allow_negative_numbers = true)]
    start: Option<i64>,
    /// Last frame of a sequence (inclusive).
    #[arg(long, allow_negative_numbers = true)]
    end: Option<i64>,
    /// Skip frames whose output already exists.
    #[arg(long)]
    skip_existing: bool,
    /// Worker threads (default: all cores). Output does not depend on it.
    #[arg(long)]
    threads: Option<usize>,
    /// Write per-frame, per-stage statistics as JSON to this file.
    #[arg(long)]
    stats: Option<PathBuf>,
    /// Do not write vertex normals.
    #[arg(long)]
    no_normals: bool,
    /// No progress bar and no timing table.
    #[arg(short, long)]
    quiet: bool,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match cli.command {
        Command::Reconstruct(args) => match reconstruct(&args) {
            Ok(()) => ExitCode::SUCCESS,
            Err(message) => {
                eprintln!("error: {message}");
                ExitCode::FAILURE
            }
        },
    }
}

fn parse_level(value: &str, option: &str) -> Result<Option<u32>, String> {
    match value {
        "off" | "none" => Ok(None),
        v => v
            .parse()
            .map(Some)
            .map_err(|_| format!("{option} takes a level (0, 1, 2, ...) or `off`, got {v:?}")),
    }
}

fn options_from(args: &ReconstructArgs) -> Result<ReconstructOptions, String> {
    let mut options = ReconstructOptions::new(args.particle_radius);
    options.field.influence_radius = args.influence_radius;
    options.field.cell_size = args.cell_size;
    options.field.t_low = args.t_low;
    options.field.t_high = args.t_high;
    options.isolated_sphere_level = parse_level(&args.isolated_spheres, "--isolated-spheres")?;
    options.field.validate().map_err(|e| e.to_string())?;
    Ok(options)
}

fn reconstruct(args: &ReconstructArgs) -> Result<(), String> {
    if let Some(threads) = args.threads {
        if threads == 0 {
            return Err("--threads must be at least 1".into());
        }
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build_global()
            .map_err(|e| e.to_string())?;
    }
    let options = options_from(args)?;
    let plan =
        plan_frames(&args.input, &args.output, args.start, args.end).map_err(|e| e.to_string())?;
    let job = JobOptions {
        input_format: args.input_format,
        write: MeshWriteOptions {
            normals: !args.no_normals,
            ..MeshWriteOptions::default()
        },
        skip_existing: args.skip_existing,
    };
    let bar = if args.quiet {
        ProgressBar::hidden()
    } else {
        let bar =
            ProgressBar::with_draw_target(Some(plan.len() as u64), ProgressDrawTarget::stderr());
        bar.set_style(
            ProgressStyle::with_template(
                "{spinner} [{elapsed_precise}] {bar:30} {pos}/{len} frames  {msg}",
            )
            .expect("valid template"),
        );
        bar.enable_steady_tick(std::time::Duration::from_millis(120));
        bar
    };
    let clock = Instant::now();
    let result = run_frames(
        &plan,
        &options,
        &job,
        &mut |_, frame| bar.set_prefix(frame.input.display().to_string()),
        &mut |stage| bar.set_message(stage.to_string()),
        &mut |report: &FrameReport| {
            bar.inc(1);
            if !args.quiet && plan.len() == 1 {
                bar.suspend(|| eprint!("{}", report.reconstruction.table()));
            }
        },
    );
    bar.finish_and_clear();
    let reports = result.map_err(|e| e.to_string())?;
    let total = clock.elapsed().as_secs_f64();
    if !args.quiet {
        summarize(&reports, total);
    }
    if let Some(path) = &args.stats {
        let json = serde_json::json!({
            "options": options,
            "frames": reports,
            "total_seconds": total,
            "peak_rss_bytes": peak_rss_bytes(),
        });
        let text = serde_json::to_string_pretty(&json).map_err(|e| e.to_string())?;
        std::fs::write(path, text).map_err(|e| format!("{}: {e}", path.display()))?;
    }
    Ok(())
}

fn summarize(reports: &[FrameReport], total: f64) {
    let done: Vec<&FrameReport> = reports.iter().filter(|r| !r.skipped).collect();
    let skipped = reports.len() - done.len();
    let triangles: usize = done
        .iter()
        .map(|r| r.reconstruction.fluid_triangles + r.reconstruction.sphere_triangles)
        .sum();
    eprintln!(
        "{} frame(s) reconstructed{} in {:.2} s, {} triangles written, peak memory {}",
        done.len(),
        if skipped > 0 {
            format!(", {skipped} skipped")
        } else {
            String::new()
        },
        total,
        triangles,
        peak_rss_bytes()
            .map(|b| format!("{:.1} MiB", b as f64 / (1 << 20) as f64))
            .unwrap_or_else(|| "unknown".into()),
    );
}
