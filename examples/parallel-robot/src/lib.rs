//! The spatial parallel robot of the paper on flexdyn: its scenes (the rigid
//! robot and its flexible variants, generated at build time from `scenes/`),
//! geometry and closed-form inverse kinematics ([`robot`]), the circle and
//! inverse and forward dynamics along it ([`robot`], with the runtime's
//! servo constraints and joint PD loop, `flexdyn_runtime::control`), and the
//! speed-against-error study behind `docs/performance.md` ([`report`]).
//! The `parallel-robot` binary drives them from the command line.

pub mod report;
pub mod robot;

/// The generated robot scene modules (one per file in `scenes/`).
#[allow(missing_docs)]
pub mod scenes {
    include!(concat!(env!("OUT_DIR"), "/scenes.rs"));
}

/// Test only: a copy of `parallel_robot_rigid` with one emitted coefficient
/// deliberately wrong (see `build.rs`), evaluated by
/// `parallel-robot eval --perturbed` to prove the CasADi validation catches it.
#[doc(hidden)]
#[allow(missing_docs)]
pub mod perturbed_scenes {
    include!(concat!(env!("OUT_DIR"), "/perturbed/scenes.rs"));
}

/// The robot scenes compiled into this crate, for the generic commands
/// (`flexdyn::cli::eval`, `simulate`, `inverse`) run on them.
pub const COMPILED_SCENES: flexdyn::compiled::Compiled = flexdyn::compiled::Compiled {
    scenes: scenes::SCENES,
    model: scenes::model,
    perturbed_scenes: perturbed_scenes::SCENES,
    perturbed_model: perturbed_scenes::model,
};
