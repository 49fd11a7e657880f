//! `flexdyn generate`: the Rust module of one or more scenes, written into a
//! directory (how `generated/` is refreshed).

use std::path::PathBuf;

/// Generate the Rust module of one or more scenes into a directory.
///
/// Writes `<scene name>.rs` per scene (and `<scene name>.h` with
/// `--c-header`), only when its content changed, and nothing at all if any
/// scene has an error.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scene file(s) to generate.
    #[arg(long, required_unless_present = "all")]
    pub scene: Vec<PathBuf>,
    /// Generate every scene in `scenes/`.
    #[arg(long)]
    pub all: bool,
    /// Output directory.
    #[arg(long, default_value = "generated")]
    pub out: PathBuf,
    /// Also write the C interface: `extern "C"` wrappers in each module and
    /// the C header `<scene name>.h` beside it (see docs/embedded.md).
    #[arg(long)]
    pub c_header: bool,
    /// Scalar type of the generated code, overriding the scene's `precision`
    /// (`f32`: the module implements the runtime's `Model<.., f32>`).
    #[arg(long, value_parser = ["f64", "f32"])]
    pub precision: Option<String>,
    /// Generate f32 even for a scene whose stiffness spread f32 does not
    /// resolve (refused by default; see docs/embedded.md, "f32 or f64").
    #[arg(long)]
    pub allow_unresolved_f32: bool,
    /// Print nothing but errors.
    #[arg(long)]
    pub quiet: bool,
}

/// Run the command.
pub fn run(args: &Args) -> Result<(), String> {
    let mut builder = crate::codegen::Builder::new()
        .out_dir(&args.out)
        .c_interface(args.c_header)
        .allow_unresolved_f32(args.allow_unresolved_f32);
    match args.precision.as_deref() {
        Some("f32") => builder = builder.precision(crate::codegen::Precision::F32),
        Some(_) => builder = builder.precision(crate::codegen::Precision::F64),
        None => {}
    }
    for s in &args.scene {
        builder = builder.scene(s);
    }
    if args.all {
        builder = builder.scenes_in("scenes");
    }
    let report = builder.generate().map_err(|e| e.to_string())?;
    if !args.quiet {
        for s in &report.scenes {
            println!("{s}");
        }
        println!(
            "{} file(s) written to {} ({} unchanged)",
            report.written.len(),
            args.out.display(),
            report.scenes.len().saturating_sub(report.written.len())
        );
    }
    Ok(())
}
