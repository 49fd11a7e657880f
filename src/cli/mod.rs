//! The `flexdyn` commands, one module each: its `clap` arguments and the
//! function that runs it. Binaries built on flexdyn (for example the
//! examples under `examples/`) reuse them with their own compiled-in scenes.

pub mod eval;
pub mod export;
pub mod generate;
pub mod import;
pub mod inverse;
pub mod linearize;
pub mod simulate;

/// Prints on stderr (unless `quiet`) what the generator changed in the
/// scene a command runs (constraints dropped as redundant).
fn tell_notes(model: &crate::codegen::Model, quiet: bool) {
    for note in model.notes.iter().filter(|_| !quiet) {
        eprintln!("note: {note}");
    }
}
