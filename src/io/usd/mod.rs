//! OpenUSD stages of whole surface sequences, written frame by frame.
//!
//! [`UsdStageWriter`] writes one stage holding a sequence: a `UsdGeomMesh` (`/Surface/Fluid`)
//! with time samples at the simulation's frame numbers for `points`, `faceVertexCounts`,
//! `faceVertexIndices`, `normals`, `extent`, `velocities` (the velocity attribute, `v`,
//! `vel` or `velocity`, as it is: units per second) and `primvars:NAME` for the other
//! attributes (vertex interpolation; 1–4 components as `float`…`float4`, more as
//! `float[]` with `elementSize`). The isolated particles (droplets) are, by default
//! ([`UsdDroplets::Points`]), a `UsdGeomPoints` prim (`/Surface/Droplets`) with
//! time-sampled `points`, `widths` (2 r_i: the particle's diameter), `extent`,
//! `velocities` and `primvars:NAME` per point: renderers draw them as spheres, and
//! importers keep the velocities (Blender makes a point cloud with `radius` and `velocity`
//! attributes, which Cycles blurs). [`UsdDroplets::Instancer`] writes them instead as a
//! `UsdGeomPointInstancer` (`/Surface/Spheres`) of the icosphere, with time-sampled
//! positions, velocities and primvars per instance, and `scales` (each factor on all
//! three axes) for frames whose spheres have sizes of their own (a frame without them
//! has an empty array there: every instance at the prototype's size); Blender 5.0's
//! importer drops an instancer's velocities, so its droplets get no motion blur. The layer metadata sets `startTimeCode`/`endTimeCode` to the
//! first and last frame, `timeCodesPerSecond` = `framesPerSecond` = [`UsdOptions::fps`],
//! `upAxis` and `metersPerUnit`.
//!
//! | extension | format |
//! |---|---|
//! | `.usdc`, `.usd` | binary crate file (version 0.8.0), written by this module's own encoder |
//! | `.usda` | text |
//!
//! Memory does not grow with the sequence: a crate file keeps its tables at the end, so
//! every array goes to the file when its frame is appended and the writer keeps only
//! their offsets (8 bytes per array and frame); the text encoder spools each property's
//! samples to an anonymous temporary file beside the output and joins them at the end.
//! The stage is written to a temporary file beside the target and renamed over it by
//! [`UsdStageWriter::finish`]: a stage that is dropped unfinished, or whose writes failed,
//! leaves nothing behind and keeps an existing target.

mod coding;
mod crate_file;
mod stage;
mod usda;
mod usdc;

use crate::error::{Error, Result};
use crate::io::atomic::temporary_path;
use crate::mesh::{Surface, TriMesh};
use stage::{Series, Values};
use std::collections::HashSet;
use std::io;
use std::path::{Path, PathBuf};

/// The stage's up axis (`upAxis` layer metadata).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum UpAxis {
    /// +Y up, the simulators' convention. The default.
    #[default]
    Y,
    /// +Z up.
    Z,
}

impl UpAxis {
    /// The metadata token: `Y` or `Z`.
    pub fn token(self) -> &'static str {
        match self {
            UpAxis::Y => "Y",
            UpAxis::Z => "Z",
        }
    }
}

impl std::str::FromStr for UpAxis {
    type Err = String;

    /// `Y` or `Z`, either case.
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "Y" | "y" => Ok(UpAxis::Y),
            "Z" | "z" => Ok(UpAxis::Z),
            other => Err(format!("the up axis is Y or Z, got {other:?}")),
        }
    }
}

impl std::fmt::Display for UpAxis {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.token())
    }
}

/// How a stage holds the isolated particles (the surface's sphere instances).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum UsdDroplets {
    /// A `UsdGeomPoints` prim, `/Surface/Droplets`: a point per particle with its width
    /// (2 r_i), velocity and attributes. The default: every renderer draws points as
    /// spheres, and importers keep the velocities for motion blur.
    #[default]
    Points,
    /// A `UsdGeomPointInstancer`, `/Surface/Spheres`, of the icosphere mesh (the
    /// surface's sphere template).
    Instancer,
}

impl UsdDroplets {
    /// The option's word: `points` or `instancer`.
    pub fn name(self) -> &'static str {
        match self {
            UsdDroplets::Points => "points",
            UsdDroplets::Instancer => "instancer",
        }
    }
}

impl std::str::FromStr for UsdDroplets {
    type Err = String;

    /// `points` or `instancer`, either case.
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "points" => Ok(UsdDroplets::Points),
            "instancer" => Ok(UsdDroplets::Instancer),
            _ => Err(format!(
                "the isolated particles of a USD stage are points or instancer, got {s:?}"
            )),
        }
    }
}

impl std::fmt::Display for UsdDroplets {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Stage file formats.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum UsdFormat {
    /// Binary crate file (`.usdc`, `.usd`).
    Usdc,
    /// Text (`.usda`).
    Usda,
}

impl UsdFormat {
    /// The format named by a file's extension.
    pub fn from_path(path: &Path) -> Result<Self> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .unwrap_or_default()
            .to_ascii_lowercase();
        match ext.as_str() {
            "usdc" | "usd" => Ok(UsdFormat::Usdc),
            "usda" => Ok(UsdFormat::Usda),
            _ => Err(Error::UnsupportedFormat {
                path: path.to_path_buf(),
                message: format!("unknown USD extension {ext:?}; supported: .usdc, .usd, .usda"),
            }),
        }
    }
}

/// Options of [`UsdStageWriter`].
#[derive(Clone, Debug, PartialEq)]
pub struct UsdOptions {
    /// Frames per second: `timeCodesPerSecond` and `framesPerSecond`. Default 24.
    pub fps: f64,
    /// `upAxis`. Default [`UpAxis::Y`].
    pub up_axis: UpAxis,
    /// `metersPerUnit`: meters in one world unit. Default 1.
    pub meters_per_unit: f64,
    /// Write vertex normals when the meshes have them. Default `true`.
    pub normals: bool,
    /// Format override; `None` chooses by extension. Default `None`.
    pub format: Option<UsdFormat>,
    /// The isolated particles as points or as an instancer. Default
    /// [`UsdDroplets::Points`].
    pub droplets: UsdDroplets,
}

impl Default for UsdOptions {
    fn default() -> Self {
        UsdOptions {
            fps: 24.0,
            up_axis: UpAxis::Y,
            meters_per_unit: 1.0,
            normals: true,
            format: None,
            droplets: UsdDroplets::Points,
        }
    }
}

impl UsdOptions {
    /// Fails with [`Error::InvalidOption`] unless `fps` and `meters_per_unit` are positive
    /// and finite.
    pub fn validate(&self) -> Result<()> {
        for (option, value) in [("fps", self.fps), ("meters_per_unit", self.meters_per_unit)] {
            if !(value.is_finite() && value > 0.0) {
                return Err(Error::InvalidOption {
                    option,
                    message: format!("{value} is not a positive finite number"),
                });
            }
        }
        Ok(())
    }
}

/// The largest frame number, either way, a USD stage takes: its time codes are doubles,
/// which hold every integer up to 2^53 exactly; above it neighbouring frame numbers share
/// one time code (three frames gave two samples).
pub const MAX_STAGE_FRAME: i64 = 1 << 53;

/// Refuses frame numbers a stage at `path` cannot give distinct time codes
/// ([`MAX_STAGE_FRAME`]), naming the first.
pub fn check_time_codes(path: &Path, frames: &[i64]) -> Result<()> {
    match frames.iter().find(|n| n.unsigned_abs() > MAX_STAGE_FRAME as u64) {
        Some(n) => Err(Error::UnsupportedFormat {
            path: path.to_path_buf(),
            message: format!(
                "frame number {n}: a USD time code holds frame numbers up to ±2^53 ({MAX_STAGE_FRAME}) exactly, and larger ones would share time codes"
            ),
        }),
        None => Ok(()),
    }
}

/// Writes `surface` as a stage of one frame, `frame` (its time code: a single time sample
/// there, the time range `frame`..`frame`), atomically: [`UsdStageWriter`] with one
/// [`UsdStageWriter::append_frame`]. A stage per frame of a sequence, as a farm writes them
/// or USD value clips take them.
pub fn write_stage(
    path: &Path,
    frame: i64,
    surface: &Surface,
    options: &UsdOptions,
) -> Result<UsdStageStats> {
    let mut stage = UsdStageWriter::create(path, options)?;
    stage.append_frame(frame, surface)?;
    stage.finish()
}

/// What a [`UsdStageWriter`] wrote.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct UsdStageStats {
    /// Bytes of the stage file.
    pub bytes: u64,
    /// Frames in the stage.
    pub frames: usize,
    /// Triangles over all frames (fluid plus every sphere instance of an instancer).
    pub triangles: usize,
    /// Vertices over all frames (fluid plus every sphere instance of an instancer).
    pub vertices: usize,
    /// Isolated particles over all frames (points or instances).
    pub droplets: usize,
}

/// The format-specific part of the writer (`Send`, so a writer can move to the thread
/// that finishes a run's frames).
trait Encoder: Send {
    /// Writes sample `slot` (at `time`) of series `index`, defined by `series`.
    fn sample(
        &mut self,
        index: usize,
        series: &Series,
        slot: usize,
        time: f64,
        values: Values<'_>,
    ) -> io::Result<()>;

    /// Writes the rest of the stage (every series, the prim tree, the metadata) and
    /// returns the file's size in bytes.
    fn finish(self: Box<Self>, end: &StageEnd<'_>) -> io::Result<u64>;
}

/// What the encoders need at the end: the series, the time of each slot, the prim tree
/// and the layer metadata.
struct StageEnd<'a> {
    series: &'a [Series],
    times: &'a [f64],
    tree: stage::Prim<'a>,
    metadata: Vec<(&'static str, stage::Meta)>,
}

/// A stage being written, one frame at a time: [`UsdStageWriter::create`], then
/// [`UsdStageWriter::append_frame`] per frame (in any order of frame numbers, each once),
/// then [`UsdStageWriter::finish`].
///
/// ```no_run
/// use meniscus::io::usd::{UsdOptions, UsdStageWriter};
/// # fn main() -> meniscus::Result<()> {
/// # let frames: Vec<(i64, meniscus::mesh::Surface)> = Vec::new();
/// let mut stage = UsdStageWriter::create("shot.usdc".as_ref(), &UsdOptions::default())?;
/// for (number, surface) in &frames {
///     stage.append_frame(*number, surface)?;
/// }
/// let stats = stage.finish()?;
/// # Ok(())
/// # }
/// ```
pub struct UsdStageWriter {
    path: PathBuf,
    temporary: PathBuf,
    options: UsdOptions,
    encoder: Option<Box<dyn Encoder>>,
    series: Vec<Series>,
    /// Time of each appended frame, in the order appended (the slot of a sample).
    times: Vec<f64>,
    frames: HashSet<i64>,
    templates: Vec<TriMesh>,
    /// Set when a write failed: the file's content is no longer known.
    broken: bool,
    stats: UsdStageStats,
}

impl UsdStageWriter {
    /// Starts a stage at `path` (written to a temporary file beside it until
    /// [`UsdStageWriter::finish`]).
    pub fn create(path: &Path, options: &UsdOptions) -> Result<Self> {
        options.validate()?;
        let format = match options.format {
            Some(f) => f,
            None => UsdFormat::from_path(path)?,
        };
        if path.is_dir() {
            return Err(Error::io(
                path,
                io::Error::new(
                    io::ErrorKind::IsADirectory,
                    "the output path is a directory",
                ),
            ));
        }
        let temporary = temporary_path(path);
        let file = std::fs::File::create(&temporary).map_err(|e| Error::io(path, e))?;
        let dir = match path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let encoder: io::Result<Box<dyn Encoder>> = match format {
            UsdFormat::Usdc => {
                usdc::UsdcEncoder::new(file).map(|e| Box::new(e) as Box<dyn Encoder>)
            }
            UsdFormat::Usda => Ok(Box::new(usda::UsdaEncoder::new(file, dir))),
        };
        let encoder = encoder.map_err(|e| {
            let _ = std::fs::remove_file(&temporary);
            Error::io(path, e)
        })?;
        Ok(UsdStageWriter {
            path: path.to_path_buf(),
            temporary,
            options: options.clone(),
            encoder: Some(encoder),
            series: stage::fluid_series(),
            times: Vec::new(),
            frames: HashSet::new(),
            templates: Vec::new(),
            broken: false,
            stats: UsdStageStats::default(),
        })
    }

    /// The stage's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Frames appended so far.
    pub fn frames(&self) -> usize {
        self.times.len()
    }

    /// Adds frame `frame` (its time code) of `surface` to every series. Checked before
    /// anything is written: a frame number already in the stage fails with
    /// [`Error::FramesExist`], an attribute with a wrong value count, a property name
    /// that two attributes share or one that earlier frames wrote with another number of
    /// components with [`Error::Attribute`]; the stage stays usable after these. A
    /// failed write ([`Error::Io`]) leaves it unusable: [`UsdStageWriter::finish`] then
    /// fails too and removes the temporary file.
    pub fn append_frame(&mut self, frame: i64, surface: &Surface) -> Result<()> {
        self.check_usable()?;
        check_time_codes(&self.path, &[frame])?;
        if self.frames.contains(&frame) {
            return Err(Error::FramesExist {
                path: self.path.clone(),
                frames: vec![frame],
                planned: 1,
            });
        }
        let template = &surface.spheres.template;
        let prototype = self
            .templates
            .iter()
            .position(|t| t == template)
            .unwrap_or(self.templates.len());
        let plan = stage::plan_frame(&self.path, surface, prototype, &self.options)?;
        let mut indices = Vec::with_capacity(plan.samples.len());
        for (series, _) in &plan.samples {
            match self
                .series
                .iter()
                .position(|s| s.owner == series.owner && s.name == series.name)
            {
                Some(i) if self.series[i].element != series.element => {
                    return Err(Error::Attribute {
                        path: self.path.clone(),
                        attribute: series.name.clone(),
                        message: format!(
                            "frame {frame} has it as {}, earlier frames as {}",
                            series.element.type_name(),
                            self.series[i].element.type_name()
                        ),
                    })
                }
                found => indices.push(found),
            }
        }
        if let Some(t) = plan.template {
            if prototype == self.templates.len() {
                self.templates.push(t.clone());
            }
        }
        let (slot, time) = (self.times.len(), frame as f64);
        let encoder = self
            .encoder
            .as_mut()
            .expect("a usable writer has its encoder");
        for ((series, values), found) in plan.samples.into_iter().zip(indices) {
            let index = found.unwrap_or_else(|| {
                self.series.push(series);
                self.series.len() - 1
            });
            if let Err(e) = encoder.sample(index, &self.series[index], slot, time, values) {
                self.broken = true;
                return Err(Error::io(&self.path, e));
            }
        }
        self.times.push(time);
        self.frames.insert(frame);
        let spheres = &surface.spheres;
        let instances = match self.options.droplets {
            UsdDroplets::Points => 0,
            UsdDroplets::Instancer => spheres.centers.len(),
        };
        self.stats.frames += 1;
        self.stats.droplets += spheres.centers.len();
        self.stats.triangles +=
            surface.fluid.triangle_count() + spheres.template.triangle_count() * instances;
        self.stats.vertices +=
            surface.fluid.vertex_count() + spheres.template.vertex_count() * instances;
        Ok(())
    }

    /// Fails when an earlier write failed.
    fn check_usable(&self) -> Result<()> {
        if self.broken || self.encoder.is_none() {
            return Err(Error::io(
                &self.path,
                io::Error::other("an earlier write of this stage failed"),
            ));
        }
        Ok(())
    }

    /// Writes the tables (or joins the text) and renames the stage over its path.
    pub fn finish(mut self) -> Result<UsdStageStats> {
        self.check_usable()?;
        let encoder = self
            .encoder
            .take()
            .expect("a usable writer has its encoder");
        let end = StageEnd {
            series: &self.series,
            times: &self.times,
            tree: stage::prim_tree(&self.series, &self.templates),
            metadata: stage::layer_metadata(&self.options, &self.times),
        };
        let written = encoder
            .finish(&end)
            .and_then(|bytes| std::fs::rename(&self.temporary, &self.path).map(|_| bytes));
        match written {
            Ok(bytes) => {
                self.stats.bytes = bytes;
                Ok(std::mem::take(&mut self.stats))
            }
            Err(e) => {
                let _ = std::fs::remove_file(&self.temporary);
                Err(Error::io(&self.path, e))
            }
        }
    }
}

impl Drop for UsdStageWriter {
    /// An unfinished stage leaves nothing behind.
    fn drop(&mut self) {
        if self.encoder.take().is_some() || self.broken {
            let _ = std::fs::remove_file(&self.temporary);
        }
    }
}
