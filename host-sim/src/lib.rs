#![doc = include_str!("../../README.md")]
#![warn(missing_docs)]

pub mod baselines;
pub mod demo;
pub mod eval;
pub mod hil;
pub mod io;
pub mod phantom;
pub mod plot;
pub mod qemu;
pub mod register;
pub mod sample;
pub mod stats;
pub mod sweep;
