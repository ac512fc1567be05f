//! Legacy VTK (`# vtk DataFile Version x.y`): ASCII or BINARY (big-endian), any dataset
//! whose points come in a `POINTS n type` section. Cell sections are skipped;
//! `POINT_DATA` SCALARS, VECTORS, NORMALS and FIELD arrays become attributes.

use super::{Attribute, Particles};
use crate::error::{Error, Result};
use crate::io::atomic::write_atomically;
use crate::io::text::{Cursor, Scalar};
use glam::Vec3;
use std::io::Write;
use std::path::Path;

fn scalar_type(name: &str) -> Option<Scalar> {
    Some(match name.to_ascii_lowercase().as_str() {
        "bit" => return None,
        "char" => Scalar::I8,
        "unsigned_char" => Scalar::U8,
        "short" => Scalar::I16,
        "unsigned_short" => Scalar::U16,
        "int" | "vtkidtype" => Scalar::I32,
        "unsigned_int" => Scalar::U32,
        "long" | "vtktypeint64" => Scalar::I64,
        "unsigned_long" | "vtktypeuint64" => Scalar::U64,
        "float" => Scalar::F32,
        "double" => Scalar::F64,
        _ => return None,
    })
}

pub(super) fn read(path: &Path, bytes: &[u8]) -> Result<Particles> {
    let mut c = Cursor::new(path, bytes);
    let version = c.line()?;
    if !version.starts_with("# vtk DataFile Version") {
        return Err(Error::parse(
            path,
            "line 1",
            format!("not a legacy VTK file: first line is {version:?}"),
        ));
    }
    let new_cells = version
        .rsplit(' ')
        .next()
        .and_then(|v| v.parse::<f32>().ok())
        .is_some_and(|v| v >= 5.0);
    c.line()?; // title
    let encoding = c.line()?.trim().to_ascii_uppercase();
    let binary = match encoding.as_str() {
        "BINARY" => Some(true),
        "ASCII" => None,
        other => return Err(c.error(format!("expected ASCII or BINARY, found {other:?}"))),
    };
    let mut positions: Option<Vec<Vec3>> = None;
    let mut attributes = Vec::new();
    let mut point_data = false;
    let mut npoints = 0usize;
    while !c.at_end() {
        let keyword = c.token("a section keyword")?.to_ascii_uppercase();
        match keyword.as_str() {
            "DATASET" => {
                c.token("a dataset type")?;
            }
            "POINTS" => {
                let n: usize = c.number("the point count")?;
                let ty = c.token("the point type")?;
                let scalar = scalar_type(ty)
                    .ok_or_else(|| c.error(format!("unsupported point type {ty:?}")))?;
                if binary.is_some() {
                    c.finish_line();
                }
                let v = c.values(n * 3, scalar, binary)?;
                npoints = n;
                positions = Some(
                    v.chunks_exact(3)
                        .map(|p| Vec3::new(p[0], p[1], p[2]))
                        .collect(),
                );
            }
            "VERTICES" | "LINES" | "POLYGONS" | "TRIANGLE_STRIPS" | "CELLS" => {
                let _n: usize = c.number("the cell count")?;
                let size: usize = c.number("the cell list size")?;
                if new_cells {
                    for _ in 0..2 {
                        let part = c.token("OFFSETS or CONNECTIVITY")?;
                        let ty = c.token("an index type")?;
                        let scalar = scalar_type(ty)
                            .ok_or_else(|| c.error(format!("unsupported {part} type {ty:?}")))?;
                        if binary.is_some() {
                            c.finish_line();
                        }
                        let count = if part.eq_ignore_ascii_case("OFFSETS") {
                            _n
                        } else {
                            size
                        };
                        c.skip_values(count, scalar, binary)?;
                    }
                } else {
                    if binary.is_some() {
                        c.finish_line();
                    }
                    c.skip_values(size, Scalar::I32, binary)?;
                }
            }
            "CELL_TYPES" => {
                let n: usize = c.number("the cell count")?;
                if binary.is_some() {
                    c.finish_line();
                }
                c.skip_values(n, Scalar::I32, binary)?;
            }
            "POINT_DATA" => {
                let n: usize = c.number("the point count")?;
                if n != npoints {
                    return Err(c.error(format!("POINT_DATA has {n} values, POINTS has {npoints}")));
                }
                point_data = true;
            }
            "CELL_DATA" => {
                let _n: usize = c.number("the cell count")?;
                point_data = false;
            }
            "SCALARS"
            | "VECTORS"
            | "NORMALS"
            | "TENSORS"
            | "COLOR_SCALARS"
            | "TEXTURE_COORDINATES" => {
                let name = c.token("an attribute name")?.to_string();
                let (components, scalar) = match keyword.as_str() {
                    "SCALARS" => {
                        let ty = c.token("a scalar type")?;
                        let scalar = scalar_type(ty)
                            .ok_or_else(|| c.error(format!("unsupported type {ty:?}")))?;
                        let rest = c.line()?.trim().to_string();
                        let comps = if rest.is_empty() {
                            1
                        } else {
                            rest.parse()
                                .map_err(|_| c.error(format!("bad component count {rest:?}")))?
                        };
                        let table = c.token("LOOKUP_TABLE")?;
                        if !table.eq_ignore_ascii_case("LOOKUP_TABLE") {
                            return Err(c.error(format!(
                                "expected LOOKUP_TABLE after SCALARS, found {table:?}"
                            )));
                        }
                        c.token("a lookup table name")?;
                        (comps, scalar)
                    }
                    "VECTORS" | "NORMALS" => {
                        let ty = c.token("a vector type")?;
                        (
                            3,
                            scalar_type(ty)
                                .ok_or_else(|| c.error(format!("unsupported type {ty:?}")))?,
                        )
                    }
                    "TENSORS" => {
                        let ty = c.token("a tensor type")?;
                        (
                            9,
                            scalar_type(ty)
                                .ok_or_else(|| c.error(format!("unsupported type {ty:?}")))?,
                        )
                    }
                    "COLOR_SCALARS" => (c.number("a component count")?, Scalar::U8),
                    _ => {
                        let d: usize = c.number("a dimension")?;
                        let ty = c.token("a type")?;
                        (
                            d,
                            scalar_type(ty)
                                .ok_or_else(|| c.error(format!("unsupported type {ty:?}")))?,
                        )
                    }
                };
                if binary.is_some() {
                    c.finish_line();
                }
                if point_data {
                    let values = c.values(npoints * components, scalar, binary)?;
                    attributes.push(Attribute {
                        name,
                        components,
                        values,
                    });
                } else {
                    return Err(c.error("CELL_DATA arrays are not supported in particle files"));
                }
            }
            "FIELD" => {
                c.token("a field name")?;
                let arrays: usize = c.number("the array count")?;
                for _ in 0..arrays {
                    let name = c.token("an array name")?.to_string();
                    let components: usize = c.number("a component count")?;
                    let tuples: usize = c.number("a tuple count")?;
                    let ty = c.token("an array type")?;
                    let scalar = scalar_type(ty)
                        .ok_or_else(|| c.error(format!("unsupported type {ty:?}")))?;
                    if binary.is_some() {
                        c.finish_line();
                    }
                    let values = c.values(components * tuples, scalar, binary)?;
                    if point_data && tuples == npoints {
                        attributes.push(Attribute {
                            name,
                            components,
                            values,
                        });
                    }
                }
            }
            "METADATA" => {
                // Skip to the blank line that ends the metadata block.
                loop {
                    if c.pos >= c.bytes.len() || c.line()?.trim().is_empty() {
                        break;
                    }
                }
            }
            other => return Err(c.error(format!("unknown section {other:?}"))),
        }
    }
    let positions = positions.ok_or_else(|| Error::parse(path, "header", "no POINTS section"))?;
    Ok(Particles {
        positions,
        attributes,
    })
}

pub(super) fn write(path: &Path, particles: &Particles) -> Result<()> {
    let n = particles.positions.len();
    write_atomically(path, |w| {
        write!(w, "# vtk DataFile Version 4.2\nmeniscus particles\nBINARY\nDATASET POLYDATA\nPOINTS {n} float\n")?;
        for p in &particles.positions {
            for v in p.to_array() {
                w.write_all(&v.to_be_bytes())?;
            }
        }
        write!(w, "\nVERTICES {n} {}\n", 2 * n)?;
        for i in 0..n as i32 {
            w.write_all(&1i32.to_be_bytes())?;
            w.write_all(&i.to_be_bytes())?;
        }
        w.write_all(b"\n")?;
        if !particles.attributes.is_empty() {
            writeln!(w, "POINT_DATA {n}")?;
            for a in &particles.attributes {
                let name: String = a.name.chars().map(|ch| if ch.is_whitespace() { '_' } else { ch }).collect();
                if a.components == 3 {
                    writeln!(w, "VECTORS {name} float")?;
                } else {
                    writeln!(w, "SCALARS {name} float {}\nLOOKUP_TABLE default", a.components)?;
                }
                for v in &a.values {
                    w.write_all(&v.to_be_bytes())?;
                }
                w.write_all(b"\n")?;
            }
        }
        Ok(())
    })
    .map(|_| ())
}

/// Streams the positions of a legacy VTK file (BINARY or ASCII) whose first data section
/// is `POINTS n float|double` (what SPlisHSPlasH and DualSPHysics write) from disk in
/// chunks of at most 65 536 particles; the rest of the file is not read. Returns
/// `Ok(None)` for any other layout (another section first, another point type), which the
/// whole-file reader handles and reports on. Memory: one chunk (and, for ASCII, one line),
/// whatever the file size.
pub fn stream_positions(
    path: &Path,
    positions: &mut dyn FnMut(&[Vec3]) -> Result<()>,
) -> Result<Option<usize>> {
    use std::io::BufRead;
    let mut r = super::open_buffered(path)?;
    let mut offset = 0u64;
    let mut line = Vec::new();
    let mut next_line =
        |r: &mut std::io::BufReader<std::fs::File>, offset: &mut u64| -> Result<Option<String>> {
            line.clear();
            let n = r
                .read_until(b'\n', &mut line)
                .map_err(|e| Error::io(path, e))?;
            *offset += n as u64;
            if n == 0 || line.len() > 4096 {
                return Ok(None);
            }
            Ok(Some(String::from_utf8_lossy(&line).trim().to_string()))
        };
    let header_ok = matches!(next_line(&mut r, &mut offset)?, Some(l) if l.starts_with("# vtk DataFile Version"));
    let _title = next_line(&mut r, &mut offset)?;
    let encoding = next_line(&mut r, &mut offset)?;
    let binary = matches!(&encoding, Some(l) if l.eq_ignore_ascii_case("BINARY"));
    let ascii = matches!(&encoding, Some(l) if l.eq_ignore_ascii_case("ASCII"));
    if !(header_ok && (binary || ascii)) {
        return Ok(None);
    }
    let mut lines_read = 3;
    let (count, double) = loop {
        let Some(l) = next_line(&mut r, &mut offset)? else {
            return Ok(None);
        };
        lines_read += 1;
        let tokens: Vec<&str> = l.split_whitespace().collect();
        match tokens.as_slice() {
            [] => continue,
            [k, _] if k.eq_ignore_ascii_case("DATASET") => continue,
            [k, n, ty] if k.eq_ignore_ascii_case("POINTS") => {
                let Ok(n) = n.parse::<usize>() else {
                    return Ok(None);
                };
                match ty.to_ascii_lowercase().as_str() {
                    "float" => break (n, false),
                    "double" => break (n, true),
                    _ => return Ok(None),
                }
            }
            _ => return Ok(None),
        }
    };
    if ascii {
        super::stream_ascii_records(
            path,
            &mut r,
            super::AsciiRecords {
                line: lines_read + 1,
                count,
                fields: 3,
                xyz: [0, 1, 2],
                one: "particle",
                many: "points",
            },
            positions,
        )?;
        return Ok(Some(count));
    }
    let size = if double { 24 } else { 12 };
    let coordinate = |record: &[u8], i: usize| -> f32 {
        if double {
            f64::from_be_bytes(record[8 * i..8 * i + 8].try_into().expect("8 bytes")) as f32
        } else {
            f32::from_be_bytes(record[4 * i..4 * i + 4].try_into().expect("4 bytes"))
        }
    };
    super::stream_records(
        path,
        &mut r,
        super::Records {
            offset,
            count,
            stride: size,
            one: "particle",
            many: "points",
        },
        &|record| {
            Vec3::new(
                coordinate(record, 0),
                coordinate(record, 1),
                coordinate(record, 2),
            )
        },
        positions,
    )?;
    Ok(Some(count))
}
