//! Particle attributes carried to the surface (velocity for motion blur, density, any
//! scalar or vector the input holds).
//!
//! This module is a leaf: the attribute types ([`Attribute`], [`AttributeLayout`]), the
//! choice of which a run carries ([`AttributeSelection`]) and their checks, which the
//! readers (`io`), the tiles and the writers share. Selecting the attributes of read
//! particles is [`crate::io::particles::Particles::select`].
//!
//! The stage that carries the attributes to the surface is `transfer`.

use crate::error::{Error, Result};
use std::path::Path;

/// Per-item values of one named attribute: per particle, per mesh vertex or per sphere
/// instance, `components` floats each.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Attribute {
    /// Name as in the input file (`velocity`, `density`, ...).
    pub name: String,
    /// Components per item (1 for scalars, 3 for vectors).
    pub components: usize,
    /// `components × items` values, item-major.
    pub values: Vec<f32>,
}

impl Attribute {
    /// Number of items (particles, vertices or instances) the attribute holds.
    pub fn len(&self) -> usize {
        self.values.len().checked_div(self.components).unwrap_or(0)
    }

    /// True when the attribute holds no item.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The values of item `i`.
    pub fn item(&self, i: usize) -> &[f32] {
        &self.values[i * self.components..(i + 1) * self.components]
    }
}

/// Name and size of one attribute of a payload.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize)]
pub struct AttributeLayout {
    /// Name as in the input.
    pub name: String,
    /// Components per item.
    pub components: usize,
}

impl AttributeLayout {
    /// The layout of `attribute`.
    pub fn of(attribute: &Attribute) -> Self {
        AttributeLayout {
            name: attribute.name.clone(),
            components: attribute.components,
        }
    }
}

/// Floats per payload row of `layout`.
pub(crate) fn payload_width(layout: &[AttributeLayout]) -> usize {
    layout.iter().map(|a| a.components).sum()
}

/// Which point attributes of the input a run carries to the surface.
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum AttributeSelection {
    /// The velocity, when the input has one (the first attribute named `v`, `vel` or
    /// `velocity`, in any case), else none. The default.
    #[default]
    Velocity,
    /// None: positions only.
    None,
    /// Every attribute the input holds.
    All,
    /// These, by name (exact, else the one name that matches ignoring case), in this order.
    Names(Vec<String>),
}

impl std::str::FromStr for AttributeSelection {
    type Err = String;
    /// `none`, `all`, or a comma-separated list of names.
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s.trim() {
            "none" => Ok(AttributeSelection::None),
            "all" => Ok(AttributeSelection::All),
            "" => Err("an empty list of attributes (use none)".into()),
            list => {
                let names: Vec<String> = list.split(',').map(|n| n.trim().to_string()).collect();
                if names.iter().any(String::is_empty) {
                    return Err(format!("an empty name in the list {list:?}"));
                }
                Ok(AttributeSelection::Names(names))
            }
        }
    }
}

impl AttributeSelection {
    /// True when no attribute can be selected, whatever the input holds.
    pub fn is_none(&self) -> bool {
        *self == AttributeSelection::None
    }

    /// The indices into `available` (an input's attribute names, in file order) of the
    /// attributes this selection asks for, in its order. A name the input lacks (or
    /// selected twice) is an [`Error::Attribute`] naming `path` and listing the
    /// names it has. The one rule for whole-file and streaming readers.
    pub(crate) fn resolve(&self, path: &Path, available: &[&str]) -> Result<Vec<usize>> {
        Ok(match self {
            AttributeSelection::None => Vec::new(),
            AttributeSelection::All => (0..available.len()).collect(),
            AttributeSelection::Velocity => available
                .iter()
                .position(|n| VELOCITY_NAMES.iter().any(|v| n.eq_ignore_ascii_case(v)))
                .into_iter()
                .collect(),
            AttributeSelection::Names(names) => {
                let mut wanted = Vec::with_capacity(names.len());
                for name in names {
                    let exact = available.iter().position(|n| *n == name.as_str());
                    let folded: Vec<usize> = (0..available.len())
                        .filter(|&k| available[k].eq_ignore_ascii_case(name))
                        .collect();
                    let k = match (exact, folded.as_slice()) {
                        (Some(k), _) => k,
                        (None, [k]) => *k,
                        _ => {
                            return Err(Error::Attribute {
                                path: path.to_path_buf(),
                                attribute: name.clone(),
                                message: if available.is_empty() {
                                    "the input holds no point attributes".into()
                                } else {
                                    format!("not in the input, which has: {}", available.join(", "))
                                },
                            })
                        }
                    };
                    if wanted.contains(&k) {
                        return Err(Error::Attribute {
                            path: path.to_path_buf(),
                            attribute: name.clone(),
                            message: "selected twice".into(),
                        });
                    }
                    wanted.push(k);
                }
                wanted
            }
        })
    }
}

/// Names the default selection takes as the velocity (compared ignoring case).
pub const VELOCITY_NAMES: [&str; 3] = ["v", "vel", "velocity"];

/// The error for the non-finite `value` of `attribute` at `particle` of `path`, as
/// [`check_attribute`] reports it.
pub(crate) fn non_finite_attribute(
    path: &Path,
    attribute: &str,
    particle: usize,
    value: f32,
) -> Error {
    Error::Attribute {
        path: path.to_path_buf(),
        attribute: attribute.to_string(),
        message: format!("particle {particle} has a non-finite value {value}"),
    }
}

/// Checks that `a` holds `count` items of at least one component, all finite.
pub(crate) fn check_attribute(path: &Path, a: &Attribute, count: usize) -> Result<()> {
    let fail = |message: String| Error::Attribute {
        path: path.to_path_buf(),
        attribute: a.name.clone(),
        message,
    };
    if a.components == 0 || a.values.len() != a.components * count {
        return Err(fail(format!(
            "{} values of {} components for {count} particles",
            a.values.len(),
            a.components
        )));
    }
    if let Some(v) = a.values.iter().position(|v| !v.is_finite()) {
        return Err(non_finite_attribute(
            path,
            &a.name,
            v / a.components,
            a.values[v],
        ));
    }
    Ok(())
}
