//! `flexdyn generate`: the Rust module of one or more scenes, written into a
//! directory (how `generated/` is refreshed).

use std::path::PathBuf;

/// Generate the Rust module of one or more scenes into a directory.
///
/// Writes `<scene name>.rs` per scene, only when its content changed, and
/// nothing at all if any scene has an error.
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
    /// Print nothing but errors.
    #[arg(long)]
    pub quiet: bool,
}

/// Run the command.
pub fn run(args: &Args) -> Result<(), String> {
    let mut builder = crate::codegen::Builder::new().out_dir(&args.out);
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
