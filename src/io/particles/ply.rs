//! PLY point clouds: `format ascii | binary_little_endian | binary_big_endian 1.0`, the
//! `vertex` element's x, y, z (any scalar type) as positions and every other scalar vertex
//! property as a 1-component attribute (`vx, vy, vz` or `velocity_x/y/z` become one
//! 3-component `velocity`). Other elements are skipped, list properties included.

use super::records::{open_buffered, stream_ascii_records, stream_records};
use super::records::{AsciiRecords, Records};
use super::{read_bytes, Attribute, ParticleCodec, Particles, StreamSink};
use crate::attributes::AttributeLayout;
use crate::error::{Error, Result};
use crate::io::atomic::write_atomically;
use crate::io::ply_header::{self, PlyElement, PlyHeader};
use crate::io::text::Cursor;
use glam::Vec3;
use std::io::{BufRead, Write};
use std::path::Path;

/// The PLY format.
pub(super) struct Ply;

impl ParticleCodec for Ply {
    fn read(&self, path: &Path) -> Result<Particles> {
        read(path, &read_bytes(path)?)
    }

    /// Streams a file (binary or ASCII) whose first element is `vertex` with scalar
    /// properties only; the rows of later elements are walked and checked as the
    /// whole-file reader does. `Ok(None)` for any other layout (another element first, a
    /// second vertex element, a list property, an unreadable header).
    fn stream(&self, path: &Path, sink: &mut dyn StreamSink) -> Result<Option<usize>> {
        stream(path, sink)
    }

    fn write(&self, path: &Path, particles: &Particles) -> Result<()> {
        write(path, particles)
    }
}

/// Reads a whole PLY file held in memory.
fn read(path: &Path, bytes: &[u8]) -> Result<Particles> {
    let mut c = Cursor::new(path, bytes);
    let header = ply_header::parse(&mut c)?;
    ply_header::check_counts(&c, &header)?;
    let binary = header.binary;
    let mut positions = Vec::new();
    let mut attributes: Vec<Attribute> = Vec::new();
    for element in &header.elements {
        if element.name != "vertex" {
            for _ in 0..element.count {
                ply_header::skip_row(&mut c, element, binary)?;
            }
            continue;
        }
        if element.properties.iter().any(|p| p.list_count.is_some()) {
            return Err(c.error("list properties in the vertex element are not supported"));
        }
        let (Some(x), Some(y), Some(z)) = (element.find("x"), element.find("y"), element.find("z"))
        else {
            return Err(c.error("the vertex element has no x, y, z properties"));
        };
        let mut columns: Vec<Vec<f32>> =
            vec![Vec::with_capacity(element.count); element.properties.len()];
        for _ in 0..element.count {
            for (column, p) in columns.iter_mut().zip(&element.properties) {
                column.push(c.value(p.scalar, binary)?);
            }
        }
        positions = (0..element.count)
            .map(|i| Vec3::new(columns[x][i], columns[y][i], columns[z][i]))
            .collect();
        let names: Vec<&str> = element.properties.iter().map(|p| p.name.as_str()).collect();
        attributes = group_attributes(&names, columns, [x, y, z]);
    }
    Ok(Particles {
        positions,
        attributes,
    })
}

/// The attributes of a vertex element with property `names` and positions in the columns
/// `xyz`: name and columns of each, in the order the readers give them (`vx, vy, vz` and
/// `velocity_x/y/z` grouped into one 3-component `velocity` first, then every other
/// property as a scalar, in file order).
fn attribute_columns(names: &[&str], xyz: [usize; 3]) -> Vec<(String, Vec<usize>)> {
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
            used[a] = true;
            used[b] = true;
            used[c] = true;
            out.push(("velocity".to_string(), vec![a, b, c]));
        }
    }
    for (k, name) in names.iter().enumerate() {
        if !used[k] {
            out.push((name.to_string(), vec![k]));
        }
    }
    out
}

/// Turns the non-position columns into attributes, grouping velocity components.
fn group_attributes(names: &[&str], mut columns: Vec<Vec<f32>>, xyz: [usize; 3]) -> Vec<Attribute> {
    attribute_columns(names, xyz)
        .into_iter()
        .map(|(name, ks)| match ks[..] {
            [k] => Attribute {
                name,
                components: 1,
                values: std::mem::take(&mut columns[k]),
            },
            _ => {
                let items = columns[ks[0]].len();
                let mut values = Vec::with_capacity(ks.len() * items);
                values.extend(
                    (0..items)
                        .flat_map(|i| ks.iter().map(move |&k| (k, i)))
                        .map(|(k, i)| columns[k][i]),
                );
                Attribute {
                    name,
                    components: ks.len(),
                    values,
                }
            }
        })
        .collect()
}

/// Writes binary little-endian PLY: `x y z`, then every attribute as float properties
/// (`vx vy vz` for a 3-component `velocity`).
fn write(path: &Path, particles: &Particles) -> Result<()> {
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

/// [`Ply`]'s streaming reader: once the header is read, [`StreamSink::select`] picks
/// among the vertex attributes (named and grouped as the whole-file reader does); their
/// payload rows go to `sink` with the positions. Returns the count, or `Ok(None)` for a
/// layout that does not stream.
fn stream(path: &Path, sink: &mut dyn StreamSink) -> Result<Option<usize>> {
    let mut r = open_buffered(path)?;
    let Some((header_len, header_lines, h)) = read_header(path, &mut r)? else {
        return Ok(None);
    };
    let Some(element) = h.elements.first().filter(|e| e.name == "vertex") else {
        return Ok(None);
    };
    // The whole-file reader keeps the last vertex element.
    if h.elements[1..].iter().any(|e| e.name == "vertex") {
        return Ok(None);
    }
    // The counts must fit in the file before anything is spooled (or room sought) for them.
    let file_bytes = std::fs::metadata(path)
        .map_err(|e| Error::io(path, e))?
        .len();
    let left = usize::try_from(file_bytes.saturating_sub(header_len as u64)).unwrap_or(usize::MAX);
    ply_header::check_counts_within(path, &h, left)?;
    if element.properties.iter().any(|p| p.list_count.is_some()) {
        return Ok(None);
    }
    let (Some(x), Some(y), Some(z)) = (element.find("x"), element.find("y"), element.find("z"))
    else {
        return Ok(None);
    };
    let names: Vec<&str> = element.properties.iter().map(|p| p.name.as_str()).collect();
    let declared = attribute_columns(&names, [x, y, z]);
    let layouts: Vec<AttributeLayout> = declared
        .iter()
        .map(|(name, ks)| AttributeLayout {
            name: name.clone(),
            components: ks.len(),
        })
        .collect();
    let chosen = sink.select(element.count, &layouts)?;
    // The property columns of the payload row, in order.
    let columns: Vec<usize> = chosen
        .iter()
        .flat_map(|&k| declared[k].1.iter().copied())
        .collect();
    match h.binary {
        None => stream_ascii_records(
            path,
            &mut r,
            AsciiRecords {
                line: header_lines + 1,
                count: element.count,
                fields: element.properties.len(),
                xyz: Some([x, y, z]),
                payload: &columns,
                one: "vertex",
                many: "vertices",
            },
            &mut |chunk, rows| sink.records(chunk, rows),
        )?,
        Some(big_endian) => {
            let vertices = Vertices {
                element,
                offset: header_len as u64,
                big_endian,
                xyz: [x, y, z],
                columns: &columns,
            };
            vertices.stream(path, &mut r, sink)?
        }
    }
    check_tail(path, header_len, &h)?;
    Ok(Some(element.count))
}

/// Walks the rows of the elements after the vertex element (of `h`, whose header takes
/// `header_len` bytes) as the whole-file reader does (`ply_header::skip_row`: list lengths
/// read and checked, values skipped), so that the stream refuses what that reader refuses.
/// One more pass over the file when there are such elements; memory: one buffer.
fn check_tail(path: &Path, header_len: usize, h: &PlyHeader) -> Result<()> {
    use std::io::Read;
    if h.elements.len() == 1 {
        return Ok(());
    }
    let mut r = open_buffered(path)?;
    let fail = |message: String| Error::parse(path, "after the vertices", message);
    let io = |e: std::io::Error| Error::io(path, e);
    match h.binary {
        Some(big_endian) => {
            let vertex = &h.elements[0];
            let stride: u64 = vertex
                .properties
                .iter()
                .map(|p| p.scalar.size() as u64)
                .sum();
            let len = std::fs::metadata(path).map_err(io)?.len();
            let mut pos =
                (header_len as u64).saturating_add(stride.saturating_mul(vertex.count as u64));
            let skip = |r: &mut std::io::BufReader<std::fs::File>, pos: &mut u64, n: u64| {
                if len.saturating_sub(*pos) < n {
                    return Err(fail(format!(
                        "truncated: {n} bytes needed, {} left",
                        len.saturating_sub(*pos)
                    )));
                }
                r.seek_relative(n as i64).map_err(io)?;
                *pos += n;
                Ok(())
            };
            std::io::Seek::seek(&mut r, std::io::SeekFrom::Start(pos)).map_err(io)?;
            let mut word = [0u8; 8];
            for element in &h.elements[1..] {
                for _ in 0..element.count {
                    for p in &element.properties {
                        let Some(count) = p.list_count else {
                            skip(&mut r, &mut pos, p.scalar.size() as u64)?;
                            continue;
                        };
                        let size = count.size();
                        if len.saturating_sub(pos) < size as u64 {
                            return Err(fail(format!(
                                "truncated: a {size}-byte list length, {} bytes left",
                                len.saturating_sub(pos)
                            )));
                        }
                        r.read_exact(&mut word[..size]).map_err(io)?;
                        pos += size as u64;
                        // As `Cursor::value` reads it: a float.
                        let n = count.decode(&word[..size], big_endian) as f32;
                        if n.is_nan() || n < 0.0 {
                            return Err(fail(format!("negative list length {n}")));
                        }
                        let bytes = (n as u64)
                            .checked_mul(p.scalar.size() as u64)
                            .ok_or_else(|| fail("value count overflows".into()))?;
                        skip(&mut r, &mut pos, bytes)?;
                    }
                }
            }
        }
        None => {
            r.seek_relative(header_len as i64).map_err(io)?;
            let mut token = Vec::new();
            // The next whitespace-separated token (text), as `Cursor::token` reads it.
            let mut next = |r: &mut std::io::BufReader<std::fs::File>| -> Result<String> {
                token.clear();
                loop {
                    let buf = r.fill_buf().map_err(io)?;
                    let Some(&b) = buf.first() else { break };
                    if b.is_ascii_whitespace() {
                        r.consume(1);
                        if token.is_empty() {
                            continue;
                        }
                        break;
                    }
                    token.push(b);
                    r.consume(1);
                }
                if token.is_empty() {
                    return Err(fail("unexpected end of file, expected a value".into()));
                }
                String::from_utf8(token.clone())
                    .map_err(|_| fail("expected a value, found non-text bytes".into()))
            };
            let vertex = &h.elements[0];
            for _ in 0..vertex.count.saturating_mul(vertex.properties.len()) {
                next(&mut r)?;
            }
            for element in &h.elements[1..] {
                for _ in 0..element.count {
                    for p in &element.properties {
                        let n = match p.list_count {
                            None => 1.0,
                            Some(_) => {
                                let t = next(&mut r)?;
                                let n = t
                                    .parse::<f64>()
                                    .map_err(|_| fail(format!("expected a number, found {t:?}")))?
                                    as f32;
                                if n.is_nan() || n < 0.0 {
                                    return Err(fail(format!("negative list length {n}")));
                                }
                                n
                            }
                        };
                        for _ in 0..n as u64 {
                            next(&mut r)?;
                        }
                    }
                }
            }
        }
    }
    Ok(())
}

/// Reads the header (at most 64 KiB, up to `end_header`) from `r`; returns its length in
/// bytes and lines, and the parsed header, or `None` when there is no readable one.
fn read_header(path: &Path, r: &mut impl BufRead) -> Result<Option<(usize, usize, PlyHeader)>> {
    let mut header = Vec::new();
    loop {
        let n = r
            .read_until(b'\n', &mut header)
            .map_err(|e| Error::io(path, e))?;
        if n == 0 || header.len() > 1 << 16 {
            return Ok(None);
        }
        if header.ends_with(b"end_header\n") {
            break;
        }
    }
    let mut c = Cursor::new(path, &header);
    let Ok(h) = ply_header::parse(&mut c) else {
        return Ok(None);
    };
    let lines = header.iter().filter(|&&b| b == b'\n').count();
    Ok(Some((header.len(), lines, h)))
}

/// The binary vertex records of a streaming read.
struct Vertices<'a> {
    element: &'a PlyElement,
    /// Byte offset of the first record.
    offset: u64,
    big_endian: bool,
    /// The properties holding x, y, z.
    xyz: [usize; 3],
    /// The properties of the payload row, in order.
    columns: &'a [usize],
}

impl Vertices<'_> {
    /// Streams the records from `r` (at the first one) to `sink`.
    fn stream(
        &self,
        path: &Path,
        r: &mut impl std::io::Read,
        sink: &mut dyn StreamSink,
    ) -> Result<()> {
        let properties = &self.element.properties;
        let mut offsets = Vec::with_capacity(properties.len());
        let mut stride = 0;
        for p in properties {
            offsets.push(stride);
            stride += p.scalar.size();
        }
        let field = |rec: &[u8], k: usize| -> f32 {
            let p = &properties[k];
            p.scalar.decode(
                &rec[offsets[k]..offsets[k] + p.scalar.size()],
                self.big_endian,
            ) as f32
        };
        let [x, y, z] = self.xyz;
        stream_records(
            path,
            r,
            Records {
                offset: self.offset,
                count: self.element.count,
                stride,
                one: "vertex",
                many: "vertices",
            },
            &|record, payload| {
                payload.extend(self.columns.iter().map(|&k| field(record, k)));
                Some(Vec3::new(
                    field(record, x),
                    field(record, y),
                    field(record, z),
                ))
            },
            &mut |chunk, rows| sink.records(chunk, rows),
        )
    }
}
