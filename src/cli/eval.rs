//! `flexdyn eval`: every generated term of any scene at states read from
//! JSON, written as JSON (what the CasADi validation compares). A scene
//! compiled into the binary is evaluated by its compiled module (when the
//! file still describes it: an edited copy is interpreted), any other scene
//! file is generated in memory and interpreted ([`crate::interpreted`]):
//! bitwise the same numbers.

use std::path::PathBuf;

use crate::compiled::{Choice, Compiled};
use crate::dynamic::DynModel;
use crate::eval::{check_state, evaluate, States};
use crate::table::{read_input, write_atomic};

/// Evaluate every generated term of a scene at states read from
/// JSON (`{"states": [{"q": [..], "qd": [..], "t": 0.0}]}`) and write them
/// as JSON.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scene file: a compiled-in scene is evaluated by its compiled module,
    /// any other by the interpreter (bitwise the same numbers).
    #[arg(long)]
    pub scene: PathBuf,
    /// Interpret the scene file even when a scene of its name is compiled
    /// in (e.g. an edited copy of a shipped scene).
    #[arg(long, conflicts_with = "perturbed")]
    pub interpret: bool,
    /// States file.
    #[arg(long)]
    pub states: PathBuf,
    /// Output file (standard output when absent).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Test-only hook: evaluate the build of the scene with one emitted
    /// coefficient deliberately wrong.
    #[arg(long, hide = true)]
    pub perturbed: bool,
}

/// Run the command on the scenes of `compiled`.
pub fn run(args: &Args, compiled: &Compiled) -> Result<(), String> {
    let parsed = crate::codegen::Model::load(&args.scene).map_err(|e| e.to_string())?;
    super::tell_notes(&parsed, false);
    let lookup = if args.perturbed {
        compiled.perturbed_model
    } else {
        compiled.model
    };
    let interpreted = match args.perturbed {
        true => None,
        false => match compiled.choose(&args.scene, &parsed.name, args.interpret)? {
            Choice::Compiled(_) => None,
            Choice::Interpreted(i) => Some(i),
        },
    };
    let fresh = |name: &str| -> Result<Box<dyn DynModel>, String> {
        match &interpreted {
            Some(i) => Ok(Box::new(i.clone())),
            None => lookup(name).ok_or_else(|| {
                format!(
                    "scene `{name}` has no perturbed build (those are: {})",
                    compiled.perturbed_scenes.join(", ")
                )
            }),
        }
    };
    let mut model = fresh(&parsed.name)?;
    let text = read_input(&args.states, "states file")?;
    let input: States =
        serde_json::from_str(&text).map_err(|e| format!("{}: {e}", args.states.display()))?;
    let mut results = Vec::with_capacity(input.states.len());
    for (k, s) in input.states.iter().enumerate() {
        check_state(model.as_ref(), s, k)?;
        if !s.params.is_empty() {
            // Parameters apply to this state only: start from the defaults.
            model = fresh(&parsed.name)?;
        }
        results.push(evaluate(model.as_mut(), s).map_err(|e| format!("state {k}: {e}"))?);
    }
    let undefined: Vec<(usize, &String)> = results
        .iter()
        .enumerate()
        .filter_map(|(k, r)| r.forward_dynamics_error.as_ref().map(|e| (k, e)))
        .collect();
    if let Some((k, e)) = undefined.first() {
        eprintln!(
            "warning: the forward dynamics are left out at {} of {} states \
             (`forward_dynamics_error` in each); state {k}: {e}",
            undefined.len(),
            results.len()
        );
    }
    let json = serde_json::json!({ "scene": parsed.name, "results": results });
    let text = serde_json::to_string(&json).map_err(|e| e.to_string())?;
    match &args.out {
        Some(path) => write_atomic(path, &text),
        None => {
            println!("{text}");
            Ok(())
        }
    }
}
