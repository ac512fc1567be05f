//! What the stage holds, independent of the file format: the time series of the fluid mesh
//! and of the sphere instancer, the arrays a frame adds to them, and the prim tree both
//! encoders write at the end.
//!
//! ```text
//! /Surface                         Xform (the default prim)
//!   /Surface/Fluid                 Mesh: extent, faceVertexCounts, faceVertexIndices,
//!                                  points, normals, velocities, primvars:NAME (series);
//!                                  subdivisionScheme = "none"
//!   /Surface/Droplets              Points (the default for isolated particles, when a
//!                                  frame had any): points, widths (2 r_i), extent,
//!                                  velocities, primvars:NAME (series)
//!   /Surface/Spheres               PointInstancer (instead of Droplets, by
//!                                  UsdDroplets::Instancer, when a frame had isolated
//!                                  spheres): positions, protoIndices, extent, scales (when a
//!                                  frame's spheres have sizes of their own), velocities,
//!                                  primvars:NAME (series); prototypes → Sphere…
//!     /Surface/Spheres/Prototypes  Scope
//!       …/Sphere, Sphere_1, …      Mesh: the icosphere template(s), static
//! ```

use super::{UsdDroplets, UsdOptions};
use crate::attributes::{Attribute, VELOCITY_NAMES};
use crate::error::{Error, Result};
use crate::mesh::{SphereInstances, Surface, TriMesh};
use glam::Vec3;
use std::path::Path;

/// Name of the root prim (the layer's default prim).
pub(crate) const ROOT: &str = "Surface";

/// The prim a series belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub(crate) enum Owner {
    /// The fluid mesh, `/Surface/Fluid`.
    Fluid,
    /// The sphere instancer, `/Surface/Spheres`.
    Spheres,
    /// The isolated particles as a point cloud, `/Surface/Droplets`.
    Droplets,
}

/// Element type of an array.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Element {
    /// `int`.
    Int,
    /// `point3f`.
    Point,
    /// `normal3f`.
    Normal,
    /// `vector3f`.
    Vector,
    /// `float3` (an extent: two per array).
    Float3,
    /// A primvar of `n` floats per item: `float`, `float2`, `float3`, `float4`, or `float`
    /// with `elementSize = n` beyond 4.
    Floats(usize),
}

impl Element {
    /// The USD type name of an array of this element.
    pub(crate) fn type_name(self) -> &'static str {
        match self {
            Element::Int => "int[]",
            Element::Point => "point3f[]",
            Element::Normal => "normal3f[]",
            Element::Vector => "vector3f[]",
            Element::Float3 | Element::Floats(3) => "float3[]",
            Element::Floats(2) => "float2[]",
            Element::Floats(4) => "float4[]",
            Element::Floats(_) => "float[]",
        }
    }

    /// Floats per array element (0 for ints).
    pub(crate) fn width(self) -> usize {
        match self {
            Element::Int => 0,
            Element::Point | Element::Normal | Element::Vector | Element::Float3 => 3,
            Element::Floats(n) if n <= 4 => n,
            Element::Floats(_) => 1,
        }
    }

    /// `elementSize` metadata: items of more than 4 floats are that many array elements.
    pub(crate) fn element_size(self) -> Option<usize> {
        match self {
            Element::Floats(n) if n > 4 => Some(n),
            _ => None,
        }
    }
}

/// One time-sampled property.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Series {
    /// The prim holding it.
    pub(crate) owner: Owner,
    /// Property name (`points`, `primvars:density`).
    pub(crate) name: String,
    /// Element type.
    pub(crate) element: Element,
    /// `interpolation` metadata (`vertex` for normals and primvars).
    pub(crate) interpolation: Option<&'static str>,
}

/// The values of one array, borrowed from the frame.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Values<'a> {
    /// Vectors (points, normals, velocities, extents).
    Vec3(&'a [Vec3]),
    /// Flat floats, `width` per array element.
    Floats(&'a [f32]),
    /// Triangles as a flat int array (faceVertexIndices).
    Triangles(&'a [[u32; 3]]),
    /// One int `count` times (faceVertexCounts, protoIndices).
    Repeat(i32, usize),
    /// Two corners (an extent).
    Corners([Vec3; 2]),
    /// Uniform scales: each factor as a `float3` of three equal components.
    Scales(&'a [f32]),
    /// Point widths: `diameter` times each scale, or `diameter` `count` times when there
    /// are no scales.
    Widths {
        /// The scales (empty: all 1).
        scales: &'a [f32],
        /// The template's diameter.
        diameter: f32,
        /// Points.
        count: usize,
    },
}

impl Values<'_> {
    /// Array elements for an element type of `width` floats (0: ints).
    pub(crate) fn len(&self, width: usize) -> usize {
        match *self {
            Values::Vec3(v) => v.len(),
            Values::Scales(v) => v.len(),
            Values::Widths { count, .. } => count,
            Values::Floats(v) => v.len() / width.max(1),
            Values::Triangles(t) => 3 * t.len(),
            Values::Repeat(_, n) => n,
            Values::Corners(_) => 2,
        }
    }

    /// The floats, element after element (empty for int values).
    pub(crate) fn floats(&self) -> Box<dyn Iterator<Item = f32> + '_> {
        match *self {
            Values::Vec3(v) => Box::new(v.iter().flat_map(|p| p.to_array())),
            Values::Floats(v) => Box::new(v.iter().copied()),
            Values::Corners(c) => Box::new(c.into_iter().flat_map(|p| p.to_array())),
            Values::Scales(v) => Box::new(v.iter().flat_map(|&s| [s; 3])),
            Values::Widths {
                scales,
                diameter,
                count,
            } => widths(scales, diameter, count),
            Values::Triangles(_) | Values::Repeat(..) => Box::new(std::iter::empty()),
        }
    }

    /// The ints (empty for float values).
    pub(crate) fn ints(&self) -> Box<dyn Iterator<Item = i32> + '_> {
        match *self {
            Values::Triangles(t) => Box::new(t.iter().flatten().map(|&i| i as i32)),
            Values::Repeat(v, n) => Box::new(std::iter::repeat_n(v, n)),
            Values::Vec3(_)
            | Values::Floats(_)
            | Values::Corners(_)
            | Values::Scales(_)
            | Values::Widths { .. } => Box::new(std::iter::empty()),
        }
    }
}

/// The widths of `count` points: `diameter` times each of `scales`, or `diameter` for
/// every point without scales.
pub(crate) fn widths(
    scales: &[f32],
    diameter: f32,
    count: usize,
) -> Box<dyn Iterator<Item = f32> + '_> {
    if scales.is_empty() {
        Box::new(std::iter::repeat_n(diameter, count))
    } else {
        Box::new(scales.iter().map(move |&s| s * diameter))
    }
}

/// The radius of a sphere template: the mean distance of its vertices from the origin
/// (the icosphere's vertices lie on the sphere; the mean, unlike the farthest, does not
/// grow with the noise of a template read back from an archive).
pub(crate) fn template_radius(template: &TriMesh) -> f32 {
    let n = template.positions.len().max(1) as f64;
    let sum: f64 = template.positions.iter().map(|p| p.length() as f64).sum();
    (sum / n) as f32
}

/// The extent of the droplets: every point padded by its radius.
fn droplets_extent(spheres: &SphereInstances, radius: f32) -> [Vec3; 2] {
    let far = [Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)];
    if spheres.centers.is_empty() {
        return [Vec3::ZERO; 2];
    }
    spheres
        .centers
        .iter()
        .zip(widths(&spheres.scales, 2.0 * radius, spheres.centers.len()))
        .fold(far, |[lo, hi], (c, w)| {
            let pad = Vec3::splat(0.5 * w);
            [lo.min(*c - pad), hi.max(*c + pad)]
        })
}

/// The arrays one frame adds, each to a series (an existing one or one to create).
pub(crate) struct FramePlan<'a> {
    /// (series, values); the series is new when it is not among the writer's yet.
    pub(crate) samples: Vec<(Series, Values<'a>)>,
    /// The sphere template, when the frame has spheres.
    pub(crate) template: Option<&'a TriMesh>,
}

/// A USD identifier for an attribute name: letters, digits and `_`, not starting with a
/// digit (anything else becomes `_`).
pub(crate) fn identifier(name: &str) -> String {
    let mut out: String = name
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    if out.is_empty() || out.starts_with(|c: char| c.is_ascii_digit()) {
        out.insert(0, '_');
    }
    out
}

/// The min and max corners of `points`, moved by the corners `pad` (a sphere's extent
/// around each centre), or two zero corners when there are none.
pub(crate) fn extent(points: &[Vec3], pad: [Vec3; 2]) -> [Vec3; 2] {
    if points.is_empty() {
        return [Vec3::ZERO; 2];
    }
    let (lo, hi) = points.iter().fold(
        (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    [lo + pad[0], hi + pad[1]]
}

/// The extent of the sphere instances: every centre moved by the corners of the
/// template, scaled by the instance's scale.
fn instances_extent(spheres: &SphereInstances) -> [Vec3; 2] {
    let pad = extent(&spheres.template.positions, [Vec3::ZERO; 2]);
    if spheres.scales.is_empty() {
        return extent(&spheres.centers, pad);
    }
    let far = [Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)];
    spheres
        .centers
        .iter()
        .zip(&spheres.scales)
        .fold(far, |[lo, hi], (c, &s)| {
            [lo.min(*c + pad[0] * s), hi.max(*c + pad[1] * s)]
        })
}

/// The series an attribute of `owner` goes to: `velocities` for a 3-component velocity
/// (named `v`, `vel` or `velocity`, any case, as the default attribute selection finds
/// it), `primvars:NAME` otherwise.
fn attribute_series(owner: Owner, a: &Attribute) -> Series {
    let velocity = VELOCITY_NAMES
        .iter()
        .any(|v| a.name.eq_ignore_ascii_case(v));
    if velocity && a.components == 3 {
        return Series {
            owner,
            name: "velocities".into(),
            element: Element::Vector,
            interpolation: None,
        };
    }
    Series {
        owner,
        name: format!("primvars:{}", identifier(&a.name)),
        element: Element::Floats(a.components),
        interpolation: Some("vertex"),
    }
}

/// Adds the samples of `attributes` (one item per `items`) to `plan`, after checking
/// each: 1 or more components, one item per vertex or instance, a property name no other
/// attribute of the frame takes.
fn plan_attributes<'a>(
    path: &Path,
    owner: Owner,
    attributes: &'a [Attribute],
    items: usize,
    plan: &mut Vec<(Series, Values<'a>)>,
) -> Result<()> {
    for a in attributes {
        let fail = |message: String| Error::Attribute {
            path: path.to_path_buf(),
            attribute: a.name.clone(),
            message,
        };
        if a.components == 0 || a.values.len() != a.components * items {
            return Err(fail(format!(
                "{} values for {items} items of {} components",
                a.values.len(),
                a.components
            )));
        }
        let series = attribute_series(owner, a);
        if plan
            .iter()
            .any(|(s, _)| s.owner == owner && s.name == series.name)
        {
            return Err(fail(format!(
                "another attribute is also written as {}",
                series.name
            )));
        }
        plan.push((series, Values::Floats(&a.values)));
    }
    Ok(())
}

/// A series of the writer's own (not from an attribute).
fn fixed(owner: Owner, name: &str, element: Element) -> Series {
    Series {
        owner,
        name: name.into(),
        element,
        interpolation: None,
    }
}

/// The series every stage has: the fluid mesh's topology, points and extent.
pub(crate) fn fluid_series() -> Vec<Series> {
    vec![
        fixed(Owner::Fluid, "extent", Element::Float3),
        fixed(Owner::Fluid, "faceVertexCounts", Element::Int),
        fixed(Owner::Fluid, "faceVertexIndices", Element::Int),
        fixed(Owner::Fluid, "points", Element::Point),
    ]
}

/// The arrays of one frame of `surface`, checked; its spheres instance prototype
/// `prototype`.
pub(crate) fn plan_frame<'a>(
    path: &Path,
    surface: &'a Surface,
    prototype: usize,
    options: &UsdOptions,
) -> Result<FramePlan<'a>> {
    let fluid = &surface.fluid;
    let fluid_extent = extent(&fluid.positions, [Vec3::ZERO; 2]);
    let mut samples = vec![
        (
            fixed(Owner::Fluid, "extent", Element::Float3),
            Values::Corners(fluid_extent),
        ),
        (
            fixed(Owner::Fluid, "faceVertexCounts", Element::Int),
            Values::Repeat(3, fluid.triangles.len()),
        ),
        (
            fixed(Owner::Fluid, "faceVertexIndices", Element::Int),
            Values::Triangles(&fluid.triangles),
        ),
        (
            fixed(Owner::Fluid, "points", Element::Point),
            Values::Vec3(&fluid.positions),
        ),
    ];
    if options.normals
        && !fluid.positions.is_empty()
        && fluid.normals.len() == fluid.positions.len()
    {
        let mut normals = fixed(Owner::Fluid, "normals", Element::Normal);
        normals.interpolation = Some("vertex");
        samples.push((normals, Values::Vec3(&fluid.normals)));
    }
    plan_attributes(
        path,
        Owner::Fluid,
        &fluid.attributes,
        fluid.positions.len(),
        &mut samples,
    )?;
    let spheres = &surface.spheres;
    spheres
        .check_scales()
        .map_err(|message| Error::UnsupportedFormat {
            path: path.to_path_buf(),
            message,
        })?;
    if options.droplets == UsdDroplets::Points {
        if !spheres.centers.is_empty() {
            let n = spheres.centers.len();
            let radius = template_radius(&spheres.template);
            samples.push((
                fixed(Owner::Droplets, "points", Element::Point),
                Values::Vec3(&spheres.centers),
            ));
            samples.push((
                fixed(Owner::Droplets, "extent", Element::Float3),
                Values::Corners(droplets_extent(spheres, radius)),
            ));
            let mut widths = fixed(Owner::Droplets, "widths", Element::Floats(1));
            widths.interpolation = Some("vertex");
            samples.push((
                widths,
                Values::Widths {
                    scales: &spheres.scales,
                    diameter: 2.0 * radius,
                    count: n,
                },
            ));
            plan_attributes(path, Owner::Droplets, &spheres.attributes, n, &mut samples)?;
        }
        return Ok(FramePlan {
            samples,
            template: None,
        });
    }
    let template = (!spheres.centers.is_empty()).then_some(&spheres.template);
    if template.is_some() {
        let n = spheres.centers.len();
        samples.push((
            fixed(Owner::Spheres, "positions", Element::Point),
            Values::Vec3(&spheres.centers),
        ));
        samples.push((
            fixed(Owner::Spheres, "extent", Element::Float3),
            Values::Corners(instances_extent(spheres)),
        ));
        samples.push((
            fixed(Owner::Spheres, "protoIndices", Element::Int),
            Values::Repeat(prototype as i32, n),
        ));
        if !spheres.scales.is_empty() {
            samples.push((
                fixed(Owner::Spheres, "scales", Element::Float3),
                Values::Scales(&spheres.scales),
            ));
        }
        plan_attributes(path, Owner::Spheres, &spheres.attributes, n, &mut samples)?;
    }
    Ok(FramePlan { samples, template })
}

/// A property's value in the prim tree.
#[derive(Debug)]
pub(crate) enum Value<'a> {
    /// The series with this index.
    Series(usize),
    /// A uniform token (`subdivisionScheme`).
    UniformToken(&'static str),
    /// A static array (the prototypes' arrays).
    Array(Element, Values<'a>),
    /// Relationship targets, as absolute prim paths.
    Targets(Vec<String>),
}

/// A property of a prim.
#[derive(Debug)]
pub(crate) struct Property<'a> {
    /// Its name.
    pub(crate) name: String,
    /// Its value (which says its type).
    pub(crate) value: Value<'a>,
    /// `interpolation` metadata.
    pub(crate) interpolation: Option<&'static str>,
}

/// A prim of the tree.
#[derive(Debug)]
pub(crate) struct Prim<'a> {
    /// Its name.
    pub(crate) name: String,
    /// Its schema type (`Mesh`).
    pub(crate) type_name: &'static str,
    /// Its properties, in order.
    pub(crate) properties: Vec<Property<'a>>,
    /// Its children, in order.
    pub(crate) children: Vec<Prim<'a>>,
}

/// Layer metadata of the stage, in order: (name, value).
#[derive(Debug, PartialEq)]
pub(crate) enum Meta {
    /// A token (`upAxis`, `defaultPrim`).
    Token(String),
    /// A double.
    Double(f64),
    /// A string (`doc`).
    Text(String),
}

/// The layer metadata: default prim, documentation, time range and rate, axes and units.
pub(crate) fn layer_metadata(options: &UsdOptions, times: &[f64]) -> Vec<(&'static str, Meta)> {
    let mut meta = vec![
        ("defaultPrim", Meta::Token(ROOT.into())),
        (
            "documentation",
            Meta::Text(format!(
                "Fluid surface sequence written by meniscus {}",
                env!("CARGO_PKG_VERSION")
            )),
        ),
    ];
    if let (Some(first), Some(last)) = (
        times.iter().copied().reduce(f64::min),
        times.iter().copied().reduce(f64::max),
    ) {
        meta.push(("startTimeCode", Meta::Double(first)));
        meta.push(("endTimeCode", Meta::Double(last)));
    }
    meta.push(("timeCodesPerSecond", Meta::Double(options.fps)));
    meta.push(("framesPerSecond", Meta::Double(options.fps)));
    meta.push(("upAxis", Meta::Token(options.up_axis.token().into())));
    meta.push(("metersPerUnit", Meta::Double(options.meters_per_unit)));
    meta
}

/// The properties of the series of `owner`, in the writer's order.
fn series_properties(series: &[Series], owner: Owner) -> Vec<Property<'static>> {
    series
        .iter()
        .enumerate()
        .filter(|(_, s)| s.owner == owner)
        .map(|(i, s)| Property {
            name: s.name.clone(),
            value: Value::Series(i),
            interpolation: s.interpolation,
        })
        .collect()
}

/// The static mesh of a sphere template.
fn prototype(name: String, template: &TriMesh) -> Prim<'_> {
    let array = |name: &str, element, values| Property {
        name: name.into(),
        value: Value::Array(element, values),
        interpolation: None,
    };
    let corners = extent(&template.positions, [Vec3::ZERO; 2]);
    let mut properties = vec![
        array("extent", Element::Float3, Values::Corners(corners)),
        array(
            "faceVertexCounts",
            Element::Int,
            Values::Repeat(3, template.triangles.len()),
        ),
        array(
            "faceVertexIndices",
            Element::Int,
            Values::Triangles(&template.triangles),
        ),
        array("points", Element::Point, Values::Vec3(&template.positions)),
    ];
    if !template.normals.is_empty() && template.normals.len() == template.positions.len() {
        let mut normals = array("normals", Element::Normal, Values::Vec3(&template.normals));
        normals.interpolation = Some("vertex");
        properties.push(normals);
    }
    properties.push(Property {
        name: "subdivisionScheme".into(),
        value: Value::UniformToken("none"),
        interpolation: None,
    });
    Prim {
        name,
        type_name: "Mesh",
        properties,
        children: Vec::new(),
    }
}

/// Name of the prototype of template `k`.
fn prototype_name(k: usize) -> String {
    if k == 0 {
        "Sphere".into()
    } else {
        format!("Sphere_{k}")
    }
}

/// The prim tree of a stage with `series` and the sphere `templates` (no instancer
/// without templates, no point cloud without its series).
pub(crate) fn prim_tree<'a>(series: &[Series], templates: &'a [TriMesh]) -> Prim<'a> {
    let mut fluid_properties = series_properties(series, Owner::Fluid);
    fluid_properties.push(Property {
        name: "subdivisionScheme".into(),
        value: Value::UniformToken("none"),
        interpolation: None,
    });
    let mut children = vec![Prim {
        name: "Fluid".into(),
        type_name: "Mesh",
        properties: fluid_properties,
        children: Vec::new(),
    }];
    let droplets = series_properties(series, Owner::Droplets);
    if !droplets.is_empty() {
        children.push(Prim {
            name: "Droplets".into(),
            type_name: "Points",
            properties: droplets,
            children: Vec::new(),
        });
    }
    if !templates.is_empty() {
        let prototypes: Vec<Prim> = templates
            .iter()
            .enumerate()
            .map(|(k, t)| prototype(prototype_name(k), t))
            .collect();
        let targets = (0..templates.len())
            .map(|k| format!("/{ROOT}/Spheres/Prototypes/{}", prototype_name(k)))
            .collect();
        let mut properties = series_properties(series, Owner::Spheres);
        properties.push(Property {
            name: "prototypes".into(),
            value: Value::Targets(targets),
            interpolation: None,
        });
        children.push(Prim {
            name: "Spheres".into(),
            type_name: "PointInstancer",
            properties,
            children: vec![Prim {
                name: "Prototypes".into(),
                type_name: "Scope",
                properties: Vec::new(),
                children: prototypes,
            }],
        });
    }
    Prim {
        name: ROOT.into(),
        type_name: "Xform",
        properties: Vec::new(),
        children,
    }
}
