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
    let doc = Doc { root: &root, path };
    let counts = Counts {
        nodes: doc.array("nodes")?.len(),
        meshes: doc.array("meshes")?.len(),
        accessors: doc.array("accessors")?.len(),
        views: doc.array("bufferViews")?.len(),
        buffers: doc.array("buffers")?.len(),
    };
    let buffer_len = doc.buffers(&counts, bin_len)?;
    let views = doc.views(&counts, &buffer_len)?;
    let accessors = doc.accessors(&counts, &buffer_len, &views)?;
    let mesh_vertices = doc.meshes(&counts, &accessors)?;
    let nodes = doc.nodes(&counts, &mesh_vertices)?;
    doc.check_acyclic(&nodes.parent)?;
    doc.scenes(&counts, &nodes)
}

/// How many of each top-level array the document holds.
struct Counts {
    nodes: usize,
    meshes: usize,
    accessors: usize,
    views: usize,
    buffers: usize,
}

/// A buffer view's extent.
struct View {
    len: u64,
    stride: Option<u64>,
}

/// What the mesh check needs of an accessor: component type, type, element count.
type Accessor<'a> = (u64, &'a str, u64);

/// The node hierarchy, checked to be a forest.
struct Nodes {
    /// Each node's parent.
    parent: Vec<Option<usize>>,
    /// The vertices each node's subtree instantiates (a mesh counts once per node using
    /// it).
    vertices: Vec<u64>,
}

/// The document being checked; errors name `path`.
struct Doc<'a> {
    root: &'a Value,
    path: &'a Path,
}

impl<'a> Doc<'a> {
    fn bad(&self, location: String, message: String) -> Error {
        Error::parse(self.path, location, message)
    }

    /// Buffers: only embedded data (a data: URI or the GLB binary chunk) is read; a URI
    /// naming a file would be read relative to the working directory, whatever it is
    /// (/dev/zero included). Returns each buffer's byte length.
    fn buffers(&self, counts: &Counts, bin_len: Option<usize>) -> Result<Vec<u64>> {
        let mut buffer_len = Vec::with_capacity(counts.buffers);
        for (i, b) in self.array("buffers")?.iter().enumerate() {
            let at = format!("buffers[{i}]");
            let len = self.uint(b, "byteLength", &at)?.unwrap_or(0);
            match b.get("uri") {
                Some(Value::String(uri)) if uri.starts_with("data:") => {}
                Some(Value::String(uri)) => {
                    return Err(self.bad(
                        at,
                        format!(
                            "the buffer is an external file ({uri:?}); only embedded buffers (data: URIs, the GLB binary chunk) are read"
                        ),
                    ))
                }
                Some(_) => return Err(self.bad(at, "uri is not a string".into())),
                None => {
                    let have = bin_len.ok_or_else(|| {
                        self.bad(at.clone(), "no uri and no GLB binary chunk to refer to".into())
                    })?;
                    if (have as u64) < len {
                        return Err(self.bad(
                            at,
                            format!("byteLength {len} exceeds the {have} bytes of the GLB binary chunk"),
                        ));
                    }
                }
            }
            buffer_len.push(len);
        }
        Ok(buffer_len)
    }

    /// Buffer views lie inside their buffers.
    fn views(&self, counts: &Counts, buffer_len: &[u64]) -> Result<Vec<View>> {
        let mut views = Vec::with_capacity(counts.views);
        for (i, v) in self.array("bufferViews")?.iter().enumerate() {
            let at = format!("bufferViews[{i}]");
            let buffer = self.index(v, "buffer", &at, counts.buffers, "buffers")?;
            let buffer = buffer.ok_or_else(|| self.bad(at.clone(), "no buffer".into()))?;
            let offset = self.uint(v, "byteOffset", &at)?.unwrap_or(0);
            let len = self.uint(v, "byteLength", &at)?.unwrap_or(0);
            let stride = self.uint(v, "byteStride", &at)?;
            match offset.checked_add(len) {
                Some(end) if end <= buffer_len[buffer] => {}
                _ => {
                    return Err(self.bad(
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
        Ok(views)
    }

    /// Accessors lie inside their buffer views (sparse parts too). One without a buffer
    /// view is zeros (plus its sparse values): it may not hold more bytes than the file's
    /// buffers (64 KiB at least), or a few bytes of JSON would ask for gigabytes.
    fn accessors(
        &self,
        counts: &Counts,
        buffer_len: &[u64],
        views: &[View],
    ) -> Result<Vec<Accessor<'a>>> {
        let zeros_limit = buffer_len
            .iter()
            .fold(0u64, |a, &b| a.saturating_add(b))
            .max(1 << 16);
        let mut accessors = Vec::with_capacity(counts.accessors);
        for (i, a) in self.array("accessors")?.iter().enumerate() {
            let at = format!("accessors[{i}]");
            let component = self.uint(a, "componentType", &at)?;
            let component_size: u64 = match component {
                Some(5120 | 5121) => 1,
                Some(5122 | 5123) => 2,
                Some(5125 | 5126) => 4,
                other => {
                    return Err(self.bad(at, format!("componentType {other:?} is not a glTF type")));
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
                other => return Err(self.bad(at, format!("type {other:?} is not a glTF type"))),
            };
            let count = self.uint(a, "count", &at)?.unwrap_or(0);
            if count == 0 {
                return Err(self.bad(
                    at,
                    "count is 0 (glTF accessors hold at least one element)".into(),
                ));
            }
            let size = component_size * components;
            if let Some(view) = self.index(a, "bufferView", &at, counts.views, "bufferViews")? {
                let offset = self.uint(a, "byteOffset", &at)?.unwrap_or(0);
                self.extent(&at, offset, count, size, &views[view], view)?;
            } else if count.saturating_mul(size) > zeros_limit {
                return Err(self.bad(
                    at,
                    format!(
                        "{count} elements of {size} bytes without a bufferView: more than the {zeros_limit} bytes the file's buffers hold"
                    ),
                ));
            }
            if let Some(sparse) = a.get("sparse") {
                self.sparse(sparse, &at, counts, views, count, size)?;
            }
            accessors.push((component.unwrap_or(0), kind, count));
        }
        Ok(accessors)
    }

    /// The sparse part of accessor `at` (`count` elements of `size` bytes): its indices and
    /// values lie inside their buffer views.
    fn sparse(
        &self,
        sparse: &Value,
        at: &str,
        counts: &Counts,
        views: &[View],
        count: u64,
        size: u64,
    ) -> Result<()> {
        let at = format!("{at}.sparse");
        let n = self.uint(sparse, "count", &at)?.unwrap_or(0);
        if n == 0 || n > count {
            return Err(self.bad(at, format!("count {n} is not in 1..={count}")));
        }
        for (part, element) in [("indices", None), ("values", Some(size))] {
            let at = format!("{at}.{part}");
            let p = sparse
                .get(part)
                .ok_or_else(|| self.bad(at.clone(), "missing".into()))?;
            let view = self
                .index(p, "bufferView", &at, counts.views, "bufferViews")?
                .ok_or_else(|| self.bad(at.clone(), "no bufferView".into()))?;
            let element = match element {
                Some(size) => size,
                None => match self.uint(p, "componentType", &at)? {
                    Some(5121) => 1,
                    Some(5123) => 2,
                    Some(5125) => 4,
                    other => {
                        return Err(self.bad(
                            at,
                            format!("componentType {other:?} is not an unsigned integer type"),
                        ))
                    }
                },
            };
            let offset = self.uint(p, "byteOffset", &at)?.unwrap_or(0);
            self.extent(&at, offset, n, element, &views[view], view)?;
        }
        Ok(())
    }

    /// Meshes: primitives refer to accessors that exist; indices are unsigned integer
    /// scalars, positions and normals float VEC3. Returns the vertices of each mesh.
    fn meshes(&self, counts: &Counts, accessors: &[Accessor]) -> Result<Vec<u64>> {
        let mut mesh_vertices = vec![0u64; counts.meshes];
        for (i, m) in self.array("meshes")?.iter().enumerate() {
            let prims = m.get("primitives").and_then(Value::as_array);
            for (j, prim) in prims.into_iter().flatten().enumerate() {
                let at = format!("meshes[{i}].primitives[{j}]");
                mesh_vertices[i] =
                    mesh_vertices[i].saturating_add(self.primitive(prim, &at, counts, accessors)?);
            }
        }
        Ok(mesh_vertices)
    }

    /// One primitive of a mesh (see [`Doc::meshes`]); returns its vertices.
    fn primitive(
        &self,
        prim: &Value,
        at: &str,
        counts: &Counts,
        accessors: &[Accessor],
    ) -> Result<u64> {
        if let Some(k) = self.index(prim, "indices", at, counts.accessors, "accessors")? {
            let (component, kind, _) = accessors[k];
            if !matches!(component, 5121 | 5123 | 5125) || kind != "SCALAR" {
                return Err(self.bad(
                    format!("{at}.indices"),
                    format!(
                        "accessor {k} ({kind}, componentType {component}) is not an unsigned integer scalar"
                    ),
                ));
            }
        }
        let attributes = match prim.get("attributes") {
            Some(Value::Object(map)) => map,
            _ => return Err(self.bad(at.into(), "no attributes".into())),
        };
        let mut vertices = 0u64;
        for (name, value) in attributes {
            let at = format!("{at}.attributes.{name}");
            let k = match value.as_u64() {
                Some(k) if (k as usize) < counts.accessors && k <= usize::MAX as u64 => k as usize,
                _ => {
                    return Err(self.bad(
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
                vertices = vertices.saturating_add(count);
            }
            if (name == "POSITION" || name == "NORMAL") && (component != 5126 || kind != "VEC3") {
                return Err(self.bad(
                    at,
                    format!("accessor {k} ({kind}, componentType {component}) is not a float VEC3"),
                ));
            }
        }
        Ok(vertices)
    }

    /// Nodes: meshes and children exist and no node has two parents; with the vertices
    /// each subtree instantiates (children before parents, in reversed pre-order from the
    /// roots: with one parent each, the walk visits a node at most once, and nodes on a
    /// cycle not at all).
    fn nodes(&self, counts: &Counts, mesh_vertices: &[u64]) -> Result<Nodes> {
        let nodes = self.array("nodes")?;
        let mut parent: Vec<Option<usize>> = vec![None; nodes.len()];
        let mut children: Vec<Vec<usize>> = Vec::with_capacity(nodes.len());
        let mut vertices: Vec<u64> = Vec::with_capacity(nodes.len());
        for (i, n) in nodes.iter().enumerate() {
            let at = format!("nodes[{i}]");
            let mesh = self.index(n, "mesh", &at, counts.meshes, "meshes")?;
            vertices.push(mesh.map_or(0, |m| mesh_vertices[m]));
            let mut own = Vec::new();
            let list = match n.get("children") {
                None => &[][..],
                Some(Value::Array(list)) => &list[..],
                Some(_) => return Err(self.bad(at, "children is not an array".into())),
            };
            for (k, c) in list.iter().enumerate() {
                let c =
                    self.index_value(c, &format!("{at}.children[{k}]"), counts.nodes, "nodes")?;
                if c == i {
                    return Err(self.bad(at, format!("node {i} is its own child")));
                }
                if let Some(p) = parent[c] {
                    return Err(self.bad(
                        at,
                        format!("node {c} is a child of both node {p} and node {i} (glTF nodes have one parent)"),
                    ));
                }
                parent[c] = Some(i);
                own.push(c);
            }
            children.push(own);
        }
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
        Ok(Nodes { parent, vertices })
    }

    /// No node is its own descendant, so that the walk from the scene ends. With one
    /// parent each, a cycle is a loop of parent links: follow them from every node, each
    /// node visited at most once overall.
    fn check_acyclic(&self, parent: &[Option<usize>]) -> Result<()> {
        let mut state = vec![0u8; parent.len()]; // 0 unseen, 1 on the current chain, 2 done
        for start in 0..parent.len() {
            let mut chain = Vec::new();
            let mut at = Some(start);
            while let Some(n) = at {
                match state[n] {
                    2 => break,
                    1 => {
                        return Err(self.bad(
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
        Ok(())
    }

    /// Scenes list distinct root nodes that exist (the walk visits each node once),
    /// instantiating no more vertices than a mesh can index; the default scene exists.
    fn scenes(&self, counts: &Counts, nodes: &Nodes) -> Result<()> {
        let scenes = self.array("scenes")?;
        for (i, s) in scenes.iter().enumerate() {
            let at = format!("scenes[{i}]");
            let list = match s.get("nodes") {
                None => &[][..],
                Some(Value::Array(list)) => &list[..],
                Some(_) => return Err(self.bad(at, "nodes is not an array".into())),
            };
            let mut listed = vec![false; counts.nodes];
            let mut total = 0u64;
            for (k, n) in list.iter().enumerate() {
                let n = self.index_value(n, &format!("{at}.nodes[{k}]"), counts.nodes, "nodes")?;
                if std::mem::replace(&mut listed[n], true) {
                    return Err(self.bad(at, format!("node {n} is listed twice")));
                }
                if let Some(p) = nodes.parent[n] {
                    return Err(self.bad(
                        at,
                        format!("node {n} is listed as a root but is a child of node {p}"),
                    ));
                }
                total = total.saturating_add(nodes.vertices[n]);
            }
            if total > u32::MAX as u64 {
                return Err(self.bad(
                    at,
                    format!(
                        "the scene instantiates {total} vertices, more than a mesh can index ({})",
                        u32::MAX
                    ),
                ));
            }
        }
        if let Some(s) = self.root.get("scene") {
            self.index_value(s, "scene", scenes.len(), "scenes")?;
        }
        Ok(())
    }

    /// A top-level array; absent is empty.
    fn array(&self, key: &str) -> Result<&'a [Value]> {
        match self.root.get(key) {
            None => Ok(&[]),
            Some(Value::Array(a)) => Ok(a),
            Some(_) => Err(self.bad(key.into(), "is not an array".into())),
        }
    }

    /// An optional non-negative integer property.
    fn uint(&self, object: &Value, key: &str, at: &str) -> Result<Option<u64>> {
        match object.get(key) {
            None => Ok(None),
            Some(v) => v.as_u64().map(Some).ok_or_else(|| {
                self.bad(
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
            _ => Err(self.bad(
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
            return Err(self.bad(
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
            _ => Err(self.bad(
                at.into(),
                format!(
                    "{count} elements of {size} bytes (stride {stride}) from byte {offset} exceed buffer view {index} ({} bytes)",
                    view.len
                ),
            )),
        }
    }
}

/// Refuses an accessor the gltf crate's readers would panic on: another element type than
/// `dimensions` of one of `types`, no elements, a buffer-view stride shorter than an
/// element, or (sparse) no substituted elements.
pub(super) fn check_accessor(
    path: &Path,
    accessor: &gltf::Accessor,
    what: &str,
    dimensions: gltf::accessor::Dimensions,
    types: &[gltf::accessor::DataType],
) -> Result<()> {
    let fail = |m: String| {
        Err(Error::parse(
            path,
            "glTF",
            format!("{what} accessor {}: {m}", accessor.index()),
        ))
    };
    if accessor.dimensions() != dimensions || !types.contains(&accessor.data_type()) {
        return fail(format!(
            "elements of {:?} {:?}, expected {dimensions:?} of {types:?}",
            accessor.dimensions(),
            accessor.data_type()
        ));
    }
    if accessor.count() == 0 {
        return fail("no elements".into());
    }
    let short = |view: Option<gltf::buffer::View>, size: usize| {
        view.and_then(|v| v.stride()).is_some_and(|s| s < size)
    };
    if short(accessor.view(), accessor.size()) {
        return fail("buffer view stride shorter than an element".into());
    }
    if let Some(sparse) = accessor.sparse() {
        let index_size = sparse.indices().index_type().size();
        if sparse.count() == 0
            || short(Some(sparse.indices().view()), index_size)
            || short(Some(sparse.values().view()), accessor.size())
        {
            return fail("malformed sparse storage".into());
        }
    }
    Ok(())
}
