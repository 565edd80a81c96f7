//! `ribreg template`: a labelled template cloud (and, once, its prepared parts) from what a
//! CT segmentation and planning workflow hands over — a labelmap volume, one mesh per
//! part, or a point cloud — in ribreg's patient frame ([`crate::io::space`]).
//!
//! Labels are ribreg's: 1 = sternum, 2..=5 = the costal cartilage of that rib (both
//! sides share a rib's label), 0 = not used.

pub mod autolabel;
mod job;
pub mod labelmap;
pub mod prepared;

pub use job::{run, TemplateJob, TemplateOutcome};
