//! glTF 2.0 output, built with serde_json: the document is small and fixed in shape, and
//! writing its JSON directly keeps the byte layout (alignment, accessor bounds) in view.
//! The `gltf` crate reads the result back in the tests.

use crate::mesh::{Surface, TriMesh};
use serde_json::{json, Value};
use std::io::{Result, Write};

const FLOAT: u32 = 5126;
const UNSIGNED_INT: u32 = 5125;
const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;

pub(super) struct Document {
    json: Value,
    bin: Vec<u8>,
    pub vertices: usize,
}

#[derive(Default)]
struct Builder {
    bin: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl Builder {
    fn push_view(&mut self, bytes: &[u8], target: u32) -> usize {
        while self.bin.len() % 4 != 0 {
            self.bin.push(0);
        }
        let offset = self.bin.len();
        self.bin.extend_from_slice(bytes);
        self.views.push(
            json!({"buffer": 0, "byteOffset": offset, "byteLength": bytes.len(), "target": target}),
        );
        self.views.len() - 1
    }

    /// A buffer view without a target (animation data).
    fn push_view_untargeted(&mut self, bytes: &[u8]) -> usize {
        while self.bin.len() % 4 != 0 {
            self.bin.push(0);
        }
        let offset = self.bin.len();
        self.bin.extend_from_slice(bytes);
        self.views
            .push(json!({"buffer": 0, "byteOffset": offset, "byteLength": bytes.len()}));
        self.views.len() - 1
    }

    fn push_accessor(&mut self, value: Value) -> usize {
        self.accessors.push(value);
        self.accessors.len() - 1
    }

    /// Adds a mesh's attributes and indices; returns the primitive JSON.
    fn primitive(&mut self, mesh: &TriMesh, normals: bool) -> Value {
        let mut bytes = Vec::with_capacity(mesh.vertex_count() * 12);
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        for p in &mesh.positions {
            for (k, v) in p.to_array().into_iter().enumerate() {
                bytes.extend_from_slice(&v.to_le_bytes());
                lo[k] = lo[k].min(v);
                hi[k] = hi[k].max(v);
            }
        }
        let view = self.push_view(&bytes, ARRAY_BUFFER);
        let position = self.push_accessor(json!({
            "bufferView": view, "componentType": FLOAT, "count": mesh.vertex_count(),
            "type": "VEC3", "min": lo, "max": hi
        }));
        let mut attributes = json!({ "POSITION": position });
        if normals && mesh.normals.len() == mesh.positions.len() {
            bytes.clear();
            for n in &mesh.normals {
                for v in n.to_array() {
                    bytes.extend_from_slice(&v.to_le_bytes());
                }
            }
            let view = self.push_view(&bytes, ARRAY_BUFFER);
            let normal = self.push_accessor(json!({
                "bufferView": view, "componentType": FLOAT, "count": mesh.vertex_count(), "type": "VEC3"
            }));
            attributes["NORMAL"] = json!(normal);
        }
        bytes.clear();
        let mut max_index = 0u32;
        for t in &mesh.triangles {
            for i in t {
                bytes.extend_from_slice(&i.to_le_bytes());
                max_index = max_index.max(*i);
            }
        }
        let view = self.push_view(&bytes, ELEMENT_ARRAY_BUFFER);
        let indices = self.push_accessor(json!({
            "bufferView": view, "componentType": UNSIGNED_INT, "count": mesh.triangle_count() * 3,
            "type": "SCALAR", "min": [0], "max": [max_index]
        }));
        json!({ "attributes": attributes, "indices": indices, "mode": 4 })
    }
}

fn asset() -> Value {
    json!({"version": "2.0", "generator": concat!("meniscus ", env!("CARGO_PKG_VERSION"))})
}

pub(super) fn build(surface: &Surface, normals: bool) -> Document {
    let mut b = Builder::default();
    let mut meshes = Vec::new();
    let mut nodes = Vec::new();
    let mut roots = Vec::new();
    let mut vertices = 0;
    // glTF forbids empty accessors: an empty part is left out.
    if surface.fluid.triangle_count() > 0 {
        let p = b.primitive(&surface.fluid, normals);
        meshes.push(json!({"name": "fluid", "primitives": [p]}));
        nodes.push(json!({"name": "fluid", "mesh": meshes.len() - 1}));
        roots.push(nodes.len() - 1);
        vertices += surface.fluid.vertex_count();
    }
    let spheres = &surface.spheres;
    if !spheres.centers.is_empty() && spheres.template.triangle_count() > 0 {
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
    while b.bin.len() % 4 != 0 {
        b.bin.push(0);
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
        json["buffers"] = json!([{"byteLength": b.bin.len()}]);
    }
    Document {
        json,
        bin: b.bin,
        vertices,
    }
}

/// A sequence: one node per frame (fluid and spheres merged into one mesh), shown in turn
/// by a step-interpolated scale animation (scale 1 during its frame, 0 otherwise) at
/// `fps` frames per second.
pub(super) fn build_sequence(frames: &[TriMesh], fps: f32, normals: bool) -> Document {
    let mut b = Builder::default();
    let mut meshes = Vec::new();
    let mut nodes = Vec::new();
    let mut vertices = 0;
    let n = frames.len();
    for (i, mesh) in frames.iter().enumerate() {
        let mut node = json!({"name": format!("frame_{i}"), "scale": if i == 0 { [1.0, 1.0, 1.0] } else { [0.0, 0.0, 0.0] }});
        if mesh.triangle_count() > 0 {
            let p = b.primitive(mesh, normals);
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
    let view = b.push_view_untargeted(&times);
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
        let view = b.push_view_untargeted(&scales);
        let output = b.push_accessor(json!({
            "bufferView": view, "componentType": FLOAT, "count": n, "type": "VEC3"
        }));
        samplers.push(json!({"input": input, "output": output, "interpolation": "STEP"}));
        channels.push(json!({"sampler": i, "target": {"node": i, "path": "scale"}}));
    }
    while b.bin.len() % 4 != 0 {
        b.bin.push(0);
    }
    let roots: Vec<usize> = (0..n).collect();
    let mut json = json!({
        "asset": asset(),
        "scene": 0,
        "scenes": [{"nodes": roots}],
        "nodes": nodes,
        "accessors": b.accessors,
        "bufferViews": b.views,
        "buffers": [{"byteLength": b.bin.len()}],
        "animations": [{"name": "sequence", "samplers": samplers, "channels": channels}],
    });
    if !meshes.is_empty() {
        json["meshes"] = json!(meshes);
    }
    Document {
        json,
        bin: b.bin,
        vertices,
    }
}

impl Document {
    pub fn write_glb(&self, w: &mut impl Write) -> Result<()> {
        let mut json = serde_json::to_vec(&self.json).map_err(std::io::Error::other)?;
        while json.len() % 4 != 0 {
            json.push(b' ');
        }
        let has_bin = !self.bin.is_empty();
        let total = 12 + 8 + json.len() + if has_bin { 8 + self.bin.len() } else { 0 };
        w.write_all(b"glTF")?;
        w.write_all(&2u32.to_le_bytes())?;
        w.write_all(&(total as u32).to_le_bytes())?;
        w.write_all(&(json.len() as u32).to_le_bytes())?;
        w.write_all(b"JSON")?;
        w.write_all(&json)?;
        if has_bin {
            w.write_all(&(self.bin.len() as u32).to_le_bytes())?;
            w.write_all(b"BIN\0")?;
            w.write_all(&self.bin)?;
        }
        Ok(())
    }

    pub fn write_gltf(&self, w: &mut impl Write) -> Result<()> {
        let mut json = self.json.clone();
        if !self.bin.is_empty() {
            json["buffers"][0]["uri"] = json!(format!(
                "data:application/octet-stream;base64,{}",
                base64(&self.bin)
            ));
        }
        serde_json::to_writer(&mut *w, &json).map_err(std::io::Error::other)?;
        w.write_all(b"\n")
    }
}

fn base64(bytes: &[u8]) -> String {
    const TABLE: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            *chunk.get(1).unwrap_or(&0),
            *chunk.get(2).unwrap_or(&0),
        ];
        let n = ((b[0] as u32) << 16) | ((b[1] as u32) << 8) | b[2] as u32;
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(TABLE[((n >> (18 - 6 * k)) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    #[test]
    fn base64_matches_known_vectors() {
        assert_eq!(super::base64(b""), "");
        assert_eq!(super::base64(b"f"), "Zg==");
        assert_eq!(super::base64(b"fo"), "Zm8=");
        assert_eq!(super::base64(b"foo"), "Zm9v");
        assert_eq!(super::base64(b"foobar"), "Zm9vYmFy");
    }
}
