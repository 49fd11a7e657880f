//! `flexdyn export`: a scene's symbolic inputs as JSON
//! (`docs/export-format.md`), the input of the CasADi validation.

use std::path::PathBuf;

/// Export a scene's symbolic inputs (energies, constraints, actuators) as
/// JSON in the documented `flexdyn-scene-export/1` format.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scene file.
    #[arg(long)]
    pub scene: PathBuf,
    /// Output file.
    #[arg(long)]
    pub out: PathBuf,
}

/// Run the command.
pub fn run(args: &Args) -> Result<(), String> {
    let model = crate::codegen::Model::load(&args.scene).map_err(|e| e.to_string())?;
    crate::table::write_atomic(&args.out, &crate::codegen::export_json(&model))
}
