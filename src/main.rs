//! The `meniscus` command line: argument parsing, progress display and reports. All
//! reconstruction logic lives in the library.

#[path = "cli/archive.rs"]
mod archive_command;
#[path = "cli/radius.rs"]
mod radius_check;
#[path = "cli/warnings.rs"]
mod warnings;

use archive_command::{archive, ArchiveCommand};
use clap::{ArgMatches, Args, CommandFactory, FromArgMatches, Parser, Subcommand};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use meniscus::attributes::AttributeSelection;
use meniscus::io::mesh::MeshWriteOptions;
use meniscus::io::particles::ParticleFormat;
use meniscus::io::usd::{UpAxis, UsdDroplets};
use meniscus::job::{
    check_outputs, peak_rss_bytes, plan_frames, run_frames, FrameReport, FrameStatus, JobOptions,
};
use meniscus::pipeline::ReconstructOptions;
use meniscus::settings::ReconstructSettings;
use radius_check::resolve_radius;
use warnings::ineffective_options;

use std::path::{Path, PathBuf};
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
    Reconstruct(Box<ReconstructArgs>),
    /// Inspect, check, extract from or fill a `.mseq` mesh-sequence archive.
    #[command(subcommand)]
    Archive(ArchiveCommand),
}

/// The playback rate of a sequence in one file, and a USD stage's metadata.
#[derive(Args)]
struct StageArgs {
    /// Playback rate of a `{}` sequence written into one .glb/.gltf, and the time codes
    /// per second of a USD stage, frames per second.
    #[arg(long, default_value_t = 24.0)]
    fps: f64,
    /// Up axis of a USD stage output: Y (the simulators' convention) or Z.
    #[arg(long, default_value_t = UpAxis::Y)]
    up_axis: UpAxis,
    /// Meters in one world unit of a USD stage output (its `metersPerUnit`).
    #[arg(allow_negative_numbers = true, long, default_value_t = 1.0)]
    meters_per_unit: f64,
    /// Isolated particles of a USD stage: `points` (a point cloud with widths and
    /// velocities, which renderers draw as spheres and blur) or `instancer` (a point
    /// instancer of the sphere mesh).
    #[arg(long, value_name = "points|instancer", default_value_t = UsdDroplets::Points)]
    usd_droplets: UsdDroplets,
}

/// Frame selection of a sequence: a range, or a list and a share as render farms give
/// them.
#[derive(Args)]
struct FarmArgs {
    /// First frame of a sequence (inclusive).
    #[arg(long, allow_negative_numbers = true)]
    start: Option<i64>,
    /// Last frame of a sequence (inclusive).
    #[arg(long, allow_negative_numbers = true)]
    end: Option<i64>,
    /// Frames to take, instead of --start/--end: `1-100`, `1-100:2` (every second),
    /// `1,5,7-20`; sorted, each once. Every selected frame needs a file.
    #[arg(long, value_name = "LIST", allow_hyphen_values = true, conflicts_with_all = ["start", "end"])]
    frames: Option<meniscus::sequence::FrameSelection>,
    /// Take every N-th frame of the selection starting at the I-th (0-based): one of N
    /// machines' share, round-robin.
    #[arg(long, value_name = "I/N")]
    shard: Option<meniscus::sequence::Shard>,
}

impl FarmArgs {
    fn choice(&self) -> meniscus::sequence::FrameChoice {
        meniscus::sequence::FrameChoice {
            start: self.start,
            end: self.end,
            frames: self.frames.clone(),
            shard: self.shard,
        }
    }
}

#[derive(Args)]
struct ReconstructArgs {
    /// Particle file (.xyz, .vtk, .vtu, .vtp, .ply, .bgeo), or a sequence: a pattern with
    /// `{}` for the frame number, or a ParaView collection (.pvd; frames 0, 1, 2, … by
    /// timestep).
    input: String,
    /// Output mesh (.glb, .gltf, .ply, .obj, .vtk); a pattern with `{}` for sequences.
    #[arg(short, long)]
    output: String,
    /// Particle radius r, world units (half the rest spacing). Default: estimated from
    /// the first frame's spacing (printed). A given r far from that estimate is warned
    /// about (outside 0.25×–4×) or refused (outside 0.05×–20×).
    #[arg(allow_negative_numbers = true, short = 'r', long)]
    particle_radius: Option<f32>,
    /// Take `-r` as given, without comparing it with the particles' spacing.
    #[arg(long)]
    no_radius_check: bool,
    /// The point attribute holding each particle's radius (`none`: ignore it). Default:
    /// Houdini's `pscale` when the input has it. Without `-r`, r is its median; a given
    /// `-r` is checked against that median.
    #[arg(long, value_name = "NAME")]
    radius_attribute: Option<meniscus::radius::RadiusAttribute>,
    /// The radius the run uses: `-r`, or the estimate.
    #[arg(skip)]
    radius: f32,
    /// Influence radius R, multiples of r.
    #[arg(allow_negative_numbers = true, long, default_value_t = defaults().influence_radius)]
    influence_radius: f32,
    /// Marching-cubes cell size h, multiples of r.
    #[arg(
        allow_negative_numbers = true,
        short = 'c',
        long,
        default_value_t = defaults().cell_size
    )]
    cell_size: f32,
    /// Lower eigenvalue threshold t_low of the Solenthaler concavity factor (isotropic
    /// kernel).
    #[arg(long, default_value_t = defaults().t_low)]
    t_low: f32,
    /// Upper eigenvalue threshold t_high of the Solenthaler concavity factor (isotropic
    /// kernel).
    #[arg(long, default_value_t = defaults().t_high)]
    t_high: f32,
    /// Icosphere subdivision level for isolated particles (no neighbour within R), or
    /// `off` to leave them in the field.
    #[arg(long, default_value_t = off_or(defaults().isolated_spheres))]
    isolated_spheres: String,
    #[arg(long, help = with_defaults(DECIMATE_HELP, |s| s.decimate))]
    decimate: Option<String>,
    #[arg(long, allow_hyphen_values = true, help = with_defaults(DECIMATE_ERROR_HELP, |s| off_or(s.decimate_error)))]
    decimate_error: Option<String>,
    #[arg(long, help = with_defaults(SMOOTH_HELP, |s| s.smooth))]
    smooth: Option<u32>,
    /// Loop subdivision steps after decimation (0 = off).
    #[arg(long, default_value_t = defaults().subdivide)]
    subdivide: u32,
    #[arg(long, help = with_defaults(KEEP_INSIDE_HELP, |s| off_or(s.keep_inside)))]
    keep_inside: Option<String>,
    #[arg(allow_negative_numbers = true, long, help = with_defaults(COVERAGE_HELP, |s| s.particle_coverage))]
    particle_coverage: Option<f32>,
    /// Iso-surface offset, multiples of r: extract where phi = offset·r, moving the surface
    /// outwards by about that much (0 = the paper's surface; 0.133 removes its inward
    /// bias on the shipped frames, at some flat-region smoothness).
    #[arg(long, default_value_t = defaults().iso_offset, allow_negative_numbers = true)]
    iso_offset: f32,
    #[arg(long, value_enum, help = with_defaults(KERNEL_HELP, |s| kernel_name(s.kernel)))]
    kernel: Option<KernelArg>,
    /// The pipeline of Akinci et al. 2013 exactly: `--kernel isotropic
    /// --particle-coverage 0 --decimate 0.8 --decimate-error off --smooth 0 --keep-inside off`
    /// (any of those given beside it wins).
    #[arg(long)]
    paper: bool,
    /// Anisotropic kernels: radius h_a of an unstretched kernel, multiples of r.
    #[arg(long, default_value_t = defaults().kernel_radius)]
    kernel_radius: f32,
    /// Anisotropic kernels: largest ratio of the longest to the shortest axis (k_r).
    #[arg(long, default_value_t = defaults().max_stretch)]
    max_stretch: f32,
    /// Anisotropic kernels: fewest neighbours within R for a stretched kernel (N_ε).
    #[arg(long, default_value_t = defaults().min_neighbours)]
    min_neighbours: u32,
    /// Anisotropic kernels: centre smoothing λ in [0, 1] (0 = the particle positions).
    #[arg(long, default_value_t = defaults().centre_smoothing)]
    centre_smoothing: f32,
    /// Tile edge in marching-cubes cells (rounded up to 8-cell blocks); default: one tile
    /// if the scene fits the memory budget, else the largest tile that does. The
    /// marching-cubes mesh does not depend on it.
    #[arg(long)]
    tile_size: Option<u32>,
    /// Memory the run may use: `512MiB`, `2GiB` (powers of 2), `2GB` (powers of 10) or
    /// plain bytes; a bare `2g` or `512M` is refused as ambiguous. Default half the
    /// available memory. Picks the tile size; a run whose smallest tile cannot fit fails
    /// before any work.
    #[arg(long)]
    memory_budget: Option<String>,
    /// Directory for the spill file of a tiled run (default: the system's temporary
    /// directory); removed on success, error and Ctrl-C.
    #[arg(long)]
    temp_dir: Option<PathBuf>,
    /// Input format, overriding the extension (xyz, vtk, vtu, vtp, ply, bgeo).
    #[arg(long)]
    input_format: Option<ParticleFormat>,
    #[command(flatten)]
    farm: FarmArgs,
    /// Skip frames whose output already exists, or that the `.mseq` output holds (the
    /// others are appended).
    #[arg(long)]
    skip_existing: bool,
    /// Print one JSON line per finished frame on stdout (frame, input, output, status
    /// done/skipped/failed, triangles, seconds, peak_rss_bytes, error), for farm managers.
    #[arg(long)]
    json_progress: bool,
    /// Report a frame that fails and go on with the next (default: stop at the first).
    /// The exit status is 1 when any frame failed; a `.mseq` output keeps the others.
    #[arg(long)]
    keep_going: bool,
    /// Worker threads (default: all cores). Output does not depend on it.
    #[arg(long)]
    threads: Option<usize>,
    /// Write per-frame, per-stage statistics as JSON to this file.
    #[arg(long)]
    stats: Option<PathBuf>,
    /// Error bound of a `.mseq` output, world units (each coordinate within it), as
    /// `archive info` prints it and `archive pack` takes it; appending needs the
    /// archive's own. Default 0.01 × the particle radius.
    #[arg(allow_negative_numbers = true, long)]
    error_bound: Option<f64>,
    /// Error bound of the attributes in a `.mseq` output, in each attribute's own units
    /// (m/s for a velocity): every value within it.
    #[arg(allow_negative_numbers = true, long, default_value_t = meniscus::archive::DEFAULT_ATTRIBUTE_ERROR_BOUND)]
    attribute_error_bound: f64,
    #[command(flatten)]
    stage: StageArgs,
    /// Point attributes carried to the surface: a comma-separated list of names
    /// (`velocity,density`), `all`, or `none`. Default: the velocity (`v`, `vel` or
    /// `velocity`, any case) when the input has one.
    #[arg(long, value_name = "LIST")]
    attributes: Option<String>,
    /// Do not write vertex normals.
    #[arg(long)]
    no_normals: bool,
    /// No progress bar and no timing table.
    #[arg(short, long)]
    quiet: bool,
}

/// The settings' defaults, for particles of radius 1: every default of `reconstruct`'s
/// flags comes from them ([`ReconstructSettings::new`], which reads the library's).
fn defaults() -> ReconstructSettings {
    ReconstructSettings::new(1.0)
}

/// `off` for `None`, else the value.
fn off_or<T: std::fmt::Display>(value: Option<T>) -> String {
    value.map_or_else(|| "off".to_string(), |v| v.to_string())
}

/// A kernel as `--kernel` names it.
fn kernel_name(kernel: meniscus::field::Kernel) -> &'static str {
    match kernel {
        meniscus::field::Kernel::Isotropic => "isotropic",
        _ => "anisotropic",
    }
}

/// A flag's help with its default and, where `--paper` changes it, the paper's value.
fn with_defaults<T: std::fmt::Display>(
    help: &str,
    value: impl Fn(&ReconstructSettings) -> T,
) -> String {
    let (default, paper) = (value(&defaults()), value(&ReconstructSettings::paper(1.0)));
    let paper = paper.to_string();
    if paper == default.to_string() {
        format!("{help} [default: {default}]")
    } else {
        format!("{help} [default: {default}; --paper: {paper}]")
    }
}

const DECIMATE_HELP: &str = "Quadric decimation: fraction of triangles to remove (0.8 = the paper's), `adaptive` (stop on the error bound only: flat regions simplify, curved ones keep their triangles), or `off`; the default holds the anisotropic surface to the paper's triangle count";
const DECIMATE_ERROR_HELP: &str = "Error bound of decimation, multiples of r (RMS distance of a collapse to the original planes), or `off`; with a fraction, whichever is reached first stops it";
const SMOOTH_HELP: &str = "Taubin smoothing steps after decimation (0 = off): removes the field's small bumps without shrinking the surface";
const KEEP_INSIDE_HELP: &str = "Least depth of every non-isolated particle centre under the final surface, multiples of r (0 to 1): where decimation or subdivision left one shallower or outside, the surface over it is pushed out; `off` leaves the surface as they made it";
const COVERAGE_HELP: &str = "Coverage radius c, multiples of r: particles the paper's surface would leave outside are enclosed in a ball of c·r (0 = off, the pure Solenthaler field)";
const KERNEL_HELP: &str = "Particle kernel: `anisotropic` (Yu & Turk 2013 kernels stretched along the local surface: smoother, and on the particles instead of inside them) or `isotropic` (the paper's Solenthaler field)";

/// Why a command failed: what it prints and its exit code.
enum Failure {
    /// An option or argument that cannot work (exit 2, as clap's own usage errors).
    Usage(String),
    /// A file, its content, or the run itself (exit 1).
    Run(String),
}

impl Failure {
    /// An option the user gave, with a value that cannot work.
    fn option(option: &str, message: impl std::fmt::Display) -> Self {
        Failure::Usage(format!("invalid option {option}: {message}"))
    }
}

impl From<meniscus::Error> for Failure {
    fn from(e: meniscus::Error) -> Self {
        match e {
            meniscus::Error::InvalidOption { option, message } => {
                Failure::option(&flag(option), message)
            }
            e => Failure::Run(e.to_string()),
        }
    }
}

/// The flag of a library option name (`particle_radius` → `--particle-radius`,
/// `t_low/t_high` → `--t-low/--t-high`, `input` → `INPUT`).
fn flag(option: &str) -> String {
    option
        .split('/')
        .map(|name| match name {
            "input" => "INPUT".to_string(),
            name => format!("--{}", name.replace('_', "-")),
        })
        .collect::<Vec<_>>()
        .join("/")
}

fn main() -> ExitCode {
    meniscus::tune_allocator();
    let matches = Cli::command()
        .try_get_matches()
        .unwrap_or_else(|e| exit_with_hint(e));
    let cli = Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit());
    // A panic inside a library entry point comes back as an error that is printed once,
    // naming the input; the default hook would print it a first time (kept with
    // RUST_BACKTRACE, for bug reports).
    let default_hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        if !meniscus::error::panic_is_caught() || std::env::var_os("RUST_BACKTRACE").is_some() {
            default_hook(info);
        }
    }));
    // Ctrl-C: the first stops the run at the next tile or stage (temporary files are
    // removed, no partial output is left); a second one exits at once, leaving the
    // temporary files to the next run (which removes those of runs that are gone) and
    // an archive being appended to without its index (the next append writes it).
    let cancel = meniscus::CancelToken::new();
    let handler = cancel.clone();
    let _ = ctrlc::set_handler(move || {
        if handler.cancel() {
            std::process::exit(130);
        }
        eprintln!(
            "\ninterrupted: stopping at the next tile or stage (Ctrl-C again to quit now, \
             leaving temporary files that the next run removes)"
        );
    });
    let result = match cli.command {
        Command::Reconstruct(mut args) => {
            let given = matches
                .subcommand_matches("reconstruct")
                .expect("the reconstruct subcommand");
            reconstruct(&mut args, given, &cancel)
        }
        Command::Archive(command) => archive(command, &cancel),
    };
    if result.is_err() && cancel.is_cancelled() {
        eprintln!("error: interrupted");
        return ExitCode::from(130);
    }
    report(result)
}

/// Prints a command-line error and exits; an extra argument that is an existing file (a
/// shell glob the shell expanded) gets a hint at the `{}` pattern.
fn exit_with_hint(e: clap::Error) -> ! {
    use clap::error::{ContextKind, ContextValue, ErrorKind};
    let extra = match e.get(ContextKind::InvalidArg) {
        Some(ContextValue::String(arg)) if e.kind() == ErrorKind::UnknownArgument => {
            Some(arg.clone())
        }
        _ => None,
    };
    let Some(extra) = extra.filter(|a| Path::new(a).is_file()) else {
        e.exit()
    };
    let _ = e.print();
    eprintln!(
        "hint: {extra:?} is a file: did the shell expand a glob into several inputs? A sequence is \
         one quoted pattern with {{}} where the frame number goes, e.g. {:?}",
        meniscus::sequence::suggested_pattern(&extra)
    );
    std::process::exit(e.exit_code())
}

fn report(result: Result<(), Failure>) -> ExitCode {
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(Failure::Usage(message)) => {
            eprintln!("error: {message}");
            ExitCode::from(2)
        }
        Err(Failure::Run(message)) => {
            eprintln!("error: {message}");
            ExitCode::FAILURE
        }
    }
}

/// A flag's value that is `off` (or `none`) or a `T`, which the message names as `what`.
fn parse_or_off<T: std::str::FromStr>(
    value: &str,
    option: &str,
    what: &str,
) -> Result<Option<T>, Failure> {
    match value {
        "off" | "none" => Ok(None),
        v => v
            .parse()
            .map(Some)
            .map_err(|_| Failure::option(option, format!("takes {what} or `off`, got {v:?}"))),
    }
}

/// `--kernel` values.
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
enum KernelArg {
    Isotropic,
    Anisotropic,
}

fn options_from(args: &ReconstructArgs) -> Result<ReconstructOptions, Failure> {
    let r = args.radius;
    let base = match args.paper {
        true => ReconstructSettings::paper(r),
        false => ReconstructSettings::new(r),
    };
    let settings = ReconstructSettings {
        particle_radius: r,
        influence_radius: args.influence_radius,
        cell_size: args.cell_size,
        t_low: args.t_low,
        t_high: args.t_high,
        particle_coverage: args.particle_coverage.unwrap_or(base.particle_coverage),
        iso_offset: args.iso_offset,
        kernel: match args.kernel {
            None => base.kernel,
            Some(KernelArg::Isotropic) => meniscus::field::Kernel::Isotropic,
            Some(KernelArg::Anisotropic) => meniscus::field::Kernel::Anisotropic,
        },
        kernel_radius: args.kernel_radius,
        max_stretch: args.max_stretch,
        min_neighbours: args.min_neighbours,
        centre_smoothing: args.centre_smoothing,
        isolated_spheres: parse_or_off(
            &args.isolated_spheres,
            "--isolated-spheres",
            "a level (0, 1, 2, ...)",
        )?,
        decimate: match &args.decimate {
            None => base.decimate,
            Some(text) => text.parse().map_err(|e| Failure::option("--decimate", e))?,
        },
        decimate_error: match &args.decimate_error {
            None => base.decimate_error,
            Some(v) => parse_or_off(v, "--decimate-error", "a bound (multiples of r)")?,
        },
        smooth: args.smooth.unwrap_or(base.smooth),
        subdivide: args.subdivide,
        // A `.mseq` output defers it by itself (see `job`).
        defer_subdivision: false,
        keep_inside: match &args.keep_inside {
            None => base.keep_inside,
            Some(v) => parse_or_off(v, "--keep-inside", "a depth (multiples of r)")?,
        },
        tile_size: args.tile_size,
        memory_budget: match &args.memory_budget {
            Some(text) => Some(
                meniscus::tiles::parse_memory_size(text)
                    .map_err(|e| Failure::option("--memory-budget", e))?,
            ),
            None => None,
        },
        temp_dir: args.temp_dir.clone(),
    };
    Ok(settings.options()?)
}

fn reconstruct(
    args: &mut ReconstructArgs,
    given: &ArgMatches,
    cancel: &meniscus::CancelToken,
) -> Result<(), Failure> {
    // Options first, then the frames: usage errors (exit 2) before any file is read
    // (without -r, checked for r = 1 until the estimate replaces it).
    check_run_options(args)?;
    args.radius = args.particle_radius.unwrap_or(1.0);
    options_from(args)?;
    let attributes = match &args.attributes {
        Some(list) => list
            .parse()
            .map_err(|e| Failure::option("--attributes", e))?,
        None => AttributeSelection::default(),
    };
    let plan = plan_frames(&args.input, &args.output, &args.farm.choice())?;
    check_outputs(&plan).map_err(|e| Failure::Usage(e.to_string()))?;
    // The pool before the radius estimate, its first parallel work.
    if let Some(threads) = args.threads {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build_global()
            .map_err(|e| Failure::Run(e.to_string()))?;
    }
    args.radius = resolve_radius(args, &plan[0].0.input)?;
    let options = options_from(args)?;
    for warning in ineffective_options(args, given, &plan, &attributes) {
        eprintln!("warning: {warning}");
    }
    let job = job_options(args, attributes, cancel);
    let clock = Instant::now();
    let reports = run_with_progress(args, &plan, &options, &job).map_err(|e| match e {
        meniscus::Error::FramesExist { .. } => Failure::Run(format!(
            "{e}\nhint: --skip-existing skips the frames the archive holds and appends the others"
        )),
        e => e.into(),
    })?;
    let total = clock.elapsed().as_secs_f64();
    if !args.quiet {
        summarize(&reports, total, &args.output);
    }
    if let Some(path) = &args.stats {
        write_stats(path, &options, &reports, total)?;
    }
    check_failed(&reports)
}

/// The options of a run that the library does not check: `--threads`, `--fps`.
fn check_run_options(args: &ReconstructArgs) -> Result<(), Failure> {
    if args.threads == Some(0) {
        return Err(Failure::option("--threads", "must be at least 1, got 0"));
    }
    if !(args.stage.fps.is_finite() && args.stage.fps > 0.0) {
        return Err(Failure::option(
            "--fps",
            format!("must be > 0 (frames per second), got {}", args.stage.fps),
        ));
    }
    Ok(())
}

/// What the run does with its files.
fn job_options(
    args: &ReconstructArgs,
    attributes: AttributeSelection,
    cancel: &meniscus::CancelToken,
) -> JobOptions {
    JobOptions {
        input_format: args.input_format,
        write: MeshWriteOptions {
            normals: !args.no_normals,
            ..MeshWriteOptions::default()
        },
        skip_existing: args.skip_existing,
        archive_error_bound: args
            .error_bound
            .unwrap_or(meniscus::archive::default_error_bound(args.radius)),
        archive_attribute_error_bound: args.attribute_error_bound,
        fps: args.stage.fps,
        up_axis: args.stage.up_axis,
        meters_per_unit: args.stage.meters_per_unit,
        usd_droplets: args.stage.usd_droplets,
        attributes,
        radius_attribute: args.radius_attribute.clone().unwrap_or_default(),
        cancel: cancel.clone(),
        keep_going: args.keep_going,
    }
}

/// The progress bar of `frames` frames on stderr (hidden with `--quiet`).
fn progress_bar(args: &ReconstructArgs, frames: usize) -> ProgressBar {
    if args.quiet {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::with_draw_target(Some(frames as u64), ProgressDrawTarget::stderr());
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {bar:30} {pos}/{len} frames  {msg}",
        )
        .expect("valid template"),
    );
    bar.enable_steady_tick(std::time::Duration::from_millis(120));
    bar
}

/// Runs the frames of `plan` behind a progress bar, printing what each finished frame
/// calls for: its `--json-progress` line, its error (with `--keep-going`), warnings, and
/// the stage table of a single frame.
fn run_with_progress(
    args: &ReconstructArgs,
    plan: &[(meniscus::sequence::Frame, PathBuf)],
    options: &ReconstructOptions,
    job: &JobOptions,
) -> meniscus::Result<Vec<FrameReport>> {
    let bar = progress_bar(args, plan.len());
    let mut warned = false;
    let result = run_frames(
        plan,
        options,
        job,
        &mut |_, frame| bar.set_prefix(frame.input.display().to_string()),
        &mut |stage| bar.set_message(stage.to_string()),
        &mut |report: &FrameReport| {
            bar.inc(1);
            if args.json_progress {
                println!("{}", report.progress_line());
            }
            if args.keep_going {
                if let Some(error) = &report.error {
                    bar.suspend(|| eprintln!("error: frame {}: {error}", report.frame));
                }
            }
            if !warned && !report.dropped_attributes.is_empty() {
                warned = true;
                bar.suspend(|| {
                    eprintln!(
                        "warning: {} cannot hold point attributes; not written: {}",
                        report.output.display(),
                        report.dropped_attributes.join(", ")
                    )
                });
            }
            let contained = report.reconstruction.containment.as_ref();
            if let Some(left) = contained.map(|c| c.remaining).filter(|&n| n > 0) {
                bar.suspend(|| {
                    eprintln!(
                        "warning: {}: {left} particle centres stay less than the keep-inside \
                         depth under the surface (decimation folded it where containment \
                         could not tell its side)",
                        report.input.display()
                    )
                });
            }
            if !args.quiet && plan.len() == 1 && report.error.is_none() && !report.skipped {
                bar.suspend(|| eprint!("{}", report.reconstruction.table()));
            }
        },
    );
    bar.finish_and_clear();
    result
}

/// Writes the `--stats` JSON: the options, every frame's report, the run's time and peak
/// memory.
fn write_stats(
    path: &std::path::Path,
    options: &ReconstructOptions,
    reports: &[FrameReport],
    total: f64,
) -> Result<(), Failure> {
    let json = serde_json::json!({
        "options": options,
        "frames": reports,
        "total_seconds": total,
        "peak_rss_bytes": peak_rss_bytes(),
    });
    let text = serde_json::to_string_pretty(&json).map_err(|e| Failure::Run(e.to_string()))?;
    std::fs::write(path, text).map_err(|e| Failure::from(meniscus::Error::io(path, e)))
}

/// Fails the run when any frame failed (with `--keep-going`), naming them.
fn check_failed(reports: &[FrameReport]) -> Result<(), Failure> {
    let failed: Vec<&FrameReport> = reports
        .iter()
        .filter(|r| r.status == FrameStatus::Failed)
        .collect();
    if failed.is_empty() {
        return Ok(());
    }
    let numbers: Vec<String> = failed.iter().map(|r| r.frame.to_string()).collect();
    Err(Failure::Run(format!(
        "{} of {} frames failed (frame{} {}); the others were written",
        failed.len(),
        reports.len(),
        if failed.len() == 1 { "" } else { "s" },
        numbers.join(", ")
    )))
}

/// The run's summary line: frames, time, triangles, where they went (`output` as given
/// to `-o`) and peak memory.
fn summarize(reports: &[FrameReport], total: f64, output: &str) {
    let count = |s| reports.iter().filter(|r| r.status == s).count();
    let (done, skipped, failed) = (
        count(FrameStatus::Done),
        count(FrameStatus::Skipped),
        count(FrameStatus::Failed),
    );
    let triangles: usize = reports.iter().map(|r| r.triangles()).sum();
    eprintln!(
        "{} frame(s) reconstructed{}{} in {:.2} s, {} triangles written to {}, peak memory {}",
        done,
        if skipped > 0 {
            format!(", {skipped} skipped")
        } else {
            String::new()
        },
        if failed > 0 {
            format!(", {failed} failed")
        } else {
            String::new()
        },
        total,
        triangles,
        output,
        peak_rss_bytes()
            .map(|b| format!("{:.1} MiB", b as f64 / (1 << 20) as f64))
            .unwrap_or_else(|| "unknown".into()),
    );
}
