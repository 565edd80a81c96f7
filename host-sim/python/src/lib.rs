//! The `ribreg._ribreg` extension module behind the `ribreg` Python package
//! (`host-sim/python/python/ribreg`): a thin layer over `ribreg-sim` and `ribreg-core`,
//! with no algorithm of its own.
//!
//! * [`registration`]: `register`, `Template`, `Registration`, `read_cloud`,
//!   `read_waypoints` — numpy arrays in and out, the CLI's readers and results.
//! * [`link`]: the robot PC's side of the wire protocol (`ribreg.link`, `ribreg.sim`).
//!
//! Errors: bad input raises `ValueError` with the core's or the reader's message; a
//! file that cannot be read raises `OSError`; a link failure raises `ribreg.LinkError`
//! (an `OSError`).

use pyo3::prelude::*;

pub mod link;
pub mod registration;

#[pymodule]
fn _ribreg(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    registration::add(m)?;
    link::add(m)?;
    Ok(())
}
