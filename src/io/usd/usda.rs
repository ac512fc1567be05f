//! The text stage: each property's samples are spooled, as the text they become, to an
//! anonymous temporary file beside the output; at the end the layer is written with each
//! property's `timeSamples` block copied from its spool.

use super::stage::{Element, Meta, Prim, Property, Series, Value, Values};
use super::{Encoder, StageEnd};
use std::fmt::Write as _;
use std::fs::File;
use std::io::{self, BufWriter, Seek, SeekFrom, Write};
use std::path::PathBuf;

/// Text buffered before it goes to a file.
const CHUNK: usize = 1 << 16;

/// Indentation of the samples in a `timeSamples` block (the fluid's and the instancer's
/// properties are two prims deep).
const SAMPLE_INDENT: &str = "                ";

/// The samples of one property, as text.
struct Spool {
    file: BufWriter<File>,
    /// Which slots have a sample.
    sampled: Vec<bool>,
}

/// Text encoder of a stage.
pub(super) struct UsdaEncoder {
    out: BufWriter<File>,
    /// Directory of the spools (the output's).
    dir: PathBuf,
    spools: Vec<Option<Spool>>,
}

impl UsdaEncoder {
    /// Starts the text stage in `file`, spooling in `dir`.
    pub(super) fn new(file: File, dir: PathBuf) -> Self {
        UsdaEncoder {
            out: BufWriter::with_capacity(1 << 20, file),
            dir,
            spools: Vec::new(),
        }
    }
}

/// `v` in the shortest text that reads back as the same `f32` when parsed as a double
/// and rounded to float (as USD's text parser does), else with 9 significant digits
/// (always exact).
fn push_f32(text: &mut String, v: f32) {
    if !v.is_finite() {
        text.push_str(if v.is_nan() {
            "nan"
        } else if v > 0.0 {
            "inf"
        } else {
            "-inf"
        });
        return;
    }
    let start = text.len();
    let _ = write!(text, "{v:?}");
    let exact = text[start..]
        .parse::<f64>()
        .is_ok_and(|d| (d as f32).to_bits() == v.to_bits());
    if !exact {
        text.truncate(start);
        let _ = write!(text, "{v:.8e}");
    }
}

/// Writes `values` as a USD array of `element` (`[1, 2]`, `[(x, y, z), …]`) to `out`.
fn write_array(out: &mut impl Write, element: Element, values: Values<'_>) -> io::Result<()> {
    let mut text = String::with_capacity(CHUNK + 256);
    text.push('[');
    let width = element.width();
    let mut first = true;
    let mut separator = |text: &mut String| {
        if !std::mem::take(&mut first) {
            text.push_str(", ");
        }
    };
    if width == 0 {
        for v in values.ints() {
            separator(&mut text);
            let _ = write!(text, "{v}");
            if text.len() >= CHUNK {
                out.write_all(text.as_bytes())?;
                text.clear();
            }
        }
    } else {
        let mut item = 0;
        for v in values.floats() {
            if item == 0 {
                separator(&mut text);
                if width > 1 {
                    text.push('(');
                }
            } else {
                text.push_str(", ");
            }
            push_f32(&mut text, v);
            item += 1;
            if item == width {
                if width > 1 {
                    text.push(')');
                }
                item = 0;
                if text.len() >= CHUNK {
                    out.write_all(text.as_bytes())?;
                    text.clear();
                }
            }
        }
    }
    text.push(']');
    out.write_all(text.as_bytes())
}

/// A time code as text (frame numbers are integers).
fn time_text(time: f64) -> String {
    format!("{time}")
}

impl Encoder for UsdaEncoder {
    fn sample(
        &mut self,
        index: usize,
        series: &Series,
        slot: usize,
        time: f64,
        values: Values<'_>,
    ) -> io::Result<()> {
        if self.spools.len() <= index {
            self.spools.resize_with(index + 1, || None);
        }
        let spool = match &mut self.spools[index] {
            Some(s) => s,
            empty => empty.insert(Spool {
                file: BufWriter::with_capacity(1 << 20, tempfile::tempfile_in(&self.dir)?),
                sampled: Vec::new(),
            }),
        };
        write!(spool.file, "{SAMPLE_INDENT}{}: ", time_text(time))?;
        write_array(&mut spool.file, series.element, values)?;
        spool.file.write_all(b",\n")?;
        if spool.sampled.len() <= slot {
            spool.sampled.resize(slot + 1, false);
        }
        spool.sampled[slot] = true;
        Ok(())
    }

    fn finish(mut self: Box<Self>, end: &StageEnd<'_>) -> io::Result<u64> {
        let mut spools = std::mem::take(&mut self.spools);
        let out = &mut self.out;
        writeln!(out, "#usda 1.0\n(")?;
        for (name, meta) in &end.metadata {
            let name = if *name == "documentation" {
                "doc"
            } else {
                name
            };
            match meta {
                Meta::Token(t) | Meta::Text(t) => writeln!(out, "    {name} = \"{}\"", escape(t))?,
                Meta::Double(d) => writeln!(out, "    {name} = {d:?}")?,
            }
        }
        writeln!(out, ")\n")?;
        let mut text = TextTree {
            out,
            spools: &mut spools,
            times: end.times,
            series: end.series,
        };
        text.prim(&end.tree, 0)?;
        self.out.flush()?;
        let file = self.out.into_inner().map_err(|e| e.into_error())?;
        Ok(file.metadata()?.len())
    }
}

/// `s` with quotes and backslashes escaped for a quoted string.
fn escape(s: &str) -> String {
    s.replace('\\', "\\\\").replace('"', "\\\"")
}

/// Writes the prim tree.
struct TextTree<'a, W: Write> {
    out: &'a mut W,
    spools: &'a mut Vec<Option<Spool>>,
    times: &'a [f64],
    series: &'a [Series],
}

impl<W: Write> TextTree<'_, W> {
    fn prim(&mut self, prim: &Prim<'_>, depth: usize) -> io::Result<()> {
        let pad = "    ".repeat(depth);
        writeln!(
            self.out,
            "{pad}def {} \"{}\"\n{pad}{{",
            prim.type_name, prim.name
        )?;
        for property in &prim.properties {
            self.property(property, &format!("{pad}    "))?;
        }
        for (k, child) in prim.children.iter().enumerate() {
            if k > 0 || !prim.properties.is_empty() {
                writeln!(self.out)?;
            }
            self.prim(child, depth + 1)?;
        }
        writeln!(self.out, "{pad}}}")
    }

    /// The metadata block of a property (`interpolation`, `elementSize`), or nothing.
    fn metadata(property: &Property<'_>, element: Element, pad: &str) -> String {
        let mut lines = Vec::new();
        if let Some(i) = property.interpolation {
            lines.push(format!("{pad}    interpolation = \"{i}\""));
        }
        if let Some(n) = element.element_size() {
            lines.push(format!("{pad}    elementSize = {n}"));
        }
        if lines.is_empty() {
            String::new()
        } else {
            format!(" (\n{}\n{pad})", lines.join("\n"))
        }
    }

    fn property(&mut self, property: &Property<'_>, pad: &str) -> io::Result<()> {
        let name = &property.name;
        match &property.value {
            Value::UniformToken(t) => writeln!(self.out, "{pad}uniform token {name} = \"{t}\""),
            Value::Targets(targets) => {
                let list: Vec<String> = targets.iter().map(|t| format!("<{t}>")).collect();
                writeln!(self.out, "{pad}rel {name} = [{}]", list.join(", "))
            }
            Value::Array(element, values) => {
                write!(self.out, "{pad}{} {name} = ", element.type_name())?;
                write_array(self.out, *element, *values)?;
                writeln!(self.out, "{}", Self::metadata(property, *element, pad))
            }
            Value::Series(i) => self.series(*i, property, pad),
        }
    }

    /// A time-sampled property: its declaration with metadata, then its samples (an empty
    /// array for every frame that had none).
    fn series(&mut self, i: usize, property: &Property<'_>, pad: &str) -> io::Result<()> {
        let element = self.series[i].element;
        let (type_name, name) = (element.type_name(), &property.name);
        let metadata = Self::metadata(property, element, pad);
        if !metadata.is_empty() {
            writeln!(self.out, "{pad}{type_name} {name}{metadata}")?;
        }
        writeln!(self.out, "{pad}{type_name} {name}.timeSamples = {{")?;
        let mut sampled = Vec::new();
        if let Some(spool) = self.spools.get_mut(i).and_then(Option::take) {
            let mut file = spool.file.into_inner().map_err(|e| e.into_error())?;
            file.seek(SeekFrom::Start(0))?;
            io::copy(&mut file, self.out)?;
            sampled = spool.sampled;
        }
        for (slot, &time) in self.times.iter().enumerate() {
            if !sampled.get(slot).copied().unwrap_or(false) {
                writeln!(self.out, "{SAMPLE_INDENT}{}: [],", time_text(time))?;
            }
        }
        writeln!(self.out, "{pad}}}")
    }
}
