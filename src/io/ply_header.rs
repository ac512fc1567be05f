//! The PLY header, shared by the particle and the mesh readers: format line, elements and
//! their scalar or list properties, up to `end_header`.

use crate::error::{Error, Result};
use crate::io::text::{Cursor, Scalar};

/// One property of an element.
pub(crate) struct PlyProperty {
    pub name: String,
    /// The value type (the item type of a list).
    pub scalar: Scalar,
    /// For a list property, the type of its length prefix.
    pub list_count: Option<Scalar>,
}

/// One element: name, count and properties in file order.
pub(crate) struct PlyElement {
    pub name: String,
    pub count: usize,
    pub properties: Vec<PlyProperty>,
}

impl PlyElement {
    /// Index of the property called `name`.
    pub fn find(&self, name: &str) -> Option<usize> {
        self.properties.iter().position(|p| p.name == name)
    }
}

/// A parsed header; the cursor is left at the first data byte.
pub(crate) struct PlyHeader {
    /// `None` for ASCII, `Some(big_endian)` for binary.
    pub binary: Option<bool>,
    pub elements: Vec<PlyElement>,
}

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

/// Parses the header at the start of `c`.
pub(crate) fn parse(c: &mut Cursor) -> Result<PlyHeader> {
    if c.line()?.trim() != "ply" {
        return Err(Error::parse(
            c.path,
            "line 1",
            "not a PLY file: the first line must be \"ply\"",
        ));
    }
    let mut binary = None;
    let mut elements: Vec<PlyElement> = Vec::new();
    loop {
        if c.pos >= c.bytes.len() {
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
            ["element", name, count] => elements.push(PlyElement {
                name: name.to_string(),
                count: count
                    .parse()
                    .map_err(|_| c.error(format!("bad element count {count:?}")))?,
                properties: Vec::new(),
            }),
            ["property", "list", count, item, name] => {
                let (Some(count), Some(item)) = (scalar_type(count), scalar_type(item)) else {
                    return Err(c.error(format!("bad list property {line:?}")));
                };
                let element = elements
                    .last_mut()
                    .ok_or_else(|| c.error("property before any element"))?;
                element.properties.push(PlyProperty {
                    name: name.to_string(),
                    scalar: item,
                    list_count: Some(count),
                });
            }
            ["property", ty, name] => {
                let scalar = scalar_type(ty)
                    .ok_or_else(|| c.error(format!("unknown property type {ty:?}")))?;
                let element = elements
                    .last_mut()
                    .ok_or_else(|| c.error("property before any element"))?;
                element.properties.push(PlyProperty {
                    name: name.to_string(),
                    scalar,
                    list_count: None,
                });
            }
            ["end_header"] => break,
            _ => return Err(c.error(format!("unexpected header line {line:?}"))),
        }
    }
    let binary = binary.ok_or_else(|| c.error("header has no format line"))?;
    Ok(PlyHeader { binary, elements })
}

/// Skips one element instance (all its properties, lists included).
pub(crate) fn skip_row(c: &mut Cursor, element: &PlyElement, binary: Option<bool>) -> Result<()> {
    for p in &element.properties {
        match p.list_count {
            None => c.skip_values(1, p.scalar, binary)?,
            Some(count) => {
                let n = c.value(count, binary)?;
                if n.is_nan() || n < 0.0 {
                    return Err(c.error(format!("negative list length {n}")));
                }
                c.skip_values(n as usize, p.scalar, binary)?;
            }
        }
    }
    Ok(())
}

/// Checks, before anything is reserved or looped over, that the elements' counts fit in the
/// bytes after the header (`c` at the first data byte): every binary row takes at least
/// the sizes of its scalars and list-length prefixes, every ASCII value at least one byte.
/// An element without properties may not claim more rows than there are bytes left.
pub(crate) fn check_counts(c: &Cursor, header: &PlyHeader) -> Result<()> {
    check_counts_within(c.path, header, c.bytes.len().saturating_sub(c.pos))
}

/// [`check_counts`] for a file whose `left` bytes after the header are not in memory (a
/// streamed file: its length less the header's).
pub(crate) fn check_counts_within(
    path: &std::path::Path,
    header: &PlyHeader,
    left: usize,
) -> Result<()> {
    let mut need: usize = 0;
    for element in &header.elements {
        let row: usize = match header.binary {
            Some(_) => element
                .properties
                .iter()
                .map(|p| p.list_count.unwrap_or(p.scalar).size())
                .sum(),
            None => element.properties.len(),
        };
        let bytes = if row == 0 {
            (element.count > left).then_some(usize::MAX)
        } else {
            element.count.checked_mul(row)
        };
        need = bytes.and_then(|b| need.checked_add(b)).ok_or_else(|| {
            Error::parse(
                path,
                "header",
                format!(
                    "element {:?} claims {} rows, more than the {left} bytes after the header can hold",
                    element.name, element.count
                ),
            )
        })?;
        if need > left {
            return Err(Error::parse(
                path,
                "header",
                format!(
                    "truncated: element {:?} claims {} rows of at least {row} bytes each, but only {left} bytes follow the header",
                    element.name, element.count
                ),
            ));
        }
    }
    Ok(())
}
