//! Each particle's own radius, from a point attribute of the input: which attribute
//! ([`RadiusAttribute`]: Houdini's `pscale` when present, another only when named), its
//! checks (one finite number > 0 per particle) and its figures ([`ParticleRadii`]: the
//! median, which is the run's reference radius `r` when none is given).
//!
//! Read from a file by [`read_radii`] in one streamed pass that keeps the radius column
//! alone (4 bytes per particle), or from attributes in memory by [`radii_of`].

use crate::attributes::{Attribute, AttributeLayout, AttributeSelection};
use crate::error::{Error, Result};
use crate::io::particles::{read_particles, ParticleFormat, StreamSink};
use glam::Vec3;
use std::path::Path;

/// The attribute Houdini writes a particle's radius to, taken by default.
pub const HOUDINI_RADIUS: &str = "pscale";

/// Which point attribute holds each particle's radius.
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum RadiusAttribute {
    /// Houdini's [`HOUDINI_RADIUS`] (`pscale`, exactly so named) when the input has it,
    /// else none. The default.
    #[default]
    Houdini,
    /// None: every particle has the run's one radius `r`.
    None,
    /// This attribute (the exact name, else the one name that matches ignoring case),
    /// which the input must have.
    Named(String),
}

impl std::str::FromStr for RadiusAttribute {
    type Err = String;
    /// `none`, or an attribute's name.
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s.trim() {
            "" => Err("an empty attribute name (use none for no radius attribute)".into()),
            "none" => Ok(RadiusAttribute::None),
            name => Ok(RadiusAttribute::Named(name.to_string())),
        }
    }
}

impl RadiusAttribute {
    /// The index into `available` (an input's attribute names, in file order) of the
    /// radius attribute, `None` when the input has none to take. A named attribute the
    /// input lacks is an [`Error::Attribute`] listing the names it has, as for
    /// [`AttributeSelection::Names`].
    pub(crate) fn resolve(&self, path: &Path, available: &[&str]) -> Result<Option<usize>> {
        match self {
            RadiusAttribute::None => Ok(None),
            RadiusAttribute::Houdini => Ok(available.iter().position(|n| *n == HOUDINI_RADIUS)),
            RadiusAttribute::Named(name) => Ok(AttributeSelection::Names(vec![name.clone()])
                .resolve(path, available)?
                .first()
                .copied()),
        }
    }
}

/// The widest ratio, either way, of a particle's radius to its frame's median radius
/// ([`ParticleRadii::median`]): every radius must lie within `median / RADIUS_SPREAD` and
/// `median × RADIUS_SPREAD`. Foam or spray particles several times the fluid's radius, or
/// an adaptive simulation's radii spanning 1:10, pass; a particle 100× or 1000× the others
/// (a stray `pscale`) is refused before any work. Why a bound at all: the lattice stays
/// one cell size (`h·r`), so a particle ρ times the reference radius covers ρ³ times the
/// field blocks of a normal one, and the reach of every particle's neighbour search grows
/// with the largest ρ of the frame (one particle of 1000× asked for terabytes).
pub const RADIUS_SPREAD: f32 = 10.0;

/// The smallest and the largest radius (world units) any run accepts, the reference
/// radius `r` as well as each particle's: beyond them the squares of a particle's reaches
/// (up to 64 cells of up to [`RADIUS_SPREAD`]× r) leave f32's range and the surface turns
/// to NaN (a radius of `f32::MAX` gave a surface of NaN coordinates).
pub const RADIUS_LIMITS: (f32, f32) = (1e-12, 1e12);

/// Each particle's radius (world units, input order), checked: one finite number > 0
/// per particle, within [`RADIUS_LIMITS`] and within [`RADIUS_SPREAD`]× of the median.
#[derive(Clone, Debug, PartialEq)]
pub struct ParticleRadii {
    /// The attribute they were read from.
    pub attribute: String,
    /// The radii, one per particle, in input order.
    pub values: Vec<f32>,
}

impl ParticleRadii {
    /// The radii of `attribute` for `count` particles of `path` (named in errors), after
    /// checking them: one component, `count` values, each finite and > 0; else an
    /// [`Error::InvalidRadius`] naming the file, the attribute and the first bad particle.
    pub fn new(path: &Path, attribute: Attribute, count: usize) -> Result<Self> {
        if attribute.components != 1 {
            return Err(Error::InvalidRadius {
                path: path.to_path_buf(),
                attribute: attribute.name,
                particle: None,
                message: format!(
                    "has {} components per particle; a radius is one number",
                    attribute.components
                ),
            });
        }
        let radii = ParticleRadii {
            attribute: attribute.name,
            values: attribute.values,
        };
        radii.check(path, count)?;
        Ok(radii)
    }

    /// Checks that there are `count` radii, each finite and > 0, within [`RADIUS_LIMITS`]
    /// and within [`RADIUS_SPREAD`]× of the median either way; else an
    /// [`Error::InvalidRadius`] naming `path`, the attribute, the first bad particle and
    /// its value.
    pub fn check(&self, path: &Path, count: usize) -> Result<()> {
        let fail = |particle: Option<usize>, message: String| Error::InvalidRadius {
            path: path.to_path_buf(),
            attribute: self.attribute.clone(),
            particle,
            message,
        };
        if self.values.len() != count {
            let n = self.values.len();
            return Err(fail(
                None,
                format!("holds {n} values for {count} particles"),
            ));
        }
        if let Some(i) = self
            .values
            .iter()
            .position(|&v| !(v.is_finite() && v > 0.0))
        {
            return Err(fail(
                Some(i),
                format!(
                    "radius {:?}; a radius must be a finite number > 0",
                    self.values[i]
                ),
            ));
        }
        let (lo, hi) = RADIUS_LIMITS;
        if let Some(i) = self.values.iter().position(|&v| !(lo..=hi).contains(&v)) {
            return Err(fail(
                Some(i),
                format!(
                    "radius {:?}; a radius must lie within {lo:e}–{hi:e} world units (the squares of its reaches must stay finite in f32)",
                    self.values[i]
                ),
            ));
        }
        if count == 0 {
            return Ok(());
        }
        let median = self.median();
        let (low, high) = (median / RADIUS_SPREAD, median * RADIUS_SPREAD);
        match self.values.iter().position(|&v| !(low..=high).contains(&v)) {
            Some(i) => {
                let v = self.values[i];
                Err(fail(
                    Some(i),
                    format!(
                        "radius {v:?} is {:.3} × the frame's median radius {median:?}; a particle's radius must lie within 1/{RADIUS_SPREAD}×–{RADIUS_SPREAD}× the median (docs/radius.md)",
                        v / median
                    ),
                ))
            }
            None => Ok(()),
        }
    }

    /// The median radius, world units: the lower middle value (a radius of the input,
    /// so a uniform attribute's median is its value exactly).
    pub fn median(&self) -> f32 {
        let mut sorted = self.values.clone();
        let middle = (sorted.len() - 1) / 2;
        *sorted.select_nth_unstable_by(middle, f32::total_cmp).1
    }

    /// The smallest and the largest radius, world units.
    pub fn range(&self) -> (f32, f32) {
        self.values
            .iter()
            .fold((f32::INFINITY, 0.0f32), |(lo, hi), &v| {
                (lo.min(v), hi.max(v))
            })
    }

    /// True when every particle has the same radius.
    pub fn is_uniform(&self) -> bool {
        let (lo, hi) = self.range();
        lo == hi
    }
}

/// The radii of particles in memory: the attribute `which` picks among `attributes`
/// (each holding one item per particle of `count`), checked; `None` when it picks none.
/// `path` names the particles in errors.
pub fn radii_of(
    path: &Path,
    attributes: &[Attribute],
    count: usize,
    which: &RadiusAttribute,
) -> Result<Option<ParticleRadii>> {
    let names: Vec<&str> = attributes.iter().map(|a| a.name.as_str()).collect();
    match which.resolve(path, &names)? {
        None => Ok(None),
        Some(k) => ParticleRadii::new(path, attributes[k].clone(), count).map(Some),
    }
}

/// The radii of the particle file `path` (the format from `format` or the extension):
/// the attribute `which` picks, checked ([`ParticleRadii::new`]); `None` when it picks
/// none. Formats that stream are read in one pass keeping the radius column alone (the
/// reading stops after the header when there is none); other layouts are read whole.
pub fn read_radii(
    path: &Path,
    format: Option<ParticleFormat>,
    which: &RadiusAttribute,
) -> Result<Option<ParticleRadii>> {
    if *which == RadiusAttribute::None {
        return Ok(None);
    }
    let format = match format {
        Some(f) => f,
        None => ParticleFormat::from_path(path)?,
    };
    if format == ParticleFormat::Xyz {
        // Raw positions hold no attributes.
        which.resolve(path, &[])?;
        return Ok(None);
    }
    let mut sink = RadiusColumn {
        path,
        which,
        attribute: None,
        absent: false,
        values: Vec::new(),
    };
    let streamed = match format.codec().stream(path, &mut sink) {
        Err(Error::Interrupted) if sink.absent => return Ok(None),
        streamed => streamed?,
    };
    match (streamed, sink.attribute) {
        (Some(count), Some(layout)) => {
            let attribute = Attribute {
                name: layout.name,
                components: layout.components,
                values: sink.values,
            };
            ParticleRadii::new(path, attribute, count).map(Some)
        }
        (Some(_), None) => Ok(None),
        (None, _) => {
            let particles = read_particles(path, Some(format))?;
            radii_of(
                path,
                &particles.attributes,
                particles.positions.len(),
                which,
            )
        }
    }
}

/// The [`StreamSink`] of [`read_radii`]: keeps the radius column. When the header
/// declares no radius attribute it stops the reader at once (with
/// [`Error::Interrupted`], `absent` set: nothing is left to read).
struct RadiusColumn<'a> {
    path: &'a Path,
    which: &'a RadiusAttribute,
    attribute: Option<AttributeLayout>,
    absent: bool,
    values: Vec<f32>,
}

impl StreamSink for RadiusColumn<'_> {
    fn select(&mut self, count: usize, declared: &[AttributeLayout]) -> Result<Vec<usize>> {
        let names: Vec<&str> = declared.iter().map(|a| a.name.as_str()).collect();
        let Some(k) = self.which.resolve(self.path, &names)? else {
            self.absent = true;
            return Err(Error::Interrupted);
        };
        let layout = declared[k].clone();
        if layout.components != 1 {
            return Err(Error::InvalidRadius {
                path: self.path.to_path_buf(),
                attribute: layout.name,
                particle: None,
                message: format!(
                    "has {} components per particle; a radius is one number",
                    layout.components
                ),
            });
        }
        self.values.reserve_exact(count);
        self.attribute = Some(layout);
        Ok(vec![k])
    }

    fn records(&mut self, _: &[Vec3], rows: &[f32]) -> Result<()> {
        self.values.extend_from_slice(rows);
        Ok(())
    }

    fn array(&mut self, _: usize, rows: &[f32]) -> Result<()> {
        self.values.extend_from_slice(rows);
        Ok(())
    }
}
