//! numpy arrays in and out: particle positions and attributes read from arrays
//! (borrowed when they already have the library's layout), vertices and attributes
//! returned as arrays.

use glam::Vec3;
use meniscus::attributes::Attribute;
use numpy::ndarray::Array2;
use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods,
};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::IntoPyDict;

/// An (N, 3) array's rows as `Vec3`: borrowed when it is C-contiguous float32, else
/// converted (float64, strided).
pub(crate) enum Positions<'py> {
    Borrowed(numpy::PyReadonlyArray2<'py, f32>),
    Owned(Vec<Vec3>),
}

pub(crate) fn positions_of<'py>(array: &Bound<'py, PyAny>) -> PyResult<Positions<'py>> {
    let bad = |what: String| {
        PyValueError::new_err(format!(
            "invalid positions: expected an (N, 3) float32 or float64 array, got {what}"
        ))
    };
    if let Ok(a) = array.downcast::<PyArray2<f32>>() {
        let shape = a.shape();
        if shape[1] != 3 {
            return Err(bad(format!("shape {shape:?}")));
        }
        let a = a.readonly();
        if a.is_c_contiguous() {
            return Ok(Positions::Borrowed(a));
        }
        let v = a.as_array();
        return Ok(Positions::Owned(
            v.rows()
                .into_iter()
                .map(|r| Vec3::new(r[0], r[1], r[2]))
                .collect(),
        ));
    }
    if let Ok(a) = array.downcast::<PyArray2<f64>>() {
        let shape = a.shape();
        if shape[1] != 3 {
            return Err(bad(format!("shape {shape:?}")));
        }
        let a = a.readonly();
        let v = a.as_array();
        return Ok(Positions::Owned(
            v.rows()
                .into_iter()
                .map(|r| Vec3::new(r[0] as f32, r[1] as f32, r[2] as f32))
                .collect(),
        ));
    }
    match array.downcast::<numpy::PyUntypedArray>() {
        Ok(a) => Err(bad(format!(
            "shape {:?} of dtype {}",
            a.shape(),
            a.dtype().str()?
        ))),
        Err(_) => Err(bad(format!("{}", array.get_type().name()?))),
    }
}

impl Positions<'_> {
    pub(crate) fn as_slice(&self) -> &[Vec3] {
        match self {
            Positions::Borrowed(a) => {
                let flat = a.as_slice().expect("C-contiguous");
                // SAFETY: Vec3 is three f32 (repr(C), align 4); the array holds 3 × N
                // floats, row-major.
                unsafe { std::slice::from_raw_parts(flat.as_ptr().cast::<Vec3>(), flat.len() / 3) }
            }
            Positions::Owned(v) => v,
        }
    }
}

/// One attribute from an (N,) or (N, k) array of any float dtype.
pub(crate) fn attribute_of(
    name: String,
    array: &Bound<'_, PyAny>,
    count: usize,
) -> PyResult<Attribute> {
    let np = array.py().import_bound("numpy")?;
    let converted = np
        .getattr("ascontiguousarray")?
        .call(
            (array,),
            Some(&[("dtype", "float32")].into_py_dict_bound(array.py())),
        )
        .map_err(|e| {
            PyValueError::new_err(format!(
                "invalid attributes: {name:?} is not a float array: {e}"
            ))
        })?;
    let a: PyReadonlyArrayDyn<f32> = converted.extract()?;
    let shape = a.shape().to_vec();
    let components = match shape.as_slice() {
        [n] if *n == count => 1,
        [n, k] if *n == count && *k > 0 => *k,
        _ => {
            return Err(PyValueError::new_err(format!(
            "invalid attributes: {name:?} has shape {shape:?}; expected ({count},) or ({count}, k)"
        )))
        }
    };
    let values = a.as_slice()?.to_vec();
    if let Some(i) = values.iter().position(|v| !v.is_finite()) {
        return Err(PyValueError::new_err(format!(
            "invalid attributes: {name:?} of particle {} has a non-finite value {}",
            i / components,
            values[i]
        )));
    }
    Ok(Attribute {
        name,
        components,
        values,
    })
}

pub(crate) fn vec3s<'py>(py: Python<'py>, v: &[Vec3]) -> Bound<'py, PyArray2<f32>> {
    let flat: Vec<f32> = v.iter().flat_map(|p| p.to_array()).collect();
    Array2::from_shape_vec((v.len(), 3), flat)
        .expect("3 per row")
        .into_pyarray_bound(py)
}

pub(crate) fn attribute_array<'py>(py: Python<'py>, a: &Attribute) -> Bound<'py, PyAny> {
    if a.components == 1 {
        PyArray1::from_slice_bound(py, &a.values).into_any()
    } else {
        Array2::from_shape_vec((a.len(), a.components), a.values.clone())
            .expect("components per row")
            .into_pyarray_bound(py)
            .into_any()
    }
}
