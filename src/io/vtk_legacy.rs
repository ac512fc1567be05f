//! The legacy VTK grammar (`# vtk DataFile Version x.y`), shared by the particle reader
//! (whole-file and streaming scan) and the mesh reader: header, scalar types and the
//! section headers they parse the same way. Each reader walks the sections itself; the
//! token source behind [`Tokens`] decides what a failure is (an error with its message,
//! or, for the scan, a layout it leaves to the whole-file reader).

use crate::error::Error;
use crate::io::text::{Cursor, Scalar};
use std::str::FromStr;

/// The value type named `name` (case-insensitive); `None` for `bit` and unknown names.
pub(crate) fn scalar_type(name: &str) -> Option<Scalar> {
    Some(match name.to_ascii_lowercase().as_str() {
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

/// A source of legacy VTK tokens: `expected` names what a token should be, for messages.
pub(crate) trait Tokens {
    type Error;
    /// The next whitespace-separated token.
    fn next_word(&mut self, expected: &str) -> Result<String, Self::Error>;
    /// The next token as a number.
    fn next_number<T: FromStr>(&mut self, expected: &str) -> Result<T, Self::Error>;
    /// The rest of the current line, consuming its newline.
    fn next_line(&mut self) -> Result<String, Self::Error>;
    /// Whether no byte is left (whitespace included).
    fn is_eof(&mut self) -> Result<bool, Self::Error>;
    /// Before a block of values: a binary block starts on the next line.
    fn block_start(&mut self, binary: bool) -> Result<(), Self::Error>;
    /// Skips `count` values of `scalar` (binary: big-endian).
    fn skip_block(&mut self, count: usize, scalar: Scalar, binary: bool)
        -> Result<(), Self::Error>;
    /// A grammar failure here.
    fn fail(&self, message: String) -> Self::Error;
    /// The first line is not a legacy VTK version line.
    fn not_vtk(&self, first_line: &str) -> Self::Error;
}

impl Tokens for Cursor<'_> {
    type Error = Error;

    fn next_word(&mut self, expected: &str) -> Result<String, Error> {
        self.token(expected).map(str::to_string)
    }

    fn next_number<T: FromStr>(&mut self, expected: &str) -> Result<T, Error> {
        self.number(expected)
    }

    fn next_line(&mut self) -> Result<String, Error> {
        self.line().map(str::to_string)
    }

    fn is_eof(&mut self) -> Result<bool, Error> {
        Ok(self.pos >= self.bytes.len())
    }

    fn block_start(&mut self, binary: bool) -> Result<(), Error> {
        if binary {
            self.finish_line();
        }
        Ok(())
    }

    fn skip_block(&mut self, count: usize, scalar: Scalar, binary: bool) -> Result<(), Error> {
        self.skip_values(count, scalar, binary.then_some(true))
    }

    fn fail(&self, message: String) -> Error {
        self.error(message)
    }

    fn not_vtk(&self, first_line: &str) -> Error {
        Error::parse(
            self.path,
            "line 1",
            format!("not a legacy VTK file: first line is {first_line:?}"),
        )
    }
}

/// The three header lines.
pub(crate) struct Header {
    /// Version 5 or later: cells as `OFFSETS` and `CONNECTIVITY` arrays.
    pub new_cells: bool,
    /// BINARY (big-endian), else ASCII.
    pub binary: bool,
}

/// Parses the version, title and encoding lines at the start of `t`.
pub(crate) fn header<T: Tokens>(t: &mut T) -> Result<Header, T::Error> {
    let version = t.next_line()?;
    if !version.starts_with("# vtk DataFile Version") {
        return Err(t.not_vtk(&version));
    }
    let new_cells = version
        .rsplit(' ')
        .next()
        .and_then(|v| v.parse::<f32>().ok())
        .is_some_and(|v| v >= 5.0);
    t.next_line()?; // title
    let binary = match t.next_line()?.trim().to_ascii_uppercase().as_str() {
        "BINARY" => true,
        "ASCII" => false,
        other => return Err(t.fail(format!("expected ASCII or BINARY, found {other:?}"))),
    };
    Ok(Header { new_cells, binary })
}

/// A type token: `unsupported {label} {ty:?}` when it names no known type.
pub(crate) fn scalar<T: Tokens>(
    t: &mut T,
    expected: &str,
    label: &str,
) -> Result<Scalar, T::Error> {
    let ty = t.next_word(expected)?;
    scalar_type(&ty).ok_or_else(|| t.fail(format!("unsupported {label} {ty:?}")))
}

/// After `POINTS`: the count and the type (`expected` names the type token).
pub(crate) fn points<T: Tokens>(t: &mut T, expected: &str) -> Result<(usize, Scalar), T::Error> {
    let n: usize = t.next_number("the point count")?;
    Ok((n, scalar(t, expected, "point type")?))
}

/// Skips a cell section (`VERTICES`, `LINES`, `POLYGONS`, `TRIANGLE_STRIPS`, `CELLS`)
/// after its keyword, in the classic or the 5.x layout.
pub(crate) fn skip_cells<T: Tokens>(
    t: &mut T,
    new_cells: bool,
    binary: bool,
) -> Result<(), T::Error> {
    let n: usize = t.next_number("the cell count")?;
    let size: usize = t.next_number("the cell list size")?;
    if new_cells {
        for _ in 0..2 {
            let part = t.next_word("OFFSETS or CONNECTIVITY")?;
            let scalar = scalar(t, "an index type", &format!("{part} type"))?;
            t.block_start(binary)?;
            let count = if part.eq_ignore_ascii_case("OFFSETS") {
                n
            } else {
                size
            };
            t.skip_block(count, scalar, binary)?;
        }
    } else {
        t.block_start(binary)?;
        t.skip_block(size, Scalar::I32, binary)?;
    }
    Ok(())
}

/// Skips a `CELL_TYPES` section after its keyword.
pub(crate) fn skip_cell_types<T: Tokens>(t: &mut T, binary: bool) -> Result<(), T::Error> {
    let n: usize = t.next_number("the cell count")?;
    t.block_start(binary)?;
    t.skip_block(n, Scalar::I32, binary)
}

/// The rest of a `SCALARS` header after its type: the optional component count on the same
/// line, then `LOOKUP_TABLE name`.
pub(crate) fn scalars_tail<T: Tokens>(t: &mut T) -> Result<usize, T::Error> {
    let rest = t.next_line()?.trim().to_string();
    let components = if rest.is_empty() {
        1
    } else {
        rest.parse()
            .map_err(|_| t.fail(format!("bad component count {rest:?}")))?
    };
    let table = t.next_word("LOOKUP_TABLE")?;
    if !table.eq_ignore_ascii_case("LOOKUP_TABLE") {
        return Err(t.fail(format!(
            "expected LOOKUP_TABLE after SCALARS, found {table:?}"
        )));
    }
    t.next_word("a lookup table name")?;
    Ok(components)
}

/// Whether `keyword` (upper case) starts a data array: `SCALARS`, `VECTORS`, `NORMALS`,
/// `TENSORS`, `COLOR_SCALARS` or `TEXTURE_COORDINATES`.
pub(crate) fn is_attribute(keyword: &str) -> bool {
    matches!(
        keyword,
        "SCALARS" | "VECTORS" | "NORMALS" | "TENSORS" | "COLOR_SCALARS" | "TEXTURE_COORDINATES"
    )
}

/// A particle attribute header after its keyword (`SCALARS`, `VECTORS`, `NORMALS`,
/// `TENSORS`, `COLOR_SCALARS`, `TEXTURE_COORDINATES`): name, components, value type.
/// `COLOR_SCALARS` are unsigned bytes.
pub(crate) fn attribute<T: Tokens>(
    t: &mut T,
    keyword: &str,
) -> Result<(String, usize, Scalar), T::Error> {
    let name = t.next_word("an attribute name")?;
    let (components, scalar) = match keyword {
        "SCALARS" => {
            let scalar = scalar(t, "a scalar type", "type")?;
            (scalars_tail(t)?, scalar)
        }
        "VECTORS" | "NORMALS" => (3, scalar(t, "a vector type", "type")?),
        "TENSORS" => (9, scalar(t, "a tensor type", "type")?),
        "COLOR_SCALARS" => (t.next_number("a component count")?, Scalar::U8),
        _ => {
            let d: usize = t.next_number("a dimension")?;
            (d, scalar(t, "a type", "type")?)
        }
    };
    Ok((name, components, scalar))
}

/// After `FIELD`: the field name and the array count.
pub(crate) fn field<T: Tokens>(t: &mut T) -> Result<usize, T::Error> {
    t.next_word("a field name")?;
    t.next_number("the array count")
}

/// One `FIELD` array header, up to its block: name, components, tuples, value type
/// (`expected` and `label` name the type token, as in [`scalar`]).
pub(crate) fn field_array<T: Tokens>(
    t: &mut T,
    binary: bool,
    expected: &str,
    label: &str,
) -> Result<(String, usize, usize, Scalar), T::Error> {
    let name = t.next_word("an array name")?;
    let components: usize = t.next_number("a component count")?;
    let tuples: usize = t.next_number("a tuple count")?;
    let scalar = scalar(t, expected, label)?;
    t.block_start(binary)?;
    Ok((name, components, tuples, scalar))
}

/// Skips a `METADATA` block, up to the blank line that ends it.
pub(crate) fn skip_metadata<T: Tokens>(t: &mut T) -> Result<(), T::Error> {
    loop {
        if t.is_eof()? || t.next_line()?.trim().is_empty() {
            return Ok(());
        }
    }
}
