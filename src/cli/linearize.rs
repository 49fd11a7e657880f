//! `flexdyn linearize`: the continuous-time linearization `x' ~ f0 + A (x -
//! x0) + B (u - u0)` of a scene's equations of motion at one state, with
//! `u` the actuator inputs, from the exact generated derivatives
//! ([`flexdyn_runtime::forward_dynamics_derivatives`]), written as JSON.
//!
//! Unconstrained scenes: `x = (q, qd)`. Constrained scenes: `x = (z, zd)`
//! with `z` independent coordinates (named by `--independent`, else chosen
//! by a column-pivoted QR factorisation of `Phi_q`: the `nc` best pivots
//! are the dependent coordinates `w`). On the constraint manifold `dq/dz =
//! S` (`S_z = I`, `S_w = -Phi_w^-1 Phi_z`), `dqd/dzd = S`, and `dqd/dz` has
//! `Phi_w dwd/dz = -G S` with `G = d(Phi_q qd + Phi_t)/dq`; so `A =
//! [[0, I], [F_q S + F_qd dqd/dz, F_qd S]]` and `B = [[0], [F_tau]]`, `F`
//! the rows `z` of the derivatives of `qdd`.

use std::path::PathBuf;

use nalgebra::{DMatrix, DVector};

use crate::compiled::Compiled;
use crate::dynamic::no_mass_hint;
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
    /// The independent coordinates of a constrained scene (as many as
    /// coordinates minus constraints), comma-separated; chosen by a pivoted
    /// factorisation of the constraint Jacobian when absent.
    #[arg(long, value_delimiter = ',', value_name = "NAMES")]
    pub independent: Option<Vec<String>>,
    /// Output file (standard output when absent).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// The linearization as written.
#[derive(Debug, serde::Serialize)]
struct Linearization {
    scene: String,
    t: f64,
    /// Names of the state entries: the (independent) coordinates, then
    /// their rates (`<name>_dot`).
    states: Vec<String>,
    /// A constrained scene's dependent coordinates, and how the
    /// independent ones were chosen.
    #[serde(skip_serializing_if = "Option::is_none")]
    reduction: Option<Reduction>,
    /// Names of the inputs (the actuators).
    inputs: Vec<String>,
    /// The operating point `x0`.
    x0: Vec<f64>,
    /// The inputs `u0`.
    u0: Vec<f64>,
    /// `f(x0, u0)`, the rates and accelerations: zero at an equilibrium.
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

/// How a constrained scene's state was reduced.
#[derive(Debug, serde::Serialize)]
struct Reduction {
    /// The dependent coordinates `w`, determined by the independent ones.
    dependent: Vec<String>,
    /// `--independent`, or the pivoted QR factorisation of `Phi_q`.
    chosen_by: &'static str,
    /// The full state `(q, qd)` the linearization is taken at (after
    /// projection onto the constraints).
    q: Vec<f64>,
    /// Its velocities.
    qd: Vec<f64>,
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
    if !parsed.outputs.dynamics_derivatives {
        return Err(format!(
            "{}: scene `{}` does not generate the derivatives `linearize` needs: add \
             `outputs = [\"dynamics_derivatives\"]`",
            args.scene.display(),
            parsed.name
        ));
    }
    if nc == 0 && args.independent.is_some() {
        return Err(format!(
            "--independent: scene `{}` has no constraints (every coordinate is independent)",
            parsed.name
        ));
    }
    let coordinates: Vec<String> = model.coordinates().iter().map(|c| c.to_string()).collect();
    let given = match &args.independent {
        Some(names) => Some(named(names, &coordinates, nq - nc, &parsed.name)?),
        None => None,
    };
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
    let mut at = flexdyn_runtime::StateOf {
        q: DVector::from_column_slice(&state.q),
        qd: DVector::from_column_slice(&state.qd),
        t: state.t,
    };
    let constraints: Vec<String> = parsed.constraints.iter().map(|c| c.name.clone()).collect();
    super::simulate::make_consistent(model.as_ref(), &mut at, false, &constraints)?;
    let tau = DVector::from_column_slice(&u0);
    let d =
        flexdyn_runtime::forward_dynamics_derivatives(model.as_ref(), &at.q, &at.qd, at.t, &tau)
            .map_err(|e| {
                format!(
                    "linearize at {}: {e}{}",
                    args.state.display(),
                    no_mass_hint(model.as_ref(), &e)
                )
            })?;
    // The independent coordinates, and dq/dz, dqd/dz (both nq x nz).
    let (independent, reduction, s_mat, s_dot) = if nc == 0 {
        let all: Vec<usize> = (0..nq).collect();
        (all, None, DMatrix::identity(nq, nq), DMatrix::zeros(nq, nq))
    } else {
        let mut phi_q = DMatrix::zeros(nc, nq);
        let mut phi_t = DVector::zeros(nc);
        model.constraint_jacobian(at.q.as_slice(), at.t, phi_q.as_mut_slice());
        model.constraint_time_derivative(at.q.as_slice(), at.t, phi_t.as_mut_slice());
        let (z, chosen_by) = match given {
            Some(z) => (z, "--independent"),
            None => (pivoted(&phi_q), "pivoted QR factorisation of Phi_q"),
        };
        let w: Vec<usize> = (0..nq).filter(|i| !z.contains(i)).collect();
        let phi_w = phi_q.select_columns(&w);
        let lu = phi_w.clone().full_piv_lu();
        let name_list =
            |ix: &[usize]| -> Vec<String> { ix.iter().map(|&i| coordinates[i].clone()).collect() };
        let singular = || {
            format!(
                "the constraints do not determine the dependent coordinates {} from the \
                 independent ones {} here (their columns of Phi_q are singular): choose other \
                 --independent coordinates",
                name_list(&w).join(", "),
                name_list(&z).join(", ")
            )
        };
        if !lu.is_invertible() || rcond(&lu) <= 1e-12 {
            return Err(singular());
        }
        let solve = |b: &DMatrix<f64>| lu.solve(b).ok_or_else(singular);
        // S: rows z the identity, rows w -Phi_w^-1 Phi_z.
        let sw = -solve(&phi_q.select_columns(&z))?;
        let mut s_mat = DMatrix::zeros(nq, z.len());
        for (k, &i) in z.iter().enumerate() {
            s_mat[(i, k)] = 1.0;
        }
        for (r, &i) in w.iter().enumerate() {
            s_mat.row_mut(i).copy_from(&sw.row(r));
        }
        let dw = -solve(&(&d.velocity_constraint_q * &s_mat))?;
        let mut s_dot = DMatrix::zeros(nq, z.len());
        for (r, &i) in w.iter().enumerate() {
            s_dot.row_mut(i).copy_from(&dw.row(r));
        }
        let reduction = Reduction {
            dependent: name_list(&w),
            chosen_by,
            q: at.q.as_slice().to_vec(),
            qd: at.qd.as_slice().to_vec(),
        };
        (z, Some(reduction), s_mat, s_dot)
    };
    let nz = independent.len();
    let rows_z = |m: &DMatrix<f64>| m.select_rows(&independent);
    let (f_q, f_qd, f_tau) = (rows_z(&d.qdd_q), rows_z(&d.qdd_qd), rows_z(&d.qdd_tau));
    // x' = (zd, zdd(z, zd, u)).
    let mut a = DMatrix::zeros(2 * nz, 2 * nz);
    let mut b = DMatrix::zeros(2 * nz, nu);
    a.view_mut((0, nz), (nz, nz)).fill_with_identity();
    a.view_mut((nz, 0), (nz, nz))
        .copy_from(&(&f_q * &s_mat + &f_qd * &s_dot));
    a.view_mut((nz, nz), (nz, nz)).copy_from(&(&f_qd * &s_mat));
    b.view_mut((nz, 0), (nz, nu)).copy_from(&f_tau);
    let pick = |v: &DVector<f64>| independent.iter().map(|&i| v[i]).collect::<Vec<f64>>();
    let states = independent
        .iter()
        .map(|&i| coordinates[i].clone())
        .chain(
            independent
                .iter()
                .map(|&i| format!("{}_dot", coordinates[i])),
        )
        .collect();
    let rows = crate::eval::rows;
    let out = Linearization {
        scene: parsed.name.clone(),
        t: at.t,
        states,
        reduction,
        inputs: actuators,
        x0: [pick(&at.q), pick(&at.qd)].concat(),
        u0,
        f0: [pick(&at.qd), pick(&d.qdd)].concat(),
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

/// The indices of the independent coordinates `names` (exactly `count`,
/// distinct, of the scene's `coordinates`).
fn named(
    names: &[String],
    coordinates: &[String],
    count: usize,
    scene: &str,
) -> Result<Vec<usize>, String> {
    let mut out = Vec::new();
    for name in names {
        let i = coordinates.iter().position(|c| c == name).ok_or_else(|| {
            format!(
                "--independent: scene `{scene}` has no coordinate `{name}` (coordinates: {})",
                coordinates.join(", ")
            )
        })?;
        if out.contains(&i) {
            return Err(format!("--independent: `{name}` is named twice"));
        }
        out.push(i);
    }
    if out.len() != count {
        return Err(format!(
            "--independent: scene `{scene}` has {} coordinates and {} constraints, so {count} \
             independent coordinates; {} named",
            coordinates.len(),
            coordinates.len() - count,
            out.len()
        ));
    }
    out.sort_unstable();
    Ok(out)
}

/// The independent coordinates of a column-pivoted QR factorisation of
/// `phi_q` (`nc x nq`): all but its first `nc` pivot columns, in order.
fn pivoted(phi_q: &DMatrix<f64>) -> Vec<usize> {
    let (nc, nq) = phi_q.shape();
    let qr = phi_q.clone().col_piv_qr();
    // The column order of `Phi_q P`: permute the indices as the columns.
    let mut order = nalgebra::RowDVector::from_fn(nq, |_, j| j as f64);
    qr.p().permute_columns(&mut order);
    let dependent: Vec<usize> = order.iter().take(nc).map(|&j| j as usize).collect();
    (0..nq).filter(|i| !dependent.contains(i)).collect()
}

/// A reciprocal condition estimate from an LU factorisation:
/// smallest over largest pivot magnitude of `U`.
fn rcond(lu: &nalgebra::linalg::FullPivLU<f64, nalgebra::Dyn, nalgebra::Dyn>) -> f64 {
    let pivots = lu.u().diagonal().map(f64::abs);
    let (lo, hi) = (pivots.min(), pivots.max());
    if hi > 0.0 {
        lo / hi
    } else {
        0.0
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
