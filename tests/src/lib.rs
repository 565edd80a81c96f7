//! Host tests of ribreg: an independent `f64` reference of the pipeline ([`mod@reference`])
//! and shared test helpers ([`support`]).

pub mod reference;
pub mod support;
