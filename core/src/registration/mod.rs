//! The skeleton-graph registration (paper section III, steps 4–10): template
//! preparation, target skeleton, endpoint matching and the local-rigid mapping.
//!
//! Contract: depends on [`crate::math`], [`crate::config`], [`crate::limits`] and
//! [`crate::error`] only — not on the acquisition chain, the wire protocol or the
//! controller. [`pipeline::register`] and the resumable [`pipeline::Registering`] give the
//! same result bit for bit; [`crate::config::Config::default`] is the paper's method,
//! [`crate::config::Config::improved`] the guided rib model ([`guided`]) on an
//! anterior-surface template ([`anterior`]). One registration's working state is bounded
//! by [`crate::limits::MAX_WORKING_STATE`] (asserted below). A cloud the method cannot
//! register is refused with an [`crate::Error`] that says what was found and expected.

pub mod anterior;
pub mod endpoints;
pub mod example;
pub mod guided;
pub mod local_rigid;
pub mod metrics;
pub mod pipeline;
pub mod reach;
pub mod skeleton;

use crate::limits::{CACHE_CAPACITY, MAX_WORKING_STATE};
use core::mem::size_of;

/// One registration's working state, bytes (the template, the registration in progress
/// or its result, the mapping cache): at most [`MAX_WORKING_STATE`].
pub const WORKING_STATE: usize = size_of::<pipeline::Template>()
    + max(
        size_of::<pipeline::Registering>(),
        size_of::<pipeline::Registration>(),
    )
    + size_of::<local_rigid::TransformCache<CACHE_CAPACITY>>();

const fn max(a: usize, b: usize) -> usize {
    if a > b {
        a
    } else {
        b
    }
}

const _: () = assert!(WORKING_STATE <= MAX_WORKING_STATE);
