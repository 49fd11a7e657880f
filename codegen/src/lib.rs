//! flexdyn-codegen: from a scene's energies to specialised Rust.
//!
//! Each scene goes through the stages in order, one module each, driven by
//! the [`Builder`]:
//!
//! 1. `load`: the scene file's TOML to a typed scene; a derived scene's base
//!    file is read and resolved;
//! 2. `model`: frames, coordinates, constraints, actuators, and every
//!    component (one file per kind) turned into its energies `T`, `V`, `D`
//!    on the expression graph (`expr`; vectors and rotations in `geometry`,
//!    the finite-element maths of flexible links in `fem`);
//! 3. `reduce`: a derived scene's reductions (modes dropped, coordinates
//!    frozen);
//! 4. `derive`: Lagrange's equations ([`Equations`]);
//! 5. `prune`: negligible summands dropped where the scene asks for it;
//!    `checks` refuses a derivation whose constants overflow `f64` and
//!    `energy` components with a negative mass or dissipation; an
//!    `f32` module is refused where `resolution` finds a stiffness spread
//!    beyond f32's resolution (unless [`Builder::allow_unresolved_f32`]);
//! 6. `schedule`: the table of emitted functions ([`interpret::Function`]:
//!    name, inputs, outputs with their shapes and symmetry) and a
//!    straight-line program per function of a scene (common subexpressions,
//!    shared pairs of factors and terms), lowered once into operations in
//!    evaluation order;
//! 7. `emit`: the formatted Rust module, printing those operations, naming
//!    the runtime crate by the path [`Builder::runtime_path`] (default
//!    `flexdyn_runtime`); with [`Builder::c_interface`], `emit_c` adds its
//!    `extern "C"` wrappers and writes the C header.
//!
//! [`interpret`] is emit's twin for run time: it assembles the same lowered
//!    operations into instruction tapes that compute, bitwise, what the
//!    emitted Rust computes, so a scene file can be evaluated without
//!    compiling it.
//!
//! Each stage imports only from earlier ones. `export` writes a model's
//! symbolic inputs as JSON ([`export_json`]); `import` writes scene text
//! from a URDF robot description ([`import_urdf`]), which is then loaded
//! like any scene; `files` writes outputs all or nothing, devices and FIFOs
//! through ([`OutputFiles`]).
//!
//! The public API is the builder and its results, the symbolic model of a
//! scene ([`Model::load`], [`Model::equations`]; the types of its fields,
//! the finite-element data of flexible links in [`flexible`]) with the expression graph
//! its terms live in ([`Graph`], [`Node`], [`Id`], [`Symbol`], [`Func`],
//! [`powi_f64`]), functions of time in the scene grammar ([`TimeFunction`]),
//! and errors with their position ([`Error`], [`Source`]).

mod builder;
mod checks;
mod derive;
mod emit;
mod emit_c;
mod error;
mod export;
mod expr;
mod fem;
mod files;
mod geometry;
mod hash;
mod import;
mod inertia;
pub mod interpret;
mod load;
mod model;
mod prune;
mod reduce;
mod redundancy;
mod resolution;
mod samples;
mod schedule;
mod solve;
#[cfg(test)]
mod tests;
mod time_function;

pub use builder::{generate_scene, Builder, Generated, Report};
pub use derive::{Equations, MarkerTerms};
pub use emit::FunctionReport;
pub use error::{Error, Source};
pub use export::export_json;
pub use expr::{powi_f64, Func, Graph, Id, Node, Symbol};
pub use files::{check_output, read_limited, write_atomic, OutputFiles};
pub use import::{import_urdf, UrdfOptions};
pub use model::{
    Actuator, Body, Component, Constraint, Coordinate, FlexibleLink, Marker, Model, Outputs,
    Precision, RuntimeParameter, OUTPUTS,
};
pub use redundancy::dependent_rows;
pub use schedule::OpCount;
pub use time_function::TimeFunction;

/// The finite-element data of a flexible link ([`FlexibleLink`]), as the
/// model holds it.
pub mod flexible {
    pub use crate::fem::modal::{ModeKind, Station};
    pub use crate::fem::{
        Beam, BoundaryConditions, EndCondition, FeModel, Invariants, Material, ModalBasis, Section,
    };
}
