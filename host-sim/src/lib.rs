pub mod io;
pub mod phantom;
pub mod register;
pub mod demo;
