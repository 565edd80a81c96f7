#![doc = include_str!("../../README.md")]

pub mod baselines;
pub mod demo;
pub mod error;
pub mod eval;
pub mod hil;
pub mod io;
pub mod phantom;
pub mod plot;
pub mod register;
pub mod sample;
pub mod stats;
pub mod sweep;
pub mod template;
