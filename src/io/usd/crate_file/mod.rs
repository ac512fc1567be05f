//! The encoder of USD's binary crate format (`.usdc`, version 0.8.0): values go to the
//! file as they come, the structural tables at the end.
//!
//! A crate file is an 88-byte bootstrap (`PXR-USDC`, the version, the offset of the table
//! of contents), the values, then six sections — TOKENS, STRINGS, FIELDS, FIELDSETS,
//! PATHS, SPECS — and the table of contents naming them. A spec is a path, a spec type
//! and a field set (a run of field indices ended by `u32::MAX`); a field is a token (its
//! name) and a [`ValueRep`]: 8 bytes holding the value's type, array/inlined/compressed
//! bits and either the value itself (tokens, enums, bools) or the file offset of its
//! bytes. Nothing in the tables needs a value's bytes, so a writer can stream arrays
//! (points, indices) to the file one frame at a time and keep only their offsets; a time
//! series is a small record pointing at one shared array of times and at the offsets of
//! its samples. [`coding`](super::coding) holds the two compressions the tables and int
//! arrays use.

use super::coding;
use std::collections::HashMap;
use std::io::{self, Seek, SeekFrom, Write};

/// Crate format version written: 0.8.0 (compressed tables and int arrays, 64-bit array
/// sizes), which every USD since 20.x reads.
const VERSION: [u8; 3] = [0, 8, 0];

/// Bytes of the bootstrap at the start of the file.
const BOOTSTRAP_BYTES: u64 = 88;

/// Int arrays shorter than this are stored as they are (the readers' own threshold).
const MIN_COMPRESSED_ARRAY: usize = 16;

/// Marker ending a field set.
const END_OF_FIELD_SET: u32 = u32::MAX;

/// Value types of the crate format (the subset this writer emits), numbered as the format
/// numbers them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub(crate) enum Type {
    /// `bool`.
    Bool = 1,
    /// `int`.
    Int = 3,
    /// `float`.
    Float = 8,
    /// `double`.
    Double = 9,
    /// `string` (an index into the STRINGS table).
    String = 10,
    /// `token` (an index into the TOKENS table).
    Token = 11,
    /// `float2` (GfVec2f).
    Vec2f = 20,
    /// `float3`, `point3f`, `normal3f`, `vector3f` (GfVec3f).
    Vec3f = 24,
    /// `float4` (GfVec4f).
    Vec4f = 28,
    /// A list of paths (relationship targets).
    PathListOp = 34,
    /// A list of tokens as Sdf stores children names (`std::vector<TfToken>`).
    TokenVector = 41,
    /// `def`, `over`, `class`.
    Specifier = 42,
    /// varying or uniform.
    Variability = 44,
    /// A time series.
    TimeSamples = 46,
    /// A list of doubles (the times of a series).
    DoubleVector = 48,
}

/// Spec types, numbered as Sdf numbers them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub(crate) enum SpecType {
    /// An attribute.
    Attribute = 1,
    /// A prim.
    Prim = 6,
    /// The layer itself (`/`), holding the layer metadata.
    PseudoRoot = 7,
    /// A relationship.
    Relationship = 8,
}

/// A value as a field holds it: type byte, flag bits and a 48-bit payload.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub(crate) struct ValueRep(pub(crate) u64);

impl ValueRep {
    const ARRAY: u64 = 1 << 63;
    const INLINED: u64 = 1 << 62;
    const COMPRESSED: u64 = 1 << 61;
    const PAYLOAD: u64 = (1 << 48) - 1;

    fn new(ty: Type, payload: u64) -> ValueRep {
        ValueRep(((ty as u64) << 48) | (payload & Self::PAYLOAD))
    }

    /// A value held in the rep itself (tokens and strings as table indices).
    pub(crate) fn inlined(ty: Type, payload: u32) -> ValueRep {
        ValueRep(Self::new(ty, payload as u64).0 | Self::INLINED)
    }

    /// An empty array of `ty` (stored in the rep: payload 0).
    pub(crate) fn empty_array(ty: Type) -> ValueRep {
        ValueRep(Self::new(ty, 0).0 | Self::ARRAY)
    }

    fn array_at(ty: Type, offset: u64) -> ValueRep {
        ValueRep(Self::new(ty, offset).0 | Self::ARRAY)
    }
}

/// An index into the path table.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub(crate) struct PathId(u32);

/// A path of the table: its last element (a token), whether that element is a property
/// (`.name`) rather than a prim (`/name`), and its children.
struct PathEntry {
    token: u32,
    property: bool,
    children: Vec<PathId>,
}

/// Strings interned in first-use order.
#[derive(Default)]
struct Interner {
    items: Vec<String>,
    index: HashMap<String, u32>,
}

impl Interner {
    fn intern(&mut self, s: &str) -> u32 {
        if let Some(&i) = self.index.get(s) {
            return i;
        }
        let i = self.items.len() as u32;
        self.items.push(s.to_string());
        self.index.insert(s.to_string(), i);
        i
    }
}

/// A crate file being written to `out`: values first (each call writes at the end and
/// returns its rep), then [`CrateWriter::finish`] writes the tables.
pub(crate) struct CrateWriter<W: Write + Seek> {
    out: W,
    pos: u64,
    tokens: Interner,
    /// The STRINGS table: token index of each string.
    strings: Vec<u32>,
    fields: Vec<(u32, ValueRep)>,
    field_index: HashMap<(u32, ValueRep), u32>,
    field_sets: Vec<u32>,
    paths: Vec<PathEntry>,
    specs: Vec<(PathId, u32, SpecType)>,
}

impl<W: Write + Seek> CrateWriter<W> {
    /// Starts a crate file at the current position of `out` (an empty file), leaving room
    /// for the bootstrap.
    pub(crate) fn new(mut out: W) -> io::Result<Self> {
        out.write_all(&[0u8; BOOTSTRAP_BYTES as usize])?;
        let mut writer = CrateWriter {
            out,
            pos: BOOTSTRAP_BYTES,
            tokens: Interner::default(),
            strings: Vec::new(),
            fields: Vec::new(),
            field_index: HashMap::new(),
            field_sets: Vec::new(),
            paths: Vec::new(),
            specs: Vec::new(),
        };
        let empty = writer.tokens.intern("");
        writer.paths.push(PathEntry {
            token: empty,
            property: false,
            children: Vec::new(),
        });
        Ok(writer)
    }

    fn write(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.out.write_all(bytes)?;
        self.pos += bytes.len() as u64;
        Ok(())
    }

    fn write_u64(&mut self, v: u64) -> io::Result<()> {
        self.write(&v.to_le_bytes())
    }

    /// Pads with zeros to a multiple of 8 bytes (arrays start aligned, as Pixar's writer
    /// aligns them, so readers can map them in place).
    fn align(&mut self) -> io::Result<()> {
        let pad = self.pos.next_multiple_of(8) - self.pos;
        self.write(&[0u8; 8][..pad as usize])
    }

    /// The root path `/`.
    pub(crate) fn root(&self) -> PathId {
        PathId(0)
    }

    /// The path `parent/name` (a prim) or `parent.name` (a property).
    pub(crate) fn child_path(&mut self, parent: PathId, name: &str, property: bool) -> PathId {
        let token = self.tokens.intern(name);
        let id = PathId(self.paths.len() as u32);
        self.paths.push(PathEntry {
            token,
            property,
            children: Vec::new(),
        });
        self.paths[parent.0 as usize].children.push(id);
        id
    }

    /// A token value.
    pub(crate) fn token(&mut self, s: &str) -> ValueRep {
        ValueRep::inlined(Type::Token, self.tokens.intern(s))
    }

    /// A string value.
    pub(crate) fn string(&mut self, s: &str) -> ValueRep {
        let token = self.tokens.intern(s);
        let index = match self.strings.iter().position(|&t| t == token) {
            Some(i) => i,
            None => {
                self.strings.push(token);
                self.strings.len() - 1
            }
        };
        ValueRep::inlined(Type::String, index as u32)
    }

    /// A double, stored after the values written so far.
    pub(crate) fn double(&mut self, v: f64) -> io::Result<ValueRep> {
        self.align()?;
        let rep = ValueRep::new(Type::Double, self.pos);
        self.write(&v.to_le_bytes())?;
        Ok(rep)
    }

    /// A list of tokens as Sdf stores children names (`primChildren`, `properties`).
    pub(crate) fn token_vector(&mut self, names: &[&str]) -> io::Result<ValueRep> {
        self.align()?;
        let rep = ValueRep::new(Type::TokenVector, self.pos);
        self.write_u64(names.len() as u64)?;
        for name in names {
            let t = self.tokens.intern(name);
            self.write(&t.to_le_bytes())?;
        }
        Ok(rep)
    }

    /// An explicit list of target paths (a relationship's `targetPaths`).
    pub(crate) fn path_list(&mut self, targets: &[PathId]) -> io::Result<ValueRep> {
        /// List-op header bits: explicit, and has explicit items.
        const EXPLICIT_WITH_ITEMS: u8 = 0b11;
        let rep = ValueRep::new(Type::PathListOp, self.pos);
        self.write(&[EXPLICIT_WITH_ITEMS])?;
        self.write_u64(targets.len() as u64)?;
        for t in targets {
            self.write(&t.0.to_le_bytes())?;
        }
        Ok(rep)
    }

    /// An array of `items` elements of `ty` (a float type: `Float`, `Vec2f`, `Vec3f`,
    /// `Vec4f`) from the floats `values` yields, element after element.
    pub(crate) fn float_array(
        &mut self,
        ty: Type,
        items: usize,
        values: impl Iterator<Item = f32>,
    ) -> io::Result<ValueRep> {
        if items == 0 {
            return Ok(ValueRep::empty_array(ty));
        }
        self.align()?;
        let rep = ValueRep::array_at(ty, self.pos);
        self.write_u64(items as u64)?;
        let mut buffer = Vec::with_capacity(1 << 16);
        for v in values {
            buffer.extend_from_slice(&v.to_le_bytes());
            if buffer.len() == buffer.capacity() {
                self.write(&buffer)?;
                buffer.clear();
            }
        }
        self.write(&buffer)?;
        Ok(rep)
    }

    /// An `int` array of the `len` values `values` yields.
    pub(crate) fn int_array(
        &mut self,
        len: usize,
        values: impl Iterator<Item = i32>,
    ) -> io::Result<ValueRep> {
        if len == 0 {
            return Ok(ValueRep::empty_array(Type::Int));
        }
        self.align()?;
        let mut rep = ValueRep::array_at(Type::Int, self.pos);
        self.write_u64(len as u64)?;
        if len < MIN_COMPRESSED_ARRAY {
            let bytes: Vec<u8> = values.flat_map(i32::to_le_bytes).collect();
            self.write(&bytes)?;
        } else {
            let compressed = coding::compress_ints(len, values)?;
            self.write_u64(compressed.len() as u64)?;
            self.write(&compressed)?;
            rep.0 |= ValueRep::COMPRESSED;
        }
        Ok(rep)
    }

    /// The times of time series (one list any number of series can share).
    pub(crate) fn times(&mut self, times: &[f64]) -> io::Result<ValueRep> {
        self.align()?;
        let rep = ValueRep::new(Type::DoubleVector, self.pos);
        self.write_u64(times.len() as u64)?;
        let bytes: Vec<u8> = times.iter().flat_map(|t| t.to_le_bytes()).collect();
        self.write(&bytes)?;
        Ok(rep)
    }

    /// A time series: `samples[i]` at time `i` of the list `times` (a [`Self::times`]
    /// rep). The record points at values written before it: an offset (8: the next word)
    /// to the times' rep, the rep, an offset (8) to the sample count, the count and the
    /// samples' reps.
    pub(crate) fn time_samples(
        &mut self,
        times: ValueRep,
        samples: &[ValueRep],
    ) -> io::Result<ValueRep> {
        self.align()?;
        let rep = ValueRep::new(Type::TimeSamples, self.pos);
        let mut record = Vec::with_capacity(32 + 8 * samples.len());
        record.extend_from_slice(&8i64.to_le_bytes());
        record.extend_from_slice(&times.0.to_le_bytes());
        record.extend_from_slice(&8i64.to_le_bytes());
        record.extend_from_slice(&(samples.len() as u64).to_le_bytes());
        for s in samples {
            record.extend_from_slice(&s.0.to_le_bytes());
        }
        self.write(&record)?;
        Ok(rep)
    }

    /// A spec at `path` with `fields` (name, value).
    pub(crate) fn spec(&mut self, path: PathId, ty: SpecType, fields: &[(&str, ValueRep)]) {
        let set = self.field_sets.len() as u32;
        for &(name, rep) in fields {
            let token = self.tokens.intern(name);
            let next = self.fields.len() as u32;
            let index = *self.field_index.entry((token, rep)).or_insert(next);
            if index == next {
                self.fields.push((token, rep));
            }
            self.field_sets.push(index);
        }
        self.field_sets.push(END_OF_FIELD_SET);
        self.specs.push((path, set, ty));
    }

    /// Writes the tables, the table of contents and the bootstrap; returns the file's
    /// size in bytes and the writer (flushed).
    pub(crate) fn finish(mut self) -> io::Result<(u64, W)> {
        let mut sections: Vec<(&str, u64, u64)> = Vec::new();
        type Section<W> = fn(&mut CrateWriter<W>) -> io::Result<()>;
        let writers: [(&str, Section<W>); 6] = [
            ("TOKENS", Self::write_tokens),
            ("STRINGS", Self::write_strings),
            ("FIELDS", Self::write_fields),
            ("FIELDSETS", Self::write_field_sets),
            ("PATHS", Self::write_paths),
            ("SPECS", Self::write_specs),
        ];
        for (name, write) in writers {
            let start = self.pos;
            write(&mut self)?;
            sections.push((name, start, self.pos - start));
        }
        let toc = self.pos;
        self.write_u64(sections.len() as u64)?;
        for (name, start, size) in sections {
            let mut entry = [0u8; 32];
            entry[..name.len()].copy_from_slice(name.as_bytes());
            entry[16..24].copy_from_slice(&start.to_le_bytes());
            entry[24..].copy_from_slice(&size.to_le_bytes());
            self.write(&entry)?;
        }
        let size = self.pos;
        let mut boot = [0u8; BOOTSTRAP_BYTES as usize];
        boot[..8].copy_from_slice(b"PXR-USDC");
        boot[8..11].copy_from_slice(&VERSION);
        boot[16..24].copy_from_slice(&toc.to_le_bytes());
        self.out.seek(SeekFrom::Start(0))?;
        self.out.write_all(&boot)?;
        self.out.flush()?;
        Ok((size, self.out))
    }

    /// A compressed int table: its compressed size, then the bytes.
    fn write_compressed_ints(&mut self, values: &[u32]) -> io::Result<()> {
        let compressed = coding::compress_ints(values.len(), values.iter().map(|&v| v as i32))?;
        self.write_u64(compressed.len() as u64)?;
        self.write(&compressed)
    }

    fn write_tokens(&mut self) -> io::Result<()> {
        let mut text = Vec::new();
        for t in &self.tokens.items {
            text.extend_from_slice(t.as_bytes());
            text.push(0);
        }
        let compressed = coding::lz4_framed(&text)?;
        self.write_u64(self.tokens.items.len() as u64)?;
        self.write_u64(text.len() as u64)?;
        self.write_u64(compressed.len() as u64)?;
        self.write(&compressed)
    }

    fn write_strings(&mut self) -> io::Result<()> {
        self.write_u64(self.strings.len() as u64)?;
        let bytes: Vec<u8> = self.strings.iter().flat_map(|s| s.to_le_bytes()).collect();
        self.write(&bytes)
    }

    fn write_fields(&mut self) -> io::Result<()> {
        self.write_u64(self.fields.len() as u64)?;
        let tokens: Vec<u32> = self.fields.iter().map(|f| f.0).collect();
        self.write_compressed_ints(&tokens)?;
        let reps: Vec<u8> = self
            .fields
            .iter()
            .flat_map(|f| f.1 .0.to_le_bytes())
            .collect();
        let compressed = coding::lz4_framed(&reps)?;
        self.write_u64(compressed.len() as u64)?;
        self.write(&compressed)
    }

    fn write_field_sets(&mut self) -> io::Result<()> {
        self.write_u64(self.field_sets.len() as u64)?;
        let sets = std::mem::take(&mut self.field_sets);
        self.write_compressed_ints(&sets)
    }

    /// The path tree in depth-first order as three int lists: the path's index, its
    /// element token (negative for a property) and a jump: -2 a leaf without a next
    /// sibling, -1 a first child follows and no sibling, 0 the next sibling follows, or the
    /// distance to the next sibling when the first child follows.
    fn write_paths(&mut self) -> io::Result<()> {
        let [indices, tokens, jumps] = self.path_lists();
        self.write_u64(self.paths.len() as u64)?;
        self.write_u64(indices.len() as u64)?;
        self.write_compressed_ints(&indices)?;
        self.write_compressed_ints(&tokens)?;
        self.write_compressed_ints(&jumps)
    }

    /// The three lists of [`Self::write_paths`] (tokens and jumps as their bits).
    fn path_lists(&self) -> [Vec<u32>; 3] {
        let mut lists = [Vec::new(), Vec::new(), Vec::new()];
        self.emit_path(PathId(0), false, &mut lists);
        lists
    }

    /// Appends `id` and its subtree (children in creation order) to the path lists.
    fn emit_path(&self, id: PathId, has_sibling: bool, lists: &mut [Vec<u32>; 3]) {
        let entry = &self.paths[id.0 as usize];
        let at = lists[0].len();
        lists[0].push(id.0);
        let token = entry.token as i32;
        lists[1].push(if entry.property { -token } else { token } as u32);
        lists[2].push(0);
        for (k, &child) in entry.children.iter().enumerate() {
            self.emit_path(child, k + 1 < entry.children.len(), lists);
        }
        // The next sibling comes right after this subtree.
        let jump = match (!entry.children.is_empty(), has_sibling) {
            (true, true) => (lists[0].len() - at) as i32,
            (true, false) => -1,
            (false, true) => 0,
            (false, false) => -2,
        };
        lists[2][at] = jump as u32;
    }

    fn write_specs(&mut self) -> io::Result<()> {
        self.write_u64(self.specs.len() as u64)?;
        let specs = std::mem::take(&mut self.specs);
        let paths: Vec<u32> = specs.iter().map(|s| s.0 .0).collect();
        let sets: Vec<u32> = specs.iter().map(|s| s.1).collect();
        let types: Vec<u32> = specs.iter().map(|s| s.2 as u32).collect();
        self.write_compressed_ints(&paths)?;
        self.write_compressed_ints(&sets)?;
        self.write_compressed_ints(&types)
    }
}

#[cfg(test)]
mod tests;
