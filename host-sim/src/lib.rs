#![doc = include_str!("../../README.md")]
#![warn(missing_docs)]

pub mod io;
pub mod phantom;
pub mod prep;
pub mod register;
pub mod demo;
pub mod plot;
