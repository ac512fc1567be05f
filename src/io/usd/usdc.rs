//! The binary stage: samples go to the crate file as frames arrive; at the end, the shared
//! times, one time series per property and the specs of the prim tree.

use super::crate_file::{CrateWriter, PathId, SpecType, Type, ValueRep};
use super::stage::{Element, Meta, Prim, Series, Value, Values};
use super::{Encoder, StageEnd};
use std::collections::HashMap;
use std::fs::File;
use std::io::{self, BufWriter};

/// `SdfSpecifier` of a defined prim.
const DEF: u32 = 0;
/// `SdfVariability` values.
const VARYING: u32 = 0;
const UNIFORM: u32 = 1;

/// The crate type of an array of `element`.
fn crate_type(element: Element) -> Type {
    match element {
        Element::Int => Type::Int,
        Element::Point | Element::Normal | Element::Vector | Element::Float3 => Type::Vec3f,
        Element::Floats(2) => Type::Vec2f,
        Element::Floats(3) => Type::Vec3f,
        Element::Floats(4) => Type::Vec4f,
        Element::Floats(_) => Type::Float,
    }
}

/// Crate-file encoder of a stage.
pub(super) struct UsdcEncoder {
    file: CrateWriter<BufWriter<File>>,
    /// Per series, the rep of each slot's sample (`None`: the frame had none).
    samples: Vec<Vec<Option<ValueRep>>>,
}

impl UsdcEncoder {
    /// Starts the crate file in `file` (empty).
    pub(super) fn new(file: File) -> io::Result<Self> {
        Ok(UsdcEncoder {
            file: CrateWriter::new(BufWriter::with_capacity(1 << 20, file))?,
            samples: Vec::new(),
        })
    }
}

/// Paths and specs of the prim tree, written once the series are.
struct SpecWriter<'a, 'w> {
    file: &'w mut CrateWriter<BufWriter<File>>,
    /// The series, and the rep of each one's time series.
    series: &'a [Series],
    reps: &'a [ValueRep],
    prims: HashMap<String, PathId>,
    /// Relationships whose targets are resolved once every prim has its path.
    relationships: Vec<(PathId, &'a [String])>,
}

impl<'a> SpecWriter<'a, '_> {
    /// The specs of `prim` (at `path`, named `name` under its parent) and its subtree.
    fn prim(&mut self, parent: PathId, parent_name: &str, prim: &'a Prim<'a>) -> io::Result<()> {
        let path = self.file.child_path(parent, &prim.name, false);
        let name = format!("{parent_name}/{}", prim.name);
        self.prims.insert(name.clone(), path);
        let mut fields = vec![
            ("specifier", ValueRep::inlined(Type::Specifier, DEF)),
            ("typeName", self.file.token(prim.type_name)),
        ];
        if !prim.properties.is_empty() {
            let names: Vec<&str> = prim.properties.iter().map(|p| p.name.as_str()).collect();
            fields.push(("properties", self.file.token_vector(&names)?));
        }
        if !prim.children.is_empty() {
            let names: Vec<&str> = prim.children.iter().map(|c| c.name.as_str()).collect();
            fields.push(("primChildren", self.file.token_vector(&names)?));
        }
        self.file.spec(path, SpecType::Prim, &fields);
        for property in &prim.properties {
            let at = self.file.child_path(path, &property.name, true);
            self.property(at, property)?;
        }
        for child in &prim.children {
            self.prim(path, &name, child)?;
        }
        Ok(())
    }

    /// The spec of one property at `path`.
    fn property(
        &mut self,
        path: PathId,
        property: &'a super::stage::Property<'a>,
    ) -> io::Result<()> {
        let (type_name, variability, value, element) = match &property.value {
            Value::Targets(targets) => {
                self.relationships.push((path, targets));
                return Ok(());
            }
            Value::Series(i) => {
                let element = self.series[*i].element;
                (
                    element.type_name(),
                    VARYING,
                    ("timeSamples", self.reps[*i]),
                    Some(element),
                )
            }
            Value::UniformToken(token) => {
                ("token", UNIFORM, ("default", self.file.token(token)), None)
            }
            Value::Array(element, values) => {
                let rep = array(self.file, *element, *values)?;
                (
                    element.type_name(),
                    VARYING,
                    ("default", rep),
                    Some(*element),
                )
            }
        };
        let mut fields = vec![
            ("custom", ValueRep::inlined(Type::Bool, 0)),
            ("typeName", self.file.token(type_name)),
            (
                "variability",
                ValueRep::inlined(Type::Variability, variability),
            ),
        ];
        if let Some(interpolation) = property.interpolation {
            fields.push(("interpolation", self.file.token(interpolation)));
        }
        if let Some(size) = element.and_then(Element::element_size) {
            fields.push(("elementSize", ValueRep::inlined(Type::Int, size as u32)));
        }
        fields.push(value);
        self.file.spec(path, SpecType::Attribute, &fields);
        Ok(())
    }

    /// The relationship specs, their targets resolved.
    fn relationships(&mut self) -> io::Result<()> {
        for (path, targets) in std::mem::take(&mut self.relationships) {
            let ids: Vec<PathId> = targets.iter().map(|t| self.prims[t]).collect();
            let list = self.file.path_list(&ids)?;
            self.file.spec(
                path,
                SpecType::Relationship,
                &[
                    ("variability", ValueRep::inlined(Type::Variability, UNIFORM)),
                    ("targetPaths", list),
                ],
            );
        }
        Ok(())
    }
}

/// Writes `values` as an array of `element` to `file` (through concrete iterators: this
/// is the per-frame hot path).
fn array(
    file: &mut CrateWriter<BufWriter<File>>,
    element: Element,
    values: Values<'_>,
) -> io::Result<ValueRep> {
    let (ty, len) = (crate_type(element), values.len(element.width()));
    let vectors = |v: &[glam::Vec3]| v.iter().flat_map(|p| p.to_array()).collect::<Vec<_>>();
    match values {
        Values::Vec3(v) => file.float_array(ty, len, v.iter().flat_map(|p| p.to_array())),
        Values::Floats(v) => file.float_array(ty, len, v.iter().copied()),
        Values::Corners(c) => file.float_array(ty, len, vectors(&c).into_iter()),
        Values::Scales(v) => file.float_array(ty, len, v.iter().flat_map(|&s| [s; 3])),
        Values::Widths {
            scales,
            diameter,
            count,
        } => file.float_array(ty, len, super::stage::widths(scales, diameter, count)),
        Values::Triangles(t) => file.int_array(len, t.iter().flatten().map(|&i| i as i32)),
        Values::Repeat(v, n) => file.int_array(len, std::iter::repeat_n(v, n)),
    }
}

impl Encoder for UsdcEncoder {
    fn sample(
        &mut self,
        index: usize,
        series: &Series,
        slot: usize,
        _time: f64,
        values: Values<'_>,
    ) -> io::Result<()> {
        let rep = array(&mut self.file, series.element, values)?;
        if self.samples.len() <= index {
            self.samples.resize_with(index + 1, Vec::new);
        }
        let reps = &mut self.samples[index];
        if reps.len() <= slot {
            reps.resize(slot + 1, None);
        }
        reps[slot] = Some(rep);
        Ok(())
    }

    fn finish(mut self: Box<Self>, end: &StageEnd<'_>) -> io::Result<u64> {
        let mut order: Vec<usize> = (0..end.times.len()).collect();
        order.sort_by(|&a, &b| end.times[a].total_cmp(&end.times[b]));
        let times: Vec<f64> = order.iter().map(|&s| end.times[s]).collect();
        let times = self.file.times(&times)?;
        let mut series = Vec::with_capacity(end.series.len());
        for (i, s) in end.series.iter().enumerate() {
            let empty = ValueRep::empty_array(crate_type(s.element));
            let recorded = self.samples.get(i);
            let reps: Vec<ValueRep> = order
                .iter()
                .map(|&slot| {
                    recorded
                        .and_then(|r| r.get(slot).copied().flatten())
                        .unwrap_or(empty)
                })
                .collect();
            series.push(self.file.time_samples(times, &reps)?);
        }
        let root = self.file.root();
        let mut fields = Vec::new();
        for (name, meta) in &end.metadata {
            let rep = match meta {
                Meta::Token(t) => self.file.token(t),
                Meta::Double(d) => self.file.double(*d)?,
                Meta::Text(s) => self.file.string(s),
            };
            fields.push((*name, rep));
        }
        fields.push((
            "primChildren",
            self.file.token_vector(&[end.tree.name.as_str()])?,
        ));
        self.file.spec(root, SpecType::PseudoRoot, &fields);
        let mut specs = SpecWriter {
            file: &mut self.file,
            series: end.series,
            reps: &series,
            prims: HashMap::new(),
            relationships: Vec::new(),
        };
        specs.prim(root, "", &end.tree)?;
        specs.relationships()?;
        let (bytes, _) = self.file.finish()?;
        Ok(bytes)
    }
}
