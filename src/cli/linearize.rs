//! `flexdyn linearize`: the continuous-time linearization `x' ~ f0 + A (x -
//! x0) + B (u - u0)` of an unconstrained scene's equations of motion, with
//! `x = (q, qd)` and `u` the actuator inputs, at one state, from the exact
//! generated derivatives of the inverse dynamics
//! ([`flexdyn_runtime::forward_dynamics_derivatives`]), written as JSON.

use std::path::PathBuf;

use nalgebra::{DMatrix, DVector};

use crate::compiled::Compiled;
use crate::table::write_atomic;

/// Linearize a scene at a state: `A = df/dx`, `B = df/du` of `x' = f(x, u)`
/// with `x = (q, qd)`, as JSON with the row and column names. The scene
/// must ask for `outputs = ["dynamics_derivatives"]`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scene file (unconstrained, with `outputs = ["dynamics_derivatives"]`).
    #[arg(long)]
    pub scene: PathBuf,
    /// Interpret the scene file even when a scene of its name is compiled in.
    #[arg(long)]
    pub interpret: bool,
    /// The operating point: `{"q": [..], "qd": [..], "t": 0.0}` (optionally
    /// `"tau"`: the inputs, and `"params"`: runtime parameter values).
    #[arg(long)]
    pub state: PathBuf,
    /// An actuator input at the operating point (zero unless given, or
    /// given in the state's `tau`); repeat for several.
    #[arg(long = "input", value_name = "NAME=VALUE")]
    pub inputs: Vec<String>,
    /// Output file (standard output when absent).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// The linearization as written.
#[derive(Debug, serde::Serialize)]
struct Linearization {
    scene: String,
    t: f64,
    /// Names of the state entries: the coordinates, then their rates
    /// (`<name>_dot`).
    states: Vec<String>,
    /// Names of the inputs (the actuators).
    inputs: Vec<String>,
    /// The operating point `x0 = (q, qd)`.
    x0: Vec<f64>,
    /// The inputs `u0`.
    u0: Vec<f64>,
    /// `f(x0, u0) = (qd, qdd)`: zero at an equilibrium.
    f0: Vec<f64>,
    /// `df/dx` (rows of `2 nq`).
    #[serde(rename = "A")]
    a: Vec<Vec<f64>>,
    /// `df/du` (rows of `nu`).
    #[serde(rename = "B")]
    b: Vec<Vec<f64>>,
    /// The eigenvalues of `A` as `[re, im]`, by increasing real part.
    #[serde(rename = "eigenvalues_A")]
    eigenvalues_a: Vec<[f64; 2]>,
}

/// Run the command on the scenes of `compiled`.
pub fn run(args: &Args, compiled: &Compiled) -> Result<(), String> {
    let parsed = crate::codegen::Model::load(&args.scene).map_err(|e| e.to_string())?;
    super::tell_notes(&parsed, false);
    if let Some(out) = &args.out {
        crate::table::check_output(out)?;
    }
    let mut model = compiled.load(&args.scene, &parsed.name, args.interpret)?;
    let (nq, nc, nu) = (model.nq(), model.nc(), model.nu());
    if nc != 0 {
        return Err(format!(
            "scene `{}` has {nc} constraints: `linearize` handles unconstrained scenes only \
             (a linearization in independent coordinates is not provided yet)",
            parsed.name
        ));
    }
    if !parsed.outputs.dynamics_derivatives {
        return Err(format!(
            "{}: scene `{}` does not generate the derivatives `linearize` needs: add \
             `outputs = [\"dynamics_derivatives\"]`",
            args.scene.display(),
            parsed.name
        ));
    }
    let state = crate::eval::read_state(&args.state, model.as_mut())?;
    let actuators: Vec<String> = model.actuators().iter().map(|a| a.to_string()).collect();
    let mut u0 = match state.tau.is_empty() {
        true => vec![0.0; nu],
        false => state.tau.clone(),
    };
    for text in &args.inputs {
        let (name, value) = super::simulate::assignment("--input", text)?;
        let j = actuators.iter().position(|a| a == name).ok_or_else(|| {
            format!(
                "--input `{text}`: scene `{}` has no actuator `{name}` (actuators: {})",
                parsed.name,
                actuators.join(", ")
            )
        })?;
        u0[j] = value
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| format!("--input `{text}`: `{value}` is not a finite number"))?;
    }
    let (q, qd) = (
        DVector::from_column_slice(&state.q),
        DVector::from_column_slice(&state.qd),
    );
    let tau = DVector::from_column_slice(&u0);
    let d = flexdyn_runtime::forward_dynamics_derivatives(model.as_ref(), &q, &qd, state.t, &tau)
        .map_err(|e| format!("linearize at {}: {e}", args.state.display()))?;
    // x' = (qd, qdd(q, qd, u)).
    let mut a = DMatrix::zeros(2 * nq, 2 * nq);
    let mut b = DMatrix::zeros(2 * nq, nu);
    a.view_mut((0, nq), (nq, nq)).fill_with_identity();
    a.view_mut((nq, 0), (nq, nq)).copy_from(&d.qdd_q);
    a.view_mut((nq, nq), (nq, nq)).copy_from(&d.qdd_qd);
    b.view_mut((nq, 0), (nq, nu)).copy_from(&d.qdd_tau);
    let coordinates = model.coordinates();
    let states = coordinates
        .iter()
        .map(|c| c.to_string())
        .chain(coordinates.iter().map(|c| format!("{c}_dot")))
        .collect();
    let rows = |m: &DMatrix<f64>| -> Vec<Vec<f64>> {
        m.row_iter().map(|r| r.iter().copied().collect()).collect()
    };
    let out = Linearization {
        scene: parsed.name.clone(),
        t: state.t,
        states,
        inputs: actuators,
        x0: state.q.iter().chain(&state.qd).copied().collect(),
        u0,
        f0: state.qd.iter().chain(d.qdd.iter()).copied().collect(),
        a: rows(&a),
        b: rows(&b),
        eigenvalues_a: eigenvalues(&a)?,
    };
    let text = serde_json::to_string_pretty(&out).map_err(|e| e.to_string())?;
    match &args.out {
        Some(path) => write_atomic(path, &text),
        None => {
            println!("{text}");
            Ok(())
        }
    }
}

/// The eigenvalues of `a` (real Schur form, bounded iterations), sorted by
/// real part, then imaginary part.
fn eigenvalues(a: &DMatrix<f64>) -> Result<Vec<[f64; 2]>, String> {
    const MAX_SWEEPS: usize = 10_000;
    let schur = nalgebra::linalg::Schur::try_new(a.clone(), f64::EPSILON, MAX_SWEEPS)
        .ok_or("the eigenvalues of A did not converge")?;
    let mut values: Vec<[f64; 2]> = schur
        .complex_eigenvalues()
        .iter()
        .map(|z| [z.re, z.im])
        .collect();
    values.sort_by(|x, y| x[0].total_cmp(&y[0]).then(x[1].total_cmp(&y[1])));
    Ok(values)
}
