//! `ribreg.link`: the robot PC's side of the wire protocol.
use pyo3::prelude::*;

/// Adds the link's classes and functions to the module.
pub fn add(_m: &Bound<'_, PyModule>) -> PyResult<()> {
    Ok(())
}
