//! glTF 2.0 meshes.
//!
//! **Written** with serde_json: the document is small and fixed in shape, and writing its
//! JSON directly keeps the byte layout (alignment, accessor bounds) in view. The `gltf`
//! crate reads the result back in the tests.
//!
//! The binary buffer is never assembled in memory: the document records which mesh arrays
//! go where, and writing streams them in chunks of [`CHUNK_BYTES`] (base64-encoded on the
//! fly for `.gltf`), so a 70 M-triangle surface is written without a 1.7 GB copy.
//!
//! The isolated-particle spheres are one mesh and one node per instance, its
//! `translation` the centre and, when the instances carry scales, its `scale` the
//! instance's factor on all three axes. Attributes become application-specific vertex
//! attributes (`_VELOCITY`, float accessors; names in [`super::columns`]). Spheres with
//! attributes are written as one merged mesh (instances scaled and translated, each vertex
//! with its particle's values) instead of one node per instance: glTF attributes belong
//! to a mesh, and Blender's importer drops per-instance attributes of
//! `EXT_mesh_gpu_instancing`.
//!
//! **Read** with the `gltf` crate (`.glb`, `.gltf` with embedded buffers), after
//! [`gltf_check`]'s checks: every triangle primitive of the default scene, node transforms
//! applied. Float `_NAME` accessors come back as attributes named `name` (lower-cased,
//! sorted by name; values as stored, not transformed by the nodes; primitives that do not
//! all carry the same attributes lose them, as [`TriMesh::append`] does).

use super::columns;
use super::gltf_check::{self, check_accessor};
use super::parts::{write_chunked, CHUNK_BYTES};
use crate::attributes::Attribute;
use crate::error::{Error, Result};
use crate::io::base64::Base64Writer;
use crate::mesh::{SphereInstances, Surface, TriMesh};
use glam::{Mat4, Vec3};
use serde_json::{json, Value};
use std::io::Write;
use std::path::Path;

/// Reads a glTF mesh (`.glb`, or `.gltf` with embedded buffers) held in memory.
pub(super) fn read(path: &Path, bytes: &[u8]) -> Result<TriMesh> {
    let bad = |m: String| Error::parse(path, "glTF", m);
    // Indices, extents, component types and the node hierarchy are checked first: the
    // crate's readers trust them (and the scene walk below ends only on a forest).
    gltf_check::check(path, bytes)?;
    // Last guard: the gltf crate's validation indexes with unchecked accessor indices and
    // panics on some malformed documents: such a document is an error, not a crash.
    let imported = std::panic::catch_unwind(|| gltf::import_slice(bytes))
        .map_err(|_| bad("malformed document (an index out of range)".into()))?;
    let (doc, buffers, _) = imported.map_err(|e| bad(e.to_string()))?;
    let mut mesh = TriMesh::default();
    let scene = doc
        .default_scene()
        .or_else(|| doc.scenes().next())
        .ok_or_else(|| bad("no scene".into()))?;
    // Depth-first in document order: the stack holds nodes reversed.
    let mut stack: Vec<(gltf::Node, Mat4)> = scene.nodes().map(|n| (n, Mat4::IDENTITY)).collect();
    stack.reverse();
    while let Some((node, parent)) = stack.pop() {
        let transform = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
        if let Some(m) = node.mesh() {
            for prim in m.primitives() {
                if prim.mode() != gltf::mesh::Mode::Triangles {
                    continue;
                }
                let piece = read_primitive(path, &prim, &buffers, transform, mesh.positions.len())?;
                // Normals and attributes are kept only when every primitive has them.
                mesh.append(&piece);
            }
        }
        let children: Vec<gltf::Node> = node.children().collect();
        for child in children.into_iter().rev() {
            stack.push((child, transform));
        }
    }
    Ok(mesh)
}

/// One triangle primitive, `transform`ed, for a mesh that holds `before` vertices so far.
fn read_primitive(
    path: &Path,
    prim: &gltf::Primitive,
    buffers: &[gltf::buffer::Data],
    transform: Mat4,
    before: usize,
) -> Result<TriMesh> {
    let bad = |m: String| Error::parse(path, "glTF", m);
    // The gltf crate's readers assume accessors of the right type and layout (they panic
    // otherwise): checked first.
    use gltf::accessor::{DataType, Dimensions};
    let position = prim
        .get(&gltf::Semantic::Positions)
        .ok_or_else(|| bad("a primitive has no POSITION".into()))?;
    check_accessor(
        path,
        &position,
        "POSITION",
        Dimensions::Vec3,
        &[DataType::F32],
    )?;
    if let Some(a) = prim.get(&gltf::Semantic::Normals) {
        check_accessor(path, &a, "NORMAL", Dimensions::Vec3, &[DataType::F32])?;
    }
    if let Some(a) = prim.indices() {
        let types = [DataType::U8, DataType::U16, DataType::U32];
        check_accessor(path, &a, "indices", Dimensions::Scalar, &types)?;
    }
    let reader = prim.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
    let mut piece = TriMesh {
        positions: reader
            .read_positions()
            .ok_or_else(|| bad("a primitive has no POSITION".into()))?
            .map(|p| transform.transform_point3(Vec3::from(p)))
            .collect(),
        ..TriMesh::default()
    };
    // Indices are offset by the vertices before this primitive: the total must fit u32.
    let n = u32::try_from(piece.positions.len())
        .ok()
        .filter(|&n| n.checked_add(before as u32).is_some())
        .ok_or_else(|| bad("more than 2^32 vertices".into()))?;
    if let Some(ns) = reader.read_normals() {
        piece.normals = ns
            .map(|v| {
                transform
                    .transform_vector3(Vec3::from(v))
                    .normalize_or_zero()
            })
            .collect();
    }
    match reader.read_indices() {
        Some(ix) => {
            let ix: Vec<u32> = ix.into_u32().collect();
            // Checked per primitive: once offset (TriMesh::append), an index past this
            // primitive would name another primitive's vertex, or overflow.
            if let Some(&i) = ix.iter().find(|&&i| i >= n) {
                return Err(bad(format!(
                    "primitive index {i} out of range (the primitive has {n} vertices)"
                )));
            }
            piece.triangles = ix.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();
        }
        None => {
            piece.triangles = (0..n / 3 * 3)
                .step_by(3)
                .map(|i| [i, i + 1, i + 2])
                .collect();
        }
    }
    piece.attributes = gltf_attributes(path, prim, buffers, n as usize)?;
    Ok(piece)
}

/// The application-specific float attributes (`_NAME`) of a primitive with `vertices`
/// vertices, sorted by name, `_NAME_0 … _NAME_k` scalars (k ≥ 4) regrouped. Attributes of
/// other component types or of matrix type are skipped.
fn gltf_attributes(
    path: &Path,
    prim: &gltf::Primitive,
    buffers: &[gltf::buffer::Data],
    vertices: usize,
) -> Result<Vec<Attribute>> {
    use gltf::accessor::{util::Iter, DataType, Dimensions};
    let get = |b: gltf::Buffer| buffers.get(b.index()).map(|d| &d.0[..]);
    let mut vectors = Vec::new();
    let mut scalars = Vec::new();
    for (semantic, accessor) in prim.attributes() {
        let gltf::Semantic::Extras(name) = semantic else {
            continue;
        };
        let components = match accessor.dimensions() {
            Dimensions::Scalar => 1,
            Dimensions::Vec2 => 2,
            Dimensions::Vec3 => 3,
            Dimensions::Vec4 => 4,
            _ => continue,
        };
        if accessor.data_type() != DataType::F32 {
            continue;
        }
        let dimensions = accessor.dimensions();
        check_accessor(
            path,
            &accessor,
            &format!("_{name}"),
            dimensions,
            &[DataType::F32],
        )?;
        if accessor.count() != vertices {
            return Err(Error::parse(
                path,
                format!("attribute _{name}"),
                format!(
                    "{} values for a primitive of {vertices} vertices",
                    accessor.count()
                ),
            ));
        }
        let unreadable = || {
            Error::parse(
                path,
                format!("attribute _{name}"),
                "the accessor's data cannot be read",
            )
        };
        let values: Vec<f32> = match components {
            1 => Iter::<f32>::new(accessor, get)
                .ok_or_else(unreadable)?
                .collect(),
            2 => Iter::<[f32; 2]>::new(accessor, get)
                .ok_or_else(unreadable)?
                .flatten()
                .collect(),
            3 => Iter::<[f32; 3]>::new(accessor, get)
                .ok_or_else(unreadable)?
                .flatten()
                .collect(),
            _ => Iter::<[f32; 4]>::new(accessor, get)
                .ok_or_else(unreadable)?
                .flatten()
                .collect(),
        };
        let name = name.to_ascii_lowercase();
        if components == 1 {
            scalars.push((name, values));
        } else {
            vectors.push(Attribute {
                name,
                components,
                values,
            });
        }
    }
    // `_S_10` after `_S_9`, so that split attributes regroup in component order.
    let key = |name: &str| match name.rsplit_once('_') {
        Some((base, n)) if !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()) => {
            (base.to_string(), n.parse::<u64>().ok())
        }
        _ => (name.to_string(), None),
    };
    scalars.sort_by_key(|(name, _)| key(name));
    let mut all = columns::regroup(scalars, false);
    all.extend(vectors);
    all.sort_by(|a, b| a.name.cmp(&b.name));
    Ok(all)
}
const FLOAT: u32 = 5126;
const UNSIGNED_INT: u32 = 5125;
const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;

/// Encodes item `i` of a generated buffer view into the buffer.
type Encode<'a> = Box<dyn Fn(usize, &mut Vec<u8>) + 'a>;

/// Data of one buffer view, borrowed from the meshes until it is written.
enum Payload<'a> {
    Vectors(&'a [Vec3]),
    Triangles(&'a [[u32; 3]]),
    Bytes(Vec<u8>),
    /// `items` items of `item_bytes` each, encoded on the fly by `encode(i, buf)`.
    Generated {
        items: usize,
        item_bytes: usize,
        encode: Encode<'a>,
    },
}

impl Payload<'_> {
    fn byte_len(&self) -> usize {
        match self {
            Payload::Vectors(v) => v.len() * 12,
            Payload::Triangles(t) => t.len() * 12,
            Payload::Bytes(b) => b.len(),
            Payload::Generated {
                items, item_bytes, ..
            } => items * item_bytes,
        }
    }

    /// Writes the little-endian bytes in chunks.
    fn write(&self, w: &mut impl Write) -> std::io::Result<()> {
        match self {
            Payload::Vectors(v) => write_chunked(w, v.iter(), |buf, p| {
                for c in p.to_array() {
                    buf.extend_from_slice(&c.to_le_bytes());
                }
            }),
            Payload::Triangles(t) => write_chunked(w, t.iter(), |buf, tri| {
                for i in tri {
                    buf.extend_from_slice(&i.to_le_bytes());
                }
            }),
            Payload::Bytes(b) => w.write_all(b),
            Payload::Generated { items, encode, .. } => {
                write_chunked(w, 0..*items, |buf, i| encode(i, buf))
            }
        }
    }
}

pub(super) struct Document<'a> {
    json: Value,
    /// The buffer's views in order; each starts 4-byte aligned.
    payloads: Vec<Payload<'a>>,
    /// Length of the whole buffer (a multiple of 4).
    bin_len: usize,
    pub(super) vertices: usize,
}

#[derive(Default)]
struct Builder<'a> {
    payloads: Vec<Payload<'a>>,
    bin_len: usize,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl<'a> Builder<'a> {
    /// Adds a buffer view (`target` `None` for animation data); returns its index.
    fn push_view(&mut self, payload: Payload<'a>, target: Option<u32>) -> usize {
        let offset = self.bin_len.next_multiple_of(4);
        let len = payload.byte_len();
        self.bin_len = (offset + len).next_multiple_of(4);
        let mut view = json!({"buffer": 0, "byteOffset": offset, "byteLength": len});
        if let Some(target) = target {
            view["target"] = json!(target);
        }
        self.views.push(view);
        self.payloads.push(payload);
        self.views.len() - 1
    }

    fn push_accessor(&mut self, value: Value) -> usize {
        self.accessors.push(value);
        self.accessors.len() - 1
    }

    /// Adds a mesh's attributes and indices; returns the primitive JSON.
    fn primitive(&mut self, mesh: &'a TriMesh, normals: bool) -> Value {
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        for p in &mesh.positions {
            for (k, v) in p.to_array().into_iter().enumerate() {
                lo[k] = lo[k].min(v);
                hi[k] = hi[k].max(v);
            }
        }
        let view = self.push_view(Payload::Vectors(&mesh.positions), Some(ARRAY_BUFFER));
        let position = self.push_accessor(json!({
            "bufferView": view, "componentType": FLOAT, "count": mesh.vertex_count(),
            "type": "VEC3", "min": lo, "max": hi
        }));
        let mut attributes = json!({ "POSITION": position });
        if normals && mesh.normals.len() == mesh.positions.len() {
            let view = self.push_view(Payload::Vectors(&mesh.normals), Some(ARRAY_BUFFER));
            let normal = self.push_accessor(json!({
                "bufferView": view, "componentType": FLOAT, "count": mesh.vertex_count(), "type": "VEC3"
            }));
            attributes["NORMAL"] = json!(normal);
        }
        let max_index = mesh
            .triangles
            .iter()
            .flat_map(|t| t.iter().copied())
            .max()
            .unwrap_or(0);
        let view = self.push_view(
            Payload::Triangles(&mesh.triangles),
            Some(ELEMENT_ARRAY_BUFFER),
        );
        let indices = self.push_accessor(json!({
            "bufferView": view, "componentType": UNSIGNED_INT, "count": mesh.triangle_count() * 3,
            "type": "SCALAR", "min": [0], "max": [max_index]
        }));
        json!({ "attributes": attributes, "indices": indices, "mode": 4 })
    }

    /// Adds the accessors of `attributes` (one item per `repeat` vertices, `items` items)
    /// to a primitive's `attributes` object.
    fn attributes(
        &mut self,
        primitive: &mut Value,
        attributes: &'a [Attribute],
        repeat: usize,
        items: usize,
    ) {
        for a in attributes {
            let k = a.components;
            let semantics = columns::gltf_semantics(a);
            let split = semantics.len() > 1;
            for (c, semantic) in semantics.into_iter().enumerate() {
                let width = if split { 1 } else { k };
                let encode = move |i: usize, buf: &mut Vec<u8>| {
                    let item = a.item(i / repeat);
                    let values = if split { &item[c..c + 1] } else { item };
                    for v in values {
                        buf.extend_from_slice(&v.to_le_bytes());
                    }
                };
                let view = self.push_view(
                    Payload::Generated {
                        items: items * repeat,
                        item_bytes: 4 * width,
                        encode: Box::new(encode),
                    },
                    Some(ARRAY_BUFFER),
                );
                let ty = ["SCALAR", "VEC2", "VEC3", "VEC4"][width - 1];
                let accessor = self.push_accessor(json!({
                    "bufferView": view, "componentType": FLOAT, "count": items * repeat, "type": ty
                }));
                primitive["attributes"][semantic] = json!(accessor);
            }
        }
    }

    /// The sphere instances merged into one primitive: the template scaled by every
    /// instance's scale and translated to its centre (as [`SphereInstances::merged`]
    /// does), each vertex with its instance's attribute values.
    fn merged_spheres(&mut self, s: &'a SphereInstances, normals: bool) -> Value {
        let t = &s.template;
        let n = t.vertex_count();
        let count = n * s.centers.len();
        let position = move |i: usize| s.vertex(i / n, i % n);
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        for i in 0..count {
            for (k, v) in position(i).to_array().into_iter().enumerate() {
                lo[k] = lo[k].min(v);
                hi[k] = hi[k].max(v);
            }
        }
        let vec3 = |v: Vec3, buf: &mut Vec<u8>| {
            for c in v.to_array() {
                buf.extend_from_slice(&c.to_le_bytes());
            }
        };
        let view = self.push_view(
            Payload::Generated {
                items: count,
                item_bytes: 12,
                encode: Box::new(move |i, buf| vec3(position(i), buf)),
            },
            Some(ARRAY_BUFFER),
        );
        let position = self.push_accessor(json!({
            "bufferView": view, "componentType": FLOAT, "count": count,
            "type": "VEC3", "min": lo, "max": hi
        }));
        let mut attributes = json!({ "POSITION": position });
        if normals && t.normals.len() == n {
            let view = self.push_view(
                Payload::Generated {
                    items: count,
                    item_bytes: 12,
                    encode: Box::new(move |i, buf| vec3(t.normals[i % n], buf)),
                },
                Some(ARRAY_BUFFER),
            );
            let normal = self.push_accessor(json!({
                "bufferView": view, "componentType": FLOAT, "count": count, "type": "VEC3"
            }));
            attributes["NORMAL"] = json!(normal);
        }
        let per = t.triangle_count();
        let used = t.triangles.iter().flatten();
        let lo_index = used.clone().copied().min().unwrap_or(0);
        let hi_index = used.copied().max().unwrap_or(0) + ((s.centers.len() - 1) * n) as u32;
        let view = self.push_view(
            Payload::Generated {
                items: per * s.centers.len(),
                item_bytes: 12,
                encode: Box::new(move |j, buf| {
                    let base = (j / per * n) as u32;
                    for v in t.triangles[j % per] {
                        buf.extend_from_slice(&(v + base).to_le_bytes());
                    }
                }),
            },
            Some(ELEMENT_ARRAY_BUFFER),
        );
        let indices = self.push_accessor(json!({
            "bufferView": view, "componentType": UNSIGNED_INT, "count": per * s.centers.len() * 3,
            "type": "SCALAR", "min": [lo_index], "max": [hi_index]
        }));
        let mut p = json!({ "attributes": attributes, "indices": indices, "mode": 4 });
        self.attributes(&mut p, &s.attributes, n, s.centers.len());
        p
    }

    fn finish(self, json: Value, vertices: usize) -> Document<'a> {
        Document {
            json,
            payloads: self.payloads,
            bin_len: self.bin_len,
            vertices,
        }
    }
}

fn asset() -> Value {
    json!({"version": "2.0", "generator": concat!("meniscus ", env!("CARGO_PKG_VERSION"))})
}

pub(super) fn build(surface: &Surface, normals: bool) -> Document<'_> {
    let mut b = Builder::default();
    let mut meshes = Vec::new();
    let mut nodes = Vec::new();
    let mut roots = Vec::new();
    let mut vertices = 0;
    // glTF forbids empty accessors: an empty part is left out.
    if surface.fluid.triangle_count() > 0 {
        let mut p = b.primitive(&surface.fluid, normals);
        b.attributes(
            &mut p,
            &surface.fluid.attributes,
            1,
            surface.fluid.vertex_count(),
        );
        meshes.push(json!({"name": "fluid", "primitives": [p]}));
        nodes.push(json!({"name": "fluid", "mesh": meshes.len() - 1}));
        roots.push(nodes.len() - 1);
        vertices += surface.fluid.vertex_count();
    }
    let spheres = &surface.spheres;
    if !spheres.centers.is_empty()
        && spheres.template.triangle_count() > 0
        && !spheres.attributes.is_empty()
    {
        let p = b.merged_spheres(spheres, normals);
        meshes.push(json!({"name": "isolated_particles", "primitives": [p]}));
        nodes.push(json!({"name": "isolated_particles", "mesh": meshes.len() - 1}));
        roots.push(nodes.len() - 1);
        vertices += spheres.template.vertex_count() * spheres.centers.len();
    } else if !spheres.centers.is_empty() && spheres.template.triangle_count() > 0 {
        let p = b.primitive(&spheres.template, normals);
        meshes.push(json!({"name": "isolated_particle", "primitives": [p]}));
        let mesh = meshes.len() - 1;
        let first = nodes.len() + 1;
        let children: Vec<usize> = (first..first + spheres.centers.len()).collect();
        nodes.push(json!({"name": "isolated_particles", "children": children}));
        roots.push(nodes.len() - 1);
        for (k, c) in spheres.centers.iter().enumerate() {
            let mut node = json!({"mesh": mesh, "translation": c.to_array()});
            if let Some(&s) = spheres.scales.get(k) {
                node["scale"] = json!([s, s, s]);
            }
            nodes.push(node);
        }
        vertices += spheres.template.vertex_count();
    }
    let mut json = json!({
        "asset": asset(),
        "scene": 0,
        "scenes": [{"nodes": roots}],
        "nodes": nodes,
    });
    if !meshes.is_empty() {
        json["meshes"] = json!(meshes);
        json["accessors"] = json!(b.accessors);
        json["bufferViews"] = json!(b.views);
        json["buffers"] = json!([{"byteLength": b.bin_len}]);
    }
    b.finish(json, vertices)
}

/// A sequence: one node per frame (fluid and spheres merged into one mesh), named
/// `frame_N` after its frame number N, shown in turn by a step-interpolated scale
/// animation (scale 1 during its frame, 0 otherwise): frame N from time N/`fps` seconds
/// (Blender's frame N; (N − first)/`fps` when the first frame is negative), so a gap in
/// the numbering stays a gap and the first frame shows from time 0. `frames` are in increasing order of
/// their numbers.
pub(super) fn build_sequence<'a>(
    frames: &[&'a (i64, TriMesh)],
    fps: f64,
    normals: bool,
) -> Document<'a> {
    let mut b = Builder::default();
    let mut meshes = Vec::new();
    let mut nodes = Vec::new();
    let mut vertices = 0;
    let n = frames.len();
    for (i, (number, mesh)) in frames.iter().copied().enumerate() {
        let mut node = json!({"name": format!("frame_{number}"), "scale": if i == 0 { [1.0, 1.0, 1.0] } else { [0.0, 0.0, 0.0] }});
        if mesh.triangle_count() > 0 {
            let mut p = b.primitive(mesh, normals);
            b.attributes(&mut p, &mesh.attributes, 1, mesh.vertex_count());
            meshes.push(json!({"name": format!("frame_{number}"), "primitives": [p]}));
            node["mesh"] = json!(meshes.len() - 1);
            vertices += mesh.vertex_count();
        }
        nodes.push(node);
    }
    // Shared key times, then one scale track per node. Frame N at N/fps seconds, where
    // Blender's importer keys it at its frame N (it takes t·fps as the frame); glTF times
    // cannot be negative, so a sequence starting below 0 starts at 0.
    let origin = frames.first().map_or(0, |(number, _)| (*number).min(0));
    let key_times: Vec<f32> = frames
        .iter()
        .map(|(number, _)| ((number - origin) as f64 / fps) as f32)
        .collect();
    let times = key_times.iter().flat_map(|t| t.to_le_bytes()).collect();
    let view = b.push_view(Payload::Bytes(times), None);
    let input = b.push_accessor(json!({
        "bufferView": view, "componentType": FLOAT, "count": n, "type": "SCALAR",
        "min": [key_times.first().copied().unwrap_or(0.0)],
        "max": [key_times.last().copied().unwrap_or(0.0)]
    }));
    let mut samplers = Vec::with_capacity(n);
    let mut channels = Vec::with_capacity(n);
    for i in 0..n {
        let mut scales = Vec::with_capacity(n * 12);
        for k in 0..n {
            let v: f32 = if k == i { 1.0 } else { 0.0 };
            for _ in 0..3 {
                scales.extend_from_slice(&v.to_le_bytes());
            }
        }
        let view = b.push_view(Payload::Bytes(scales), None);
        let output = b.push_accessor(json!({
            "bufferView": view, "componentType": FLOAT, "count": n, "type": "VEC3"
        }));
        samplers.push(json!({"input": input, "output": output, "interpolation": "STEP"}));
        channels.push(json!({"sampler": i, "target": {"node": i, "path": "scale"}}));
    }
    let roots: Vec<usize> = (0..n).collect();
    let mut json = json!({
        "asset": asset(),
        "scene": 0,
        "scenes": [{"nodes": roots}],
        "nodes": nodes,
        "accessors": b.accessors,
        "bufferViews": b.views,
        "buffers": [{"byteLength": b.bin_len}],
        "animations": [{"name": "sequence", "samplers": samplers, "channels": channels}],
    });
    if !meshes.is_empty() {
        json["meshes"] = json!(meshes);
    }
    b.finish(json, vertices)
}

impl Document<'_> {
    /// Streams the buffer: every view at its offset, zero padding between and at the end.
    fn write_bin(&self, w: &mut impl Write) -> std::io::Result<()> {
        let mut at = 0usize;
        for payload in &self.payloads {
            let offset = at.next_multiple_of(4);
            w.write_all(&[0u8; 3][..offset - at])?;
            payload.write(w)?;
            at = offset + payload.byte_len();
        }
        w.write_all(&[0u8; 3][..self.bin_len - at])
    }

    pub(super) fn write_glb(&self, w: &mut impl Write) -> std::io::Result<()> {
        let mut json = serde_json::to_vec(&self.json).map_err(std::io::Error::other)?;
        while json.len() % 4 != 0 {
            json.push(b' ');
        }
        let has_bin = self.bin_len > 0;
        let total = 12 + 8 + json.len() + if has_bin { 8 + self.bin_len } else { 0 };
        let total = u32::try_from(total).map_err(|_| {
            std::io::Error::other(format!(
                "{total} bytes: a .glb holds at most 4 GiB; write .ply or .vtk instead"
            ))
        })?;
        w.write_all(b"glTF")?;
        w.write_all(&2u32.to_le_bytes())?;
        w.write_all(&total.to_le_bytes())?;
        w.write_all(&(json.len() as u32).to_le_bytes())?;
        w.write_all(b"JSON")?;
        w.write_all(&json)?;
        if has_bin {
            w.write_all(&(self.bin_len as u32).to_le_bytes())?;
            w.write_all(b"BIN\0")?;
            self.write_bin(w)?;
        }
        Ok(())
    }

    pub(super) fn write_gltf(&self, w: &mut impl Write) -> std::io::Result<()> {
        if self.bin_len == 0 {
            serde_json::to_writer(&mut *w, &self.json).map_err(std::io::Error::other)?;
            return w.write_all(b"\n");
        }
        // The JSON with a placeholder URI, split around it; the base64 data is streamed in
        // between.
        const PLACEHOLDER: &str = "meniscus-buffer-data";
        let mut json = self.json.clone();
        json["buffers"][0]["uri"] = json!(PLACEHOLDER);
        let text = serde_json::to_string(&json).map_err(std::io::Error::other)?;
        let (before, after) = text
            .split_once(PLACEHOLDER)
            .expect("the placeholder is in the JSON");
        w.write_all(before.as_bytes())?;
        w.write_all(b"data:application/octet-stream;base64,")?;
        let mut encoder = Base64Writer::new(&mut *w, CHUNK_BYTES);
        self.write_bin(&mut encoder)?;
        encoder.finish()?;
        w.write_all(after.as_bytes())?;
        w.write_all(b"\n")
    }
}
