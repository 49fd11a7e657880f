//! Evaluation of a compiled scene's generated terms at given states, with
//! JSON input and output (`flexdyn eval`), used by the CasADi validation.

use serde::{Deserialize, Serialize};

use std::collections::BTreeMap;

use crate::dynamic::{matrix, no_mass_hint, vector, DynModel, Fused, IdDerivatives, MarkerPose};
use nalgebra::{DMatrix, DVector, Dyn};

/// One state to evaluate at.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct State {
    /// Positions.
    pub q: Vec<f64>,
    /// Velocities.
    pub qd: Vec<f64>,
    /// Accelerations, for the inverse dynamics (zero when left out).
    #[serde(default)]
    pub qdd: Vec<f64>,
    /// Actuator inputs, for the forward dynamics (zero when left out).
    #[serde(default)]
    pub tau: Vec<f64>,
    /// Time.
    #[serde(default)]
    pub t: f64,
    /// Runtime parameter values by name (the scene's nominal values otherwise).
    #[serde(default)]
    pub params: std::collections::BTreeMap<String, f64>,
}

/// The input file of `flexdyn eval`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct States {
    /// States to evaluate at.
    pub states: Vec<State>,
}

/// Every generated term at one state. Matrices are lists of rows.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Terms {
    /// Mass matrix.
    pub mass_matrix: Vec<Vec<f64>>,
    /// Bias forces.
    pub bias: Vec<f64>,
    /// Constraint residuals.
    pub constraints: Vec<f64>,
    /// Constraint Jacobian.
    pub constraint_jacobian: Vec<Vec<f64>>,
    /// Explicit time derivative of the constraints.
    pub constraint_time_derivative: Vec<f64>,
    /// Acceleration right-hand side.
    pub constraint_rhs: Vec<f64>,
    /// Actuator map.
    pub actuator_map: Vec<Vec<f64>>,
    /// `Phi` as the fused `constraints_and_jacobian` computes it (what the
    /// Newton iterations use).
    pub fused_constraints: Vec<f64>,
    /// `Phi_q` from `constraints_and_jacobian`.
    pub fused_position_constraint_jacobian: Vec<Vec<f64>>,
    /// `M` as the fused `dynamics_terms` computes it (what the solvers use).
    pub fused_mass_matrix: Vec<Vec<f64>>,
    /// `h` from `dynamics_terms`.
    pub fused_bias: Vec<f64>,
    /// `Phi_q` from `dynamics_terms`.
    pub fused_constraint_jacobian: Vec<Vec<f64>>,
    /// `gamma` from `dynamics_terms`.
    pub fused_constraint_rhs: Vec<f64>,
    /// Inverse dynamics `M qdd + h` at the state's accelerations.
    pub inverse_dynamics: Vec<f64>,
    /// Kinetic energy.
    pub kinetic_energy: f64,
    /// Potential energy.
    pub potential_energy: f64,
    /// Coriolis forces, when the scene generates them.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub coriolis_forces: Option<Vec<f64>>,
    /// Gravity and elastic forces, when generated.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub potential_forces: Option<Vec<f64>>,
    /// Damping forces, when generated.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub damping_forces: Option<Vec<f64>>,
    /// Coriolis matrix, when generated.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub coriolis_matrix: Option<Vec<Vec<f64>>>,
    /// `dh/dq`, when generated.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bias_jacobian_q: Option<Vec<Vec<f64>>>,
    /// `dh/dqd`, when generated.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bias_jacobian_qd: Option<Vec<Vec<f64>>>,
    /// `tau` as `inverse_dynamics_derivatives` computes it (with its
    /// derivatives, sharing subexpressions), when generated.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fused_inverse_dynamics: Option<Vec<f64>>,
    /// `d tau / d q` of the inverse dynamics at the state's accelerations,
    /// when the scene generates `dynamics_derivatives`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub inverse_dynamics_q: Option<Vec<Vec<f64>>>,
    /// `d tau / d qd`, likewise.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub inverse_dynamics_qd: Option<Vec<Vec<f64>>>,
    /// The accelerations at the state's inputs: `M^-1 (B tau - h)` for an
    /// unconstrained scene; for a constrained scene that generates
    /// `dynamics_derivatives`, those of the ideal constrained equations
    /// (`M qdd - Phi_q^T lambda = B tau - h`, `Phi_q qdd = gamma`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub forward_dynamics: Option<Vec<f64>>,
    /// Why the forward dynamics (and their derivatives) are left out at this
    /// state: the runtime's error, e.g. a mass matrix that is not positive
    /// definite because a coordinate moves no mass (the other terms are
    /// still written).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub forward_dynamics_error: Option<String>,
    /// `d qdd / d q` of the forward dynamics, for a scene that generates
    /// `dynamics_derivatives`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub forward_dynamics_q: Option<Vec<Vec<f64>>>,
    /// `d qdd / d qd`, likewise.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub forward_dynamics_qd: Option<Vec<Vec<f64>>>,
    /// `d qdd / d tau` (`nq x nu`), likewise.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub forward_dynamics_tau: Option<Vec<Vec<f64>>>,
    /// The constraint forces `lambda` with `forward_dynamics`, for a
    /// constrained scene that generates `dynamics_derivatives`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub constraint_forces: Option<Vec<f64>>,
    /// `d lambda / d q`, likewise.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub constraint_forces_q: Option<Vec<Vec<f64>>>,
    /// `d lambda / d qd`, likewise.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub constraint_forces_qd: Option<Vec<Vec<f64>>>,
    /// `d lambda / d tau` (`nc x nu`), likewise.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub constraint_forces_tau: Option<Vec<Vec<f64>>>,
    /// Each marker's kinematics, by name.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub markers: BTreeMap<String, Marker>,
}

/// A marker's kinematics at one state (world axes).
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Marker {
    /// Position of the point.
    pub position: [f64; 3],
    /// Rotation from the marker's axes to world axes, as rows.
    pub rotation: [[f64; 3]; 3],
    /// Linear velocity of the point, then angular velocity.
    pub velocity: [f64; 6],
    /// Jacobian (6 rows of `nq`): `velocity = jacobian qd` plus explicit
    /// time terms.
    pub jacobian: Vec<Vec<f64>>,
    /// Acceleration at `qdd = 0` (the point's classical acceleration, then
    /// the angular acceleration).
    pub acceleration_bias: [f64; 6],
}

/// Marker `k`'s kinematics at `(q, qd, t)`.
fn marker(model: &dyn DynModel, k: usize, q: &[f64], qd: &[f64], t: f64) -> Marker {
    let (mut position, mut rotation) = ([0.0; 3], nalgebra::Matrix3::zeros());
    let mut jacobian = DMatrix::zeros(6, model.nq());
    let out = MarkerPose {
        position: &mut position,
        rotation: rotation.as_mut_slice(),
        jacobian: jacobian.as_mut_slice(),
    };
    let given = model.marker_jacobian(k, q, t, out);
    let (mut velocity, mut acceleration_bias) = ([0.0; 6], [0.0; 6]);
    let moving = model.marker_motion(k, q, qd, t, &mut velocity, &mut acceleration_bias);
    debug_assert!(given && moving, "marker {k} is generated");
    Marker {
        position,
        rotation: std::array::from_fn(|i| std::array::from_fn(|j| rotation[(i, j)])),
        velocity,
        jacobian: rows(&jacobian),
        acceleration_bias,
    }
}

/// A matrix as a list of rows (JSON's layout).
pub(crate) fn rows(m: &nalgebra::DMatrix<f64>) -> Vec<Vec<f64>> {
    m.row_iter().map(|r| r.iter().copied().collect()).collect()
}

/// Check a state's dimensions and finiteness.
pub fn check_state(model: &dyn DynModel, s: &State, k: usize) -> Result<(), String> {
    let n = model.nq();
    if s.q.len() != n || s.qd.len() != n {
        return Err(format!(
            "state {k}: scene `{}` has {n} coordinates, got {} positions and {} velocities",
            model.name(),
            s.q.len(),
            s.qd.len()
        ));
    }
    if !(s.qdd.is_empty() || s.qdd.len() == n) {
        return Err(format!(
            "state {k}: scene `{}` has {n} coordinates, got {} accelerations",
            model.name(),
            s.qdd.len()
        ));
    }
    if !(s.tau.is_empty() || s.tau.len() == model.nu()) {
        return Err(format!(
            "state {k}: scene `{}` has {} actuators, got {} inputs `tau`",
            model.name(),
            model.nu(),
            s.tau.len()
        ));
    }
    let values = s.q.iter().chain(&s.qd).chain(&s.qdd).chain(&s.tau);
    if !(values.into_iter().all(|x| x.is_finite()) && s.t.is_finite()) {
        return Err(format!("state {k}: non-finite value"));
    }
    Ok(())
}

/// One state read from a JSON file (`{"q": [..], "qd": [..], "t": 0}`,
/// optionally `"params"`, `"qdd"`, `"tau"`), checked against `model`, with
/// its runtime parameters set on `model`; errors name the file.
pub fn read_state(path: &std::path::Path, model: &mut dyn DynModel) -> Result<State, String> {
    let text = crate::table::read_input(path, "state file")?;
    let s: State = serde_json::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))?;
    check_state(model, &s, 0).map_err(|e| format!("{}: {e}", path.display()))?;
    set_parameters(model, &s.params).map_err(|e| format!("{}: {e}", path.display()))?;
    Ok(s)
}

/// Sets a state's runtime parameters on `model`; an error naming a value
/// that is not finite or a name the scene does not have.
fn set_parameters(model: &mut dyn DynModel, params: &BTreeMap<String, f64>) -> Result<(), String> {
    for (name, &value) in params {
        if !value.is_finite() {
            return Err(format!("parameter `{name}` is not finite"));
        }
        if !model.set_parameter(name, value) {
            return Err(format!(
                "scene `{}` has no runtime parameter `{name}` (it has: {})",
                model.name(),
                model.parameters().join(", ")
            ));
        }
    }
    Ok(())
}

/// Evaluate every term at one state, with the state's runtime parameters
/// (the model is left with them set); an error naming the first term that
/// is not finite there.
pub fn evaluate(model: &mut dyn DynModel, s: &State) -> Result<Terms, String> {
    set_parameters(model, &s.params)?;
    let (q, qd, t) = (&s.q, &s.qd, s.t);
    let (nq, nc, nu) = (model.nq(), model.nc(), model.nu());
    let model = &*model;
    let vec = |n: usize, f: &dyn Fn(&mut [f64])| vector(n, f).as_slice().to_vec();
    // An optional output: `None` when the scene does not generate it.
    let optional = |rows: usize, cols: usize, f: &dyn Fn(&mut [f64]) -> bool| {
        let mut given = false;
        let m = matrix(rows, cols, |o| given = f(o));
        given.then_some(m)
    };
    let (mut h_q, mut h_qd) = (DMatrix::zeros(nq, nq), DMatrix::zeros(nq, nq));
    let jacobians = model
        .bias_jacobians(q, qd, t, h_q.as_mut_slice(), h_qd.as_mut_slice())
        .then_some((h_q, h_qd));
    let (mut fused_phi, mut fused_position_phi_q) = (DVector::zeros(nc), DMatrix::zeros(nc, nq));
    model.constraints_and_jacobian(
        q,
        t,
        fused_phi.as_mut_slice(),
        fused_position_phi_q.as_mut_slice(),
    );
    let (mut fused_m, mut fused_h) = (DMatrix::zeros(nq, nq), DVector::zeros(nq));
    let (mut fused_phi_q, mut fused_gamma) = (DMatrix::zeros(nc, nq), DVector::zeros(nc));
    let fused = Fused {
        m: fused_m.as_mut_slice(),
        h: fused_h.as_mut_slice(),
        phi_q: fused_phi_q.as_mut_slice(),
        gamma: fused_gamma.as_mut_slice(),
    };
    model.dynamics_terms(q, qd, t, fused);
    let qdd = if s.qdd.is_empty() {
        vec![0.0; s.q.len()]
    } else {
        s.qdd.clone()
    };
    let column = |m: DMatrix<f64>| m.as_slice().to_vec();
    let (mut id, mut tau_q, mut tau_qd) = (
        DVector::zeros(nq),
        DMatrix::zeros(nq, nq),
        DMatrix::zeros(nq, nq),
    );
    let out = IdDerivatives {
        tau: id.as_mut_slice(),
        tau_q: tau_q.as_mut_slice(),
        tau_qd: tau_qd.as_mut_slice(),
    };
    let id_derivatives = model
        .inverse_dynamics_derivatives(q, qd, &qdd, t, out)
        .then_some((id, tau_q, tau_qd));
    let tau = if s.tau.is_empty() {
        vec![0.0; nu]
    } else {
        s.tau.clone()
    };
    let generated = id_derivatives.is_some();
    let (forward, forward_dynamics_error) = match (nc == 0 || generated)
        .then(|| forward_dynamics(model, q, qd, t, &tau, generated))
        .transpose()
    {
        Ok(forward) => (forward, None),
        Err(e) => (None, Some(e)),
    };
    let derivatives = forward.as_ref().and_then(|f| f.derivatives.as_ref());
    let constrained = derivatives.filter(|_| nc > 0);
    let terms = Terms {
        mass_matrix: rows(&matrix(nq, nq, |o| model.mass_matrix(q, t, o))),
        bias: vec(nq, &|o| model.bias(q, qd, t, o)),
        constraints: vec(nc, &|o| model.constraints(q, t, o)),
        constraint_jacobian: rows(&matrix(nc, nq, |o| model.constraint_jacobian(q, t, o))),
        constraint_time_derivative: vec(nc, &|o| model.constraint_time_derivative(q, t, o)),
        constraint_rhs: vec(nc, &|o| model.constraint_rhs(q, qd, t, o)),
        actuator_map: rows(&matrix(nq, nu, |o| model.actuator_map(o))),
        fused_constraints: fused_phi.as_slice().to_vec(),
        fused_position_constraint_jacobian: rows(&fused_position_phi_q),
        fused_mass_matrix: rows(&fused_m),
        fused_bias: fused_h.as_slice().to_vec(),
        fused_constraint_jacobian: rows(&fused_phi_q),
        fused_constraint_rhs: fused_gamma.as_slice().to_vec(),
        inverse_dynamics: vec(nq, &|o| model.inverse_dynamics(q, qd, &qdd, t, o)),
        kinetic_energy: model.kinetic_energy(q, qd, t),
        potential_energy: model.potential_energy(q, t),
        coriolis_forces: optional(nq, 1, &|o| model.coriolis_forces(q, qd, t, o)).map(column),
        potential_forces: optional(nq, 1, &|o| model.potential_forces(q, t, o)).map(column),
        damping_forces: optional(nq, 1, &|o| model.damping_forces(q, qd, t, o)).map(column),
        coriolis_matrix: optional(nq, nq, &|o| model.coriolis_matrix(q, qd, t, o))
            .map(|m| rows(&m)),
        bias_jacobian_q: jacobians.as_ref().map(|(h_q, _)| rows(h_q)),
        bias_jacobian_qd: jacobians.as_ref().map(|(_, h_qd)| rows(h_qd)),
        fused_inverse_dynamics: id_derivatives
            .as_ref()
            .map(|(id, ..)| id.as_slice().to_vec()),
        inverse_dynamics_q: id_derivatives.as_ref().map(|(_, a, _)| rows(a)),
        inverse_dynamics_qd: id_derivatives.as_ref().map(|(.., b)| rows(b)),
        forward_dynamics: forward.as_ref().map(|f| f.qdd.as_slice().to_vec()),
        forward_dynamics_error,
        forward_dynamics_q: derivatives.map(|d| rows(&d.qdd_q)),
        forward_dynamics_qd: derivatives.map(|d| rows(&d.qdd_qd)),
        forward_dynamics_tau: derivatives.map(|d| rows(&d.qdd_tau)),
        constraint_forces: constrained.map(|d| d.lambda.as_slice().to_vec()),
        constraint_forces_q: constrained.map(|d| rows(&d.lambda_q)),
        constraint_forces_qd: constrained.map(|d| rows(&d.lambda_qd)),
        constraint_forces_tau: constrained.map(|d| rows(&d.lambda_tau)),
        markers: model
            .markers()
            .into_iter()
            .enumerate()
            .map(|(k, name)| (name.to_owned(), marker(model, k, q, qd, t)))
            .collect(),
    };
    // JSON has no number for infinities and NaN (serde writes `null`).
    let json = serde_json::to_value(&terms).map_err(|e| e.to_string())?;
    match first_null(&json) {
        Some(entry) => Err(format!(
            "`{entry}` is not finite at this state (the state is beyond the range where the \
             scene's terms are finite numbers)"
        )),
        None => Ok(terms),
    }
}

/// The forward dynamics of a scene at one state, with their derivatives
/// (and the constraint forces') where generated.
struct Forward {
    qdd: DVector<f64>,
    derivatives: Option<Derivatives>,
}

/// [`flexdyn_runtime::ForwardDerivativesOf`] at run-time sizes.
pub type Derivatives = flexdyn_runtime::ForwardDerivativesOf<f64, Dyn, Dyn, Dyn>;

/// [`Forward`] at `(q, qd, t)` with inputs `tau`, from the runtime's
/// solvers (the derivatives when `derivatives`).
fn forward_dynamics(
    model: &dyn DynModel,
    q: &[f64],
    qd: &[f64],
    t: f64,
    tau: &[f64],
    derivatives: bool,
) -> Result<Forward, String> {
    let (q, qd) = (
        DVector::from_column_slice(q),
        DVector::from_column_slice(qd),
    );
    let tau = DVector::from_column_slice(tau);
    let failed = |e: flexdyn_runtime::Error| format!("{e}{}", no_mass_hint(model, &e));
    if derivatives {
        let d = flexdyn_runtime::forward_dynamics_derivatives(model, &q, &qd, t, &tau)
            .map_err(failed)?;
        Ok(Forward {
            qdd: d.qdd.clone(),
            derivatives: Some(d),
        })
    } else {
        let config = flexdyn_runtime::DynamicsConfig::default();
        let a = flexdyn_runtime::accelerations(model, &config, &q, &qd, t, &tau).map_err(failed)?;
        Ok(Forward {
            qdd: a.qdd,
            derivatives: None,
        })
    }
}

/// The path (`mass_matrix[0][1]`) of the first `null` in `value`.
fn first_null(value: &serde_json::Value) -> Option<String> {
    use serde_json::Value;
    match value {
        Value::Null => Some(String::new()),
        Value::Array(items) => items
            .iter()
            .enumerate()
            .find_map(|(k, v)| first_null(v).map(|rest| format!("[{k}]{rest}"))),
        Value::Object(fields) => fields
            .iter()
            .find_map(|(name, v)| first_null(v).map(|rest| format!("{name}{rest}"))),
        _ => None,
    }
}
