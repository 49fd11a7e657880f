//! flexdyn runtime: solvers for the equations of motion that `flexdyn-codegen`
//! generates. `#![no_std]`, allocation-free, panic-free on bad numbers.
#![no_std]

pub mod math;
mod model;

pub use model::Model;
pub use nalgebra;
