//! PLY point clouds: `format ascii | binary_little_endian | binary_big_endian 1.0`, the
//! `vertex` element's x, y, z (any scalar type) as positions and every other scalar vertex
//! property as a 1-component attribute (`vx, vy, vz` or `velocity_x/y/z` become one
//! 3-component `velocity`). Other elements are skipped, list properties included.

use super::{Particles, PointAttribute};
use crate::error::Result;
use crate::io::atomic::write_atomically;
use crate::io::text::{Cursor, Scalar};
use glam::Vec3;
use std::io::Write;
use std::path::Path;

fn scalar_type(name: &str) -> Option<Scalar> {
    Some(match name {
        "char" | "int8" => Scalar::I8,
        "uchar" | "uint8" => Scalar::U8,
        "short" | "int16" => Scalar::I16,
        "ushort" | "uint16" => Scalar::U16,
        "int" | "int32" => Scalar::I32,
        "uint" | "uint32" => Scalar::U32,
        "float" | "float32" => Scalar::F32,
        "double" | "float64" => Scalar::F64,
        _ => return None,
    })
}

enum Property {
    Scalar { name: String, ty: Scalar },
    List { count: Scalar, item: Scalar },
}

struct Element {
    name: String,
    count: usize,
    properties: Vec<Property>,
}

pub(super) fn read(path: &Path, bytes: &[u8]) -> Result<Particles> {
    let mut c = Cursor::new(path, bytes);
    if c.line()?.trim() != "ply" {
        return Err(crate::error::Error::parse(
            path,
            "line 1",
            "not a PLY file: the first line must be \"ply\"",
        ));
    }
    let mut binary: Option<Option<bool>> = None;
    let mut elements: Vec<Element> = Vec::new();
    loop {
        if c.pos >= bytes.len() {
            return Err(c.error("header has no end_header"));
        }
        let line = c.line()?;
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            ["format", f, _version] => {
                binary = Some(match *f {
                    "ascii" => None,
                    "binary_little_endian" => Some(false),
                    "binary_big_endian" => Some(true),
                    other => return Err(c.error(format!("unknown PLY format {other:?}"))),
                })
            }
            ["comment", ..] | ["obj_info", ..] | [] => {}
            ["element", name, count] => elements.push(Element {
                name: name.to_string(),
                count: count
                    .parse()
                    .map_err(|_| c.error(format!("bad element count {count:?}")))?,
                properties: Vec::new(),
            }),
            ["property", "list", count, item, _name] => {
                let (Some(count), Some(item)) = (scalar_type(count), scalar_type(item)) else {
                    return Err(c.error(format!("bad list property {line:?}")));
                };
                elements
                    .last_mut()
                    .ok_or_else(|| c.error("property before any element"))?
                    .properties
                    .push(Property::List { count, item });
            }
            ["property", ty, name] => {
                let ty = scalar_type(ty)
                    .ok_or_else(|| c.error(format!("unknown property type {ty:?}")))?;
                elements
                    .last_mut()
                    .ok_or_else(|| c.error("property before any element"))?
                    .properties
                    .push(Property::Scalar {
                        name: name.to_string(),
                        ty,
                    });
            }
            ["end_header"] => break,
            _ => return Err(c.error(format!("unexpected header line {line:?}"))),
        }
    }
    let binary = binary.ok_or_else(|| c.error("header has no format line"))?;
    let mut positions = Vec::new();
    let mut attributes: Vec<PointAttribute> = Vec::new();
    for element in &elements {
        let is_vertex = element.name == "vertex";
        let scalar_names: Vec<&str> = element
            .properties
            .iter()
            .filter_map(|p| match p {
                Property::Scalar { name, .. } => Some(name.as_str()),
                Property::List { .. } => None,
            })
            .collect();
        let all_scalar = scalar_names.len() == element.properties.len();
        if is_vertex {
            if !all_scalar {
                return Err(c.error("list properties in the vertex element are not supported"));
            }
            let axis = |n: &str| scalar_names.iter().position(|s| *s == n);
            let (Some(x), Some(y), Some(z)) = (axis("x"), axis("y"), axis("z")) else {
                return Err(c.error("the vertex element has no x, y, z properties"));
            };
            let width = element.properties.len();
            let mut columns: Vec<Vec<f32>> = vec![Vec::with_capacity(element.count); width];
            // Rows: decode property by property (mixed types).
            for _ in 0..element.count {
                for (k, p) in element.properties.iter().enumerate() {
                    let Property::Scalar { ty, .. } = p else {
                        unreachable!()
                    };
                    columns[k].push(c.value(*ty, binary)?);
                }
            }
            positions = (0..element.count)
                .map(|i| Vec3::new(columns[x][i], columns[y][i], columns[z][i]))
                .collect();
            attributes = group_attributes(&scalar_names, columns, [x, y, z]);
        } else {
            for _ in 0..element.count {
                for p in &element.properties {
                    match p {
                        Property::Scalar { ty, .. } => c.skip_values(1, *ty, binary)?,
                        Property::List { count, item } => {
                            let n = c.value(*count, binary)?;
                            if n.is_nan() || n < 0.0 {
                                return Err(c.error(format!("negative list length {n}")));
                            }
                            c.skip_values(n as usize, *item, binary)?;
                        }
                    }
                }
            }
        }
    }
    Ok(Particles {
        positions,
        attributes,
    })
}

/// Turns the non-position columns into attributes, grouping velocity components.
fn group_attributes(
    names: &[&str],
    mut columns: Vec<Vec<f32>>,
    xyz: [usize; 3],
) -> Vec<PointAttribute> {
    let mut used = vec![false; names.len()];
    for k in xyz {
        used[k] = true;
    }
    let mut out = Vec::new();
    for triple in [
        ["vx", "vy", "vz"],
        ["velocity_x", "velocity_y", "velocity_z"],
    ] {
        let idx: Vec<Option<usize>> = triple
            .iter()
            .map(|t| names.iter().position(|n| n == t))
            .collect();
        if let [Some(a), Some(b), Some(c)] = idx[..] {
            let mut values = Vec::with_capacity(3 * columns[a].len());
            for ((x, y), z) in columns[a].iter().zip(&columns[b]).zip(&columns[c]) {
                values.extend([*x, *y, *z]);
            }
            used[a] = true;
            used[b] = true;
            used[c] = true;
            out.push(PointAttribute {
                name: "velocity".into(),
                components: 3,
                values,
            });
        }
    }
    for (k, name) in names.iter().enumerate() {
        if !used[k] {
            out.push(PointAttribute {
                name: name.to_string(),
                components: 1,
                values: std::mem::take(&mut columns[k]),
            });
        }
    }
    out
}

pub(super) fn write(path: &Path, particles: &Particles) -> Result<()> {
    let n = particles.positions.len();
    write_atomically(path, |w| {
        write!(w, "ply\nformat binary_little_endian 1.0\ncomment meniscus particles\nelement vertex {n}\nproperty float x\nproperty float y\nproperty float z\n")?;
        for a in &particles.attributes {
            if a.name == "velocity" && a.components == 3 {
                writeln!(w, "property float vx\nproperty float vy\nproperty float vz")?;
            } else if a.components == 1 {
                writeln!(w, "property float {}", a.name)?;
            } else {
                for k in 0..a.components {
                    writeln!(w, "property float {}_{k}", a.name)?;
                }
            }
        }
        writeln!(w, "end_header")?;
        for (i, p) in particles.positions.iter().enumerate() {
            for v in p.to_array() {
                w.write_all(&v.to_le_bytes())?;
            }
            for a in &particles.attributes {
                for v in &a.values[i * a.components..(i + 1) * a.components] {
                    w.write_all(&v.to_le_bytes())?;
                }
            }
        }
        Ok(())
    })
    .map(|_| ())
}
