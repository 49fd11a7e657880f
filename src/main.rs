//! The `flexdyn` command line.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// Exact, allocation-free equations of motion for rigid and flexible
/// multibody systems, generated from scene files.
#[derive(Parser)]
#[command(name = "flexdyn", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Generate the Rust module of one or more scenes into a directory.
    ///
    /// Writes `<scene name>.rs` per scene, only when its content changed, and
    /// nothing at all if any scene has an error.
    Generate {
        /// Scene file(s) to generate.
        #[arg(long, required_unless_present = "all")]
        scene: Vec<PathBuf>,
        /// Generate every scene in `scenes/`.
        #[arg(long)]
        all: bool,
        /// Output directory.
        #[arg(long, default_value = "generated")]
        out: PathBuf,
        /// Print nothing but errors.
        #[arg(long)]
        quiet: bool,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match cli.command {
        Command::Generate {
            scene,
            all,
            out,
            quiet,
        } => {
            let mut builder = flexdyn::codegen::Builder::new().out_dir(&out);
            for s in scene {
                builder = builder.scene(s);
            }
            if all {
                builder = builder.scenes_in("scenes");
            }
            match builder.generate() {
                Ok(report) => {
                    if !quiet {
                        for s in &report.scenes {
                            println!("{s}");
                        }
                        println!(
                            "{} file(s) written to {} ({} unchanged)",
                            report.written.len(),
                            out.display(),
                            report.scenes.len().saturating_sub(report.written.len())
                        );
                    }
                    ExitCode::SUCCESS
                }
                Err(e) => {
                    eprintln!("error: {e}");
                    ExitCode::FAILURE
                }
            }
        }
    }
}
