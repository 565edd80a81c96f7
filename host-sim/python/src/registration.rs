//! `ribreg.register` and friends.
use pyo3::prelude::*;

/// Adds the registration API to the module.
pub fn add(_m: &Bound<'_, PyModule>) -> PyResult<()> {
    Ok(())
}
