//! flexdyn-codegen: from a scene's energies to specialised Rust.
//!
//! Data flow, one module per arrow:
//! scene file ([`scene`]) -> parsed expressions ([`parse`]) -> component
//! energies ([`model`]) -> derived terms ([`lagrange`]) -> optimised
//! straight-line program ([`program`], with repeated pairs of factors and
//! terms shared by `share`) -> emitted Rust ([`emit`]), driven by
//! the [`Builder`]; [`interpret`] evaluates the same programs at run time,
//! bitwise as the emitted Rust does. A derived scene is reduced ([`reduce`]: modes dropped,
//! coordinates frozen, negligible terms pruned) on the way.

mod builder;
pub mod diff;
pub mod emit;
pub mod error;
pub mod export;
pub mod expr;
pub mod fem;
pub mod interpret;
pub mod lagrange;
pub mod model;
pub mod parse;
pub mod program;
pub mod reduce;
pub mod scene;
mod share;

pub use builder::{generate_scene, write_if_changed, Builder, Generated, Report};
pub use error::Error;
