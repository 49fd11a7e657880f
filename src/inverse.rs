//! Inverse dynamics of any scene along prescribed coordinates: what
//! `flexdyn inverse` computes, generic over a compiled (or padded) model.
//!
//! `NP` coordinates `q_S` follow given functions of time `p(t)` (with their
//! rates and accelerations). Two cases:
//!
//! * **Determined** (`NP + NC = NQ`: the constraints fix every other
//!   coordinate): per output time the runtime's
//!   [`InverseDynamics`](flexdyn_runtime::InverseDynamics) solves
//!   `Phi(q, t) = 0` by Newton warm-started from the previous step, the
//!   velocities and accelerations from the constraint derivatives, then
//!   `Phi_q^T lambda + B tau = M qdd + h`: exact at every sample.
//! * **Free coordinates remain** (`NP + NC < NQ`, e.g. elastic coordinates):
//!   servo constraints ([`Servo`] over [`Coordinates`], [`servo_run`],
//!   generalized-alpha) integrate the free coordinates. They start at rest in
//!   static equilibrium under the prescription at the first time: Newton on
//!   `h(q, 0, t0) - Phi_q^T lambda - B tau = 0`, `Phi(q, t0) = 0`,
//!   `q_S = p(t0)` for `(q, lambda, tau)`; the velocities satisfy
//!   `Phi_q qd + Phi_t = 0` and `qd_S = p'(t0)` and are either the smallest
//!   in the mass norm ([`FreeRates::LeastEnergy`]) or zero on the coordinates
//!   the constraints do not need ([`FreeRates::Zero`]). The trial step of
//!   [`servo_run`] is taken without the coordinate projection
//!   ([`ServoConfig::trial_projection`]), as the flexible robot's.
//!
//! Either way the inputs must be determined by the prescription: as many
//! prescribed coordinates as actuators, and a non-singular projected
//! actuation (the runtime names the condition when it is not).

use flexdyn_runtime::control::{servo_run, Coordinates, Servo, ServoConfig, Target};
use flexdyn_runtime::integrate::{GeneralizedAlpha, StepSettings};
use flexdyn_runtime::nalgebra::{DMatrix, DVector, SMatrix, SVector};
use flexdyn_runtime::{
    ErrorKind, GeneralizedAlphaConfig, InverseConfig, InverseDynamics, InverseSolution, Model,
    State,
};

/// A motion `t -> [p, p', p'']`.
pub type Motion<'a> = &'a dyn Fn(f64) -> [f64; 3];

/// A prescribed coordinate: its index and its motion.
pub struct Prescribed<'a> {
    /// Index of the coordinate.
    pub coordinate: usize,
    /// Value, first and second time derivative at `t`.
    pub motion: Motion<'a>,
}

/// What to solve: the real sizes of the scene (a padded model has more),
/// the prescription and the output times.
pub struct Problem<'a> {
    /// Names of the real coordinates (the first `nq` of the model's).
    pub coordinates: Vec<String>,
    /// Names of the real constraints.
    pub constraints: Vec<String>,
    /// Names of the real actuators.
    pub actuators: Vec<String>,
    /// The prescribed real coordinates.
    pub prescribed: Vec<Prescribed<'a>>,
    /// Coordinates held at 0 that an input acts on (the pad inputs'
    /// coordinates of a padded model); not counted in the real sizes.
    pub held_inputs: Vec<usize>,
    /// Other coordinates held at 0 (a padded model's pad coordinates that
    /// no constraint and no input touches).
    pub held_free: Vec<usize>,
    /// Newton's starting point for the first sample (real coordinates).
    pub guess: Vec<f64>,
    /// Output step: outputs at `k dt` for `k = 0..=steps`.
    pub dt: f64,
    /// Output steps (one output more).
    pub steps: usize,
    /// Initial rates of the free coordinates (servo case).
    pub free_rates: FreeRates,
}

/// The initial rates of the coordinates that the prescription and the
/// constraints leave free (the servo case). Both satisfy the velocity
/// constraints `Phi_q qd + Phi_t = 0` with the prescribed rates.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum FreeRates {
    /// The rates of least kinetic energy `qd^T M qd / 2`.
    #[default]
    LeastEnergy,
    /// Zero, except on the coordinates the velocity constraints need: the
    /// first unprescribed coordinates in the scene's order whose columns of
    /// `Phi_q` are independent take the rates the constraints ask for, every
    /// later one starts at rest. With rigid coordinates listed before elastic
    /// ones (as the robot scenes do), the elastic rates start at zero.
    Zero,
}

/// How the motion was solved.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    /// Every coordinate determined by the prescription and the constraints:
    /// exact inverse dynamics at every sample.
    Determined,
    /// Free coordinates integrated under servo constraints.
    Servo,
}

/// The solution at one output time (real sizes).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample<'s> {
    /// Output time.
    pub t: f64,
    /// Actuator inputs.
    pub tau: &'s [f64],
    /// Coordinates.
    pub q: &'s [f64],
    /// Constraint forces (multipliers).
    pub lambda: &'s [f64],
}

/// Where the solution goes: each [`Sample`], in time order, as it is
/// solved (never all in memory); an error stops the solve.
pub type Sink<'s> = &'s mut dyn FnMut(&Sample<'_>) -> Result<(), String>;

/// Solves `problem` on `model` (module docs), each sample to `sink`; how it
/// was solved. Errors name the time, the coordinates and the condition
/// involved. `NP` is the number of prescribed and held coordinates,
/// `NQ - NC` when every coordinate is determined (otherwise unused).
pub fn solve<M, const NQ: usize, const NC: usize, const NU: usize, const NP: usize>(
    model: &M,
    problem: &Problem<'_>,
    sink: Sink<'_>,
) -> Result<Method, String>
where
    M: Model<NQ, NC, NU>,
{
    let (nq, nc, nu) = (
        problem.coordinates.len(),
        problem.constraints.len(),
        problem.actuators.len(),
    );
    let np = problem.prescribed.len();
    let named = |idx: &mut dyn Iterator<Item = usize>| {
        idx.map(|i| format!("`{}`", problem.coordinates[i]))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let prescribed_names = named(&mut problem.prescribed.iter().map(|p| p.coordinate));
    if np != nu {
        return Err(format!(
            "the prescription does not determine the actuator inputs: {np} prescribed \
             coordinate(s) ({prescribed_names}) for {nu} actuator(s) ({}); prescribe exactly \
             one coordinate per actuator",
            problem.actuators.join(", ")
        ));
    }
    if np + nc > nq {
        return Err(format!(
            "the prescription over-determines the motion: {np} prescribed coordinate(s) \
             ({prescribed_names}) and {nc} constraint(s) for {nq} coordinate(s)"
        ));
    }
    let zero = |_: f64| [0.0; 3];
    let mut motions: Vec<(usize, Motion<'_>)> = problem
        .prescribed
        .iter()
        .map(|p| (p.coordinate, p.motion))
        .collect();
    motions.extend(problem.held_inputs.iter().map(|&i| (i, &zero as _)));
    let servo_count = motions.len();
    motions.extend(problem.held_free.iter().map(|&i| (i, &zero as _)));
    let target = |t: f64| {
        let mut out = Target {
            position: SVector::<f64, NP>::zeros(),
            velocity: SVector::zeros(),
            acceleration: SVector::zeros(),
        };
        for (k, (_, f)) in motions.iter().enumerate().take(NP) {
            let [p, v, a] = f(t);
            out.position[k] = p;
            out.velocity[k] = v;
            out.acceleration[k] = a;
        }
        out
    };
    let mut guess = SVector::<f64, NQ>::zeros();
    for (i, g) in problem.guess.iter().enumerate().take(nq) {
        guess[i] = *g;
    }
    let rank_error = |e: flexdyn_runtime::Error| {
        format!(
            "at t = {} s: the prescription of {prescribed_names} does not determine the \
             actuator inputs ({}), or the pose is singular: {}",
            e.t,
            problem.actuators.join(", "),
            e.kind
        )
    };
    if np + nc == nq {
        if motions.len() != NP {
            return Err(format!(
                "internal: {} prescribed and held coordinates for {NP}",
                motions.len()
            ));
        }
        let index = core::array::from_fn(|k| motions[k].0);
        determined(model, problem, index, &target, guess, &rank_error, sink)
    } else {
        if servo_count != NU || NP < NU {
            return Err(format!(
                "internal: {servo_count} prescribed and held coordinates for {NU} inputs"
            ));
        }
        let index = core::array::from_fn(|k| motions[k].0);
        let servo_target = |t: f64| {
            let x = target(t);
            Target {
                position: SVector::<f64, NU>::from_fn(|k, _| x.position[k]),
                velocity: SVector::from_fn(|k, _| x.velocity[k]),
                acceleration: SVector::from_fn(|k, _| x.acceleration[k]),
            }
        };
        servo(
            model,
            problem,
            index,
            &servo_target,
            guess,
            &rank_error,
            sink,
        )
    }
}

type Targets<'a, const N: usize> = &'a dyn Fn(f64) -> Target<N>;

/// The determined case: [`InverseDynamics`] at every output time.
fn determined<M, const NQ: usize, const NC: usize, const NU: usize, const NP: usize>(
    model: &M,
    problem: &Problem<'_>,
    index: [usize; NP],
    target: Targets<'_, NP>,
    guess: SVector<f64, NQ>,
    rank_error: &dyn Fn(flexdyn_runtime::Error) -> String,
    sink: Sink<'_>,
) -> Result<Method, String>
where
    M: Model<NQ, NC, NU>,
{
    let mut solver = InverseDynamics::<NQ, NC, NU, NP>::new(index, guess, InverseConfig::default())
        .map_err(|e| e.to_string())?;
    let mut sol = InverseSolution::<NQ, NC, NU>::default();
    for t in (0..=problem.steps).map(|k| k as f64 * problem.dt) {
        let x = target(t);
        let start = *solver.guess();
        solver
            .solve(
                model,
                t,
                &x.position,
                &x.velocity,
                &x.acceleration,
                &mut sol,
            )
            .map_err(|e| match e.kind {
                ErrorKind::SingularActuation { .. } => rank_error(e),
                ErrorKind::SingularConstraintJacobian { .. }
                | ErrorKind::NewtonNotConverged { .. } => {
                    position_error(model, problem, &index, &x.position, &start, t, e)
                }
                _ => e.to_string(),
            })?;
        sink(&Sample::cut(
            problem,
            t,
            sol.tau.as_slice(),
            sol.q.as_slice(),
            sol.lambda.as_slice(),
        ))?;
    }
    Ok(Method::Determined)
}

/// The error of a failed position solve, with the constraint that is
/// violated most at Newton's starting point and the condition of the
/// Jacobian of the free coordinates there.
fn position_error<M, const NQ: usize, const NC: usize, const NU: usize, const NP: usize>(
    model: &M,
    problem: &Problem<'_>,
    index: &[usize; NP],
    p: &SVector<f64, NP>,
    start: &SVector<f64, NQ>,
    t: f64,
    e: flexdyn_runtime::Error,
) -> String
where
    M: Model<NQ, NC, NU>,
{
    let mut q = *start;
    for (k, &i) in index.iter().enumerate() {
        q[i] = p[k];
    }
    let mut phi = SVector::<f64, NC>::zeros();
    let mut phi_q = SMatrix::<f64, NC, NQ>::zeros();
    model.constraints(&q, t, &mut phi);
    model.constraint_jacobian(&q, t, &mut phi_q);
    let worst = (0..problem.constraints.len())
        .max_by(|&a, &b| phi[a].abs().total_cmp(&phi[b].abs()))
        .unwrap_or(0);
    let free: Vec<usize> = (0..problem.coordinates.len())
        .filter(|i| !index.contains(i))
        .collect();
    let jf = DMatrix::from_fn(problem.constraints.len(), free.len(), |r, c| {
        phi_q[(r, free[c])]
    });
    let sv = jf.singular_values();
    let condition = sv.max() / sv.min();
    format!(
        "at t = {t} s: the constraints cannot be solved for the coordinates {} ({}); \
         from the previous solution, constraint `{}` (multiplier `lambda_{worst}`) is \
         violated most (|Phi| = {:.3e}) and the Jacobian of those coordinates has condition \
         {condition:.3e}: a singular pose, or a prescription the mechanism cannot follow",
        free.iter()
            .map(|&i| format!("`{}`", problem.coordinates[i]))
            .collect::<Vec<_>>()
            .join(", "),
        e.kind,
        problem.constraints.get(worst).map_or("", String::as_str),
        phi[worst].abs()
    )
}

/// The servo case: static equilibrium at the first time, then
/// [`servo_run`] with generalized-alpha.
fn servo<M, const NQ: usize, const NC: usize, const NU: usize>(
    model: &M,
    problem: &Problem<'_>,
    index: [usize; NU],
    target: Targets<'_, NU>,
    guess: SVector<f64, NQ>,
    rank_error: &dyn Fn(flexdyn_runtime::Error) -> String,
    sink: Sink<'_>,
) -> Result<Method, String>
where
    M: Model<NQ, NC, NU>,
{
    let (t0, dt) = (0.0, problem.dt);
    let x0 = target(t0);
    let q = static_equilibrium(model, &index, &problem.held_free, &x0.position, guess, t0)?;
    let qd = initial_velocities(model, &index, &x0.velocity, &q, t0, problem.free_rates)?;
    let mut state = State { q, qd, t: t0 };
    let config = ServoConfig {
        trial_projection: false,
        ..ServoConfig::default()
    };
    let servo = Servo::new(model, Coordinates(index), target, config).map_err(|e| e.to_string())?;
    // L-stable (rho_inf = 0), as the robot's servo: the elastic modes a
    // step of the rigid motion does not resolve are damped, not rung.
    let config = GeneralizedAlphaConfig {
        rho_inf: 0.0,
        filter_start: false,
        ..Default::default()
    };
    let mut integrator = GeneralizedAlpha::<NQ, NC>::new(StepSettings::with_projection(), config);
    let (mut failed, mut k) = (None, 0);
    servo_run(
        &servo,
        &mut integrator,
        &mut state,
        dt,
        problem.steps,
        |s| {
            // The output times exactly (the state's time sums the steps).
            let t = k.min(problem.steps) as f64 * dt;
            k += 1;
            if failed.is_none() {
                failed = match servo.solve::<NQ, NC, NU>(&s.state.q, &s.state.qd, s.state.t) {
                    Ok(x) => sink(&Sample::cut(
                        problem,
                        t,
                        s.tau.as_slice(),
                        s.state.q.as_slice(),
                        x.lambda.as_slice(),
                    ))
                    .err(),
                    Err(e) => Some(rank_error(e)),
                };
            }
        },
    )
    .map_err(rank_error)?;
    failed.map_or(Ok(Method::Servo), Err)
}

/// Newton on `h(q, 0, t) - Phi_q^T lambda - B tau = 0`, `Phi(q, t) = 0`,
/// `q_S = p` for `(q, lambda, tau)` (module docs), the first block's
/// Jacobian by central differences; the force rows of the coordinates
/// `fixed` (which nothing acts on) are replaced by `q_i = 0`.
fn static_equilibrium<M, const NQ: usize, const NC: usize, const NU: usize>(
    model: &M,
    index: &[usize; NU],
    fixed: &[usize],
    p: &SVector<f64, NU>,
    guess: SVector<f64, NQ>,
    t: f64,
) -> Result<SVector<f64, NQ>, String>
where
    M: Model<NQ, NC, NU>,
{
    let n = NQ + NC + NU;
    let mut b = SMatrix::<f64, NQ, NU>::zeros();
    model.actuator_map(&mut b);
    let rest = SVector::<f64, NQ>::zeros();
    // Generalized forces at rest, less the constraint forces.
    let load = |q: &SVector<f64, NQ>, lambda: &DVector<f64>| {
        let mut h = SVector::<f64, NQ>::zeros();
        let mut phi_q = SMatrix::<f64, NC, NQ>::zeros();
        model.bias(q, &rest, t, &mut h);
        model.constraint_jacobian(q, t, &mut phi_q);
        let lambda = SVector::<f64, NC>::from_iterator(lambda.iter().copied());
        (h - phi_q.transpose() * lambda, phi_q)
    };
    let mut x = DVector::<f64>::zeros(n);
    x.rows_mut(0, NQ).copy_from(&guess);
    for (k, &i) in index.iter().enumerate() {
        x[i] = p[k];
    }
    let mut residual_norm = f64::INFINITY;
    for _ in 0..50 {
        let q = SVector::<f64, NQ>::from_iterator(x.rows(0, NQ).iter().copied());
        let lambda = x.rows(NQ, NC).into_owned();
        let tau = SVector::<f64, NU>::from_iterator(x.rows(NQ + NC, NU).iter().copied());
        let (f, phi_q) = load(&q, &lambda);
        let mut phi = SVector::<f64, NC>::zeros();
        model.constraints(&q, t, &mut phi);
        let f = f - b * tau;
        let mut r = DVector::<f64>::zeros(n);
        r.rows_mut(0, NQ).copy_from(&f);
        r.rows_mut(NQ, NC).copy_from(&phi);
        for (k, &i) in index.iter().enumerate() {
            r[NQ + NC + k] = q[i] - p[k];
        }
        for &i in fixed {
            r[i] = q[i];
        }
        let scale = 1.0 + f.amax().max(lambda.amax()).max(tau.amax());
        residual_norm = r.amax();
        if !residual_norm.is_finite() {
            break;
        }
        if residual_norm <= 1e-12 * scale {
            return Ok(q);
        }
        let mut jac = DMatrix::<f64>::zeros(n, n);
        for j in 0..NQ {
            let d = 1e-6 * q[j].abs().max(1e-3);
            let (mut qp, mut qm) = (q, q);
            qp[j] += d;
            qm[j] -= d;
            let column = (load(&qp, &lambda).0 - load(&qm, &lambda).0) / (2.0 * d);
            jac.view_mut((0, j), (NQ, 1)).copy_from(&column);
        }
        for i in 0..NC {
            for j in 0..NQ {
                jac[(NQ + i, j)] = phi_q[(i, j)];
                jac[(j, NQ + i)] = -phi_q[(i, j)];
            }
        }
        for k in 0..NU {
            for j in 0..NQ {
                jac[(j, NQ + NC + k)] = -b[(j, k)];
            }
            jac[(NQ + NC + k, index[k])] = 1.0;
        }
        for &i in fixed {
            jac.row_mut(i).fill(0.0);
            jac[(i, i)] = 1.0;
        }
        let dx = jac
            .full_piv_lu()
            .solve(&(-&r))
            .filter(|d| d.iter().all(|v| v.is_finite()))
            .ok_or_else(|| {
                format!(
                    "at t = {t} s: the static equilibrium under the prescription is singular \
                     (the prescription does not determine the inputs, or the pose is singular)"
                )
            })?;
        x += dx;
    }
    Err(format!(
        "at t = {t} s: the static equilibrium under the prescription did not converge \
         (residual {residual_norm:.3e}); give a better guess with --initial"
    ))
}

/// The initial velocities with `Phi_q qd + Phi_t = 0` and `qd_S = v`,
/// as `free_rates` picks them.
fn initial_velocities<M, const NQ: usize, const NC: usize, const NU: usize>(
    model: &M,
    index: &[usize; NU],
    v: &SVector<f64, NU>,
    q: &SVector<f64, NQ>,
    t: f64,
    free_rates: FreeRates,
) -> Result<SVector<f64, NQ>, String>
where
    M: Model<NQ, NC, NU>,
{
    let mut phi_q = SMatrix::<f64, NC, NQ>::zeros();
    let mut phi_t = SVector::<f64, NC>::zeros();
    model.constraint_jacobian(q, t, &mut phi_q);
    model.constraint_time_derivative(q, t, &mut phi_t);
    match free_rates {
        FreeRates::LeastEnergy => {
            let mut m = SMatrix::<f64, NQ, NQ>::zeros();
            model.mass_matrix(q, t, &mut m);
            // The rows of Phi_q qd = -Phi_t, then qd_S = v.
            let a = DMatrix::from_fn(NC + NU, NQ, |r, c| match r < NC {
                true => phi_q[(r, c)],
                false => f64::from(u8::from(index[r - NC] == c)),
            });
            let rhs = DVector::from_fn(NC + NU, |r, _| match r < NC {
                true => -phi_t[r],
                false => v[r - NC],
            });
            least_energy_velocities(&m, &a, &rhs, t)
        }
        FreeRates::Zero => needed_velocities(&phi_q, &phi_t, index, v, t),
    }
}

/// The velocities of least kinetic energy `qd^T M qd / 2` with `a qd = rhs`.
fn least_energy_velocities<const NQ: usize>(
    m: &SMatrix<f64, NQ, NQ>,
    a: &DMatrix<f64>,
    rhs: &DVector<f64>,
    t: f64,
) -> Result<SVector<f64, NQ>, String> {
    let singular = || format!("at t = {t} s: the initial velocities are not determined");
    let m_inv = DMatrix::from_column_slice(NQ, NQ, m.as_slice())
        .try_inverse()
        .ok_or_else(singular)?;
    let schur = a * &m_inv * a.transpose();
    let y = schur.full_piv_lu().solve(rhs).ok_or_else(singular)?;
    let qd = m_inv * a.transpose() * y;
    Ok(SVector::from_iterator(qd.iter().copied()))
}

/// The velocities with `Phi_q qd + Phi_t = 0` and `qd_S = v` (`S` the
/// coordinates `index`), nonzero only on `S` and on the first columns of
/// `Phi_q` outside `S` (in order) that are independent: the rates the
/// velocity constraints need, every other one zero ([`FreeRates::Zero`]).
/// An error names `t` when the constraints cannot be met so.
pub fn needed_velocities<const NQ: usize, const NC: usize, const NU: usize>(
    phi_q: &SMatrix<f64, NC, NQ>,
    phi_t: &SVector<f64, NC>,
    index: &[usize; NU],
    v: &SVector<f64, NU>,
    t: f64,
) -> Result<SVector<f64, NQ>, String> {
    let mut qd = SVector::<f64, NQ>::zeros();
    for (k, &i) in index.iter().enumerate() {
        qd[i] = v[k];
    }
    // Greedy: keep a column when it is independent of the kept ones
    // (Gram-Schmidt, twice, against an orthonormal basis of them).
    let mut basis: Vec<SVector<f64, NC>> = Vec::with_capacity(NC);
    let mut needed = Vec::with_capacity(NC);
    for j in (0..NQ).filter(|j| !index.contains(j)) {
        if basis.len() == NC {
            break;
        }
        let column = phi_q.column(j).into_owned();
        let mut r = column;
        for _ in 0..2 {
            for b in &basis {
                r -= b * b.dot(&r);
            }
        }
        if r.norm() > 1e-10 * column.norm() {
            basis.push(r.normalize());
            needed.push(j);
        }
    }
    let a = DMatrix::from_fn(NC, needed.len(), |r, c| phi_q[(r, needed[c])]);
    let rhs = DVector::from_iterator(NC, (-(phi_q * qd + phi_t)).iter().copied());
    let w = a
        .svd(true, true)
        .solve(&rhs, 1e-12)
        .map_err(|e| format!("at t = {t} s: the initial velocities are not determined: {e}"))?;
    for (c, &i) in needed.iter().enumerate() {
        qd[i] = w[c];
    }
    let residual = (phi_q * qd + phi_t).amax();
    if residual.is_nan() || residual > 1e-9 * (1.0 + rhs.amax()) {
        return Err(format!(
            "at t = {t} s: the velocity constraints cannot be met with the prescribed rates \
             (residual {residual:.3e})"
        ));
    }
    Ok(qd)
}

impl<'s> Sample<'s> {
    /// One sample, cut to the real sizes.
    fn cut(
        problem: &Problem<'_>,
        t: f64,
        tau: &'s [f64],
        q: &'s [f64],
        lambda: &'s [f64],
    ) -> Sample<'s> {
        Sample {
            t,
            tau: &tau[..problem.actuators.len()],
            q: &q[..problem.coordinates.len()],
            lambda: &lambda[..problem.constraints.len()],
        }
    }
}
