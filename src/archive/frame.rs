//! The frame payload of versions 2 and 3: a fluid surface that may be stored as the
//! control mesh of Loop subdivision, plus instanced spheres.
//!
//! meniscus's own output is the Loop subdivision of the decimated mesh (Akinci et al.
//! 2013, § 3.3), and Loop subdivision is deterministic: a frame is stored as its control
//! mesh (a quarter of the triangles per level) and the number of Loop steps, and the
//! decoder runs [`crate::subdivision::subdivide`] on the decoded control mesh. Loop's
//! masks are convex combinations (all weights ≥ 0, summing to 1), so a control mesh whose
//! coordinates are within the bound gives subdivided coordinates within the same bound of
//! the subdivision of the exact control mesh. The isolated-particle spheres are stored as
//! one template and their centres, each quantized with half the step so that template
//! vertex plus centre stays within the bound; spheres with scales store them exactly
//! (f32) and the template on a lattice finer by the largest scale, so that a scaled
//! template vertex plus its centre stays within the bound too.
//!
//! ```text
//! raw := varint(levels) u8(shape) varint(fluid vertices) varint(fluid triangles) fluid
//!        varint(sphere count)
//!        [ [count × f32 scale]            (record flag HAS_SCALES, version 5)
//!          varint(template vertices) varint(template triangles) template_streams
//!          count × 3 zigzag varints: centre − previous centre, on the lattice step / 2 ]
//! payload := zstd(raw)
//! ```
//! The streams are those of [`super::codec::encode_streams`]. `shape` is 1 when the
//! stored fluid mesh is a closed, consistently oriented 2-manifold: then `fluid` is its
//! streams and the first Loop step runs while decoding ([`super::fused`]); 2 when it is
//! also stored in parts that decode in parallel (version 3, [`super::parts`]); 0 for any
//! other mesh, stored as its streams.
//!
//! Attributes ([`super::attributes`]) are stored beside this payload, for the control
//! vertices: on decoding, each Loop step gives the new vertices the values of the same
//! masks as their positions.

use super::attributes::{self, Descriptor};
use super::codec::{
    check_counts, decode_streams, decompress, encode_streams, get_varint, put_varint, raw_capacity,
    read_count, unzigzag, zigzag, HalfEdges,
};
use super::parts::decode_streams_subdivided;
use super::parts::{decode_parts_subdivided, encode_parts, part_count};
use crate::mesh::{SphereInstances, Surface, TriMesh};
use crate::subdivision::{loop_values_of_closed, subdivide, SubdivideOptions};
use glam::Vec3;

/// `shape`: the fluid mesh is open (or not known closed and oriented) ...
const OPEN: u8 = 0;
/// ... closed and consistently oriented, stored whole ...
const CLOSED: u8 = 1;
/// ... or closed, consistently oriented and stored in parts ([`super::parts`]).
const CLOSED_IN_PARTS: u8 = 2;

/// Record flag: the sphere instances carry scales (version 5).
pub(crate) const HAS_SCALES: u32 = 2;

/// A frame to archive.
#[derive(Clone, Copy, Debug)]
pub struct ArchiveFrame<'a> {
    /// The fluid surface, or the control mesh that `subdivision_levels` Loop steps turn
    /// into it.
    pub fluid: &'a TriMesh,
    /// Loop subdivision steps the decoder applies to `fluid` (0: `fluid` is stored as is).
    pub subdivision_levels: u32,
    /// Isolated-particle spheres (may be empty).
    pub spheres: &'a SphereInstances,
}

/// Vertex and triangle counts after `levels` Loop steps of a coded mesh, when exact.
fn loop_counts(coded: super::codec::CodedMesh, levels: u32) -> Option<(u64, u64)> {
    if !coded.loop_countable {
        return None;
    }
    let (mut v, mut e, mut t) = (coded.vertices as u64, coded.edges, coded.triangles as u64);
    for _ in 0..levels {
        (v, e, t) = (v + e, 2 * e + 3 * t, 4 * t);
    }
    Some((v, t))
}

/// The sphere instances a frame stores (none without a template).
pub(crate) fn stored_instances(spheres: &SphereInstances) -> usize {
    if spheres.template.triangles.is_empty() {
        0
    } else {
        spheres.centers.len()
    }
}

/// True when the frame stores attributes: the fluid's, or those of stored instances.
pub(crate) fn has_attributes(frame: &ArchiveFrame) -> bool {
    !frame.fluid.attributes.is_empty()
        || (stored_instances(frame.spheres) > 0 && !frame.spheres.attributes.is_empty())
}

/// True when the frame stores sphere scales: stored instances that carry them.
pub(crate) fn has_scales(frame: &ArchiveFrame) -> bool {
    stored_instances(frame.spheres) > 0 && !frame.spheres.scales.is_empty()
}

/// The lattice spacing of the sphere template: `half` (the centres' spacing) over the
/// largest scale when one exceeds 1, so that a scaled template vertex stays within
/// `half / 2` of the original.
fn template_step(half: f64, scales: &[f32]) -> f64 {
    half / scales.iter().fold(1.0f32, |m, &s| m.max(s)) as f64
}

/// Appends the stored sphere instances (at least one) to `raw`: their scales when they
/// have them, the template and the centres. Returns the template's counts.
fn encode_spheres(
    spheres: &SphereInstances,
    step: f64,
    raw: &mut Vec<u8>,
) -> super::codec::CodedMesh {
    let half = step / 2.0;
    for s in &spheres.scales {
        raw.extend_from_slice(&s.to_le_bytes());
    }
    let mut template_streams = Vec::new();
    let template = encode_streams(
        &spheres.template,
        template_step(half, &spheres.scales),
        &mut template_streams,
    );
    put_varint(raw, template.vertices as u64);
    put_varint(raw, template.triangles as u64);
    raw.extend_from_slice(&template_streams);
    let mut previous = [0i64; 3];
    for c in &spheres.centers {
        let q = c.to_array().map(|x| (x as f64 / half).round() as i64);
        for k in 0..3 {
            put_varint(raw, zigzag(q[k].wrapping_sub(previous[k])));
        }
        previous = q;
    }
    template
}

/// An encoded frame.
pub(crate) struct EncodedFrame {
    pub(crate) payload: Vec<u8>,
    /// Vertices and triangles it decodes to.
    pub(crate) vertices: u32,
    pub(crate) triangles: u32,
    /// Record flags ([`attributes::HAS_ATTRIBUTES`], [`HAS_SCALES`]).
    pub(crate) flags: u32,
}

/// Encodes a frame: its payload and the vertex and triangle counts it decodes to.
/// `in_parts`: a closed control mesh may be stored in parts (version 3 and later). A
/// frame with attributes (checked with [`attributes::check`]) stores them with error
/// bound `attribute_bound` ([`super::attributes`]); a frame without them is the geometry
/// payload alone.
pub(crate) fn encode_frame(
    frame: &ArchiveFrame,
    step: f64,
    attribute_bound: f64,
    zstd_level: i32,
    in_parts: bool,
) -> std::io::Result<EncodedFrame> {
    let mut raw = Vec::new();
    let mut levels = frame.subdivision_levels;
    let mut fine = None;
    let mut half_edges = HalfEdges::of(frame.fluid);
    let mut coded = half_edges.report(frame.fluid);
    let mut counts = loop_counts(coded, levels);
    if counts.is_none() {
        // A control mesh whose subdivision the counts cannot describe (a degenerate or a
        // repeated triangle): subdivide here and store the result as it is.
        let mut mesh = frame.fluid.clone();
        subdivide(&mut mesh, &SubdivideOptions { levels });
        half_edges = HalfEdges::of(&mesh);
        coded = half_edges.report(&mesh);
        levels = 0;
        counts = Some((coded.vertices as u64, coded.triangles as u64));
        fine = Some(mesh);
    }
    let fluid = fine.as_ref().unwrap_or(frame.fluid);
    let (mut vertices, mut triangles) = counts.expect("set above");
    let parts = part_count(coded.triangles as usize);
    let shape = if !coded.closed_oriented {
        OPEN
    } else if in_parts && levels > 0 && parts > 1 {
        CLOSED_IN_PARTS
    } else {
        CLOSED
    };
    put_varint(&mut raw, levels as u64);
    raw.push(shape);
    put_varint(&mut raw, coded.vertices as u64);
    put_varint(&mut raw, coded.triangles as u64);
    // The control vertices in decoding order.
    let order = if shape == CLOSED_IN_PARTS {
        drop(half_edges);
        encode_parts(fluid, parts, step, &mut raw)
    } else {
        half_edges.encode(fluid, step, &mut raw)
    };
    let spheres = frame.spheres;
    let count = stored_instances(spheres);
    put_varint(&mut raw, count as u64);
    if count > 0 {
        let template = encode_spheres(spheres, step, &mut raw);
        vertices += count as u64 * template.vertices as u64;
        triangles += count as u64 * template.triangles as u64;
    }
    let (Ok(vertices), Ok(triangles)) = (u32::try_from(vertices), u32::try_from(triangles)) else {
        return Err(std::io::Error::other(
            "frame too large for the archive (over 2^32 vertices or triangles)",
        ));
    };
    let geometry = zstd::bulk::compress(&raw, zstd_level)?;
    drop(raw);
    let scale_flag = if has_scales(frame) { HAS_SCALES } else { 0 };
    let (payload, flags) = if has_attributes(frame) {
        let sphere_attributes = if count > 0 {
            &spheres.attributes[..]
        } else {
            &[]
        };
        let payload = attributes::encode_payload(
            attribute_bound,
            &fluid.attributes,
            &order,
            sphere_attributes,
            &geometry,
            zstd_level,
        )?;
        (payload, attributes::HAS_ATTRIBUTES | scale_flag)
    } else {
        (geometry, scale_flag)
    };
    Ok(EncodedFrame {
        payload,
        vertices,
        triangles,
        flags,
    })
}

/// Decodes a payload (the geometry) that the record header says holds `vertices`
/// vertices and `triangles` triangles (after subdivision, spheres included), with the
/// frame's attribute streams when it has them and sphere scales when `scaled` (record
/// flag [`HAS_SCALES`]). No normals.
pub(crate) fn decode_frame(
    payload: &[u8],
    vertices: usize,
    triangles: usize,
    step: f64,
    attribute_streams: Option<(&Descriptor, &[u8])>,
    scaled: bool,
) -> Result<Surface, String> {
    // The raw size is bounded by the stored (control) mesh, at most the final one.
    let raw = decompress(payload, raw_capacity(vertices, triangles))?;
    let pos = &mut 0usize;
    let (nv, nt) = (vertices as u64, triangles as u64);
    let levels = read_count(
        &raw,
        pos,
        "subdivision levels",
        super::MAX_SUBDIVISION_LEVELS as u64,
    )? as u32;
    let shape = *raw.get(*pos).ok_or("fluid shape flag missing")?;
    *pos += 1;
    let fluid_vertices = read_count(&raw, pos, "fluid vertex count", nv)?;
    let fluid_triangles = read_count(&raw, pos, "fluid triangle count", nt)?;
    let (v, t) = (fluid_vertices, fluid_triangles);
    check_counts(v, t, raw.len() - *pos)?;
    let mut fluid = decode_fluid(&raw, pos, shape, levels, v, t, step)?;
    if attribute_streams.is_none() {
        fluid.subdivide_rest();
    }
    let spheres = decode_spheres(&raw, pos, (nv, nt), step, scaled)?;
    if *pos != raw.len() {
        return Err("trailing bytes after the frame".into());
    }
    drop(raw);
    let count = spheres.centers.len();
    let mut surface = Surface {
        fluid: fluid.mesh,
        spheres,
    };
    if let Some((descriptor, streams)) = attribute_streams {
        let (control, instances) = attributes::decode_streams(descriptor, streams, v, count)?;
        add_attributes(
            &mut surface,
            fluid.fused,
            fluid.remaining_levels,
            v,
            control,
            instances,
        )?;
    }
    let (fluid, spheres) = (&surface.fluid, &surface.spheres);
    let got_vertices = fluid.vertex_count() + count * spheres.template.vertex_count();
    let got_triangles = fluid.triangle_count() + count * spheres.template.triangle_count();
    if (got_vertices, got_triangles) != (vertices, triangles) {
        return Err(format!(
            "decodes to {got_vertices} vertices and {got_triangles} triangles, header says {vertices} and {triangles}"
        ));
    }
    Ok(surface)
}

/// The fluid mesh as decoded, before its remaining Loop steps.
struct DecodedFluid {
    mesh: TriMesh,
    /// Loop steps still to run.
    remaining_levels: u32,
    /// The first Loop step ran while decoding.
    fused: bool,
}

impl DecodedFluid {
    /// Runs the remaining Loop steps.
    fn subdivide_rest(&mut self) {
        subdivide(
            &mut self.mesh,
            &SubdivideOptions {
                levels: self.remaining_levels,
            },
        );
        self.remaining_levels = 0;
    }
}

/// Decodes the fluid mesh of `v` vertices and `t` triangles stored with `shape`, to have
/// `levels` Loop steps.
fn decode_fluid(
    raw: &[u8],
    pos: &mut usize,
    shape: u8,
    levels: u32,
    v: usize,
    t: usize,
    step: f64,
) -> Result<DecodedFluid, String> {
    let (mesh, remaining_levels, fused) = match (shape, levels) {
        // The first Loop step while decoding, the parts in parallel ...
        (CLOSED_IN_PARTS, 1..) => (
            decode_parts_subdivided(raw, pos, v, t, step)?,
            levels - 1,
            true,
        ),
        (CLOSED_IN_PARTS, 0) => return Err("a mesh in parts must be subdivided".into()),
        // ... or the whole mesh ...
        (CLOSED, 1..) => (
            decode_streams_subdivided(raw, pos, v, t, step)?,
            levels - 1,
            true,
        ),
        // ... or the mesh as stored, subdivided after.
        (OPEN | CLOSED, _) => (decode_streams(raw, pos, v, t, step)?, levels, false),
        _ => return Err(format!("unknown fluid shape {shape}")),
    };
    Ok(DecodedFluid {
        mesh,
        remaining_levels,
        fused,
    })
}

/// Decodes the sphere instances (none when the count is 0) of a frame of at most `nv`
/// vertices and `nt` triangles: their scales when `scaled`, the template, on the lattice
/// of half the step over the largest scale, and the centres, on that of half the step.
fn decode_spheres(
    raw: &[u8],
    pos: &mut usize,
    (nv, nt): (u64, u64),
    step: f64,
    scaled: bool,
) -> Result<SphereInstances, String> {
    let count = read_count(raw, pos, "sphere count", nt)?;
    let mut spheres = SphereInstances::default();
    if count == 0 {
        return Ok(spheres);
    }
    if scaled {
        spheres.scales = decode_scales(raw, pos, count)?;
    }
    let half = step / 2.0;
    let tv = read_count(raw, pos, "sphere template vertex count", nv)?;
    let tt = read_count(raw, pos, "sphere template triangle count", nt)?;
    // Three coordinates of at least a byte each per centre.
    if count > (raw.len() - *pos) / 3 {
        return Err(format!(
            "{count} sphere centres cannot fit in the {} bytes left",
            raw.len() - *pos
        ));
    }
    spheres.template = decode_streams(raw, pos, tv, tt, template_step(half, &spheres.scales))?;
    spheres.centers.reserve(count);
    let mut q = [0i64; 3];
    for _ in 0..count {
        for c in &mut q {
            let d = get_varint(raw, pos).ok_or("sphere centres cut off")?;
            *c = c.wrapping_add(unzigzag(d));
        }
        spheres
            .centers
            .push(Vec3::from_array(q.map(|c| (c as f64 * half) as f32)));
    }
    Ok(spheres)
}

/// Reads `count` sphere scales (f32, little-endian), each finite and > 0.
fn decode_scales(raw: &[u8], pos: &mut usize, count: usize) -> Result<Vec<f32>, String> {
    let bytes = count
        .checked_mul(4)
        .and_then(|n| raw.get(*pos..pos.checked_add(n)?))
        .ok_or_else(|| format!("{count} sphere scales cut off"))?;
    *pos += bytes.len();
    let scales: Vec<f32> = bytes
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes(b.try_into().expect("4 bytes")))
        .collect();
    match scales.iter().position(|s| !(s.is_finite() && *s > 0.0)) {
        Some(k) => Err(format!(
            "sphere scale {k} decodes to {}: not a finite number > 0 (damaged record)",
            scales[k]
        )),
        None => Ok(scales),
    }
}

/// Gives the decoded surface its attributes: the values `control` of the `v` control
/// vertices through the fused Loop step (by the same masks as its positions, when it
/// ran) and the remaining `levels` steps, and the instances' values as stored; checks
/// that every attribute has one item per vertex or instance.
fn add_attributes(
    surface: &mut Surface,
    fused: bool,
    levels: u32,
    v: usize,
    control: Vec<crate::mesh::Attribute>,
    instances: Vec<crate::mesh::Attribute>,
) -> Result<(), String> {
    let (fluid, spheres) = (&mut surface.fluid, &mut surface.spheres);
    fluid.attributes = if fused {
        control
            .into_iter()
            .map(|a| {
                let values = loop_values_of_closed(
                    &fluid.triangles,
                    v,
                    fluid.vertex_count(),
                    &a.values,
                    a.components,
                )
                .ok_or("the subdivided fluid mesh is not a Loop step of its control mesh")?;
                Ok(crate::mesh::Attribute { values, ..a })
            })
            .collect::<Result<_, String>>()?
    } else {
        control
    };
    subdivide(fluid, &SubdivideOptions { levels });
    spheres.attributes = instances;
    for a in &fluid.attributes {
        if a.len() != fluid.vertex_count() {
            return Err(format!(
                "attribute {:?} decodes to {} items for {} fluid vertices",
                a.name,
                a.len(),
                fluid.vertex_count()
            ));
        }
    }
    for a in &spheres.attributes {
        if a.len() != spheres.centers.len() {
            return Err(format!(
                "attribute {:?} decodes to {} items for {} sphere instances",
                a.name,
                a.len(),
                spheres.centers.len()
            ));
        }
    }
    Ok(())
}
