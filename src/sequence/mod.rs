//! Frame sequences: `{}` patterns in input and output paths, and ParaView collections.
//!
//! `sim/ParticleData_Fluid_{}.bgeo` names one file per frame; `{}` stands for the frame
//! number. With a range (`--start`/`--end`, inclusive) the numbers are written plainly
//! (`7`, `10`); without one, the pattern's directory is scanned and every file whose name
//! matches (with the number written in any way, such as `0007`) is taken, in increasing
//! frame order. The output pattern receives the number exactly as the input file wrote it.
//!
//! A ParaView collection (`run.pvd`) lists a sequence's files with their times
//! ([`collection_frames`]): its datasets are frames 0, 1, 2, … in the order of their
//! `timestep`s, and the output pattern receives that number plainly.
//!
//! Render farms name frames as [`FrameSelection`]s (`1-100:2,7`) and split them among
//! machines as [`Shard`]s (`--shard I/N`, round-robin); [`choose`] applies both.

mod collection;

pub use collection::collection_frames;

use crate::error::{Error, Result};
use std::path::{Path, PathBuf};

/// One frame of a sequence.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    /// Frame number.
    pub number: i64,
    /// The number as written in the input file name (keeps zero padding).
    pub label: String,
    /// Input file.
    pub input: PathBuf,
    /// The simulation time of the frame, when its input says it (a `.pvd` collection's
    /// `timestep`).
    pub time: Option<f64>,
}

/// The placeholder in file patterns.
pub const PLACEHOLDER: &str = "{}";

/// True when `path` is a pattern (contains `{}`).
pub fn is_pattern(path: &str) -> bool {
    path.contains(PLACEHOLDER)
}

/// True when `path` is a ParaView collection (`.pvd`, any case) and not a pattern.
pub fn is_collection(path: &str) -> bool {
    !is_pattern(path)
        && Path::new(path)
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("pvd"))
}

/// True when `path` names a sequence of frames: a pattern or a collection.
pub fn is_sequence(path: &str) -> bool {
    is_pattern(path) || is_collection(path)
}

/// Replaces every placeholder of `pattern` with `label`.
pub fn substitute(pattern: &str, label: &str) -> PathBuf {
    PathBuf::from(pattern.replace(PLACEHOLDER, label))
}

/// `numbers` (increasing) as runs, for messages: `4-6, 9, 12-13`.
pub fn number_ranges(numbers: &[i64]) -> String {
    let mut runs: Vec<(i64, i64)> = Vec::new();
    for &n in numbers {
        match runs.last_mut() {
            Some((_, last)) if *last + 1 == n => *last = n,
            _ => runs.push((n, n)),
        }
    }
    runs.iter()
        .map(|&(a, b)| {
            if a == b {
                a.to_string()
            } else {
                format!("{a}-{b}")
            }
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// A `{}` pattern for what a user gave instead of one (for hints): the run of `#`, `*` or
/// `?` in the file name, else its last run of digits, replaced by `{}`; for a directory,
/// that pattern of the first file in it (by name) whose name holds digits.
pub fn suggested_pattern(input: &str) -> String {
    let path = Path::new(input);
    if path.is_dir() {
        let mut names: Vec<String> = std::fs::read_dir(path)
            .into_iter()
            .flatten()
            .flatten()
            .filter_map(|e| e.file_name().into_string().ok())
            .filter(|n| n.bytes().any(|b| b.is_ascii_digit()))
            .collect();
        names.sort();
        let name = names
            .first()
            .map_or_else(|| "frame_{}.xyz".to_string(), |n| name_pattern(n));
        return path.join(name).display().to_string();
    }
    let name = path.file_name().and_then(|n| n.to_str()).unwrap_or(input);
    match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.join(name_pattern(name)).display().to_string(),
        _ => name_pattern(name),
    }
}

/// The file name `name` with its frame number (a run of `#`, `*`, `?`, else the last run
/// of digits) replaced by `{}`; `_{}` before the extension when it has neither.
fn name_pattern(name: &str) -> String {
    let wild = |c: char| matches!(c, '#' | '*' | '?');
    let digit = |c: char| c.is_ascii_digit();
    let run = if let Some(start) = name.find(wild) {
        let end = name[start..]
            .find(|c| !wild(c))
            .map_or(name.len(), |k| start + k);
        Some((start, end))
    } else {
        name.rfind(digit).map(|last| {
            let start = name[..last].rfind(|c| !digit(c)).map_or(0, |k| k + 1);
            (start, last + 1)
        })
    };
    match (run, name.rsplit_once('.')) {
        (Some((start, end)), _) => format!("{}{{}}{}", &name[..start], &name[end..]),
        (None, Some((stem, ext))) => format!("{stem}_{{}}.{ext}"),
        (None, None) => format!("{name}_{{}}"),
    }
}

/// The frames of an input pattern, in increasing frame order. With `start`/`end`
/// (inclusive; both or either) the range is generated, and missing files are an error;
/// without either, the directory is scanned. A pattern must contain exactly one `{}`, in
/// its file name.
pub fn frames(pattern: &str, start: Option<i64>, end: Option<i64>) -> Result<Vec<Frame>> {
    let invalid = |message: String| Error::InvalidOption {
        option: "input",
        message,
    };
    if pattern.matches(PLACEHOLDER).count() != 1 {
        return Err(invalid(format!(
            "pattern {pattern:?} must contain exactly one {{}}"
        )));
    }
    let path = Path::new(pattern);
    let file_name = path
        .file_name()
        .and_then(|f| f.to_str())
        .filter(|f| f.contains(PLACEHOLDER))
        .ok_or_else(|| invalid(format!("the {{}} of {pattern:?} must be in the file name")))?;
    let (prefix, suffix) = file_name.split_once(PLACEHOLDER).expect("checked above");
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let mut found: Vec<Frame> = Vec::new();
    if let (Some(s), Some(e)) = (start, end) {
        if s > e {
            return Err(Error::InvalidOption {
                option: "start/end",
                message: format!("start {s} is after end {e}"),
            });
        }
        let mut missing = Vec::new();
        for number in s..=e {
            let label = number.to_string();
            let input = substitute(pattern, &label);
            if !input.exists() {
                missing.push((number, input));
                continue;
            }
            found.push(Frame {
                number,
                label,
                input,
                time: None,
            });
        }
        return match missing.as_slice() {
            [] => Ok(found),
            [(number, input)] => Err(Error::io(
                input,
                std::io::Error::new(
                    std::io::ErrorKind::NotFound,
                    format!("frame {number} of the range {s}..={e} is missing"),
                ),
            )),
            _ => {
                let numbers: Vec<i64> = missing.iter().map(|m| m.0).collect();
                Err(Error::io(
                    pattern,
                    std::io::Error::new(
                        std::io::ErrorKind::NotFound,
                        format!(
                            "{} frames of the range {s}..={e} are missing: {}",
                            numbers.len(),
                            number_ranges(&numbers)
                        ),
                    ),
                ))
            }
        };
    }
    let entries = std::fs::read_dir(&dir).map_err(|e| Error::io(&dir, e))?;
    for entry in entries {
        let entry = entry.map_err(|e| Error::io(&dir, e))?;
        let name = entry.file_name();
        let Some(name) = name.to_str() else { continue };
        let Some(middle) = name
            .strip_prefix(prefix)
            .and_then(|m| m.strip_suffix(suffix))
        else {
            continue;
        };
        let digits = middle.strip_prefix('-').unwrap_or(middle);
        if digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_digit()) {
            continue;
        }
        let Ok(number) = middle.parse::<i64>() else {
            continue;
        };
        if start.is_some_and(|s| number < s) || end.is_some_and(|e| number > e) {
            continue;
        }
        found.push(Frame {
            number,
            label: middle.to_string(),
            input: dir.join(name),
            time: None,
        });
    }
    found.sort_by(|a, b| (a.number, &a.label).cmp(&(b.number, &b.label)));
    if found.is_empty() {
        return Err(Error::io(
            path,
            std::io::Error::new(
                std::io::ErrorKind::NotFound,
                format!("no file in {} matches the pattern", dir.display()),
            ),
        ));
    }
    Ok(found)
}

/// The most frames a [`FrameSelection`] may name: a range such as `1-1000000000` is a
/// typo, not a job.
pub const MAX_SELECTED_FRAMES: usize = 10_000_000;

/// Frames as render farms give them: `1-100` (inclusive), `1-100:2` (every second frame
/// from 1), `1,5,7-20` (a list of ranges), any mix; numbers may be negative (`-5--1`).
/// The frames are sorted and overlaps deduplicated (`1-10,5-20` is `1-20`). Parsed with
/// [`str::parse`]; errors name the bad text.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FrameSelection {
    numbers: Vec<i64>,
}

impl FrameSelection {
    /// The selected frame numbers, increasing, each once.
    pub fn numbers(&self) -> &[i64] {
        &self.numbers
    }

    /// True when `number` is selected.
    pub fn contains(&self, number: i64) -> bool {
        self.numbers.binary_search(&number).is_ok()
    }
}

/// `"1-x"`, or `"1-x" in "1-5,1-x"` when the item is part of a list.
fn place(item: &str, whole: &str) -> String {
    if item == whole.trim() {
        format!("{item:?}")
    } else {
        format!("{item:?} in {whole:?}")
    }
}

/// A number of the grammar: optional `-`, digits.
fn parse_number(text: &str, item: &str, whole: &str) -> std::result::Result<i64, String> {
    let digits = text.strip_prefix('-').unwrap_or(text);
    if digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_digit()) {
        return Err(format!(
            "{}: {text:?} is not a frame number (expected FIRST, FIRST-LAST or FIRST-LAST:STEP, separated by commas)",
            place(item, whole)
        ));
    }
    text.parse()
        .map_err(|_| format!("{}: {text:?} is out of range", place(item, whole)))
}

impl std::str::FromStr for FrameSelection {
    type Err = String;

    fn from_str(whole: &str) -> std::result::Result<Self, String> {
        if whole.trim().is_empty() {
            return Err("an empty frame selection selects no frame".into());
        }
        let mut numbers: Vec<i64> = Vec::new();
        for item in whole.split(',') {
            let item = item.trim();
            if item.is_empty() {
                return Err(format!("{whole:?}: an empty item between commas"));
            }
            let (range, step) = match item.split_once(':') {
                Some((range, step)) => {
                    let step = parse_number(step, item, whole)?;
                    if step < 1 {
                        return Err(format!(
                            "{}: the step must be at least 1, got {step}",
                            place(item, whole)
                        ));
                    }
                    (range, Some(step))
                }
                None => (item, None),
            };
            // FIRST or FIRST-LAST; a `-` after the first character separates the two
            // (a leading one is FIRST's sign).
            let (first, last) = match range.get(1..).and_then(|r| r.find('-')) {
                Some(k) => (
                    parse_number(&range[..k + 1], item, whole)?,
                    parse_number(&range[k + 2..], item, whole)?,
                ),
                None => {
                    if step.is_some() {
                        return Err(format!(
                            "{}: a step needs a range (FIRST-LAST:STEP)",
                            place(item, whole)
                        ));
                    }
                    let n = parse_number(range, item, whole)?;
                    (n, n)
                }
            };
            if first > last {
                return Err(format!(
                    "{}: the range is reversed ({first} is after {last})",
                    place(item, whole)
                ));
            }
            let step = step.unwrap_or(1);
            let count = (last as i128 - first as i128) / step as i128 + 1;
            if numbers.len() as i128 + count > MAX_SELECTED_FRAMES as i128 {
                return Err(format!(
                    "{whole:?} selects more than {MAX_SELECTED_FRAMES} frames"
                ));
            }
            numbers.extend((0..count as i64).map(|k| first + k * step));
        }
        numbers.sort_unstable();
        numbers.dedup();
        Ok(FrameSelection { numbers })
    }
}

/// One part of a selection split among `count` machines: `--shard I/N` takes every N-th
/// frame of the selection, starting at the I-th (0-based). Round-robin rather than
/// contiguous blocks: neighbouring frames cost about the same (a splash, a calm phase),
/// so every shard gets a similar mix of cheap and expensive frames, and a sequence that
/// grows at its end keeps every earlier frame in the shard it was in (blocks would move
/// them all), so a re-run with `--skip-existing` redoes nothing.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    /// This shard, `0..count`.
    pub index: usize,
    /// How many shards the selection is split into (at least 1).
    pub count: usize,
}

impl Shard {
    /// The items of `items` this shard takes: positions `index`, `index + count`, ...
    pub fn take<T: Clone>(&self, items: &[T]) -> Vec<T> {
        items
            .iter()
            .skip(self.index)
            .step_by(self.count)
            .cloned()
            .collect()
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl std::str::FromStr for Shard {
    type Err = String;

    fn from_str(text: &str) -> std::result::Result<Self, String> {
        let bad = || format!("{text:?} is not a shard: expected I/N with 0 <= I < N (such as 0/4)");
        let (index, count) = text.split_once('/').ok_or_else(bad)?;
        let number = |t: &str| -> std::result::Result<usize, String> {
            if t.is_empty() || !t.bytes().all(|b| b.is_ascii_digit()) {
                return Err(bad());
            }
            t.parse().map_err(|_| bad())
        };
        let (index, count) = (number(index.trim())?, number(count.trim())?);
        if count == 0 {
            return Err(format!("{text:?}: the shard count must be at least 1"));
        }
        if index >= count {
            return Err(format!(
                "{text:?}: shard {index} does not exist among {count} shards (they are numbered 0 to {})",
                count - 1
            ));
        }
        Ok(Shard { index, count })
    }
}

/// Which frames of a pattern a job takes: an inclusive `start`/`end` range, or a
/// [`FrameSelection`] (not both), then optionally one [`Shard`] of them.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct FrameChoice {
    /// First frame (inclusive).
    pub start: Option<i64>,
    /// Last frame (inclusive).
    pub end: Option<i64>,
    /// The frames, as a farm names them.
    pub frames: Option<FrameSelection>,
    /// The part of the frames this machine takes.
    pub shard: Option<Shard>,
}

impl FrameChoice {
    /// True when anything narrows the frames (a single file takes none of it).
    pub fn is_given(&self) -> bool {
        *self != FrameChoice::default()
    }
}

/// The frames of `input` that `choice` takes, in increasing frame order. `input` is a
/// `{}` pattern or a `.pvd` collection ([`collection_frames`]). With a
/// [`FrameSelection`] a pattern's directory is scanned (any zero padding is matched) and
/// every selected frame must have a file; a [`Shard`] then takes its part. A shard that
/// gets no frame is an error.
pub fn choose(input: &str, choice: &FrameChoice) -> Result<Vec<Frame>> {
    if choice.frames.is_some() && (choice.start.is_some() || choice.end.is_some()) {
        return Err(Error::InvalidOption {
            option: "frames",
            message: "takes the place of start/end; give one or the other".into(),
        });
    }
    let found = if is_collection(input) {
        collection::choose(Path::new(input), choice)?
    } else {
        match &choice.frames {
            Some(selection) => select_from_pattern(input, selection)?,
            None => frames(input, choice.start, choice.end)?,
        }
    };
    match choice.shard {
        Some(shard) => {
            let taken = shard.take(&found);
            if taken.is_empty() {
                return Err(Error::InvalidOption {
                    option: "shard",
                    message: format!(
                        "shard {shard} of {} frames is empty (more shards than frames)",
                        found.len()
                    ),
                });
            }
            Ok(taken)
        }
        None => Ok(found),
    }
}

/// The frames of `pattern` that `selection` names; each needs a file.
fn select_from_pattern(pattern: &str, selection: &FrameSelection) -> Result<Vec<Frame>> {
    let scanned = match frames(pattern, None, None) {
        Ok(f) => f,
        Err(Error::Io { source, .. }) if source.kind() == std::io::ErrorKind::NotFound => {
            Vec::new()
        }
        Err(e) => return Err(e),
    };
    let found: Vec<Frame> = scanned
        .into_iter()
        .filter(|f| selection.contains(f.number))
        .collect();
    let missing: Vec<i64> = selection
        .numbers()
        .iter()
        .copied()
        .filter(|n| found.binary_search_by_key(n, |f| f.number).is_err())
        .collect();
    if !missing.is_empty() {
        return Err(unselectable(
            Path::new(pattern),
            &missing,
            selection,
            "no file for",
            "",
        ));
    }
    Ok(found)
}

/// The error for selected frames that `source` does not have: "`what` 3 of the 10
/// selected frames: 4, 5, 9`after`" (the first ten listed).
fn unselectable(
    source: &Path,
    missing: &[i64],
    selection: &FrameSelection,
    what: &str,
    after: &str,
) -> Error {
    const SHOWN: usize = 10;
    let mut list: Vec<String> = missing.iter().take(SHOWN).map(|n| n.to_string()).collect();
    if missing.len() > SHOWN {
        list.push("…".into());
    }
    Error::io(
        source,
        std::io::Error::new(
            std::io::ErrorKind::NotFound,
            format!(
                "{what} {} of the {} selected frames: {}{after}",
                missing.len(),
                selection.numbers().len(),
                list.join(", ")
            ),
        ),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_placeholder_of_an_output_pattern_is_replaced() {
        assert_eq!(
            substitute("out/{}/frame_{}.ply", "0042"),
            PathBuf::from("out/0042/frame_0042.ply")
        );
    }

    #[test]
    fn scan_sorts_numerically_and_keeps_padding() {
        let dir = tempfile::tempdir().unwrap();
        for name in ["f_10.xyz", "f_9.xyz", "f_0002.xyz", "f_x.xyz", "g_1.xyz"] {
            std::fs::write(dir.path().join(name), b"").unwrap();
        }
        let pattern = format!("{}/f_{{}}.xyz", dir.path().display());
        let frames = frames(&pattern, None, None).unwrap();
        let labels: Vec<&str> = frames.iter().map(|f| f.label.as_str()).collect();
        assert_eq!(labels, ["0002", "9", "10"]);
        let ranged = super::frames(&pattern, Some(9), None).unwrap();
        assert_eq!(ranged.len(), 2);
        assert!(
            super::frames(&pattern, Some(9), Some(11)).is_err(),
            "frame 11 is missing"
        );
        assert_eq!(
            substitute("out/s_{}.ply", "0002"),
            PathBuf::from("out/s_0002.ply")
        );
    }

    fn selected(text: &str) -> Vec<i64> {
        text.parse::<FrameSelection>()
            .unwrap_or_else(|e| panic!("{text:?}: {e}"))
            .numbers()
            .to_vec()
    }

    #[test]
    fn frame_selection_grammar() {
        assert_eq!(selected("7"), [7]);
        assert_eq!(selected("1-5"), [1, 2, 3, 4, 5]);
        assert_eq!(selected("1-10:3"), [1, 4, 7, 10]);
        assert_eq!(selected("1-9:4"), [1, 5, 9]);
        assert_eq!(selected("1-8:4"), [1, 5], "the last frame need not be hit");
        assert_eq!(selected("1,5,7-9"), [1, 5, 7, 8, 9]);
        assert_eq!(selected(" 1 , 3 "), [1, 3]);
        assert_eq!(selected("-3--1,-5"), [-5, -3, -2, -1]);
        assert_eq!(selected("-2-1"), [-2, -1, 0, 1]);
        assert_eq!(selected("4-4"), [4]);
        // Overlaps once each, sorted.
        assert_eq!(selected("5-8,1-6,7,2"), [1, 2, 3, 4, 5, 6, 7, 8]);
        assert_eq!(selected("1-9:2,2-10:2"), (1..=10).collect::<Vec<_>>());
        assert_eq!(
            selected("0-1000000:1000").len(),
            1001,
            "a step keeps large ranges small"
        );
    }

    #[test]
    fn frame_selection_refuses_what_selects_nothing_or_is_garbage() {
        for (text, says) in [
            ("", "empty"),
            ("  ", "empty"),
            ("1,,3", "empty item"),
            ("1,", "empty item"),
            ("10-1", "reversed"),
            ("1-10:0", "step must be at least 1"),
            ("1-10:-2", "step must be at least 1"),
            ("5:2", "a step needs a range"),
            ("a", "\"a\" is not a frame number"),
            ("1-b", "\"b\" is not a frame number"),
            ("1-", "\"\" is not a frame number"),
            ("1-2-3", "\"2-3\" is not a frame number"),
            ("1..5", "is not a frame number"),
            ("1-5:x", "\"x\" is not a frame number"),
            ("99999999999999999999", "out of range"),
            ("0-100000000", "more than"),
        ] {
            let e = text.parse::<FrameSelection>().unwrap_err();
            assert!(e.contains(says), "{text:?}: {e}");
            if !text.trim().is_empty() {
                assert!(e.contains(&format!("{text:?}")), "names the text: {e}");
            }
        }
    }

    #[test]
    fn shards_grammar() {
        assert_eq!("0/1".parse(), Ok(Shard { index: 0, count: 1 }));
        assert_eq!("3/4".parse(), Ok(Shard { index: 3, count: 4 }));
        for (text, says) in [
            ("4/4", "does not exist"),
            ("0/0", "at least 1"),
            ("1", "not a shard"),
            ("-1/4", "not a shard"),
            ("a/4", "not a shard"),
            ("1/4/2", "not a shard"),
            ("/4", "not a shard"),
        ] {
            let e = text.parse::<Shard>().unwrap_err();
            assert!(e.contains(says) && e.contains(text), "{text:?}: {e}");
        }
    }

    #[test]
    fn shards_are_round_robin_and_their_union_is_the_selection() {
        let selection: FrameSelection = "1-100:3,7,200-211".parse().unwrap();
        let all = selection.numbers();
        for count in 1..=9 {
            let mut union: Vec<i64> = Vec::new();
            let mut sizes = Vec::new();
            for index in 0..count {
                let part = Shard { index, count }.take(all);
                assert!(part.windows(2).all(|w| w[0] < w[1]), "increasing");
                sizes.push(part.len());
                union.extend(part);
            }
            assert_eq!(union.len(), all.len(), "{count} shards: no frame twice");
            union.sort_unstable();
            assert_eq!(union, all, "{count} shards: every frame");
            // Balanced: sizes differ by at most one.
            assert!(sizes.iter().max().unwrap() - sizes.iter().min().unwrap() <= 1);
        }
        assert_eq!(
            Shard { index: 1, count: 3 }.take(&[10, 20, 30, 40, 50]),
            [20, 50]
        );
    }

    #[test]
    fn choosing_frames_by_selection_and_shard() {
        let dir = tempfile::tempdir().unwrap();
        for name in [
            "f_0001.xyz",
            "f_0002.xyz",
            "f_0003.xyz",
            "f_0005.xyz",
            "f_0009.xyz",
        ] {
            std::fs::write(dir.path().join(name), b"").unwrap();
        }
        let pattern = format!("{}/f_{{}}.xyz", dir.path().display());
        let choice = |frames: Option<&str>, shard: Option<&str>| FrameChoice {
            frames: frames.map(|f| f.parse().unwrap()),
            shard: shard.map(|s| s.parse().unwrap()),
            ..FrameChoice::default()
        };
        let numbers = |c: &FrameChoice| -> Vec<i64> {
            choose(&pattern, c)
                .unwrap()
                .iter()
                .map(|f| f.number)
                .collect()
        };
        assert_eq!(numbers(&choice(Some("1-3,9"), None)), [1, 2, 3, 9]);
        assert_eq!(numbers(&choice(Some("1-9:4"), None)), [1, 5, 9]);
        assert_eq!(
            choose(&pattern, &choice(Some("9"), None)).unwrap()[0].label,
            "0009"
        );
        assert_eq!(numbers(&choice(Some("1-3,9"), Some("1/2"))), [2, 9]);
        assert_eq!(numbers(&choice(None, Some("0/2"))), [1, 3, 9]);
        let missing = choose(&pattern, &choice(Some("1-4,6"), None))
            .unwrap_err()
            .to_string();
        assert!(
            missing.contains("no file for 2 of the 5 selected frames: 4, 6"),
            "{missing}"
        );
        let empty = choose(&pattern, &choice(Some("1-2"), Some("2/3")))
            .unwrap_err()
            .to_string();
        assert!(empty.contains("shard 2/3 of 2 frames is empty"), "{empty}");
        let both = FrameChoice {
            start: Some(1),
            ..choice(Some("1"), None)
        };
        assert!(matches!(
            choose(&pattern, &both),
            Err(Error::InvalidOption {
                option: "frames",
                ..
            })
        ));
    }

    #[test]
    fn patterns_need_one_placeholder_in_the_file_name() {
        assert!(frames("a/{}/b.xyz", None, None).is_err());
        assert!(frames("a/b_{}_{}.xyz", None, None).is_err());
        assert!(frames("a/b.xyz", None, None).is_err());
    }
}
