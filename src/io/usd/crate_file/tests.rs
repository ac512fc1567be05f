//! Tests of the crate encoder: its files read back as Pixar's reader reads them.

use super::super::coding::decode::{decompress_ints, unframe};
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
