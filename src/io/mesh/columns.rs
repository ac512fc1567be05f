//! How per-vertex attributes are named in each mesh format, written and read back.
//!
//! | components | PLY properties | glTF semantics | VTK point data |
//! |---|---|---|---|
//! | 1 | `name` | `_NAME` (SCALAR) | `SCALARS name float 1` |
//! | 2 | `name_x name_y` | `_NAME` (VEC2) | `FIELD` array |
//! | 3 | `name_x name_y name_z` | `_NAME` (VEC3) | `VECTORS name float` |
//! | 4 | `name_x name_y name_z name_w` | `_NAME` (VEC4) | `FIELD` array |
//! | k ≥ 5 | `name_0 … name_{k-1}` | `_NAME_0 … _NAME_{k-1}` (SCALAR each) | `FIELD` array |
//!
//! Whitespace in a name becomes `_` (PLY and VTK names are single words); glTF names are
//! upper-cased with every character outside `[A-Za-z0-9_]` replaced by `_`, and come back
//! lower-cased.

use crate::attributes::Attribute;
use crate::error::{Error, Result};
use crate::mesh::{Surface, TriMesh};
use std::path::Path;

/// Component suffixes of 2-, 3- and 4-component attributes in PLY.
const XYZW: [&str; 4] = ["x", "y", "z", "w"];

/// The name as a single word (PLY property, VTK array).
pub(super) fn word(name: &str) -> String {
    name.chars()
        .map(|c| if c.is_whitespace() { '_' } else { c })
        .collect()
}

/// PLY property names of an attribute, one per component.
pub(super) fn ply_names(a: &Attribute) -> Vec<String> {
    let name = word(&a.name);
    match a.components {
        1 => vec![name],
        2..=4 => XYZW[..a.components]
            .iter()
            .map(|s| format!("{name}_{s}"))
            .collect(),
        k => (0..k).map(|c| format!("{name}_{c}")).collect(),
    }
}

/// glTF semantics of an attribute: one accessor of 1–4 components, or one scalar accessor
/// per component beyond that.
pub(super) fn gltf_semantics(a: &Attribute) -> Vec<String> {
    let name: String = a
        .name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() {
                c.to_ascii_uppercase()
            } else {
                '_'
            }
        })
        .collect();
    if a.components <= 4 {
        vec![format!("_{name}")]
    } else {
        (0..a.components).map(|c| format!("_{name}_{c}")).collect()
    }
}

/// Names the format reserves: an attribute may not take them.
fn reserved(format: Column) -> &'static [&'static str] {
    match format {
        Column::Ply => &["x", "y", "z", "nx", "ny", "nz"],
        Column::Gltf | Column::Vtk => &[],
    }
}

/// The naming scheme of a format.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(super) enum Column {
    Ply,
    Gltf,
    Vtk,
}

/// Checks that every attribute of `list` holds `items` items (`what` names the owner in
/// the message) and that its names in `format` are free and distinct.
fn check_list(
    path: &Path,
    list: &[Attribute],
    items: usize,
    what: &str,
    format: Option<Column>,
) -> Result<()> {
    let refuse = |message: String| Error::UnsupportedFormat {
        path: path.to_path_buf(),
        message,
    };
    let mut taken: Vec<String> = Vec::new();
    for a in list {
        if a.name.trim().is_empty() {
            return Err(refuse(format!("{what} has an attribute without a name")));
        }
        if a.components == 0 || a.values.len() != a.components * items {
            return Err(refuse(format!(
                "attribute {:?} of {what} holds {} values, not {} components × {items} items",
                a.name,
                a.values.len(),
                a.components
            )));
        }
        let names = match format {
            Some(Column::Ply) => ply_names(a),
            Some(Column::Gltf) => gltf_semantics(a),
            Some(Column::Vtk) => vec![word(&a.name)],
            None => continue,
        };
        for n in names {
            let clash =
                reserved(format.expect("a format")).contains(&n.as_str()) || taken.contains(&n);
            if clash {
                return Err(refuse(format!(
                    "attribute {:?} of {what} would be written as {n:?}, a name already taken in this format; rename it",
                    a.name
                )));
            }
            taken.push(n);
        }
    }
    Ok(())
}

/// Checks the attributes of a surface before it is written in a format naming them by
/// `format` (`None`: the format drops them, only the sizes are checked).
pub(super) fn check_surface(path: &Path, s: &Surface, format: Option<Column>) -> Result<()> {
    check_list(
        path,
        &s.fluid.attributes,
        s.fluid.vertex_count(),
        "the fluid mesh",
        format,
    )?;
    check_list(
        path,
        &s.spheres.attributes,
        s.spheres.centers.len(),
        "the sphere instances",
        format,
    )
}

/// Checks the attributes of sequence frames before they are written as glTF.
pub(super) fn check_frames(path: &Path, frames: &[(i64, TriMesh)]) -> Result<()> {
    for (number, f) in frames {
        check_list(
            path,
            &f.attributes,
            f.vertex_count(),
            &format!("frame {number}"),
            Some(Column::Gltf),
        )?;
    }
    Ok(())
}

/// Names of all attributes of a surface, each once, fluid first.
pub(super) fn all_names(s: &Surface) -> Vec<String> {
    let mut names: Vec<String> = Vec::new();
    for a in s.fluid.attributes.iter().chain(&s.spheres.attributes) {
        if !names.contains(&a.name) {
            names.push(a.name.clone());
        }
    }
    names
}

/// Regroups named scalar columns (PLY properties, glTF scalar accessors) into attributes:
/// `name_x name_y [name_z [name_w]]` in this order (when `xyzw`) and `name_0 … name_k`
/// (k ≥ 4) become one attribute of 2, 3, 4 or k + 1 components named `name`; any other
/// column is a scalar attribute named as it is. The result keeps the columns' order.
pub(super) fn regroup(columns: Vec<(String, Vec<f32>)>, xyzw: bool) -> Vec<Attribute> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < columns.len() {
        let take = group_len(&columns[i..], xyzw);
        if take > 1 {
            let name = columns[i]
                .0
                .rsplit_once('_')
                .expect("suffixed")
                .0
                .to_string();
            let group = &columns[i..i + take];
            let n = group[0].1.len();
            let mut values = Vec::with_capacity(n * take);
            for v in 0..n {
                values.extend(group.iter().map(|(_, col)| col[v]));
            }
            out.push(Attribute {
                name,
                components: take,
                values,
            });
            i += take;
        } else {
            let (name, values) = columns[i].clone();
            out.push(Attribute {
                name,
                components: 1,
                values,
            });
            i += 1;
        }
    }
    out
}

/// How many of the leading columns form one attribute (1 when they do not group).
fn group_len(columns: &[(String, Vec<f32>)], xyzw: bool) -> usize {
    let Some((base, _)) = columns[0].0.rsplit_once('_') else {
        return 1;
    };
    if base.is_empty() {
        return 1;
    }
    let suffix = |j: usize| -> Option<&str> {
        let name = &columns.get(j)?.0;
        let rest = name.strip_prefix(base)?.strip_prefix('_')?;
        Some(rest)
    };
    if xyzw && suffix(0) == Some("x") && suffix(1) == Some("y") {
        let mut k = 2;
        while k < 4 && suffix(k) == Some(XYZW[k]) {
            k += 1;
        }
        return k;
    }
    let digits = |j: usize| suffix(j).map(|s| s == j.to_string()).unwrap_or(false);
    let mut k = 0;
    while digits(k) {
        k += 1;
    }
    if k >= 5 {
        k
    } else {
        1
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn attr(name: &str, components: usize) -> Attribute {
        Attribute {
            name: name.into(),
            components,
            values: (0..components * 2).map(|v| v as f32).collect(),
        }
    }

    #[test]
    fn names_follow_the_component_count() {
        assert_eq!(ply_names(&attr("density", 1)), ["density"]);
        assert_eq!(ply_names(&attr("uv", 2)), ["uv_x", "uv_y"]);
        assert_eq!(
            ply_names(&attr("velocity", 3)),
            ["velocity_x", "velocity_y", "velocity_z"]
        );
        assert_eq!(ply_names(&attr("q", 4)), ["q_x", "q_y", "q_z", "q_w"]);
        assert_eq!(ply_names(&attr("s", 5))[4], "s_4");
        assert_eq!(gltf_semantics(&attr("velocity", 3)), ["_VELOCITY"]);
        assert_eq!(gltf_semantics(&attr("my temp", 1)), ["_MY_TEMP"]);
        assert_eq!(gltf_semantics(&attr("s", 6))[5], "_S_5");
    }

    #[test]
    fn columns_regroup_into_the_written_attributes() {
        for a in [
            attr("density", 1),
            attr("uv", 2),
            attr("velocity", 3),
            attr("q", 4),
            attr("stress", 6),
        ] {
            let names = ply_names(&a);
            let columns = names
                .iter()
                .enumerate()
                .map(|(c, n)| (n.clone(), (0..2).map(|i| a.item(i)[c]).collect()))
                .collect();
            assert_eq!(regroup(columns, true), vec![a]);
        }
        // Neither a lone `_x` nor a short digit run groups; `_z` without `_y` ends a group.
        let col = |n: &str| (n.to_string(), vec![1.0]);
        let got = regroup(
            vec![
                col("a_x"),
                col("b_0"),
                col("b_1"),
                col("c_x"),
                col("c_y"),
                col("c_w"),
            ],
            true,
        );
        let names: Vec<_> = got
            .iter()
            .map(|a| (a.name.as_str(), a.components))
            .collect();
        assert_eq!(
            names,
            [("a_x", 1), ("b_0", 1), ("b_1", 1), ("c", 2), ("c_w", 1)]
        );
        let got = regroup(vec![col("c_x"), col("c_y")], false);
        assert_eq!(got.len(), 2);
    }
}
