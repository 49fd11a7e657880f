//! `flexdyn eval`: every generated term of any scene at states read from
//! JSON, written as JSON (what the CasADi validation compares). A scene
//! compiled into the binary is evaluated by its compiled module (when the
//! file still describes it: an edited copy is interpreted), any other scene
//! file is generated in memory and interpreted ([`crate::interpreted`]):
//! bitwise the same numbers.

use std::path::{Path, PathBuf};

use crate::dynamic::{matrix, DynModel};
use crate::eval::{check_state, evaluate, States};
use crate::table::write_atomic;

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

/// The scenes a binary has compiled in: the index modules that
/// `flexdyn_codegen::Builder::index` writes.
#[derive(Debug, Clone, Copy)]
pub struct Compiled {
    /// Names of the compiled scenes.
    pub scenes: &'static [&'static str],
    /// The default model of a compiled scene, by name.
    pub model: fn(&str) -> Option<Box<dyn DynModel>>,
    /// Names of the test-only perturbed builds.
    pub perturbed_scenes: &'static [&'static str],
    /// The default model of a perturbed build, by name.
    pub perturbed_model: fn(&str) -> Option<Box<dyn DynModel>>,
}

/// Which model answers for a scene file (see [`Compiled::choose`]).
enum Choice {
    /// The compiled-in module of the same terms.
    Compiled(Box<dyn DynModel>),
    /// The file, generated in memory and interpreted.
    Interpreted(crate::interpreted::InterpretedModel),
}

impl Compiled {
    /// The compiled-in model when the file describes it (same terms,
    /// bitwise, at a sample state; so an edited copy of a shipped scene is
    /// never answered by the stale compiled module), else the file
    /// interpreted. `interpret` forces the latter.
    fn choose(&self, scene: &Path, name: &str, interpret: bool) -> Result<Choice, String> {
        let interpreted = crate::interpreted::InterpretedModel::load(scene)?;
        match (self.model)(name).filter(|_| !interpret) {
            Some(c) if same_terms(c.as_ref(), &interpreted) => Ok(Choice::Compiled(c)),
            Some(_) => {
                eprintln!(
                    "note: {} differs from the compiled-in scene `{name}`: interpreting it",
                    scene.display()
                );
                Ok(Choice::Interpreted(interpreted))
            }
            None => Ok(Choice::Interpreted(interpreted)),
        }
    }

    /// The model of a scene file, chosen as [`Compiled::choose`] says.
    pub fn load(
        &self,
        scene: &Path,
        name: &str,
        interpret: bool,
    ) -> Result<Box<dyn DynModel>, String> {
        Ok(match self.choose(scene, name, interpret)? {
            Choice::Compiled(c) => c,
            Choice::Interpreted(i) => Box::new(i),
        })
    }
}

/// Whether two models give the same terms at a sample state.
fn same_terms(a: &dyn DynModel, b: &dyn DynModel) -> bool {
    if a.coordinates() != b.coordinates() || a.actuators() != b.actuators() || a.nc() != b.nc() {
        return false;
    }
    let q: Vec<f64> = (0..a.nq()).map(|i| 0.3 + 0.17 * i as f64).collect();
    let qd: Vec<f64> = (0..a.nq()).map(|i| -0.4 + 0.23 * i as f64).collect();
    let qdd: Vec<f64> = (0..a.nq()).map(|i| 0.8 - 0.31 * i as f64).collect();
    let t = 0.37;
    let (nq, nc, nu) = (a.nq(), a.nc(), a.nu());
    let same = |n: usize, f: &dyn Fn(&dyn DynModel, &mut [f64])| {
        matrix(n, 1, |o| f(a, o)) == matrix(n, 1, |o| f(b, o))
    };
    same(nq * nq, &|m, o| m.mass_matrix(&q, t, o))
        && same(nq, &|m, o| m.bias(&q, &qd, t, o))
        && same(nq, &|m, o| m.inverse_dynamics(&q, &qd, &qdd, t, o))
        && same(nc, &|m, o| m.constraints(&q, t, o))
        && same(nq * nu, &|m, o| m.actuator_map(o))
        && a.potential_energy(&q, t) == b.potential_energy(&q, t)
}

/// The generic scenes of `scenes/`, compiled into this crate.
pub const COMPILED_SCENES: Compiled = Compiled {
    scenes: crate::scenes::SCENES,
    model: crate::scenes::model,
    perturbed_scenes: crate::perturbed_scenes::SCENES,
    perturbed_model: crate::perturbed_scenes::model,
};

/// Run the command on the scenes of `compiled`.
pub fn run(args: &Args, compiled: &Compiled) -> Result<(), String> {
    let parsed = crate::codegen::Model::load(&args.scene).map_err(|e| e.to_string())?;
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
    let text = std::fs::read_to_string(&args.states)
        .map_err(|e| format!("cannot read {}: {e}", args.states.display()))?;
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
