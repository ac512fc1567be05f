//! One frame of a job: read its particle file, reconstruct it with the options its sink
//! asks for, and append the surface to the sink ([`run_frame`]).

use super::report::{FrameReport, FrameStatus};
use super::sink::FrameSink;
use super::JobOptions;
use crate::attributes::AttributeSelection;
use crate::cancel::CancelToken;
use crate::error::{Error, Result};
use crate::io::particles::SpooledParticles;
use crate::io::particles::{read_particles, MappedXyz, ParticleFormat, Particles};
use crate::mesh::Surface;
use crate::pipeline::{reconstruct_sized, ReconstructOptions, ReconstructionStats};
use crate::radius::{read_radii, ParticleRadii};
use crate::sequence::Frame;
use std::path::Path;
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

/// Opens the particle file `input`. Raw .xyz is mapped window by window; BGEO, PLY
/// (binary or ASCII) with its vertices first, and VTK whose sections a scan can follow
/// are streamed once, positions and the selected attributes, into temporary files that
/// are then mapped the same way; other layouts are parsed into memory and handed over, so
/// a tiled run can drop them once they are spilled.
fn read_input(input: &Path, options: &ReconstructOptions, job: &JobOptions) -> Result<Input> {
    if input.is_dir() {
        return Err(Error::io(
            input,
            std::io::Error::new(
                std::io::ErrorKind::IsADirectory,
                "is a directory, not a particle file",
            ),
        ));
    }
    let format = match job.input_format {
        Some(f) => f,
        None => ParticleFormat::from_path(input)?,
    };
    if format == ParticleFormat::Xyz {
        if let AttributeSelection::Names(names) = &job.attributes {
            // Raw positions hold no attributes: the same error as any missing name.
            Particles::default().select(input, &AttributeSelection::Names(names.clone()))?;
        }
        return Ok(Input::Mapped(MappedXyz::open(input)?));
    }
    let spooled = SpooledParticles::from_file(
        input,
        format,
        &job.attributes,
        options.tiles.temp_dir.as_deref(),
        &job.cancel,
    )?;
    match spooled {
        Some(spooled) => Ok(Input::Spooled(spooled)),
        None => parsed(input, format, &job.attributes),
    }
}

/// Reconstructs the particles of the file `input`; `on_stage` is told each stage.
fn reconstruct_input(
    particles: Input,
    radii: Option<ParticleRadii>,
    input: &Path,
    options: &ReconstructOptions,
    cancel: &CancelToken,
    on_stage: &mut dyn FnMut(&str),
) -> Result<(Surface, ReconstructionStats)> {
    let progress = std::cell::RefCell::new(on_stage);
    let progress = |stage: &str| (progress.borrow_mut())(stage);
    match particles {
        Input::Mapped(file) => reconstruct_sized(file, radii, options, &progress, cancel),
        Input::Spooled(file) => reconstruct_sized(file, radii, options, &progress, cancel),
        Input::Parsed(particles) => reconstruct_sized(particles, radii, options, &progress, cancel),
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
    })
}

/// Reads `frame`'s particle file, reconstructs it with the options `sink` asks for
/// ([`FrameSink::options`]) and appends the surface to `sink` (`output` is the frame's
/// path in the plan). `on_stage` is told when a phase starts ("read", "reconstruct",
/// "write") and each pipeline stage.
pub(crate) fn run_frame(
    frame: &Frame,
    output: &Path,
    options: &ReconstructOptions,
    job: &JobOptions,
    sink: &mut dyn FrameSink,
    on_stage: &mut dyn FnMut(&str),
) -> Result<FrameReport> {
    on_stage("read");
    let started = Instant::now();
    let radii = read_radii(&frame.input, job.input_format, &job.radius_attribute)?;
    let particles = read_input(&frame.input, options, job)?;
    let read_seconds = started.elapsed().as_secs_f64();
    on_stage("reconstruct");
    let options = sink.options(options);
    let (surface, mut reconstruction) = reconstruct_input(
        particles,
        radii,
        &frame.input,
        &options,
        &job.cancel,
        on_stage,
    )?;
    job.cancel.check()?;
    on_stage("write");
    let clock = Instant::now();
    let appended = sink.append(frame, output, &surface, &mut reconstruction)?;
    let write_seconds = clock.elapsed().as_secs_f64();
    reconstruction.push_stage("write", write_seconds, reconstruction.fluid_triangles);
    Ok(FrameReport {
        frame: frame.number,
        time: frame.time,
        input: frame.input.clone(),
        output: output.to_path_buf(),
        status: FrameStatus::Done,
        skipped: false,
        error: None,
        seconds: started.elapsed().as_secs_f64(),
        read_seconds,
        reconstruction,
        write_seconds,
        output_bytes: appended.bytes,
        dropped_attributes: appended.dropped_attributes,
    })
}
