//! Keyword options. The reconstruction settings, which `reconstruct` and
//! `reconstruct_file` both take as `**options`, are read here and only here into the
//! library's [`ReconstructSettings`] (the CLI's flags go through the same struct); the
//! frame choice of `reconstruct_file` into [`FrameChoice`].

use meniscus::field::Kernel;
use meniscus::sequence::{FrameChoice, FrameSelection, Shard};
use meniscus::settings::{Decimation, Preset, ReconstructSettings};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

/// The reconstruction settings taken as keywords, in the order of the stubs: the
/// library's one list of them.
pub use meniscus::settings::SETTINGS;

/// The preset a function's `preset` keyword names (`None`: the function's own choice).
pub fn preset(name: Option<&str>) -> PyResult<Option<Preset>> {
    name.map(|n| {
        n.parse()
            .map_err(|e| PyValueError::new_err(format!("invalid preset: {e}")))
    })
    .transpose()
}

/// The keywords that turn the defaults (the `still` preset's) into `preset`'s
/// (`meniscus.PAPER`, `meniscus.STEADY`): the settings where
/// [`Preset::settings`] differs from [`ReconstructSettings::new`].
pub fn preset_keywords<'py>(py: Python<'py>, preset: Preset) -> PyResult<Bound<'py, PyDict>> {
    let defaults = keyword_values(py, &ReconstructSettings::new(1.0));
    let keywords = PyDict::new_bound(py);
    for ((name, value), (_, default)) in keyword_values(py, &preset.settings(1.0))
        .into_iter()
        .zip(defaults)
    {
        if !value.bind(py).eq(default.bind(py))? {
            keywords.set_item(name, value)?;
        }
    }
    Ok(keywords)
}

/// Every reconstruction setting of `s` as its keyword takes it, in the order of
/// [`SETTINGS`] (what [`settings`] reads back).
fn keyword_values(py: Python<'_>, s: &ReconstructSettings) -> Vec<(&'static str, PyObject)> {
    // As written (0.8, not 0.800000011920929): an f32 prints as its shortest decimal.
    let decimal = |x: f32| -> f64 { x.to_string().parse().expect("a float prints as one") };
    let kernel = match s.kernel {
        Kernel::Isotropic => "isotropic",
        Kernel::Anisotropic => "anisotropic",
    };
    let decimate = match s.decimate {
        Decimation::Fraction(f) => decimal(f).into_py(py),
        Decimation::Adaptive => "adaptive".into_py(py),
        Decimation::Off => py.None(),
    };
    let values = vec![
        ("influence_radius", decimal(s.influence_radius).into_py(py)),
        ("cell_size", decimal(s.cell_size).into_py(py)),
        ("t_low", decimal(s.t_low).into_py(py)),
        ("t_high", decimal(s.t_high).into_py(py)),
        (
            "particle_coverage",
            decimal(s.particle_coverage).into_py(py),
        ),
        ("iso_offset", decimal(s.iso_offset).into_py(py)),
        ("kernel", kernel.into_py(py)),
        ("kernel_radius", decimal(s.kernel_radius).into_py(py)),
        ("max_stretch", decimal(s.max_stretch).into_py(py)),
        ("min_neighbours", s.min_neighbours.into_py(py)),
        ("centre_smoothing", decimal(s.centre_smoothing).into_py(py)),
        ("isolated_spheres", s.isolated_spheres.into_py(py)),
        ("decimate", decimate),
        ("decimate_error", s.decimate_error.map(decimal).into_py(py)),
        ("smooth", s.smooth.into_py(py)),
        ("smooth_method", s.smooth_method.to_string().into_py(py)),
        (
            "smooth_max_inward",
            s.smooth_max_inward.map(decimal).into_py(py),
        ),
        (
            "smooth_feature_angle",
            s.smooth_feature_angle.map(decimal).into_py(py),
        ),
        ("subdivide", s.subdivide.into_py(py)),
        ("defer_subdivision", s.defer_subdivision.into_py(py)),
        ("keep_inside", s.keep_inside.map(decimal).into_py(py)),
        ("normal_smoothing", s.normal_smoothing.into_py(py)),
        ("tile_size", s.tile_size.into_py(py)),
        ("memory_budget", s.memory_budget.into_py(py)),
        (
            "temp_dir",
            s.temp_dir
                .as_ref()
                .map(|d| d.to_string_lossy().into_owned())
                .into_py(py),
        ),
    ];
    // A setting added to the library's list and not here fails at import.
    assert!(
        values
            .iter()
            .map(|(name, _)| *name)
            .eq(SETTINGS.iter().copied()),
        "keyword_values lists every setting of SETTINGS, in order"
    );
    values
}

/// A function's `**options`, taken one by one; what is left at the end is an unexpected
/// keyword (TypeError, as Python's own functions say it).
pub struct Keywords<'py> {
    function: &'static str,
    left: Bound<'py, PyDict>,
}

impl<'py> Keywords<'py> {
    pub fn new(
        py: Python<'py>,
        function: &'static str,
        given: Option<&Bound<'py, PyDict>>,
    ) -> PyResult<Self> {
        let left = match given {
            Some(d) => d.copy()?,
            None => PyDict::new_bound(py),
        };
        Ok(Keywords { function, left })
    }

    /// The object given for `name` (Python's `None` included), or `None` when absent.
    fn take(&self, name: &str) -> PyResult<Option<Bound<'py, PyAny>>> {
        let value = self.left.get_item(name)?;
        if value.is_some() {
            self.left.del_item(name)?;
        }
        Ok(value)
    }

    /// The value given for `name`; `None` when absent or given as `None` (the default).
    fn value<T: FromPyObject<'py>>(&self, name: &str) -> PyResult<Option<T>> {
        match self.take(name)? {
            Some(v) if !v.is_none() => extract(&v, name).map(Some),
            _ => Ok(None),
        }
    }

    /// For a setting that `None` turns off: absent → `None` (keep the default), given as
    /// `None` → `Some(None)`, given a value → `Some(Some(value))`.
    fn nullable<T: FromPyObject<'py>>(&self, name: &str) -> PyResult<Option<Option<T>>> {
        match self.take(name)? {
            None => Ok(None),
            Some(v) if v.is_none() => Ok(Some(None)),
            Some(v) => extract(&v, name).map(|x| Some(Some(x))),
        }
    }

    /// Refuses the keywords nobody took.
    pub fn finish(self) -> PyResult<()> {
        match self.left.keys().iter().next() {
            None => Ok(()),
            Some(name) => Err(PyTypeError::new_err(format!(
                "{}() got an unexpected keyword argument {}; the reconstruction options are {}",
                self.function,
                name.repr()?,
                SETTINGS.join(", ")
            ))),
        }
    }
}

fn extract<'py, T: FromPyObject<'py>>(value: &Bound<'py, PyAny>, name: &str) -> PyResult<T> {
    value
        .extract()
        .map_err(|e| PyTypeError::new_err(format!("invalid {name}: {e}")))
}

/// `base` (a preset's settings) with the reconstruction settings of `keywords` (the
/// others are left for the caller).
pub fn settings(
    mut s: ReconstructSettings,
    keywords: &Keywords<'_>,
) -> PyResult<ReconstructSettings> {
    for (name, field) in [
        ("influence_radius", &mut s.influence_radius),
        ("cell_size", &mut s.cell_size),
        ("t_low", &mut s.t_low),
        ("t_high", &mut s.t_high),
        ("particle_coverage", &mut s.particle_coverage),
        ("iso_offset", &mut s.iso_offset),
        ("kernel_radius", &mut s.kernel_radius),
        ("max_stretch", &mut s.max_stretch),
        ("centre_smoothing", &mut s.centre_smoothing),
    ] {
        if let Some(v) = keywords.value(name)? {
            *field = v;
        }
    }
    if let Some(v) = keywords.value("min_neighbours")? {
        s.min_neighbours = v;
    }
    if let Some(kernel) = keywords.value::<String>("kernel")? {
        s.kernel = match kernel.as_str() {
            "isotropic" => Kernel::Isotropic,
            "anisotropic" => Kernel::Anisotropic,
            other => {
                return Err(PyValueError::new_err(format!(
                    "invalid kernel: \"isotropic\" or \"anisotropic\", got {other:?}"
                )))
            }
        };
    }
    // None turns these off (absent: the default).
    if let Some(v) = keywords.nullable("isolated_spheres")? {
        s.isolated_spheres = v;
    }
    if let Some(v) = keywords.value("defer_subdivision")? {
        s.defer_subdivision = v;
    }
    if let Some(v) = keywords.nullable("keep_inside")? {
        s.keep_inside = v;
    }
    if let Some(v) = keywords.take("decimate")? {
        s.decimate = if v.is_none() {
            Decimation::Off
        } else if let Ok(text) = v.extract::<String>() {
            text.parse()
                .map_err(|e| PyValueError::new_err(format!("invalid decimate: {e}")))?
        } else {
            Decimation::Fraction(extract(&v, "decimate")?)
        };
    }
    if let Some(v) = keywords.nullable("decimate_error")? {
        s.decimate_error = v;
    }
    if let Some(v) = keywords.value("smooth")? {
        s.smooth = v;
    }
    if let Some(method) = keywords.value::<String>("smooth_method")? {
        s.smooth_method = method
            .parse()
            .map_err(|e| PyValueError::new_err(format!("invalid smooth_method: {e}")))?;
    }
    if let Some(v) = keywords.nullable("smooth_max_inward")? {
        s.smooth_max_inward = v;
    }
    if let Some(v) = keywords.nullable("smooth_feature_angle")? {
        s.smooth_feature_angle = v;
    }
    if let Some(v) = keywords.value("subdivide")? {
        s.subdivide = v;
    }
    if let Some(v) = keywords.value("normal_smoothing")? {
        s.normal_smoothing = v;
    }
    s.tile_size = keywords.value("tile_size")?;
    s.memory_budget = match keywords.take("memory_budget")? {
        Some(b) if !b.is_none() => Some(if let Ok(bytes) = b.extract::<u64>() {
            bytes
        } else {
            let text: String = b.extract().map_err(|_| {
                PyValueError::new_err(
                    "invalid memory_budget: bytes (int) or a size such as \"2GiB\"",
                )
            })?;
            meniscus::settings::parse_memory_budget(&text).map_err(crate::errors::to_py)?
        }),
        _ => None,
    };
    s.temp_dir = keywords.value::<PathBuf>("temp_dir")?;
    Ok(s)
}

/// The frames `reconstruct_file` takes, as the CLI's `--start/--end`, `--frames` and
/// `--shard` (the library parses the text of the last two).
pub fn frame_choice(
    start: Option<i64>,
    end: Option<i64>,
    frames: Option<&Bound<'_, PyAny>>,
    shard: Option<&Bound<'_, PyAny>>,
) -> PyResult<FrameChoice> {
    let frames = match frames.filter(|f| !f.is_none()) {
        None => None,
        Some(f) => {
            let text = if let Ok(text) = f.extract::<String>() {
                text
            } else if let Ok(numbers) = f.extract::<Vec<i64>>() {
                numbers
                    .iter()
                    .map(|n| n.to_string())
                    .collect::<Vec<_>>()
                    .join(",")
            } else {
                return Err(PyTypeError::new_err(
                    "invalid frames: a selection such as \"1-100:2,7\" or a list of frame numbers",
                ));
            };
            Some(
                text.parse::<FrameSelection>()
                    .map_err(|e| PyValueError::new_err(format!("invalid frames: {e}")))?,
            )
        }
    };
    let shard = match shard.filter(|s| !s.is_none()) {
        None => None,
        Some(s) => {
            let text = if let Ok(text) = s.extract::<String>() {
                text
            } else if let Ok((index, count)) = s.extract::<(i64, i64)>() {
                format!("{index}/{count}")
            } else {
                return Err(PyTypeError::new_err(
                    "invalid shard: (index, count) or \"index/count\", such as (0, 4)",
                ));
            };
            Some(
                text.parse::<Shard>()
                    .map_err(|e| PyValueError::new_err(format!("invalid shard: {e}")))?,
            )
        }
    };
    Ok(FrameChoice {
        start,
        end,
        frames,
        shard,
    })
}
