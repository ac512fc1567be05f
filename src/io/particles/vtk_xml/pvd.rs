//! ParaView's collection files (`.pvd`): `<VTKFile type="Collection">` holding a
//! `<Collection>` of `<DataSet timestep=".." group=".." part=".." file=".."/>` entries.
//! This reads the entries as written (markup only, with the VTK XML scanner); what they
//! mean as a frame sequence is [`crate::sequence`]'s.

use super::scan::{attribute, shorten, shown, Scanner};
use crate::error::{Error, Result};
use std::path::Path;

/// Most `<DataSet>` entries read from one collection.
const MAX_DATASETS: usize = 1 << 24;
/// Deepest element nesting followed.
const MAX_DEPTH: usize = 64;

/// One `<DataSet>` of a collection, its attributes as written.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct DataSetEntry {
    /// Line of the `<DataSet>` tag.
    pub(crate) line: usize,
    /// `file`: the dataset, relative to the collection's folder (or absolute).
    pub(crate) file: String,
    /// `timestep`, when given.
    pub(crate) timestep: Option<String>,
    /// `part` (ParaView's default `0` when absent).
    pub(crate) part: String,
    /// `group` (empty when absent).
    pub(crate) group: String,
}

/// The `<DataSet>` entries of the collection `path`, in file order. Errors name the file
/// and the line: not a VTK XML file, a `<VTKFile>` of another type than `Collection`, a
/// `<DataSet>` without `file`, malformed markup, a file that ends before its elements
/// are closed (cut off, or still being written: its entries so far are not taken for
/// the whole sequence), an element after the `<VTKFile>` closed. An empty collection is
/// returned empty.
pub(crate) fn datasets(path: &Path) -> Result<Vec<DataSetEntry>> {
    let (mut s, _) = Scanner::open(path)?;
    let at = |line: usize, message: String| Error::parse(path, format!("line {line}"), message);
    let mut stack: Vec<String> = Vec::new();
    let mut seen_file = false;
    let mut entries = Vec::new();
    while let Some((line, name, attributes, empty)) = s.next_start(&mut stack)? {
        match (stack.last().map(String::as_str), name.as_str()) {
            (None, other) if seen_file => {
                return Err(at(line, format!(
                    "<{}> after the end of the <VTKFile>: a collection is one <VTKFile> element",
                    shown(other)
                )))
            }
            (None, "VTKFile") => {
                seen_file = true;
                match attribute(&attributes, "type") {
                    Some("Collection") => {}
                    Some(other) => {
                        return Err(at(line, format!(
                            "not a collection: VTKFile type {:?}, not \"Collection\" (a .pvd lists the frames' files)",
                            shorten(other)
                        )))
                    }
                    None => return Err(at(line, "<VTKFile> without a type".into())),
                }
            }
            (None, other) => {
                return Err(at(line, format!(
                    "not a VTK collection: the first element is <{}>, not <VTKFile type=\"Collection\">",
                    shown(other)
                )))
            }
            (Some("Collection"), "DataSet") => {
                if entries.len() == MAX_DATASETS {
                    return Err(s.error(format!("more than {MAX_DATASETS} DataSet entries")));
                }
                let file = attribute(&attributes, "file")
                    .filter(|f| !f.trim().is_empty())
                    .ok_or_else(|| at(line, "<DataSet> without a file".into()))?;
                entries.push(DataSetEntry {
                    line,
                    file: file.trim().to_string(),
                    timestep: attribute(&attributes, "timestep").map(|t| t.trim().to_string()),
                    part: attribute(&attributes, "part").unwrap_or("0").trim().to_string(),
                    group: attribute(&attributes, "group").unwrap_or("").trim().to_string(),
                });
            }
            _ => {}
        }
        if !empty {
            if stack.len() == MAX_DEPTH {
                return Err(s.error(format!("elements nested deeper than {MAX_DEPTH}")));
            }
            stack.push(name);
        }
    }
    if !seen_file {
        return Err(s.error("not a VTK collection: no <VTKFile> element"));
    }
    if let Some(open) = stack.last() {
        return Err(s.error(format!(
            "the file ends inside <{}> ({} element(s) left open): the collection is cut off, or still being written",
            shown(open),
            stack.len()
        )));
    }
    Ok(entries)
}
