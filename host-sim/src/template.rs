//! CT template clouds: preparing a template for `ribreg template` (automatic labelling).

pub mod autolabel;
