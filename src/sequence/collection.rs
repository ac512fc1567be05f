//! ParaView collections (`.pvd`) as frame sequences: [`collection_frames`], and the
//! frames a [`FrameChoice`] takes of them.

use super::{unselectable, Frame, FrameChoice};
use crate::error::{Error, Result};
use crate::io::particles::{collection_datasets, DataSetEntry};
use std::path::{Path, PathBuf};

/// The frames of the ParaView collection `path` (`.pvd`): its `<DataSet>` entries sorted
/// by `timestep` (a stable sort: file order among equal ones), numbered 0, 1, 2, … in that
/// order (the label is the number written plainly), each [`Frame::time`] its timestep.
/// Without any `timestep`, the entries are taken in file order (no time). A `file` is
/// relative to the collection's folder (or absolute) and is read as its extension says.
///
/// Errors name the collection and the entry's line: not a collection, a `<DataSet>`
/// without `file`, a timestep that is not a finite number, timesteps on some entries and
/// not on others, an empty collection; two entries of one timestep are refused (the
/// same `file` listed twice counts once): other `part`s or `group`s of one time, which a
/// frame of meniscus cannot hold, or two files for one time (a duplicate). Every entry's
/// file must exist: the first missing one is an error before any frame is read.
pub fn collection_frames(path: &Path) -> Result<Vec<Frame>> {
    let entries = collection_datasets(path)?;
    if entries.is_empty() {
        return Err(Error::parse(
            path,
            "<Collection>",
            "an empty collection: no <DataSet> entry, so no frame",
        ));
    }
    let timed = timesteps(path, &entries)?;
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let missing: Vec<&(Option<f64>, &DataSetEntry)> = timed
        .iter()
        .filter(|(_, e)| !dir.join(&e.file).is_file())
        .collect();
    if let Some((_, e)) = missing.first() {
        let more = match missing.len() {
            1 => String::new(),
            n => format!(" ({} more entries name missing files)", n - 1),
        };
        return Err(Error::io(
            path,
            std::io::Error::new(
                std::io::ErrorKind::NotFound,
                format!(
                    "line {}: the DataSet's file {:?} ({}) does not exist{more}",
                    e.line,
                    e.file,
                    dir.join(&e.file).display()
                ),
            ),
        ));
    }
    Ok(timed
        .into_iter()
        .enumerate()
        .map(|(k, (time, e))| Frame {
            number: k as i64,
            label: k.to_string(),
            input: dir.join(&e.file),
            time,
        })
        .collect())
}

/// The entries in frame order with their times (see [`collection_frames`]).
fn timesteps<'a>(
    path: &Path,
    entries: &'a [DataSetEntry],
) -> Result<Vec<(Option<f64>, &'a DataSetEntry)>> {
    let at = |e: &DataSetEntry| format!("line {}", e.line);
    if entries.iter().all(|e| e.timestep.is_none()) {
        return Ok(entries.iter().map(|e| (None, e)).collect());
    }
    let mut timed = Vec::with_capacity(entries.len());
    for e in entries {
        let Some(text) = &e.timestep else {
            return Err(Error::parse(
                path,
                at(e),
                format!(
                    "<DataSet file={:?}> has no timestep while other entries have one",
                    e.file
                ),
            ));
        };
        let t = text.parse::<f64>().ok().filter(|t| t.is_finite());
        let t = t.ok_or_else(|| {
            Error::parse(
                path,
                at(e),
                format!("timestep {text:?} is not a finite number"),
            )
        })?;
        timed.push((t, e));
    }
    timed.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut kept: Vec<(Option<f64>, &DataSetEntry)> = Vec::with_capacity(timed.len());
    for (t, e) in timed {
        let Some(&(Some(previous), p)) = kept.last() else {
            kept.push((Some(t), e));
            continue;
        };
        if previous != t {
            kept.push((Some(t), e));
        } else if (&p.part, &p.group) != (&e.part, &e.group) {
            return Err(Error::parse(
                path,
                at(e),
                format!(
                    "timestep {t} has more than one part: {:?} (line {}, part {:?}{}) and {:?} (part {:?}{}); a frame is one dataset: merge the parts into one file per timestep, or list one part",
                    p.file,
                    p.line,
                    p.part,
                    group_text(p),
                    e.file,
                    e.part,
                    group_text(e)
                ),
            ));
        } else if p.file != e.file {
            return Err(Error::parse(
                path,
                at(e),
                format!(
                    "duplicate timestep {t}: {:?} (line {}) and {:?}; each timestep names one file: remove one of the entries",
                    p.file, p.line, e.file
                ),
            ));
        }
    }
    Ok(kept)
}

/// `, group "g"` for an entry with a group; empty without.
fn group_text(e: &DataSetEntry) -> String {
    match e.group.as_str() {
        "" => String::new(),
        g => format!(", group {g:?}"),
    }
}

/// The frames of the collection `path` that `choice` takes before sharding: a
/// selection's frames (each must be in the collection), or those of the range
/// `start..=end` (with both given, every frame between must be in it).
pub(super) fn choose(path: &Path, choice: &FrameChoice) -> Result<Vec<Frame>> {
    let all = collection_frames(path)?;
    let n = all.len() as i64;
    let holds = match n {
        1 => " (the collection holds frame 0)".to_string(),
        _ => format!(" (the collection holds frames 0-{})", n - 1),
    };
    let not_found = |message: String| {
        Error::io(
            path,
            std::io::Error::new(std::io::ErrorKind::NotFound, message),
        )
    };
    if let Some(selection) = &choice.frames {
        let missing: Vec<i64> = selection
            .numbers()
            .iter()
            .copied()
            .filter(|&k| !(0..n).contains(&k))
            .collect();
        if !missing.is_empty() {
            return Err(unselectable(
                path,
                &missing,
                selection,
                "no dataset for",
                &holds,
            ));
        }
        return Ok(selection
            .numbers()
            .iter()
            .map(|&k| all[k as usize].clone())
            .collect());
    }
    if let (Some(s), Some(e)) = (choice.start, choice.end) {
        if s > e {
            return Err(Error::InvalidOption {
                option: "start/end",
                message: format!("start {s} is after end {e}"),
            });
        }
        let outside: Vec<String> = [(s, e.min(-1)), (s.max(n), e)]
            .into_iter()
            .filter(|(a, b)| a <= b)
            .map(|(a, b)| match a == b {
                true => a.to_string(),
                false => format!("{a}-{b}"),
            })
            .collect();
        if !outside.is_empty() {
            return Err(not_found(format!(
                "frames {} of the range {s}..={e} are not in the collection{holds}",
                outside.join(", ")
            )));
        }
    }
    let range = choice.start.unwrap_or(i64::MIN)..=choice.end.unwrap_or(i64::MAX);
    let taken: Vec<Frame> = all
        .into_iter()
        .filter(|f| range.contains(&f.number))
        .collect();
    if taken.is_empty() {
        return Err(not_found(format!(
            "no frame of the collection is in the range {}..={}{holds}",
            choice.start.map_or(String::new(), |s| s.to_string()),
            choice.end.map_or(String::new(), |e| e.to_string()),
        )));
    }
    Ok(taken)
}
