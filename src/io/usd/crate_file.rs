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
mod tests {
    use super::coding::decode::{decompress_ints, unframe};
    use super::*;
    use std::io::Cursor;

    fn u64_at(d: &[u8], at: usize) -> u64 {
        u64::from_le_bytes(d[at..at + 8].try_into().unwrap())
    }

    /// A crate file read back as Pixar's reader reads it: tokens, fields, field sets,
    /// paths (rebuilt from the three lists) and specs.
    struct Decoded {
        tokens: Vec<String>,
        fields: Vec<(String, u64)>,
        field_sets: Vec<u32>,
        paths: Vec<String>,
        specs: Vec<(String, u32, u32)>,
    }

    /// A compressed int table at `at` (`n` ints); returns them and the offset after.
    fn ints(d: &[u8], at: usize, n: usize) -> (Vec<i32>, usize) {
        let size = u64_at(d, at) as usize;
        (decompress_ints(&d[at + 8..at + 8 + size], n), at + 8 + size)
    }

    fn decode(d: &[u8]) -> Decoded {
        assert_eq!(&d[..8], b"PXR-USDC");
        assert_eq!(d[8..11], VERSION);
        let toc = u64_at(d, 16) as usize;
        let section = |name: &str| {
            (0..u64_at(d, toc) as usize)
                .map(|i| toc + 8 + 32 * i)
                .find(|&at| d[at..at + 16].split(|&b| b == 0).next() == Some(name.as_bytes()))
                .map(|at| u64_at(d, at + 16) as usize)
                .unwrap_or_else(|| panic!("no {name} section"))
        };
        let at = section("TOKENS");
        let (n, size, packed) = (u64_at(d, at), u64_at(d, at + 8), u64_at(d, at + 16));
        let text = unframe(&d[at + 24..at + 24 + packed as usize], size as usize);
        let tokens: Vec<String> = text
            .split(|&b| b == 0)
            .take(n as usize)
            .map(|t| String::from_utf8(t.to_vec()).unwrap())
            .collect();
        let at = section("FIELDS");
        let n = u64_at(d, at) as usize;
        let (names, after) = ints(d, at + 8, n);
        let size = u64_at(d, after) as usize;
        let reps = unframe(&d[after + 8..after + 8 + size], 8 * n);
        let fields = (0..n)
            .map(|i| (tokens[names[i] as usize].clone(), u64_at(&reps, 8 * i)))
            .collect();
        let at = section("FIELDSETS");
        let field_sets = ints(d, at + 8, u64_at(d, at) as usize).0;
        let at = section("PATHS");
        let n = u64_at(d, at + 8) as usize;
        let (indices, after) = ints(d, at + 16, n);
        let (elements, after) = ints(d, after, n);
        let (jumps, _) = ints(d, after, n);
        let mut paths = vec![String::new(); u64_at(d, at) as usize];
        rebuild(&indices, &elements, &jumps, &tokens, 0, None, &mut paths);
        let at = section("SPECS");
        let n = u64_at(d, at) as usize;
        let (path_ids, after) = ints(d, at + 8, n);
        let (sets, after) = ints(d, after, n);
        let (types, _) = ints(d, after, n);
        let specs = (0..n)
            .map(|i| {
                (
                    paths[path_ids[i] as usize].clone(),
                    sets[i] as u32,
                    types[i] as u32,
                )
            })
            .collect();
        Decoded {
            tokens,
            fields,
            field_sets: field_sets.into_iter().map(|v| v as u32).collect(),
            paths,
            specs,
        }
    }

    /// The path lists walked as Pixar's reader walks them (a sibling after a subtree is
    /// reached through the jump, an only sibling or only child by the next entry).
    fn rebuild(
        indices: &[i32],
        elements: &[i32],
        jumps: &[i32],
        tokens: &[String],
        mut at: usize,
        mut parent: Option<String>,
        out: &mut [String],
    ) {
        loop {
            let path = match &parent {
                None => "/".to_string(),
                Some(p) => {
                    let name = &tokens[elements[at].unsigned_abs() as usize];
                    match (elements[at] < 0, p.as_str()) {
                        (true, _) => format!("{p}.{name}"),
                        (false, "/") => format!("/{name}"),
                        (false, _) => format!("{p}/{name}"),
                    }
                }
            };
            out[indices[at] as usize] = path.clone();
            let (has_child, has_sibling) = (jumps[at] > 0 || jumps[at] == -1, jumps[at] >= 0);
            if has_child && has_sibling {
                let sibling = at + jumps[at] as usize;
                rebuild(
                    indices,
                    elements,
                    jumps,
                    tokens,
                    sibling,
                    parent.clone(),
                    out,
                );
            }
            if has_child {
                parent = Some(path);
            } else if !has_sibling {
                return;
            }
            at += 1;
        }
    }

    /// The fields of the spec at `path`.
    fn fields_of<'a>(d: &'a Decoded, path: &str) -> Vec<&'a (String, u64)> {
        let (_, set, _) = d.specs.iter().find(|s| s.0 == path).unwrap();
        d.field_sets[*set as usize..]
            .iter()
            .take_while(|&&f| f != END_OF_FIELD_SET)
            .map(|&f| &d.fields[f as usize])
            .collect()
    }

    #[test]
    fn paths_with_children_and_siblings_decode_to_the_tree_written() {
        let mut w = CrateWriter::new(Cursor::new(Vec::new())).unwrap();
        let root = w.root();
        // A subtree with a sibling after it exercises the positive jumps.
        let a = w.child_path(root, "A", false);
        w.child_path(a, "x", true);
        let b = w.child_path(a, "B", false);
        w.child_path(b, "y", true);
        w.child_path(b, "primvars:z", true);
        let c = w.child_path(a, "C", false);
        let d = w.child_path(root, "D", false);
        let leaf = w.child_path(d, "E", false);
        for (id, ty) in [
            (root, SpecType::PseudoRoot),
            (a, SpecType::Prim),
            (c, SpecType::Prim),
            (leaf, SpecType::Prim),
        ] {
            w.spec(id, ty, &[]);
        }
        let (_, out) = w.finish().unwrap();
        let decoded = decode(&out.into_inner());
        let mut paths = decoded.paths.clone();
        paths.sort();
        assert_eq!(
            paths,
            [
                "/",
                "/A",
                "/A.x",
                "/A/B",
                "/A/B.primvars:z",
                "/A/B.y",
                "/A/C",
                "/D",
                "/D/E"
            ]
        );
        let specs: Vec<(&str, u32)> = decoded.specs.iter().map(|s| (s.0.as_str(), s.2)).collect();
        assert_eq!(specs, [("/", 7), ("/A", 6), ("/A/C", 6), ("/D/E", 6)]);
    }

    #[test]
    fn children_lists_are_token_vectors_not_token_arrays() {
        // USD 26 refuses (a prim's) and ignores (the root's) primChildren stored as a
        // token[] array: the field must have the TokenVector type, no array bit.
        let mut w = CrateWriter::new(Cursor::new(Vec::new())).unwrap();
        let root = w.root();
        let children = w.token_vector(&["World"]).unwrap();
        w.spec(root, SpecType::PseudoRoot, &[("primChildren", children)]);
        let (_, out) = w.finish().unwrap();
        let bytes = out.into_inner();
        let decoded = decode(&bytes);
        let &(ref name, rep) = fields_of(&decoded, "/")[0];
        assert_eq!(name, "primChildren");
        assert_eq!((rep >> 48) & 0xff, Type::TokenVector as u64);
        assert_eq!(rep & (ValueRep::ARRAY | ValueRep::INLINED), 0);
        let at = (rep & ValueRep::PAYLOAD) as usize;
        assert_eq!(u64_at(&bytes, at), 1);
        let token = u32::from_le_bytes(bytes[at + 8..at + 12].try_into().unwrap());
        assert_eq!(decoded.tokens[token as usize], "World");
    }

    #[test]
    fn a_time_series_points_at_the_shared_times_and_its_samples() {
        let mut w = CrateWriter::new(Cursor::new(Vec::new())).unwrap();
        let small = w.int_array(3, [7, 8, 9].into_iter()).unwrap();
        let large = w.int_array(1000, 0..1000).unwrap();
        let empty = w.int_array(0, std::iter::empty()).unwrap();
        let times = w.times(&[1.0, 2.0, 5.0]).unwrap();
        let series = w.time_samples(times, &[small, large, empty]).unwrap();
        let (_, out) = w.finish().unwrap();
        let d = out.into_inner();
        let at = (series.0 & ValueRep::PAYLOAD) as usize;
        // Offset to the times' rep, the rep, offset to the count, count, reps.
        assert_eq!(u64_at(&d, at), 8);
        assert_eq!(u64_at(&d, at + 8), times.0);
        assert_eq!(u64_at(&d, at + 16), 8);
        assert_eq!(u64_at(&d, at + 24), 3);
        let reps: Vec<u64> = (0..3).map(|i| u64_at(&d, at + 32 + 8 * i)).collect();
        assert_eq!(reps, [small.0, large.0, empty.0]);
        let t = (times.0 & ValueRep::PAYLOAD) as usize;
        assert_eq!(u64_at(&d, t), 3);
        let read: Vec<f64> = (0..3)
            .map(|i| f64::from_bits(u64_at(&d, t + 8 + 8 * i)))
            .collect();
        assert_eq!(read, [1.0, 2.0, 5.0]);
        // Fewer than 16 ints are stored as they are; more are compressed.
        assert_eq!(small.0 & ValueRep::COMPRESSED, 0);
        let s = (small.0 & ValueRep::PAYLOAD) as usize;
        assert_eq!(&d[s + 8..s + 20], [7, 0, 0, 0, 8, 0, 0, 0, 9, 0, 0, 0]);
        assert_ne!(large.0 & ValueRep::COMPRESSED, 0);
        let l = (large.0 & ValueRep::PAYLOAD) as usize;
        let size = u64_at(&d, l + 8) as usize;
        assert_eq!(
            decompress_ints(&d[l + 16..l + 16 + size], 1000),
            (0..1000).collect::<Vec<_>>()
        );
        assert_eq!(empty, ValueRep::empty_array(Type::Int));
    }

    #[test]
    fn equal_fields_are_stored_once() {
        let mut w = CrateWriter::new(Cursor::new(Vec::new())).unwrap();
        let root = w.root();
        let (a, b) = (
            w.child_path(root, "a", false),
            w.child_path(root, "b", false),
        );
        let mesh = w.token("Mesh");
        for p in [a, b] {
            w.spec(p, SpecType::Prim, &[("typeName", mesh)]);
        }
        let (_, out) = w.finish().unwrap();
        let decoded = decode(&out.into_inner());
        assert_eq!(decoded.fields.len(), 1);
        assert_eq!(
            decoded.field_sets,
            [0, END_OF_FIELD_SET, 0, END_OF_FIELD_SET]
        );
    }
}
