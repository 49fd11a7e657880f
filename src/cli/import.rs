//! `flexdyn import urdf ROBOT.urdf --out robot.toml`: a URDF robot
//! description imported as an editable scene file
//! ([`crate::codegen::import_urdf`]). The scene is loaded once before it is
//! written, so a file that is written is one the other commands accept; it
//! is written whole or not at all.

use std::path::PathBuf;

use crate::codegen::{import_urdf, Model, Source, UrdfOptions};
use crate::table::read_input;

/// Import a robot description from another format as a scene file.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(subcommand)]
    pub format: Format,
}

/// The formats `import` reads.
#[derive(Debug, clap::Subcommand)]
pub enum Format {
    /// A URDF file: links become frames and rigid bodies (fixed joints
    /// merged), revolute, continuous and prismatic joints coordinates and
    /// actuators of their names; gravity -9.81 along z.
    Urdf(UrdfArgs),
}

/// Arguments of `import urdf`.
#[derive(Debug, clap::Args)]
pub struct UrdfArgs {
    /// The URDF file.
    pub urdf: PathBuf,
    /// The scene file to write.
    #[arg(long)]
    pub out: PathBuf,
    /// A joint (URDF name) to hold fixed at zero, merging its child into
    /// the parent body (e.g. a gripper's fingers); may be repeated.
    #[arg(long = "fix", value_name = "JOINT")]
    pub fix: Vec<String>,
    /// Keep every `rpy` angle as written. By default an angle that agrees
    /// with a multiple of pi/12 to within one unit of its last written digit
    /// (and 1e-5 rad), or to within 1e-12 rad however written, is taken as
    /// exact: `1.57079632679` as pi/2, which keeps `cos` of it an exact zero
    /// in the generated code; likewise an axis component or origin
    /// coordinate within 1e-12 of zero (relative to its vector), such as
    /// `6.12323e-17`, is zero. This keeps those as written too.
    #[arg(long)]
    pub keep_angles: bool,
    /// An optional output for the scene to generate (its `outputs` list,
    /// e.g. `dynamics_derivatives`); may be repeated.
    #[arg(long = "output", value_name = "NAME",
          value_parser = clap::builder::PossibleValuesParser::new(crate::codegen::OUTPUTS))]
    pub outputs: Vec<String>,
}

/// Run the command.
pub fn run(args: &Args) -> Result<(), String> {
    let Format::Urdf(args) = &args.format;
    let text = read_input(&args.urdf, "URDF file")?;
    let options = UrdfOptions {
        fix: args.fix.clone(),
        keep_angles: args.keep_angles,
        outputs: args.outputs.clone(),
    };
    let scene = import_urdf(&Source::new(&args.urdf, text), &options).map_err(|e| e.to_string())?;
    let not_loaded = |e: crate::codegen::Error| {
        format!(
            "the scene imported from {} does not load (not written): {e}",
            args.urdf.display()
        )
    };
    let mut model =
        Model::from_source(&Source::new(&args.out, scene.clone())).map_err(not_loaded)?;
    // Derived once, for what the derivation notes (coordinates that move no
    // mass).
    model.equations().map_err(not_loaded)?;
    super::tell_notes(&model, false);
    crate::table::write_atomic(&args.out, &scene)
}
