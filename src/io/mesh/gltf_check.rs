//! Structural checks of a glTF document before the gltf crate's lazy accessors touch it.
//!
//! The crate validates JSON shapes but not everything its readers rely on: a node that is
//! its own descendant makes the scene walk loop forever, a node with two parents makes it
//! exponential, an accessor reaching past its buffer view or a float index accessor makes
//! the readers panic or misread. Every index and extent the reader follows is checked here
//! on the raw JSON, with checked arithmetic, so that a hostile file is an error that says
//! where it is wrong.

use crate::error::{Error, Result};
use serde_json::Value;
use std::path::Path;

/// Checks the document in `bytes` (`.gltf` JSON or `.glb` container).
pub(super) fn check(path: &Path, bytes: &[u8]) -> Result<()> {
    let bad = |location: String, message: String| Error::parse(path, location, message);
    let (json, bin_len): (Vec<u8>, Option<usize>) = if bytes.starts_with(b"glTF") {
        let glb = gltf::binary::Glb::from_slice(bytes)
            .map_err(|e| bad("GLB container".into(), e.to_string()))?;
        (glb.json.into_owned(), glb.bin.map(|b| b.len()))
    } else {
        (bytes.to_vec(), None)
    };
    let root: Value =
        serde_json::from_slice(&json).map_err(|e| bad("glTF JSON".into(), e.to_string()))?;
    let doc = Doc {
        root: &root,
        bad: &bad,
    };
    let counts = Counts {
        nodes: doc.array("nodes")?.len(),
        meshes: doc.array("meshes")?.len(),
        accessors: doc.array("accessors")?.len(),
        views: doc.array("bufferViews")?.len(),
        buffers: doc.array("buffers")?.len(),
    };

    // Buffers: only embedded data (a data: URI or the GLB binary chunk) is read; a URI
    // naming a file would be read relative to the working directory, whatever it is
    // (/dev/zero included).
    let mut buffer_len = Vec::with_capacity(counts.buffers);
    for (i, b) in doc.array("buffers")?.iter().enumerate() {
        let at = format!("buffers[{i}]");
        let len = doc.uint(b, "byteLength", &at)?.unwrap_or(0);
        match b.get("uri") {
            Some(Value::String(uri)) if uri.starts_with("data:") => {}
            Some(Value::String(uri)) => {
                return Err(bad(
                    at,
                    format!(
                        "the buffer is an external file ({uri:?}); only embedded buffers (data: URIs, the GLB binary chunk) are read"
                    ),
                ))
            }
            Some(_) => return Err(bad(at, "uri is not a string".into())),
            None => {
                let have = bin_len.ok_or_else(|| {
                    bad(at.clone(), "no uri and no GLB binary chunk to refer to".into())
                })?;
                if (have as u64) < len {
                    return Err(bad(
                        at,
                        format!("byteLength {len} exceeds the {have} bytes of the GLB binary chunk"),
                    ));
                }
            }
        }
        buffer_len.push(len);
    }

    // Buffer views lie inside their buffers.
    let mut views = Vec::with_capacity(counts.views);
    for (i, v) in doc.array("bufferViews")?.iter().enumerate() {
        let at = format!("bufferViews[{i}]");
        let buffer = doc.index(v, "buffer", &at, counts.buffers, "buffers")?;
        let buffer = buffer.ok_or_else(|| bad(at.clone(), "no buffer".into()))?;
        let offset = doc.uint(v, "byteOffset", &at)?.unwrap_or(0);
        let len = doc.uint(v, "byteLength", &at)?.unwrap_or(0);
        let stride = doc.uint(v, "byteStride", &at)?;
        match offset.checked_add(len) {
            Some(end) if end <= buffer_len[buffer] => {}
            _ => {
                return Err(bad(
                    at,
                    format!(
                        "bytes {offset}..{offset}+{len} exceed buffer {buffer} ({} bytes)",
                        buffer_len[buffer]
                    ),
                ))
            }
        }
        views.push(View { len, stride });
    }

    // Accessors lie inside their buffer views (sparse parts too). One without a buffer
    // view is zeros (plus its sparse values): it may not hold more bytes than the file's
    // buffers (64 KiB at least), or a few bytes of JSON would ask for gigabytes.
    let zeros_limit = buffer_len
        .iter()
        .fold(0u64, |a, &b| a.saturating_add(b))
        .max(1 << 16);
    let mut accessors = Vec::with_capacity(counts.accessors);
    for (i, a) in doc.array("accessors")?.iter().enumerate() {
        let at = format!("accessors[{i}]");
        let component = doc.uint(a, "componentType", &at)?;
        let component_size: u64 = match component {
            Some(5120 | 5121) => 1,
            Some(5122 | 5123) => 2,
            Some(5125 | 5126) => 4,
            other => {
                return Err(bad(
                    at,
                    format!("componentType {other:?} is not a glTF type"),
                ));
            }
        };
        let kind = a.get("type").and_then(Value::as_str).unwrap_or_default();
        let components: u64 = match kind {
            "SCALAR" => 1,
            "VEC2" => 2,
            "VEC3" => 3,
            "VEC4" | "MAT2" => 4,
            "MAT3" => 9,
            "MAT4" => 16,
            other => return Err(bad(at, format!("type {other:?} is not a glTF type"))),
        };
        let count = doc.uint(a, "count", &at)?.unwrap_or(0);
        if count == 0 {
            return Err(bad(
                at,
                "count is 0 (glTF accessors hold at least one element)".into(),
            ));
        }
        let size = component_size * components;
        if let Some(view) = doc.index(a, "bufferView", &at, counts.views, "bufferViews")? {
            let offset = doc.uint(a, "byteOffset", &at)?.unwrap_or(0);
            doc.extent(&at, offset, count, size, &views[view], view)?;
        } else if count.saturating_mul(size) > zeros_limit {
            return Err(bad(
                at,
                format!(
                    "{count} elements of {size} bytes without a bufferView: more than the {zeros_limit} bytes the file's buffers hold"
                ),
            ));
        }
        if let Some(sparse) = a.get("sparse") {
            let at = format!("{at}.sparse");
            let n = doc.uint(sparse, "count", &at)?.unwrap_or(0);
            if n == 0 || n > count {
                return Err(bad(at, format!("count {n} is not in 1..={count}")));
            }
            for (part, element) in [("indices", None), ("values", Some(size))] {
                let at = format!("{at}.{part}");
                let p = sparse
                    .get(part)
                    .ok_or_else(|| bad(at.clone(), "missing".into()))?;
                let view = doc
                    .index(p, "bufferView", &at, counts.views, "bufferViews")?
                    .ok_or_else(|| bad(at.clone(), "no bufferView".into()))?;
                let element = match element {
                    Some(size) => size,
                    None => match doc.uint(p, "componentType", &at)? {
                        Some(5121) => 1,
                        Some(5123) => 2,
                        Some(5125) => 4,
                        other => {
                            return Err(bad(
                                at,
                                format!("componentType {other:?} is not an unsigned integer type"),
                            ))
                        }
                    },
                };
                let offset = doc.uint(p, "byteOffset", &at)?.unwrap_or(0);
                doc.extent(&at, offset, n, element, &views[view], view)?;
            }
        }
        accessors.push((component.unwrap_or(0), kind, count));
    }

    // Meshes: primitives refer to accessors that exist; indices are unsigned integer
    // scalars, positions and normals float VEC3.
    let mut mesh_vertices = vec![0u64; counts.meshes];
    for (i, m) in doc.array("meshes")?.iter().enumerate() {
        let prims = m.get("primitives").and_then(Value::as_array);
        for (j, prim) in prims.into_iter().flatten().enumerate() {
            let at = format!("meshes[{i}].primitives[{j}]");
            if let Some(k) = doc.index(prim, "indices", &at, counts.accessors, "accessors")? {
                let (component, kind, _) = accessors[k];
                if !matches!(component, 5121 | 5123 | 5125) || kind != "SCALAR" {
                    return Err(bad(
                        format!("{at}.indices"),
                        format!(
                            "accessor {k} ({kind}, componentType {component}) is not an unsigned integer scalar"
                        ),
                    ));
                }
            }
            let attributes = match prim.get("attributes") {
                Some(Value::Object(map)) => map,
                _ => return Err(bad(at, "no attributes".into())),
            };
            for (name, value) in attributes {
                let at = format!("{at}.attributes.{name}");
                let k = match value.as_u64() {
                    Some(k) if (k as usize) < counts.accessors && k <= usize::MAX as u64 => {
                        k as usize
                    }
                    _ => {
                        return Err(bad(
                            at,
                            format!(
                                "accessor {value} does not exist (the file has {})",
                                counts.accessors
                            ),
                        ))
                    }
                };
                let (component, kind, count) = accessors[k];
                if name == "POSITION" {
                    mesh_vertices[i] = mesh_vertices[i].saturating_add(count);
                }
                if (name == "POSITION" || name == "NORMAL") && (component != 5126 || kind != "VEC3")
                {
                    return Err(bad(
                        at,
                        format!(
                            "accessor {k} ({kind}, componentType {component}) is not a float VEC3"
                        ),
                    ));
                }
            }
        }
    }

    // Nodes: meshes and children exist, and the hierarchy is a forest (no node is its own
    // descendant, none has two parents), so that the walk from the scene ends.
    let nodes = doc.array("nodes")?;
    let mut parent: Vec<Option<usize>> = vec![None; nodes.len()];
    let mut children: Vec<Vec<usize>> = Vec::with_capacity(nodes.len());
    let mut vertices: Vec<u64> = Vec::with_capacity(nodes.len());
    for (i, n) in nodes.iter().enumerate() {
        let at = format!("nodes[{i}]");
        let mesh = doc.index(n, "mesh", &at, counts.meshes, "meshes")?;
        vertices.push(mesh.map_or(0, |m| mesh_vertices[m]));
        let mut own = Vec::new();
        let list = match n.get("children") {
            None => &[][..],
            Some(Value::Array(list)) => &list[..],
            Some(_) => return Err(bad(at, "children is not an array".into())),
        };
        for (k, c) in list.iter().enumerate() {
            let c = doc.index_value(c, &format!("{at}.children[{k}]"), counts.nodes, "nodes")?;
            if c == i {
                return Err(bad(at, format!("node {i} is its own child")));
            }
            if let Some(p) = parent[c] {
                return Err(bad(
                    at,
                    format!("node {c} is a child of both node {p} and node {i} (glTF nodes have one parent)"),
                ));
            }
            parent[c] = Some(i);
            own.push(c);
        }
        children.push(own);
    }
    // With one parent each, a cycle is a loop of parent links: follow them from every node,
    // each node visited at most once overall.
    let mut state = vec![0u8; nodes.len()]; // 0 unseen, 1 on the current chain, 2 done
    for start in 0..nodes.len() {
        let mut chain = Vec::new();
        let mut at = Some(start);
        while let Some(n) = at {
            match state[n] {
                2 => break,
                1 => {
                    return Err(bad(
                        format!("nodes[{n}]"),
                        format!(
                            "node {n} is its own ancestor (the node hierarchy has a cycle through node {})",
                            parent[n].unwrap_or(n)
                        ),
                    ))
                }
                _ => {
                    state[n] = 1;
                    chain.push(n);
                    at = parent[n];
                }
            }
        }
        for n in chain {
            state[n] = 2;
        }
    }

    // The vertices each node's subtree instantiates (a mesh counts once per node using
    // it): children before parents, in reversed pre-order from the roots.
    let mut order = Vec::with_capacity(nodes.len());
    let mut stack: Vec<usize> = (0..nodes.len()).filter(|&i| parent[i].is_none()).collect();
    while let Some(i) = stack.pop() {
        order.push(i);
        stack.extend(&children[i]);
    }
    for &i in order.iter().rev() {
        let below = children[i]
            .iter()
            .fold(0u64, |a, &c| a.saturating_add(vertices[c]));
        vertices[i] = vertices[i].saturating_add(below);
    }

    // Scenes list distinct root nodes that exist (the walk visits each node once),
    // instantiating no more vertices than a mesh
    // can index.
    let scenes = doc.array("scenes")?;
    for (i, s) in scenes.iter().enumerate() {
        let at = format!("scenes[{i}]");
        let list = match s.get("nodes") {
            None => &[][..],
            Some(Value::Array(list)) => &list[..],
            Some(_) => return Err(bad(at, "nodes is not an array".into())),
        };
        let mut listed = vec![false; nodes.len()];
        let mut total = 0u64;
        for (k, n) in list.iter().enumerate() {
            let n = doc.index_value(n, &format!("{at}.nodes[{k}]"), counts.nodes, "nodes")?;
            if std::mem::replace(&mut listed[n], true) {
                return Err(bad(at, format!("node {n} is listed twice")));
            }
            if let Some(p) = parent[n] {
                return Err(bad(
                    at,
                    format!("node {n} is listed as a root but is a child of node {p}"),
                ));
            }
            total = total.saturating_add(vertices[n]);
        }
        if total > u32::MAX as u64 {
            return Err(bad(
                at,
                format!(
                    "the scene instantiates {total} vertices, more than a mesh can index ({})",
                    u32::MAX
                ),
            ));
        }
    }
    if let Some(s) = root.get("scene") {
        doc.index_value(s, "scene", scenes.len(), "scenes")?;
    }
    Ok(())
}

struct Counts {
    nodes: usize,
    meshes: usize,
    accessors: usize,
    views: usize,
    buffers: usize,
}

struct View {
    len: u64,
    stride: Option<u64>,
}

struct Doc<'a, F: Fn(String, String) -> Error> {
    root: &'a Value,
    bad: &'a F,
}

impl<F: Fn(String, String) -> Error> Doc<'_, F> {
    /// A top-level array; absent is empty.
    fn array(&self, key: &str) -> Result<&[Value]> {
        match self.root.get(key) {
            None => Ok(&[]),
            Some(Value::Array(a)) => Ok(a),
            Some(_) => Err((self.bad)(key.into(), "is not an array".into())),
        }
    }

    /// An optional non-negative integer property.
    fn uint(&self, object: &Value, key: &str, at: &str) -> Result<Option<u64>> {
        match object.get(key) {
            None => Ok(None),
            Some(v) => v.as_u64().map(Some).ok_or_else(|| {
                (self.bad)(
                    format!("{at}.{key}"),
                    format!("{v} is not a non-negative integer"),
                )
            }),
        }
    }

    /// An optional index property into an array of `len` `what`.
    fn index(
        &self,
        object: &Value,
        key: &str,
        at: &str,
        len: usize,
        what: &str,
    ) -> Result<Option<usize>> {
        match object.get(key) {
            None => Ok(None),
            Some(v) => self
                .index_value(v, &format!("{at}.{key}"), len, what)
                .map(Some),
        }
    }

    fn index_value(&self, v: &Value, at: &str, len: usize, what: &str) -> Result<usize> {
        match v.as_u64() {
            Some(i) if i < len as u64 => Ok(i as usize),
            _ => Err((self.bad)(
                at.into(),
                format!("index {v} is out of range (the file has {len} {what})"),
            )),
        }
    }

    /// `count` elements of `size` bytes from `offset` in buffer view `index` stay inside it.
    fn extent(
        &self,
        at: &str,
        offset: u64,
        count: u64,
        size: u64,
        view: &View,
        index: usize,
    ) -> Result<()> {
        let stride = view.stride.unwrap_or(size);
        if stride < size {
            return Err((self.bad)(
                at.into(),
                format!("buffer view {index} has byteStride {stride}, less than the {size}-byte element"),
            ));
        }
        let end = (count - 1)
            .checked_mul(stride)
            .and_then(|b| b.checked_add(size))
            .and_then(|b| b.checked_add(offset));
        match end {
            Some(end) if end <= view.len => Ok(()),
            _ => Err((self.bad)(
                at.into(),
                format!(
                    "{count} elements of {size} bytes (stride {stride}) from byte {offset} exceed buffer view {index} ({} bytes)",
                    view.len
                ),
            )),
        }
    }
}
