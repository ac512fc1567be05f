//! Mesh readers: PLY (ASCII, binary LE / BE, any scalar types, polygon faces
//! fan-triangulated), OBJ (`v`, `f` with `v`, `v/t`, `v//n`, `v/t/n` and negative indices,
//! polygons fan-triangulated), glTF (`.glb`, `.gltf` with embedded buffers: every
//! triangle primitive of the default scene, node transforms applied) and legacy VTK
//! (ASCII or BINARY, `POINTS` and `POLYGONS`, polygons fan-triangulated).
//!
//! Attributes come back as [`super::columns`] names them: PLY `float`/`double` vertex
//! properties other than `x y z nx ny nz` (regrouped); glTF float `_NAME` accessors,
//! named `name` (lower-cased, sorted by name; values as stored, not transformed by the
//! nodes; primitives that do not all carry the same attributes lose them, as
//! [`TriMesh::append`] does); VTK point-data arrays other than `NORMALS`. OBJ has none.

use super::columns;
use crate::attributes::Attribute;
use crate::error::{Error, Result};
use crate::io::ply_header;
use crate::io::text::{Cursor, Scalar};
use crate::io::vtk_legacy;
use crate::mesh::TriMesh;
use glam::{Mat4, Vec3};
use std::path::Path;

/// Reads a triangle mesh; the format comes from the extension.
pub fn read_mesh(path: &Path) -> Result<TriMesh> {
    let input = path.display().to_string();
    crate::error::guard(move || input, || read_mesh_unguarded(path))
}

fn read_mesh_unguarded(path: &Path) -> Result<TriMesh> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or_default()
        .to_ascii_lowercase();
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let mesh = match ext.as_str() {
        "ply" => read_ply(path, &bytes)?,
        "obj" => read_obj(path, &bytes)?,
        "glb" | "gltf" => read_gltf(path, &bytes)?,
        "vtk" => read_vtk(path, &bytes)?,
        _ => {
            return Err(Error::UnsupportedFormat {
                path: path.to_path_buf(),
                message: "mesh input must be .ply, .obj, .glb, .gltf or .vtk".into(),
            })
        }
    };
    let n = mesh.positions.len() as u32;
    if let Some(t) = mesh
        .triangles
        .iter()
        .position(|t| t.iter().any(|&i| i >= n))
    {
        return Err(Error::parse(
            path,
            format!("face {t}"),
            format!("vertex index out of range (the mesh has {n} vertices)"),
        ));
    }
    Ok(mesh)
}

fn read_ply(path: &Path, bytes: &[u8]) -> Result<TriMesh> {
    let mut c = Cursor::new(path, bytes);
    let header = ply_header::parse(&mut c)?;
    ply_header::check_counts(&c, &header)?;
    let binary = header.binary;
    let mut mesh = TriMesh::default();
    for element in &header.elements {
        match element.name.as_str() {
            "vertex" => {
                let (Some(x), Some(y), Some(z)) =
                    (element.find("x"), element.find("y"), element.find("z"))
                else {
                    return Err(c.error("vertex element without x, y, z"));
                };
                let normal = (element.find("nx"), element.find("ny"), element.find("nz"));
                // Float properties other than position and normal: attribute columns.
                let extra: Vec<usize> = (0..element.properties.len())
                    .filter(|&k| {
                        let p = &element.properties[k];
                        p.list_count.is_none()
                            && matches!(p.scalar, Scalar::F32 | Scalar::F64)
                            && !["x", "y", "z", "nx", "ny", "nz"].contains(&p.name.as_str())
                    })
                    .collect();
                let mut columns: Vec<(String, Vec<f32>)> = extra
                    .iter()
                    .map(|&k| (element.properties[k].name.clone(), Vec::new()))
                    .collect();
                let mut row = vec![0.0f32; element.properties.len()];
                for _ in 0..element.count {
                    for (slot, p) in row.iter_mut().zip(&element.properties) {
                        if p.list_count.is_some() {
                            return Err(
                                c.error("list properties in the vertex element are not supported")
                            );
                        }
                        *slot = c.value(p.scalar, binary)?;
                    }
                    mesh.positions.push(Vec3::new(row[x], row[y], row[z]));
                    if let (Some(a), Some(b), Some(cz)) = normal {
                        mesh.normals.push(Vec3::new(row[a], row[b], row[cz]));
                    }
                    for (column, &k) in columns.iter_mut().zip(&extra) {
                        column.1.push(row[k]);
                    }
                }
                mesh.attributes = columns::regroup(columns, true);
            }
            "face" => {
                for _ in 0..element.count {
                    for p in &element.properties {
                        let Some(count) = p.list_count else {
                            c.skip_values(1, p.scalar, binary)?;
                            continue;
                        };
                        let n = c.value(count, binary)?;
                        if !(0.0..=1e6).contains(&n) {
                            return Err(c.error(format!("bad list length {n}")));
                        }
                        if p.name == "vertex_indices" || p.name == "vertex_index" {
                            let items = c.indices(n as usize, p.scalar, binary)?;
                            for j in 1..items.len().saturating_sub(1) {
                                mesh.triangles.push([items[0], items[j], items[j + 1]]);
                            }
                        } else {
                            c.skip_values(n as usize, p.scalar, binary)?;
                        }
                    }
                }
            }
            _ => {
                for _ in 0..element.count {
                    ply_header::skip_row(&mut c, element, binary)?;
                }
            }
        }
    }
    Ok(mesh)
}

fn read_obj(path: &Path, bytes: &[u8]) -> Result<TriMesh> {
    let text = std::str::from_utf8(bytes)
        .map_err(|_| Error::parse(path, "file", "OBJ is not UTF-8 text"))?;
    let mut mesh = TriMesh::default();
    let mut normals: Vec<Vec3> = Vec::new();
    let mut normal_of: Vec<Option<u32>> = Vec::new();
    for (ln, line) in text.lines().enumerate() {
        let err = |m: String| Error::parse(path, format!("line {}", ln + 1), m);
        let mut w = line.split_whitespace();
        match w.next() {
            Some("v") | Some("vn") => {
                let kind = line.split_whitespace().next().unwrap_or_default();
                let v: Vec<f32> = w
                    .take(3)
                    .map(|t| t.parse().map_err(|_| err(format!("bad number {t:?}"))))
                    .collect::<Result<_>>()?;
                if v.len() != 3 {
                    return Err(err(format!("{kind} needs three numbers")));
                }
                if kind == "v" {
                    mesh.positions.push(Vec3::new(v[0], v[1], v[2]));
                    normal_of.push(None);
                } else {
                    normals.push(Vec3::new(v[0], v[1], v[2]));
                }
            }
            Some("f") => {
                let mut idx = Vec::new();
                for t in w {
                    let mut parts = t.split('/');
                    let resolve = |s: &str, n: usize| -> Result<u32> {
                        let i: i64 = s.parse().map_err(|_| err(format!("bad index {s:?}")))?;
                        let r = if i < 0 { n as i64 + i } else { i - 1 };
                        if r < 0 || r >= n as i64 {
                            return Err(err(format!("index {i} out of range")));
                        }
                        Ok(r as u32)
                    };
                    let v = resolve(parts.next().unwrap_or_default(), mesh.positions.len())?;
                    let _texture = parts.next();
                    if let Some(n) = parts.next().filter(|s| !s.is_empty()) {
                        normal_of[v as usize] = Some(resolve(n, normals.len())?);
                    }
                    idx.push(v);
                }
                if idx.len() < 3 {
                    return Err(err("a face needs three vertices".into()));
                }
                for j in 1..idx.len() - 1 {
                    mesh.triangles.push([idx[0], idx[j], idx[j + 1]]);
                }
            }
            _ => {}
        }
    }
    if !normals.is_empty() && normal_of.iter().all(|n| n.is_some()) {
        mesh.normals = normal_of
            .iter()
            .map(|n| normals[n.unwrap() as usize])
            .collect();
    }
    Ok(mesh)
}

fn read_gltf(path: &Path, bytes: &[u8]) -> Result<TriMesh> {
    let bad = |m: String| Error::parse(path, "glTF", m);
    // Indices, extents, component types and the node hierarchy are checked first: the
    // crate's readers trust them (and the scene walk below ends only on a forest).
    super::gltf_check::check(path, bytes)?;
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
                // The gltf crate's readers assume accessors of the right type and
                // layout (they panic otherwise): checked first.
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
                // Indices are offset by the vertices before this primitive: the total
                // must fit u32.
                let n = u32::try_from(piece.positions.len())
                    .ok()
                    .filter(|&n| n.checked_add(mesh.positions.len() as u32).is_some())
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
                        // Checked per primitive: once offset (TriMesh::append), an index
                        // past this primitive would name another primitive's vertex, or
                        // overflow.
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
                piece.attributes = gltf_attributes(path, &prim, &buffers, n as usize)?;
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

/// Refuses an accessor the gltf crate's readers would panic on: another element type than
/// `dimensions` of one of `types`, no elements, a buffer-view stride shorter than an
/// element, or (sparse) no substituted elements.
fn check_accessor(
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

/// Legacy VTK: `POINTS`, `POLYGONS` (classic or 5.x offsets/connectivity layout), point
/// data (`NORMALS` as normals, every other array as an attribute); other cells and cell
/// data are skipped.
fn read_vtk(path: &Path, bytes: &[u8]) -> Result<TriMesh> {
    let mut c = Cursor::new(path, bytes);
    let header = vtk_legacy::header(&mut c)?;
    let new_cells = header.new_cells;
    let binary = header.binary.then_some(true);
    let mut mesh = TriMesh::default();
    let mut npoints = 0usize;
    // The item count of the current data section and whether it is point data.
    let mut section: Option<(usize, bool)> = None;
    let typed = |c: &mut Cursor, what: &str| vtk_legacy::scalar(c, what, what);
    while !c.at_end() {
        let keyword = c.token("a section keyword")?.to_ascii_uppercase();
        match keyword.as_str() {
            "DATASET" => {
                let kind = c.token("a dataset type")?;
                if !kind.eq_ignore_ascii_case("POLYDATA") {
                    return Err(
                        c.error(format!("a mesh must be a POLYDATA dataset, found {kind:?}"))
                    );
                }
            }
            "POINTS" => {
                let (n, scalar) = vtk_legacy::points(&mut c, "point type")?;
                npoints = n;
                if binary.is_some() {
                    c.finish_line();
                }
                // Checked: a wrapped product would read a few values as the points.
                let values = npoints
                    .checked_mul(3)
                    .ok_or_else(|| c.error(format!("the point count {n} overflows")))?;
                let v = c.values(values, scalar, binary)?;
                mesh.positions = v
                    .chunks_exact(3)
                    .map(|p| Vec3::new(p[0], p[1], p[2]))
                    .collect();
            }
            "VERTICES" | "LINES" | "POLYGONS" | "TRIANGLE_STRIPS" => {
                let cells: usize = c.number("the cell count")?;
                let size: usize = c.number("the cell list size")?;
                if keyword == "TRIANGLE_STRIPS" {
                    return Err(c.error("TRIANGLE_STRIPS are not supported; write POLYGONS"));
                }
                let polygons = keyword == "POLYGONS";
                let mut lists: Vec<Vec<u32>> = Vec::new();
                if new_cells {
                    let mut offsets = Vec::new();
                    for part in ["OFFSETS", "CONNECTIVITY"] {
                        let found = c.token(part)?;
                        if !found.eq_ignore_ascii_case(part) {
                            return Err(c.error(format!("expected {part}, found {found:?}")));
                        }
                        let scalar = typed(&mut c, "index type")?;
                        if binary.is_some() {
                            c.finish_line();
                        }
                        let count = if part == "OFFSETS" { cells } else { size };
                        if !polygons {
                            c.skip_values(count, scalar, binary)?;
                        } else if part == "OFFSETS" {
                            offsets = c.indices(count, scalar, binary)?;
                        } else {
                            let ids = c.indices(count, scalar, binary)?;
                            for w in offsets.windows(2) {
                                let (a, b) = (w[0] as usize, w[1] as usize);
                                if a > b || b > ids.len() {
                                    return Err(c.error("polygon offsets out of order"));
                                }
                                lists.push(ids[a..b].to_vec());
                            }
                        }
                    }
                } else {
                    if binary.is_some() {
                        c.finish_line();
                    }
                    if polygons {
                        let mut left = size;
                        for _ in 0..cells {
                            let n = c.indices(1, Scalar::I32, binary)?[0] as usize;
                            if n >= left {
                                return Err(c.error("a polygon overruns the cell list size"));
                            }
                            lists.push(c.indices(n, Scalar::I32, binary)?);
                            left -= n + 1;
                        }
                    } else {
                        c.skip_values(size, Scalar::I32, binary)?;
                    }
                }
                for ids in lists {
                    for j in 1..ids.len().saturating_sub(1) {
                        mesh.triangles.push([ids[0], ids[j], ids[j + 1]]);
                    }
                }
            }
            "POINT_DATA" | "CELL_DATA" => {
                let n: usize = c.number("the item count")?;
                let points = keyword == "POINT_DATA";
                if points && n != npoints {
                    return Err(c.error(format!("POINT_DATA has {n} values, POINTS has {npoints}")));
                }
                section = Some((n, points));
            }
            k if vtk_legacy::is_attribute(k) => {
                let Some((items, points)) = section else {
                    return Err(c.error(format!("{keyword} outside POINT_DATA or CELL_DATA")));
                };
                let name = c.token("an array name")?.to_string();
                let (components, scalar) = match keyword.as_str() {
                    "SCALARS" => {
                        let scalar = typed(&mut c, "scalar type")?;
                        (vtk_legacy::scalars_tail(&mut c)?, scalar)
                    }
                    "VECTORS" | "NORMALS" => (3, typed(&mut c, "vector type")?),
                    "TENSORS" => (9, typed(&mut c, "tensor type")?),
                    "TEXTURE_COORDINATES" => {
                        let k: usize = c.number("a dimension")?;
                        (k, typed(&mut c, "texture coordinate type")?)
                    }
                    _ => {
                        let k: usize = c.number("a component count")?;
                        let scalar = if binary.is_some() {
                            Scalar::U8
                        } else {
                            Scalar::F32
                        };
                        (k, scalar)
                    }
                };
                if binary.is_some() {
                    c.finish_line();
                }
                let count = items
                    .checked_mul(components)
                    .ok_or_else(|| c.error("value count overflows"))?;
                if !points {
                    c.skip_values(count, scalar, binary)?;
                    continue;
                }
                let mut values = c.values(count, scalar, binary)?;
                if keyword == "COLOR_SCALARS" && binary.is_some() {
                    values.iter_mut().for_each(|v| *v /= 255.0);
                }
                if keyword == "NORMALS" {
                    mesh.normals = values
                        .chunks_exact(3)
                        .map(|n| Vec3::new(n[0], n[1], n[2]))
                        .collect();
                } else {
                    mesh.attributes.push(Attribute {
                        name,
                        components,
                        values,
                    });
                }
            }
            "FIELD" => {
                let Some((items, points)) = section else {
                    return Err(c.error("FIELD outside POINT_DATA or CELL_DATA"));
                };
                let arrays = vtk_legacy::field(&mut c)?;
                for _ in 0..arrays {
                    let (name, components, tuples, scalar) = vtk_legacy::field_array(
                        &mut c,
                        binary.is_some(),
                        "array type",
                        "array type",
                    )?;
                    let count = tuples
                        .checked_mul(components)
                        .ok_or_else(|| c.error("value count overflows"))?;
                    if !points {
                        c.skip_values(count, scalar, binary)?;
                        continue;
                    }
                    if tuples != items || components == 0 {
                        return Err(Error::parse(
                            path,
                            format!("attribute {name}"),
                            format!(
                                "{tuples} tuples of {components} components for {items} points"
                            ),
                        ));
                    }
                    let values = c.values(count, scalar, binary)?;
                    mesh.attributes.push(Attribute {
                        name,
                        components,
                        values,
                    });
                }
            }
            "LOOKUP_TABLE" => {
                c.token("a lookup table name")?;
                let size: usize = c.number("a table size")?;
                let scalar = if binary.is_some() {
                    Scalar::U8
                } else {
                    Scalar::F32
                };
                if binary.is_some() {
                    c.finish_line();
                }
                c.skip_values(size * 4, scalar, binary)?;
            }
            "METADATA" => vtk_legacy::skip_metadata(&mut c)?,
            other => return Err(c.error(format!("unknown section {other:?}"))),
        }
    }
    if mesh.normals.len() != mesh.positions.len() {
        mesh.normals.clear();
    }
    Ok(mesh)
}
