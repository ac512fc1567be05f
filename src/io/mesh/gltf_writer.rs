//! glTF 2.0 output, built with serde_json: the document is small and fixed in shape, and
//! writing its JSON directly keeps the byte layout (alignment, accessor bounds) in view.
//! The `gltf` crate reads the result back in the tests.
//!
//! The binary buffer is never assembled in memory: the document records which mesh arrays
//! go where, and writing streams them in chunks of [`CHUNK_BYTES`] (base64-encoded on the
//! fly for `.gltf`), so a 70 M-triangle surface is written without a 1.7 GB copy.
//!
//! Attributes become application-specific vertex attributes (`_VELOCITY`, float
//! accessors; names in [`super::columns`]). Spheres with attributes are written as one
//! merged mesh (instances translated, each vertex with its particle's values) instead of
//! one node per instance: glTF attributes belong to a mesh, and Blender's importer drops
//! per-instance attributes of `EXT_mesh_gpu_instancing`.

use super::columns;
use super::simple::{write_chunked, CHUNK_BYTES};
use crate::attributes::Attribute;
use crate::mesh::{SphereInstances, Surface, TriMesh};
use glam::Vec3;
use serde_json::{json, Value};
use std::io::{Result, Write};

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
    fn write(&self, w: &mut impl Write) -> Result<()> {
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
    pub vertices: usize,
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

    /// The sphere instances merged into one primitive: the template translated to every
    /// centre (as [`SphereInstances::merged`] does), each vertex with its instance's
    /// attribute values.
    fn merged_spheres(&mut self, s: &'a SphereInstances, normals: bool) -> Value {
        let t = &s.template;
        let n = t.vertex_count();
        let count = n * s.centers.len();
        let position = move |i: usize| t.positions[i % n] + s.centers[i / n];
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
        for c in &spheres.centers {
            nodes.push(json!({"mesh": mesh, "translation": c.to_array()}));
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

/// A sequence: one node per frame (fluid and spheres merged into one mesh), shown in turn
/// by a step-interpolated scale animation (scale 1 during its frame, 0 otherwise) at
/// `fps` frames per second.
pub(super) fn build_sequence(frames: &[TriMesh], fps: f32, normals: bool) -> Document<'_> {
    let mut b = Builder::default();
    let mut meshes = Vec::new();
    let mut nodes = Vec::new();
    let mut vertices = 0;
    let n = frames.len();
    for (i, mesh) in frames.iter().enumerate() {
        let mut node = json!({"name": format!("frame_{i}"), "scale": if i == 0 { [1.0, 1.0, 1.0] } else { [0.0, 0.0, 0.0] }});
        if mesh.triangle_count() > 0 {
            let mut p = b.primitive(mesh, normals);
            b.attributes(&mut p, &mesh.attributes, 1, mesh.vertex_count());
            meshes.push(json!({"name": format!("frame_{i}"), "primitives": [p]}));
            node["mesh"] = json!(meshes.len() - 1);
            vertices += mesh.vertex_count();
        }
        nodes.push(node);
    }
    // Shared key times, then one scale track per node.
    let mut times = Vec::with_capacity(n * 4);
    for k in 0..n {
        times.extend_from_slice(&(k as f32 / fps).to_le_bytes());
    }
    let view = b.push_view(Payload::Bytes(times), None);
    let input = b.push_accessor(json!({
        "bufferView": view, "componentType": FLOAT, "count": n, "type": "SCALAR",
        "min": [0.0], "max": [(n.saturating_sub(1)) as f32 / fps]
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
    fn write_bin(&self, w: &mut impl Write) -> Result<()> {
        let mut at = 0usize;
        for payload in &self.payloads {
            let offset = at.next_multiple_of(4);
            w.write_all(&[0u8; 3][..offset - at])?;
            payload.write(w)?;
            at = offset + payload.byte_len();
        }
        w.write_all(&[0u8; 3][..self.bin_len - at])
    }

    pub fn write_glb(&self, w: &mut impl Write) -> Result<()> {
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

    pub fn write_gltf(&self, w: &mut impl Write) -> Result<()> {
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
        let mut encoder = Base64Writer {
            inner: &mut *w,
            carry: Vec::with_capacity(3),
            out: Vec::with_capacity(CHUNK_BYTES / 3 * 4 + 8),
        };
        self.write_bin(&mut encoder)?;
        encoder.finish()?;
        w.write_all(after.as_bytes())?;
        w.write_all(b"\n")
    }
}

/// Base64-encodes what is written to it (standard alphabet, `=` padding on `finish`).
struct Base64Writer<W: Write> {
    inner: W,
    carry: Vec<u8>,
    out: Vec<u8>,
}

impl<W: Write> Write for Base64Writer<W> {
    fn write(&mut self, bytes: &[u8]) -> Result<usize> {
        let mut rest = bytes;
        if !self.carry.is_empty() {
            let take = (3 - self.carry.len()).min(rest.len());
            self.carry.extend_from_slice(&rest[..take]);
            rest = &rest[take..];
            if self.carry.len() < 3 {
                return Ok(bytes.len());
            }
            let group = std::mem::take(&mut self.carry);
            encode_base64(&group, &mut self.out);
        }
        let whole = rest.len() / 3 * 3;
        encode_base64(&rest[..whole], &mut self.out);
        self.carry.extend_from_slice(&rest[whole..]);
        if self.out.len() >= CHUNK_BYTES {
            self.inner.write_all(&self.out)?;
            self.out.clear();
        }
        Ok(bytes.len())
    }

    fn flush(&mut self) -> Result<()> {
        self.inner.flush()
    }
}

impl<W: Write> Base64Writer<W> {
    fn finish(mut self) -> Result<()> {
        let tail = std::mem::take(&mut self.carry);
        encode_base64(&tail, &mut self.out);
        self.inner.write_all(&self.out)
    }
}

/// Appends the base64 text of `bytes` to `out` (padded when `bytes.len()` is not a
/// multiple of 3).
fn encode_base64(bytes: &[u8], out: &mut Vec<u8>) {
    const TABLE: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            *chunk.get(1).unwrap_or(&0),
            *chunk.get(2).unwrap_or(&0),
        ];
        let n = ((b[0] as u32) << 16) | ((b[1] as u32) << 8) | b[2] as u32;
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(TABLE[((n >> (18 - 6 * k)) & 63) as usize]);
            } else {
                out.push(b'=');
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use std::io::Write;

    fn base64(bytes: &[u8]) -> String {
        let mut out = Vec::new();
        super::encode_base64(bytes, &mut out);
        String::from_utf8(out).unwrap()
    }

    #[test]
    fn base64_matches_known_vectors() {
        assert_eq!(base64(b""), "");
        assert_eq!(base64(b"f"), "Zg==");
        assert_eq!(base64(b"fo"), "Zm8=");
        assert_eq!(base64(b"foo"), "Zm9v");
        assert_eq!(base64(b"foobar"), "Zm9vYmFy");
    }

    #[test]
    fn streamed_base64_equals_one_shot_for_any_split() {
        let data: Vec<u8> = (0..1000u32).map(|i| (i * 7919 % 251) as u8).collect();
        for split in [1, 2, 3, 4, 5, 7, 64, 999] {
            let mut out = Vec::new();
            let mut w = super::Base64Writer {
                inner: &mut out,
                carry: Vec::new(),
                out: Vec::new(),
            };
            for piece in data.chunks(split) {
                w.write_all(piece).unwrap();
            }
            w.finish().unwrap();
            assert_eq!(
                String::from_utf8(out).unwrap(),
                base64(&data),
                "split {split}"
            );
        }
    }
}
