//! `meniscus archive`: inspect, check, extract from, fill and merge `.mseq` mesh-sequence
//! archives.

use crate::cli::{Failure, FarmArgs, StageArgs};
use clap::Subcommand;
use meniscus::archive::{ArchiveOptions, ArchiveReader, ArchiveWriter};
use meniscus::io::mesh::{read_mesh, MeshWriteOptions};
use meniscus::io::usd::{UsdFormat, UsdOptions};
use std::path::{Path, PathBuf};

#[derive(Subcommand)]
pub(crate) enum ArchiveCommand {
    /// Summary: frames, triangles, bytes, bytes per triangle.
    Info {
        /// The archive.
        file: PathBuf,
        /// Read what can be read of a damaged archive and exit 0: its unreadable frames
        /// are warned about (without it they make the exit status 1).
        #[arg(long)]
        skip_damaged: bool,
    },
    /// One line per frame.
    List {
        /// The archive.
        file: PathBuf,
        /// Read what can be read of a damaged archive and exit 0: its unreadable frames
        /// are warned about (without it they make the exit status 1).
        #[arg(long)]
        skip_damaged: bool,
    },
    /// Decode every frame and check its checksum; non-zero exit when one is damaged.
    Verify {
        /// The archive.
        file: PathBuf,
    },
    /// Write one frame, or every frame, as .glb, .gltf, .ply, .obj or .vtk, or as a USD
    /// stage (.usdc, .usda, .usd); existing files are replaced, as `reconstruct` replaces
    /// them.
    Extract {
        /// The archive.
        file: PathBuf,
        /// Frame number; without it every frame is written (OUTPUT needs a `{}`, unless it
        /// is one USD stage holding them all).
        #[arg(long, allow_negative_numbers = true)]
        frame: Option<i64>,
        /// Output mesh file or USD stage; `{}` stands for the frame number.
        #[arg(short, long)]
        output: String,
        #[command(flatten)]
        stage: StageArgs,
        /// Read what can be read of a damaged archive and exit 0: its unreadable frames
        /// are warned about (without it they make the exit status 1).
        #[arg(long)]
        skip_damaged: bool,
    },
    /// Join archives (one per farm task, say) into one, frames in increasing order,
    /// records copied as they are: the same bytes as one run writing every frame.
    Merge {
        /// The archives to join (each frame in exactly one, one error bound for all).
        #[arg(required = true)]
        inputs: Vec<PathBuf>,
        /// The merged archive; written whole under a temporary name, then renamed.
        #[arg(short, long)]
        output: PathBuf,
    },
    /// Rewrite a damaged or unfinished archive with every frame that can be read: damaged
    /// records skipped, a cut-off end cut, the index rebuilt; lists what it dropped.
    Repair {
        /// The archive.
        file: PathBuf,
        /// The repaired archive (a new file); by default FILE itself, replaced whole
        /// under a temporary name.
        #[arg(short, long)]
        output: Option<PathBuf>,
    },
    /// Pack existing mesh files (`{}` pattern; PLY, OBJ, glTF) into an archive.
    Pack {
        /// Mesh files, a pattern with `{}` for the frame number.
        input: String,
        /// The archive to create or append to.
        #[arg(short, long)]
        output: PathBuf,
        /// Error bound, world units (each coordinate within it), as `archive info` prints
        /// it; appending needs the archive's own. Required: meshes carry no particle radius.
        #[arg(long, allow_negative_numbers = true, alias = "error-bound-world")]
        error_bound: f64,
        /// Error bound of the meshes' vertex attributes, in each attribute's own units.
        #[arg(allow_negative_numbers = true, long, default_value_t = meniscus::archive::DEFAULT_ATTRIBUTE_ERROR_BOUND)]
        attribute_error_bound: f64,
        #[command(flatten)]
        farm: FarmArgs,
    },
}

/// Runs one `meniscus archive` subcommand.
pub(crate) fn run(command: ArchiveCommand, cancel: &meniscus::CancelToken) -> Result<(), Failure> {
    match command {
        ArchiveCommand::Info { file, skip_damaged } => info(&file, skip_damaged),
        ArchiveCommand::List { file, skip_damaged } => list(&file, skip_damaged),
        ArchiveCommand::Verify { file } => verify(&file),
        ArchiveCommand::Extract {
            file,
            frame,
            output,
            stage,
            skip_damaged,
        } => extract(&file, frame, &output, &stage, skip_damaged, cancel),
        ArchiveCommand::Merge { inputs, output } => merge(&inputs, &output),
        ArchiveCommand::Repair { file, output } => repair(&file, output.as_deref()),
        ArchiveCommand::Pack {
            input,
            output,
            error_bound,
            attribute_error_bound,
            farm,
        } => {
            let options = ArchiveOptions {
                attribute_error_bound,
                ..ArchiveOptions::new(error_bound)
            };
            pack(&input, &output, &options, &farm, cancel)
        }
    }
}

/// Warns of every frame or stretch of `file` that its reading left out
/// ([`ArchiveReader::unreadable`]); a failure when frames the archive holds were lost,
/// unless `skip_damaged` (a missing index or a cut-off end only warns: the frames before
/// it are whole).
fn report_unreadable(file: &Path, r: &ArchiveReader, skip_damaged: bool) -> Result<(), Failure> {
    let unreadable = r.unreadable();
    for u in &unreadable {
        match u.frame {
            Some(n) => eprintln!("warning: {}: frame {n}: {}", file.display(), u.message),
            None => eprintln!("warning: {}: {}", file.display(), u.message),
        }
    }
    let lost = unreadable.iter().filter(|u| !u.truncation).count();
    if lost > 0 && !skip_damaged {
        return Err(Failure::Run(format!(
            "{}: damaged: {lost} damaged record(s) or index entries left out (listed above; `archive verify` checks every frame)\nhint: {}, or --skip-damaged reads what can be read",
            file.display(),
            meniscus::archive::repair_advice(file)
        )));
    }
    Ok(())
}

/// `archive info`: frames, triangles, bytes, the error bounds and attributes.
fn info(file: &Path, skip_damaged: bool) -> Result<(), Failure> {
    let r = ArchiveReader::open(file)?;
    let bytes = std::fs::metadata(file)
        .map_err(|e| meniscus::Error::io(file, e))?
        .len();
    let triangles: u64 = r.frames().iter().map(|f| f.triangles as u64).sum();
    println!(
        "{}: {} frames, {} triangles, {} bytes, {:.3} bytes/triangle{}",
        file.display(),
        r.frames().len(),
        triangles,
        bytes,
        bytes as f64 / triangles.max(1) as f64,
        if r.recovered_by_scan() {
            " (no index: recovered by scanning)"
        } else {
            ""
        }
    );
    // A quantization step no writer gives (NaN, zero, negative, infinite): damage.
    let bad_steps: Vec<String> = r
        .frames()
        .iter()
        .filter(|f| !(f.step.is_finite() && f.step > 0.0))
        .map(|f| format!("frame {} (quantization step {})", f.number, f.step))
        .collect();
    if !bad_steps.is_empty() {
        return Err(Failure::Run(format!(
            "{}: damaged: {}: not a positive finite quantization step (`archive verify` lists \
             every damaged frame)\nhint: {}",
            file.display(),
            bad_steps.join(", "),
            meniscus::archive::repair_advice(file)
        )));
    }
    if let (Some(first), Some(last)) = (r.frames().first(), r.frames().last()) {
        println!(
            "frames {} .. {}, error bound {} (world units)",
            first.number,
            last.number,
            first.step / 2.0
        );
    }
    for f in r.frames().iter().filter(|f| !f.attributes.is_empty()) {
        let names: Vec<String> = f
            .attributes
            .iter()
            .map(|a| format!("{} ({} × {:?})", a.name, a.components, a.target))
            .collect();
        println!(
            "frame {}: attributes {}, error bound {}",
            f.number,
            names.join(", "),
            f.attribute_error_bound.unwrap_or(0.0)
        );
    }
    report_unreadable(file, &r, skip_damaged)
}

/// `archive list`: one line per frame, its record's bytes.
fn list(file: &Path, skip_damaged: bool) -> Result<(), Failure> {
    let r = ArchiveReader::open(file)?;
    println!(
        "{:>8} {:>10} {:>10} {:>12}",
        "frame", "vertices", "triangles", "bytes"
    );
    for f in r.frames() {
        println!(
            "{:>8} {:>10} {:>10} {:>12}",
            f.number,
            f.vertices,
            f.triangles,
            f.record_bytes()
        );
    }
    report_unreadable(file, &r, skip_damaged)
}

/// `archive verify`: every frame decoded; a failure when anything is damaged.
fn verify(file: &Path) -> Result<(), Failure> {
    let r = ArchiveReader::open(file)?;
    let v = r.verify();
    for (n, why) in &v.damaged {
        println!("frame {n}: DAMAGED: {why}");
    }
    for why in &v.damage {
        println!("DAMAGED: {why}");
    }
    println!(
        "{} frames good, {} damaged{}{}",
        v.good.len(),
        v.damaged.len(),
        if v.recovered_by_scan {
            ", index missing (interrupted write): recovered by scanning"
        } else {
            ""
        },
        if v.trailing_bytes > 0 {
            format!(
                ", {} trailing bytes of an incomplete frame",
                v.trailing_bytes
            )
        } else {
            String::new()
        }
    );
    if !v.is_clean() {
        return Err(Failure::Run(format!(
            "{}: damaged: {} damaged frame(s), {} other problem(s)\nhint: {}",
            file.display(),
            v.damaged.len(),
            v.damage.len(),
            meniscus::archive::repair_advice(file)
        )));
    }
    Ok(())
}

/// `archive extract`: frame `frame`, or every frame, to `output`: mesh files, or USD
/// stages by the extension.
fn extract(
    file: &Path,
    frame: Option<i64>,
    output: &str,
    stage: &StageArgs,
    skip_damaged: bool,
    cancel: &meniscus::CancelToken,
) -> Result<(), Failure> {
    // A usage error (exit 2, as `reconstruct` gives it) before the archive is read.
    let is_stage = UsdFormat::from_path(Path::new(output)).is_ok();
    if !is_stage && meniscus::io::mesh::MeshFormat::from_path(Path::new(output)).is_err() {
        let ext = Path::new(output).extension().unwrap_or_default();
        return Err(Failure::Usage(format!(
            "{output}: unknown output extension {ext:?}; supported: .glb, .gltf, .ply, .obj, \
             .vtk, .usdc, .usda, .usd (USD stage)"
        )));
    }
    let r = ArchiveReader::open(file)?;
    let numbers = frame.map(|n| vec![n]);
    if is_stage {
        let options = UsdOptions {
            fps: stage.fps,
            up_axis: stage.up_axis,
            meters_per_unit: stage.meters_per_unit,
            droplets: stage.usd_droplets,
            ..UsdOptions::default()
        };
        let written = r.extract_stage(numbers.as_deref(), output, &options, cancel)?;
        let frames = numbers.map_or(r.frames().len(), |n| n.len());
        eprintln!("{frames} frame(s) written to {} stage(s)", written.len());
        return unreadable_unless_one(file, &r, frame, skip_damaged);
    }
    let written = r.extract(
        numbers.as_deref(),
        output,
        &MeshWriteOptions::default(),
        cancel,
    )?;
    if frame.is_none() {
        eprintln!("{} frame(s) written", written.len());
    }
    unreadable_unless_one(file, &r, frame, skip_damaged)
}

/// [`report_unreadable`] after an extraction of every frame; one frame asked for and
/// written misses nothing.
fn unreadable_unless_one(
    file: &Path,
    r: &ArchiveReader,
    frame: Option<i64>,
    skip_damaged: bool,
) -> Result<(), Failure> {
    match frame {
        Some(_) => Ok(()),
        None => report_unreadable(file, r, skip_damaged),
    }
}

/// `archive merge`: `inputs` joined into `output`.
fn merge(inputs: &[PathBuf], output: &Path) -> Result<(), Failure> {
    let stats = meniscus::archive::merge(inputs, output)?;
    eprintln!(
        "{} frame(s) from {} archive(s) merged into {} ({} bytes)",
        stats.frames,
        stats.inputs,
        output.display(),
        stats.bytes
    );
    Ok(())
}

/// `archive repair`: `file` rewritten with its readable frames, to `output` or itself.
fn repair(file: &Path, output: Option<&Path>) -> Result<(), Failure> {
    let output = output.unwrap_or(file);
    let report = meniscus::archive::repair(file, output)?;
    for why in &report.dropped {
        eprintln!("dropped {why}");
    }
    for n in &report.relengthed {
        eprintln!("frame {n}: kept, the payload length in its record header corrected");
    }
    if let Some(why) = &report.header_rebuilt {
        eprintln!("{why}");
    }
    eprintln!(
        "{} frame(s) kept, {} item(s) dropped{}: {} ({} bytes)",
        report.kept.len(),
        report.dropped.len(),
        if report.index_was_missing {
            ", index rebuilt (there was none)"
        } else {
            ", index rebuilt"
        },
        output.display(),
        report.bytes
    );
    Ok(())
}

/// `archive pack`: the mesh files `input` names appended to `output`, a new archive or
/// an existing one.
fn pack(
    input: &str,
    output: &Path,
    options: &ArchiveOptions,
    farm: &FarmArgs,
    cancel: &meniscus::CancelToken,
) -> Result<(), Failure> {
    let frames = meniscus::sequence::choose(input, &farm.choice())?;
    let mut w = if output.exists() {
        // Frames it holds are refused before it is touched.
        let numbers: Vec<i64> = frames.iter().map(|f| f.number).collect();
        ArchiveReader::open(output).and_then(|r| r.check_new_frames(&numbers))?;
        ArchiveWriter::open_append(output, options)
    } else {
        ArchiveWriter::create(output, options)
    }?;
    // On an error or a Ctrl-C (checked between frames) the writer, dropped, still
    // writes the index of the frames packed so far.
    for f in &frames {
        cancel.check()?;
        let mesh = read_mesh(&f.input)?;
        w.append(f.number, &mesh)?;
    }
    w.finish()?;
    eprintln!("{} frame(s) packed into {}", frames.len(), output.display());
    Ok(())
}
