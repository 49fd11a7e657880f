//! The `flexdyn` command line.

use std::path::{Path, PathBuf};
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
    /// Export a scene's symbolic inputs (energies, constraints, actuators) as
    /// JSON in the documented `flexdyn-scene-export/1` format.
    Export {
        /// Scene file.
        #[arg(long)]
        scene: PathBuf,
        /// Output file.
        #[arg(long)]
        out: PathBuf,
    },
    /// Evaluate every generated term of a compiled scene at states read from
    /// JSON (`{"states": [{"q": [..], "qd": [..], "t": 0.0}]}`) and write
    /// them as JSON.
    Eval {
        /// Scene file (its scene must be compiled in, i.e. live in `scenes/`).
        #[arg(long)]
        scene: PathBuf,
        /// States file.
        #[arg(long)]
        states: PathBuf,
        /// Output file (standard output when absent).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Test-only hook: add DELTA to entry INDEX of TERM, as TERM:INDEX:DELTA.
        #[arg(long, hide = true)]
        perturb: Option<flexdyn::eval::Perturbation>,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
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
                    Ok(())
                }
                Err(e) => Err(e.to_string()),
            }
        }
        Command::Export { scene, out } => export(&scene, &out),
        Command::Eval {
            scene,
            states,
            out,
            perturb,
        } => eval(&scene, &states, out.as_deref(), perturb.as_ref()),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

/// Write `text` to `path` through a temporary file, so that a failure never
/// leaves a partial output behind.
fn write_atomic(path: &Path, text: &str) -> Result<(), String> {
    let tmp = path.with_extension("partial");
    std::fs::write(&tmp, text)
        .and_then(|()| std::fs::rename(&tmp, path))
        .map_err(|e| {
            let _ = std::fs::remove_file(&tmp);
            format!("cannot write {}: {e}", path.display())
        })
}

fn export(scene: &Path, out: &Path) -> Result<(), String> {
    let model = flexdyn::codegen::model::Model::load(scene).map_err(|e| e.to_string())?;
    write_atomic(out, &flexdyn::codegen::export::export_json(&model))
}

fn eval(
    scene: &Path,
    states: &Path,
    out: Option<&Path>,
    perturb: Option<&flexdyn::eval::Perturbation>,
) -> Result<(), String> {
    use flexdyn::eval::{check_state, evaluate, States};
    let parsed = flexdyn::codegen::model::Model::load(scene).map_err(|e| e.to_string())?;
    let model = flexdyn::scenes::model(&parsed.name).ok_or_else(|| {
        format!(
            "scene `{}` is not compiled into this binary: put its file in scenes/ and rebuild",
            parsed.name
        )
    })?;
    let text = std::fs::read_to_string(states)
        .map_err(|e| format!("cannot read {}: {e}", states.display()))?;
    let input: States =
        serde_json::from_str(&text).map_err(|e| format!("{}: {e}", states.display()))?;
    let mut results = Vec::with_capacity(input.states.len());
    for (k, s) in input.states.iter().enumerate() {
        check_state(model.as_ref(), s, k)?;
        let mut terms = evaluate(model.as_ref(), s);
        if let Some(p) = perturb {
            terms.perturb(p)?;
        }
        results.push(terms);
    }
    let json = serde_json::json!({ "scene": parsed.name, "results": results });
    let text = serde_json::to_string(&json).map_err(|e| e.to_string())?;
    match out {
        Some(path) => write_atomic(path, &text),
        None => {
            println!("{text}");
            Ok(())
        }
    }
}
