//! Wire messages to and from Python: through their serde form (`serde_json::Value`),
//! so Python sees plain dicts, lists, numbers and strings shaped exactly like the
//! messages' JSON (externally tagged enums: `{"Hello": {"magic": …, "version": …}}`,
//! `{"Command": "StartSweep"}`). `f32` fields arrive as the exact `float`, and a `float`
//! that held an `f32` goes back bit for bit. What the Rust types refuse (an integer out
//! of range, too many nodes in a chunk, a missing field) is a `ValueError` with serde's
//! message.

use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};
use pyo3::IntoPyObjectExt;
use serde::de::DeserializeOwned;
use serde::Serialize;
use serde_json::{Map, Number, Value};

/// A serde value as a Python object.
pub fn to_py<'py>(py: Python<'py>, v: &Value) -> PyResult<Bound<'py, PyAny>> {
    Ok(match v {
        Value::Null => py.None().into_bound(py),
        Value::Bool(b) => b.into_bound_py_any(py)?,
        Value::Number(n) => {
            if let Some(u) = n.as_u64() {
                u.into_bound_py_any(py)?
            } else if let Some(i) = n.as_i64() {
                i.into_bound_py_any(py)?
            } else {
                n.as_f64().unwrap_or(f64::NAN).into_bound_py_any(py)?
            }
        }
        Value::String(s) => s.into_bound_py_any(py)?,
        Value::Array(a) => {
            let items = a
                .iter()
                .map(|x| to_py(py, x))
                .collect::<PyResult<Vec<_>>>()?;
            PyList::new(py, items)?.into_any()
        }
        Value::Object(o) => {
            let d = PyDict::new(py);
            for (k, x) in o {
                d.set_item(k, to_py(py, x)?)?;
            }
            d.into_any()
        }
    })
}

/// A Python object (None, bool, int, float, str, list, tuple, dict with str keys) as a
/// serde value.
pub fn from_py(obj: &Bound<'_, PyAny>) -> PyResult<Value> {
    if obj.is_none() {
        Ok(Value::Null)
    } else if obj.is_instance_of::<PyBool>() {
        Ok(Value::Bool(obj.extract()?))
    } else if obj.is_instance_of::<PyInt>() {
        if let Ok(u) = obj.extract::<u64>() {
            Ok(Value::from(u))
        } else if let Ok(i) = obj.extract::<i64>() {
            Ok(Value::from(i))
        } else {
            Err(PyValueError::new_err(format!(
                "integer {obj} is out of range"
            )))
        }
    } else if obj.is_instance_of::<PyFloat>() {
        let x: f64 = obj.extract()?;
        Number::from_f64(x)
            .map(Value::Number)
            .ok_or_else(|| PyValueError::new_err(format!("{x} is not a finite number")))
    } else if obj.is_instance_of::<PyString>() {
        Ok(Value::String(obj.extract()?))
    } else if let Ok(d) = obj.cast::<PyDict>() {
        let mut m = Map::new();
        for (k, x) in d.iter() {
            m.insert(k.extract::<String>()?, from_py(&x)?);
        }
        Ok(Value::Object(m))
    } else if obj.is_instance_of::<PyList>() || obj.is_instance_of::<PyTuple>() {
        obj.try_iter()?
            .map(|x| from_py(&x?))
            .collect::<PyResult<Vec<_>>>()
            .map(Value::Array)
    } else {
        Err(PyValueError::new_err(format!(
            "cannot put a {} in a wire message",
            obj.get_type().name()?
        )))
    }
}

/// A Rust wire type as its Python form.
pub fn to_py_msg<'py, T: Serialize>(py: Python<'py>, msg: &T) -> PyResult<Bound<'py, PyAny>> {
    let v = serde_json::to_value(msg).map_err(|e| PyValueError::new_err(e.to_string()))?;
    to_py(py, &v)
}

/// A Python form as a Rust wire type; what the type refuses is a `ValueError`.
pub fn from_py_msg<T: DeserializeOwned>(obj: &Bound<'_, PyAny>) -> PyResult<T> {
    serde_json::from_value(from_py(obj)?)
        .map_err(|e| PyValueError::new_err(format!("not a valid message: {e}")))
}
