//! File-level jobs: read a particle file, reconstruct, write the surface; and whole
//! sequences of frames, chosen by [`crate::sequence::FrameChoice`] (a range, a
//! farm-style selection, a shard), each reported as done, skipped or failed
//! ([`FrameReport`]). The CLI is a thin layer over [`run_frames`].

use crate::archive::{ArchiveFrame, ArchiveOptions, ArchiveReader, ArchiveWriter};
use crate::attributes::AttributeSelection;
use crate::cancel::CancelToken;
use crate::error::{Error, Result};
use crate::io::mesh::{write_sequence_gltf, write_surface, MeshFormat, MeshWriteOptions};
use crate::io::particles::{read_particles, ParticleFormat};
use crate::io::particles::{MappedXyz, Particles, SpooledParticles};
use crate::mesh::TriMesh;
use crate::pipeline::{reconstruct_source, ReconstructOptions, ReconstructionStats};
use crate::sequence::{self, Frame, FrameChoice};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// A frame's particles as the job hands them to the pipeline.
enum Input {
    Mapped(MappedXyz),
    Spooled(SpooledParticles),
    Parsed(Particles),
}

/// A particle file parsed into memory, with the attributes `selection` asks for.
fn parsed(input: &Path, format: ParticleFormat, selection: &AttributeSelection) -> Result<Input> {
    let particles = read_particles(input, Some(format))?;
    if particles.positions.is_empty() {
        return Err(Error::EmptyInput {
            path: input.to_path_buf(),
        });
    }
    Ok(Input::Parsed(particles.select(input, selection)?))
}

/// What to do with the files of a job.
#[derive(Clone, Debug)]
pub struct JobOptions {
    /// Force an input format instead of choosing by extension.
    pub input_format: Option<ParticleFormat>,
    /// Mesh writer options.
    pub write: MeshWriteOptions,
    /// Skip frames whose output file already exists (resume a sequence); for a `.mseq`
    /// output, frames the archive already holds.
    pub skip_existing: bool,
    /// Error bound of `.mseq` outputs, world units.
    pub archive_error_bound: f64,
    /// Error bound of attributes in `.mseq` outputs, in each attribute's own units.
    pub archive_attribute_error_bound: f64,
    /// Playback rate of a sequence written into one glTF, frames per second.
    pub fps: f32,
    /// The point attributes carried to the surface.
    pub attributes: AttributeSelection,
    /// Stops the job between tiles, stages and frames ([`crate::Error::Interrupted`]).
    pub cancel: CancelToken,
    /// A frame that fails is reported (status [`FrameStatus::Failed`]) and the run goes
    /// on with the next; otherwise the first failure stops the run. Either way a `.mseq`
    /// output keeps the frames done (a failed frame is not appended) and is finished with
    /// its index. An interruption, and an I/O error on the archive itself (which leaves
    /// it unfit for more frames), always stop the run.
    pub keep_going: bool,
}

/// What became of a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum FrameStatus {
    /// Reconstructed and written.
    Done,
    /// Not reconstructed: its output existed ([`JobOptions::skip_existing`]).
    Skipped,
    /// Reading, reconstructing or writing it failed ([`FrameReport::error`] says why).
    Failed,
}

/// Where a reconstructed frame goes.
pub enum Sink<'a> {
    /// Its own mesh file.
    File,
    /// Appended to an open archive.
    Archive(&'a mut ArchiveWriter),
    /// Kept (fluid and spheres merged) for a sequence glTF written at the end.
    Collect(&'a mut Vec<TriMesh>),
}

/// The outcome of one frame.
#[derive(Clone, Debug, serde::Serialize)]
pub struct FrameReport {
    /// Frame number (0 for a single file).
    pub frame: i64,
    /// Input file.
    pub input: PathBuf,
    /// Output file.
    pub output: PathBuf,
    /// Done, skipped or failed.
    pub status: FrameStatus,
    /// True when the frame was skipped because its output existed.
    pub skipped: bool,
    /// Why the frame failed (status [`FrameStatus::Failed`]).
    pub error: Option<String>,
    /// Wall time of the whole frame (read, reconstruct, write), seconds.
    pub seconds: f64,
    /// Reading time, seconds.
    pub read_seconds: f64,
    /// Pipeline figures (stages, counts).
    pub reconstruction: ReconstructionStats,
    /// Writing time, seconds.
    pub write_seconds: f64,
    /// Bytes written.
    pub output_bytes: u64,
    /// Attributes the output format could not hold (an OBJ file holds none).
    pub dropped_attributes: Vec<String>,
}

impl FrameReport {
    /// A frame that was not reconstructed: skipped, or failed with `error`.
    fn not_done(frame: &Frame, output: &Path, error: Option<&Error>, seconds: f64) -> Self {
        FrameReport {
            frame: frame.number,
            input: frame.input.clone(),
            output: output.to_path_buf(),
            status: match error {
                Some(_) => FrameStatus::Failed,
                None => FrameStatus::Skipped,
            },
            skipped: error.is_none(),
            error: error.map(|e| e.to_string()),
            seconds,
            read_seconds: 0.0,
            reconstruction: ReconstructionStats::default(),
            write_seconds: 0.0,
            output_bytes: 0,
            dropped_attributes: Vec::new(),
        }
    }

    /// Triangles written: fluid surface plus isolated-particle spheres.
    pub fn triangles(&self) -> usize {
        self.reconstruction.fluid_triangles + self.reconstruction.sphere_triangles
    }

    /// What a farm manager needs of a finished frame, as one JSON object (the CLI's
    /// `--json-progress` line): `frame`, `input`, `output`, `status`, `triangles` (fluid
    /// plus spheres, `null` unless done), `seconds`, `peak_rss_bytes` (the process's peak
    /// so far) and, for a failed frame, `error`.
    pub fn progress_line(&self) -> serde_json::Value {
        let mut line = serde_json::json!({
            "frame": self.frame,
            "input": self.input,
            "output": self.output,
            "status": self.status,
            "triangles": (self.status == FrameStatus::Done).then(|| self.triangles()),
            "seconds": self.seconds,
            "peak_rss_bytes": peak_rss_bytes(),
        });
        if let Some(error) = &self.error {
            line["error"] = error.as_str().into();
        }
        line
    }
}

/// Reads `input`, reconstructs it and sends it to `sink`: the file `output`, an archive
/// (as frame `frame_number`; Loop subdivision is left to the archive's decoder, which
/// stores the control mesh) or a collection. `on_stage` is told
/// when a phase starts ("read", "reconstruct", "write").
pub fn reconstruct_file(
    input: &Path,
    output: &Path,
    options: &ReconstructOptions,
    job: &JobOptions,
    sink: Sink,
    frame_number: i64,
    on_stage: &mut dyn FnMut(&str),
) -> Result<FrameReport> {
    on_stage("read");
    let started = Instant::now();
    let clock = started;
    if input.is_dir() {
        return Err(Error::io(
            input,
            std::io::Error::new(
                std::io::ErrorKind::IsADirectory,
                "is a directory, not a particle file",
            ),
        ));
    }
    // Raw .xyz is mapped window by window; BGEO, PLY (binary or ASCII) with its vertices
    // first, and VTK whose sections a scan can follow are streamed once, positions and
    // the selected attributes, into temporary files that are then mapped the same way;
    // other layouts are parsed into memory and handed over, so a tiled run can drop them
    // once they are spilled.
    let format = match job.input_format {
        Some(f) => f,
        None => ParticleFormat::from_path(input)?,
    };
    let cancel = &job.cancel;
    let positions = match format {
        ParticleFormat::Xyz => {
            if let AttributeSelection::Names(names) = &job.attributes {
                // Raw positions hold no attributes: the same error as any missing name.
                Particles::default().select(input, &AttributeSelection::Names(names.clone()))?;
            }
            Input::Mapped(MappedXyz::open(input)?)
        }
        _ => match SpooledParticles::from_file(
            input,
            format,
            &job.attributes,
            options.tiles.temp_dir.as_deref(),
            cancel,
        )? {
            Some(spooled) => Input::Spooled(spooled),
            None => parsed(input, format, &job.attributes)?,
        },
    };
    let read_seconds = clock.elapsed().as_secs_f64();
    on_stage("reconstruct");
    // An archive stores the control mesh and subdivides on decoding (a quarter of the
    // triangles per level to store); the pipeline stops before subdivision.
    let deferred_levels = match sink {
        Sink::Archive(_) => options.subdivide.levels,
        _ => 0,
    };
    let deferred_options;
    let options = if deferred_levels > 0 {
        let mut o = options.clone();
        o.subdivide.levels = 0;
        o.deferred_subdivision = deferred_levels;
        deferred_options = o;
        &deferred_options
    } else {
        options
    };
    let (surface, mut reconstruction) = {
        let progress = std::cell::RefCell::new(&mut *on_stage);
        let progress = |stage: &str| (progress.borrow_mut())(stage);
        match positions {
            Input::Mapped(file) => reconstruct_source(file, options, &progress, cancel),
            Input::Spooled(file) => reconstruct_source(file, options, &progress, cancel),
            Input::Parsed(particles) => reconstruct_source(particles, options, &progress, cancel),
        }
        .map_err(|e| match e {
            // The particles came from this file.
            Error::ParticleOutOfRange {
                path: None,
                message,
            } => Error::ParticleOutOfRange {
                path: Some(input.to_path_buf()),
                message,
            },
            e => e,
        })?
    };
    cancel.check()?;
    on_stage("write");
    let clock = Instant::now();
    let mut dropped_attributes = Vec::new();
    let written = match sink {
        Sink::Archive(writer) => {
            let frame = ArchiveFrame {
                fluid: &surface.fluid,
                subdivision_levels: deferred_levels,
                spheres: &surface.spheres,
            };
            let bytes = writer.append_frame(frame_number, &frame)?;
            if deferred_levels > 0 {
                reconstruction.fluid_triangles <<= 2 * deferred_levels;
                reconstruction.push_stage(
                    "subdivision (on decoding)",
                    0.0,
                    reconstruction.fluid_triangles,
                );
            }
            bytes
        }
        Sink::Collect(frames) => {
            frames.push(surface.merged());
            0
        }
        Sink::File => {
            let stats = write_surface(output, &surface, &job.write)?;
            dropped_attributes = stats.dropped_attributes;
            stats.bytes
        }
    };
    let write_seconds = clock.elapsed().as_secs_f64();
    reconstruction.push_stage("write", write_seconds, reconstruction.fluid_triangles);
    Ok(FrameReport {
        frame: frame_number,
        input: input.to_path_buf(),
        output: output.to_path_buf(),
        status: FrameStatus::Done,
        skipped: false,
        error: None,
        seconds: started.elapsed().as_secs_f64(),
        read_seconds,
        reconstruction,
        write_seconds,
        output_bytes: written,
        dropped_attributes,
    })
}

/// The frames of a job: a single file, or the frames of a `{}` pattern that `choice`
/// takes ([`sequence::choose`]). The output must be a pattern exactly when the input is
/// (or one `.mseq`, `.glb` or `.gltf` for the whole sequence).
pub fn plan_frames(
    input: &str,
    output: &str,
    choice: &FrameChoice,
) -> Result<Vec<(Frame, PathBuf)>> {
    if sequence::is_pattern(output) && is_archive(Path::new(output)) {
        return Err(Error::InvalidOption {
            option: "output",
            message: format!(
                "{output:?}: one .mseq archive holds the whole sequence; name it without {{}}"
            ),
        });
    }
    match (sequence::is_pattern(input), sequence::is_pattern(output)) {
        (true, true) => Ok(sequence::choose(input, choice)?
            .into_iter()
            .map(|f| {
                let out = sequence::substitute(output, &f.label);
                (f, out)
            })
            .collect()),
        (false, false) => {
            if choice.is_given() {
                let option = if choice.frames.is_some() {
                    "frames"
                } else if choice.shard.is_some() && choice.start.is_none() && choice.end.is_none() {
                    "shard"
                } else {
                    "start/end"
                };
                return Err(Error::InvalidOption {
                    option,
                    message: format!(
                        "choosing frames needs a {{}} pattern in INPUT and OUTPUT; {input:?} is a single file"
                    ),
                });
            }
            Ok(vec![(
                Frame {
                    number: 0,
                    label: String::new(),
                    input: PathBuf::from(input),
                },
                PathBuf::from(output),
            )])
        }
        (true, false) if is_archive(Path::new(output)) || is_gltf(Path::new(output)) => Ok(sequence::choose(input, choice)?
            .into_iter()
            .map(|f| (f, PathBuf::from(output)))
            .collect()),
        (true, false) => Err(Error::InvalidOption {
            option: "output",
            message: format!(
                "INPUT {input:?} is a sequence pattern, so OUTPUT {output:?} needs a {{}} too (or is one .mseq, .glb or .gltf for the whole sequence)"
            ),
        }),
        (false, true) => Err(Error::InvalidOption {
            option: "output",
            message: format!("OUTPUT {output:?} has a {{}} but INPUT {input:?} is a single file"),
        }),
    }
}

/// How the frames of a plan are written.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OutputKind {
    /// Each frame to its own mesh file (a single file is one of these).
    Files,
    /// Every frame into one `.mseq` archive, appended when it exists.
    Archive,
    /// The frames of a `{}` pattern collected into one animated `.glb`/`.gltf`, written
    /// whole at the end.
    AnimatedGltf,
}

/// How [`run_frames`] writes the frames of `plan`.
pub fn output_kind(plan: &[(Frame, PathBuf)]) -> OutputKind {
    match plan.first() {
        Some((_, out)) if is_archive(out) => OutputKind::Archive,
        Some((f, out))
            if !f.label.is_empty() && is_gltf(out) && plan.iter().all(|(_, o)| o == out) =>
        {
            OutputKind::AnimatedGltf
        }
        _ => OutputKind::Files,
    }
}

/// Checks that every output of `plan` has a format [`run_frames`] writes (before any
/// work).
pub fn check_outputs(plan: &[(Frame, PathBuf)]) -> Result<()> {
    for (_, out) in plan {
        if !is_archive(out) {
            MeshFormat::from_path(out).map_err(|_| Error::UnsupportedFormat {
                path: out.clone(),
                message: format!(
                    "unknown output extension {:?}; supported: .glb, .gltf, .ply, .obj, .vtk, .mseq (archive)",
                    out.extension().unwrap_or_default().to_string_lossy()
                ),
            })?;
        }
    }
    Ok(())
}

/// Runs every planned frame in order. `on_frame` is called before each frame with its
/// index in the plan, `on_stage` at each phase, `on_done` after each frame: done,
/// skipped or failed. A failed frame stops the run with its error unless
/// [`JobOptions::keep_going`]; then the reports say which frames failed (the caller
/// decides the exit status).
pub fn run_frames(
    plan: &[(Frame, PathBuf)],
    options: &ReconstructOptions,
    job: &JobOptions,
    on_frame: &mut dyn FnMut(usize, &Frame),
    on_stage: &mut dyn FnMut(&str),
    on_done: &mut dyn FnMut(&FrameReport),
) -> Result<Vec<FrameReport>> {
    // A panic becomes an error naming the frame being worked on (its input file), also
    // when an inner entry point (reconstruct) caught it first.
    let current: std::cell::RefCell<Option<PathBuf>> = Default::default();
    let name = || {
        current
            .borrow()
            .as_ref()
            .or_else(|| plan.first().map(|(_, out)| out))
            .map(|p| p.display().to_string())
            .unwrap_or_default()
    };
    let result = crate::error::guard(name, || {
        run_frames_unguarded(plan, options, job, &current, on_frame, on_stage, on_done)
    });
    match result {
        Err(Error::Internal { input, message }) if input != name() => Err(Error::Internal {
            input: name(),
            message: format!("{input}: {message}"),
        }),
        other => other,
    }
}

fn run_frames_unguarded(
    plan: &[(Frame, PathBuf)],
    options: &ReconstructOptions,
    job: &JobOptions,
    current: &std::cell::RefCell<Option<PathBuf>>,
    on_frame: &mut dyn FnMut(usize, &Frame),
    on_stage: &mut dyn FnMut(&str),
    on_done: &mut dyn FnMut(&FrameReport),
) -> Result<Vec<FrameReport>> {
    check_outputs(plan)?;
    let kind = output_kind(plan);
    // What runs killed before they could clean up left in the temporary directory and
    // beside the outputs (names with a PID that is no running process) goes first.
    let temp = options
        .tiles
        .temp_dir
        .clone()
        .unwrap_or_else(std::env::temp_dir);
    crate::io::tempfiles::remove_temp_leftovers(&temp);
    crate::io::tempfiles::remove_output_leftovers(plan.iter().map(|(_, out)| out.as_path()));
    // A .mseq output collects every frame: appended to an existing archive, else new.
    // The frames it holds already:
    let mut held: Vec<i64> = Vec::new();
    let mut archive = match plan.first() {
        Some((_, out)) if kind == OutputKind::Archive => {
            if let Some((_, other)) = plan.iter().find(|(_, o)| o != out) {
                return Err(Error::InvalidOption {
                    option: "output",
                    message: format!(
                        "one .mseq archive holds the whole sequence, not {} and {}",
                        out.display(),
                        other.display()
                    ),
                });
            }
            // Frames the archive holds are refused before it is touched, unless they
            // are to be skipped.
            if out.exists() {
                let reader = ArchiveReader::open(out)?;
                if !job.skip_existing {
                    let numbers: Vec<i64> = plan.iter().map(|(f, _)| f.number).collect();
                    reader.check_new_frames(&numbers)?;
                }
                held = reader.frames().iter().map(|f| f.number).collect();
            }
            // With every frame skipped nothing is written: the archive is not opened for
            // writing (nor its error bound compared).
            let all_skipped =
                job.skip_existing && plan.iter().all(|(f, _)| held.contains(&f.number));
            if all_skipped {
                None
            } else {
                if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
                    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
                }
                let archive_options = ArchiveOptions {
                    attribute_error_bound: job.archive_attribute_error_bound,
                    ..ArchiveOptions::new(job.archive_error_bound)
                };
                Some(if out.exists() {
                    ArchiveWriter::open_append(out, &archive_options)?
                } else {
                    ArchiveWriter::create(out, &archive_options)?
                })
            }
        }
        _ => None,
    };
    // The writer's list also holds frames whose record header is damaged (kept in place).
    let archived: Vec<i64> = match &archive {
        Some(a) => a.frame_numbers(),
        None => held,
    };
    // A pattern written into one .glb/.gltf: frames are kept and written together.
    let sequence_gltf = kind == OutputKind::AnimatedGltf;
    let mut collected: Vec<TriMesh> = Vec::new();
    let mut reports = Vec::with_capacity(plan.len());
    for (i, (frame, output)) in plan.iter().enumerate() {
        job.cancel.check()?;
        *current.borrow_mut() = Some(frame.input.clone());
        on_frame(i, frame);
        let exists = match kind {
            OutputKind::Archive => archived.contains(&frame.number),
            _ => !sequence_gltf && output.exists(),
        };
        if job.skip_existing && exists {
            let report = FrameReport::not_done(frame, output, None, 0.0);
            on_done(&report);
            reports.push(report);
            continue;
        }
        let started = Instant::now();
        let result = output
            .parent()
            .filter(|d| !d.as_os_str().is_empty())
            .map_or(Ok(()), |dir| {
                std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))
            })
            .and_then(|()| {
                let sink = match archive.as_mut() {
                    Some(writer) => Sink::Archive(writer),
                    None if kind == OutputKind::Archive => {
                        unreachable!("the archive is opened when a frame is to be written")
                    }
                    None if sequence_gltf => Sink::Collect(&mut collected),
                    None => Sink::File,
                };
                reconstruct_file(
                    &frame.input,
                    output,
                    options,
                    job,
                    sink,
                    frame.number,
                    on_stage,
                )
            });
        match result {
            Ok(report) => {
                on_done(&report);
                reports.push(report);
            }
            Err(Error::Interrupted) => return Err(Error::Interrupted),
            Err(e) => {
                let report =
                    FrameReport::not_done(frame, output, Some(&e), started.elapsed().as_secs_f64());
                on_done(&report);
                // A write that failed part-way may have left part of a record: the
                // archive takes no more frames (the dropped writer cuts the partial
                // record and indexes the complete ones, as far as the disk lets it).
                let archive_broken = matches!(&e, Error::Io { path, .. } if kind == OutputKind::Archive && *path == plan[0].1);
                if archive_broken {
                    return Err(e);
                }
                if !job.keep_going {
                    if let Some(writer) = archive.take() {
                        if writer.is_started() {
                            writer.finish()?;
                        }
                    }
                    return Err(e);
                }
                reports.push(report);
            }
        }
    }
    // Without finish (an error or an interruption above), dropping the writer still
    // writes the index of the frames appended (see `ArchiveWriter`).
    if let Some(writer) = archive {
        // A new archive none of whose frames was done is not left behind, empty.
        if writer.is_started() {
            writer.finish()?;
        }
    }
    if sequence_gltf && reports.iter().any(|r| r.status == FrameStatus::Done) {
        let (_, out) = &plan[0];
        let written = write_sequence_gltf(out, &collected, job.fps, &job.write)?;
        if let Some(last) = reports.last_mut() {
            last.output_bytes = written.bytes;
        }
    }
    Ok(reports)
}

/// True when `path` names a glTF file (`.glb`, `.gltf`).
pub fn is_gltf(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("glb") || e.eq_ignore_ascii_case("gltf"))
}

/// True when `path` names a `.mseq` archive.
pub fn is_archive(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("mseq"))
}

pub use crate::pipeline::peak_rss_bytes;
