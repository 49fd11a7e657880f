//! Inverse dynamics of any scene along prescribed coordinates or marker
//! positions: what `flexdyn inverse` computes, on a model of any size
//! ([`DynModel`]: a compiled scene or an interpreted one), through the
//! runtime's solvers over run-time sizes.
//!
//! `NP` outputs `y(q, t)` follow given functions of time `p(t)` (with their
//! rates and accelerations): coordinates `q_S`, or markers' world
//! coordinates ([`Output`]; task space). Two cases:
//!
//! * **Determined** (`NP + NC = NQ`: the constraints fix every other
//!   coordinate): per output time the runtime's
//!   [`InverseDynamics`](flexdyn_runtime::InverseDynamics) solves
//!   `Phi(q, t) = 0` by Newton warm-started from the previous step, the
//!   velocities and accelerations from the constraint derivatives, then
//!   `Phi_q^T lambda + B tau = M qdd + h`: exact at every sample. Only
//!   coordinates: `flexdyn inverse` solves a determined marker prescription
//!   as coordinates of a scene it extends (a coordinate and a constraint per
//!   marker axis).
//! * **Free coordinates remain** (`NP + NC < NQ`, e.g. elastic coordinates):
//!   servo constraints ([`Servo`] over the outputs, [`servo_run`],
//!   generalized-alpha) integrate the free coordinates; a marker output is
//!   the marker's world coordinate with its Jacobian row and acceleration
//!   bias, explicit time terms included. They start at rest in static
//!   equilibrium under the prescription at the first time: Newton on
//!   `h(q, 0, t0) - Phi_q^T lambda - B tau = 0`, `Phi(q, t0) = 0`,
//!   `y(q, t0) = p(t0)` for `(q, lambda, tau)`; the velocities satisfy
//!   `Phi_q qd + Phi_t = 0` and `y' = p'(t0)` and are either the smallest
//!   in the mass norm ([`FreeRates::LeastEnergy`]) or zero on the coordinates
//!   neither needs ([`FreeRates::Zero`]). The trial step of
//!   [`servo_run`] is taken without the coordinate projection
//!   ([`ServoConfig::trial_projection`]), as the flexible robot's.
//!
//! Either way the inputs must be determined by the prescription: as many
//! prescribed outputs as actuators, and a non-singular projected
//! actuation (the runtime names the condition when it is not).

use flexdyn_runtime::control::{servo_run, OutputTerms, Outputs, Servo, ServoConfig, TargetOf};
use flexdyn_runtime::integrate::StepSettings;
use flexdyn_runtime::nalgebra::allocator::Allocator;
use flexdyn_runtime::nalgebra::{
    DMatrix, DVector, DefaultAllocator, Dim, Dyn, OMatrix, OVector, U1,
};
use flexdyn_runtime::{
    Equations, ErrorKind, GeneralizedAlphaConfig, GeneralizedAlphaOf, InverseConfig,
    InverseDynamicsOf, InverseSolutionOf, StateOf,
};

use std::ops::ControlFlow;

use crate::dynamic::{DynModel, MarkerPose};

/// A motion `t -> [p, p', p'']`.
pub type Motion<'a> = &'a dyn Fn(f64) -> [f64; 3];

/// What a prescription prescribes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Output {
    /// A coordinate, by index.
    Coordinate(usize),
    /// A marker's world coordinate: the marker's index (in the model's
    /// `markers()`) and the axis (0, 1, 2: x, y, z).
    Marker {
        /// Index of the marker.
        marker: usize,
        /// World axis.
        axis: usize,
    },
}

/// The names of a marker's world coordinates' axes.
pub const AXES: [char; 3] = ['x', 'y', 'z'];

/// A prescribed output and its motion.
pub struct Prescribed<'a> {
    /// What is prescribed.
    pub output: Output,
    /// Value, first and second time derivative at `t`.
    pub motion: Motion<'a>,
}

/// What to solve: the names of the scene's coordinates, constraints and
/// actuators (one per row of the model's), the prescription and the output
/// times.
pub struct Problem<'a> {
    /// Names of the coordinates.
    pub coordinates: Vec<String>,
    /// Names of the constraints.
    pub constraints: Vec<String>,
    /// Names of the actuators.
    pub actuators: Vec<String>,
    /// The prescriptions.
    pub prescribed: Vec<Prescribed<'a>>,
    /// Newton's starting point for the first sample (one value per
    /// coordinate; missing ones are 0).
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
/// constraints `Phi_q qd + Phi_t = 0` and the prescribed rates.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum FreeRates {
    /// The rates of least kinetic energy `qd^T M qd / 2`.
    #[default]
    LeastEnergy,
    /// Zero, except on the coordinates the velocity constraints and the
    /// prescribed rates need: the first coordinates in the scene's order
    /// whose columns of `Phi_q` stacked on the outputs' Jacobian `Y_q` are
    /// independent take the rates they ask for (a prescribed coordinate
    /// always: its own), every later one starts at rest. With rigid
    /// coordinates listed before elastic ones (as the robot scenes do), the
    /// elastic rates start at zero.
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

/// The solution at one output time.
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
/// was solved. Errors name the time, the prescribed outputs and the
/// condition involved, and a model whose sizes differ from the problem's
/// names.
pub fn solve(
    model: &dyn DynModel,
    problem: &Problem<'_>,
    sink: Sink<'_>,
) -> Result<Method, String> {
    let (nq, nc, nu) = (
        problem.coordinates.len(),
        problem.constraints.len(),
        problem.actuators.len(),
    );
    if (model.nq(), model.nc(), model.nu()) != (nq, nc, nu) {
        return Err(format!(
            "scene `{}` has {} coordinates, {} constraints, {} actuators; the problem names \
             {nq}, {nc}, {nu}",
            model.name(),
            model.nq(),
            model.nc(),
            model.nu()
        ));
    }
    let np = problem.prescribed.len();
    let markers = model.markers();
    let outputs: Vec<Output> = problem.prescribed.iter().map(|p| p.output).collect();
    for (k, o) in outputs.iter().enumerate() {
        match *o {
            Output::Coordinate(i) if i >= nq => {
                return Err(format!(
                    "prescribed coordinate {i} is not one of the scene's {nq}"
                ))
            }
            Output::Marker { marker, axis } if marker >= markers.len() || axis >= 3 => {
                return Err(format!(
                    "prescribed marker {marker}, axis {axis}: the scene has {} marker(s), \
                     axes 0, 1, 2",
                    markers.len()
                ))
            }
            _ if outputs[..k].contains(o) => {
                return Err(format!(
                    "`{}` is prescribed twice",
                    name(problem, &markers, *o)
                ))
            }
            _ => (),
        }
    }
    let prescribed_names = outputs
        .iter()
        .map(|&o| format!("`{}`", name(problem, &markers, o)))
        .collect::<Vec<_>>()
        .join(", ");
    if np != nu {
        return Err(format!(
            "the prescription does not determine the actuator inputs: {np} prescribed \
             output(s) ({prescribed_names}) for {nu} actuator(s) ({}); prescribe exactly \
             one coordinate or marker axis per actuator",
            problem.actuators.join(", ")
        ));
    }
    if np + nc > nq {
        return Err(format!(
            "the prescription over-determines the motion: {np} prescribed output(s) \
             ({prescribed_names}) and {nc} constraint(s) for {nq} coordinate(s)"
        ));
    }
    let target = |t: f64| {
        let mut x = TargetOf {
            position: DVector::zeros(np),
            velocity: DVector::zeros(np),
            acceleration: DVector::zeros(np),
        };
        for (k, p) in problem.prescribed.iter().enumerate() {
            [x.position[k], x.velocity[k], x.acceleration[k]] = (p.motion)(t);
        }
        x
    };
    let guess = DVector::from_fn(nq, |i, _| problem.guess.get(i).copied().unwrap_or(0.0));
    let rank_error = |e: flexdyn_runtime::Error| {
        format!(
            "at t = {} s: the prescription of {prescribed_names} does not determine the \
             actuator inputs ({}), or the pose is singular: {}",
            e.t,
            problem.actuators.join(", "),
            e.kind
        )
    };
    let job = Job {
        model,
        problem,
        outputs: &outputs,
        names: &prescribed_names,
        target: &target,
        rank_error: &rank_error,
    };
    if np + nc < nq {
        return job.servo(guess, sink);
    }
    let index = outputs
        .iter()
        .map(|o| match *o {
            Output::Coordinate(i) => Ok(i),
            Output::Marker { .. } => Err(format!(
                "the prescription of {prescribed_names} and the {nc} constraint(s) fix every \
                 coordinate: prescribe coordinates there (`flexdyn inverse` adds a coordinate \
                 and a constraint per marker axis)"
            )),
        })
        .collect::<Result<Vec<usize>, String>>()?;
    job.determined(&index, guess, sink)
}

/// The name of output `o`: the coordinate's, or `<marker>_<axis>`.
fn name(problem: &Problem<'_>, markers: &[&str], o: Output) -> String {
    match o {
        Output::Coordinate(i) => problem.coordinates[i].clone(),
        Output::Marker { marker, axis } => format!("{}_{}", markers[marker], AXES[axis]),
    }
}

/// The prescribed outputs of a model, as the servo's [`Outputs`]:
/// coordinates, and markers' world coordinates with their Jacobian rows,
/// velocities and acceleration biases (explicit time terms included).
struct Selected<'a> {
    model: &'a dyn DynModel,
    outputs: &'a [Output],
}

impl Selected<'_> {
    /// The outputs' terms at `(q, qd, t)`.
    fn at(&self, q: &DVector<f64>, qd: &DVector<f64>, t: f64) -> OutputTerms<f64, Dyn, Dyn> {
        let mut out = OutputTerms::zeros(Dyn(q.len()), Dyn(self.outputs.len()));
        self.evaluate(q, qd, t, &mut out);
        out
    }
}

impl Outputs<Dyn, Dyn> for Selected<'_> {
    fn count(&self) -> Dyn {
        Dyn(self.outputs.len())
    }
    fn evaluate(
        &self,
        q: &DVector<f64>,
        qd: &DVector<f64>,
        t: f64,
        out: &mut OutputTerms<f64, Dyn, Dyn>,
    ) {
        let nq = q.len();
        out.y_q.fill(0.0);
        out.convective.fill(0.0);
        // One marker's pose, Jacobian (6 x nq) and motion, for its axes in turn.
        let (mut position, mut rotation, mut jacobian) = ([0.0; 3], [0.0; 9], vec![0.0; 6 * nq]);
        let (mut velocity, mut bias) = ([0.0; 6], [0.0; 6]);
        let mut evaluated = None;
        for (k, o) in self.outputs.iter().enumerate() {
            match *o {
                Output::Coordinate(i) => {
                    out.y[k] = q[i];
                    out.rate[k] = qd[i];
                    out.y_q[(k, i)] = 1.0;
                }
                Output::Marker { marker, axis } => {
                    if evaluated != Some(marker) {
                        let pose = MarkerPose {
                            position: &mut position,
                            rotation: &mut rotation,
                            jacobian: &mut jacobian,
                        };
                        let m = self.model;
                        let given = m.marker_jacobian(marker, q.as_slice(), t, pose)
                            && m.marker_motion(
                                marker,
                                q.as_slice(),
                                qd.as_slice(),
                                t,
                                &mut velocity,
                                &mut bias,
                            );
                        if !given {
                            // Validated markers; the servo reports NaN.
                            position.fill(f64::NAN);
                        }
                        evaluated = Some(marker);
                    }
                    out.y[k] = position[axis];
                    out.rate[k] = velocity[axis];
                    out.convective[k] = bias[axis];
                    for j in 0..nq {
                        out.y_q[(k, j)] = jacobian[axis + 6 * j];
                    }
                }
            }
        }
    }
}

/// The desired motion of the prescribed outputs.
type Targets<'a> = &'a dyn Fn(f64) -> TargetOf<f64, Dyn>;

/// A problem with what both cases need.
struct Job<'a> {
    model: &'a dyn DynModel,
    problem: &'a Problem<'a>,
    /// The prescribed outputs.
    outputs: &'a [Output],
    /// Their names, for errors.
    names: &'a str,
    target: Targets<'a>,
    rank_error: &'a dyn Fn(flexdyn_runtime::Error) -> String,
}

impl Job<'_> {
    /// The determined case: [`InverseDynamicsOf`] at every output time, the
    /// prescribed coordinates `index`.
    fn determined(
        &self,
        index: &[usize],
        guess: DVector<f64>,
        sink: Sink<'_>,
    ) -> Result<Method, String> {
        let model = self.model;
        let mut solver = InverseDynamicsOf::<f64, Dyn, Dyn, Dyn, Dyn>::for_model(
            model,
            index,
            guess,
            InverseConfig::default(),
        )
        .map_err(|e| e.to_string())?;
        let mut sol = InverseSolutionOf::zeros(model.sizes());
        let problem = self.problem;
        for t in (0..=problem.steps).map(|k| k as f64 * problem.dt) {
            let x = (self.target)(t);
            let start = solver.guess().clone();
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
                    ErrorKind::SingularActuation { .. } => (self.rank_error)(e),
                    ErrorKind::SingularConstraintJacobian { .. }
                    | ErrorKind::NewtonNotConverged { .. } => {
                        self.position_error(index, &x.position, &start, t, e)
                    }
                    _ => e.to_string(),
                })?;
            sink(&Sample {
                t,
                tau: sol.tau.as_slice(),
                q: sol.q.as_slice(),
                lambda: sol.lambda.as_slice(),
            })?;
        }
        Ok(Method::Determined)
    }

    /// The error of a failed position solve, with the constraint that is
    /// violated most at Newton's starting point and the condition of the
    /// Jacobian of the free coordinates there.
    fn position_error(
        &self,
        index: &[usize],
        p: &DVector<f64>,
        start: &DVector<f64>,
        t: f64,
        e: flexdyn_runtime::Error,
    ) -> String {
        let problem = self.problem;
        let mut q = start.clone();
        for (k, &i) in index.iter().enumerate() {
            q[i] = p[k];
        }
        let (nq, nc) = (q.len(), problem.constraints.len());
        let mut phi = DVector::zeros(nc);
        let mut phi_q = DMatrix::zeros(nc, nq);
        Equations::constraints(self.model, &q, t, &mut phi);
        Equations::constraint_jacobian(self.model, &q, t, &mut phi_q);
        let worst = (0..nc)
            .max_by(|&a, &b| phi[a].abs().total_cmp(&phi[b].abs()))
            .unwrap_or(0);
        let free: Vec<usize> = (0..nq).filter(|i| !index.contains(i)).collect();
        let jf = DMatrix::from_fn(nc, free.len(), |r, c| phi_q[(r, free[c])]);
        let sv = jf.singular_values();
        let condition = sv.max() / sv.min();
        format!(
            "at t = {t} s: the constraints cannot be solved for the coordinates {} ({}); \
             from the previous solution, constraint `{}` (multiplier `lambda_{worst}`) is \
             violated most (|Phi| = {:.3e}) and the Jacobian of those coordinates has \
             condition {condition:.3e}: a singular pose, or a prescription the mechanism \
             cannot follow",
            free.iter()
                .map(|&i| format!("`{}`", problem.coordinates[i]))
                .collect::<Vec<_>>()
                .join(", "),
            e.kind,
            problem.constraints.get(worst).map_or("", String::as_str),
            phi.get(worst).map_or(0.0, |x| x.abs())
        )
    }

    /// The servo case: static equilibrium at the first time, then
    /// [`servo_run`] with generalized-alpha.
    fn servo(&self, guess: DVector<f64>, sink: Sink<'_>) -> Result<Method, String> {
        let (model, problem) = (self.model, self.problem);
        let (t0, dt) = (0.0, problem.dt);
        let x0 = (self.target)(t0);
        let outputs = Selected {
            model,
            outputs: self.outputs,
        };
        let q = static_equilibrium(&outputs, &x0.position, guess, t0)
            .map_err(|e| format!("at t = {t0} s, prescribing {}: {e}", self.names))?;
        let qd = initial_velocities(&outputs, &x0.velocity, &q, t0, problem.free_rates)?;
        let mut state = StateOf { q, qd, t: t0 };
        let config = ServoConfig {
            trial_projection: false,
            ..ServoConfig::default()
        };
        let servo = Servo::new(model, outputs, self.target, config).map_err(|e| e.to_string())?;
        // L-stable (rho_inf = 0), as the robot's servo: the elastic modes a
        // step of the rigid motion does not resolve are damped, not rung.
        let config = GeneralizedAlphaConfig {
            rho_inf: 0.0,
            filter_start: false,
            ..Default::default()
        };
        let mut integrator =
            GeneralizedAlphaOf::<f64, Dyn, Dyn>::new(StepSettings::with_projection(), config);
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
                failed = match servo.solve::<Dyn, Dyn, Dyn>(&s.state.q, &s.state.qd, s.state.t) {
                    Ok(x) => sink(&Sample {
                        t,
                        tau: s.tau.as_slice(),
                        q: s.state.q.as_slice(),
                        lambda: x.lambda.as_slice(),
                    })
                    .err(),
                    Err(e) => Some((self.rank_error)(e)),
                };
                // The first failure stops the run.
                match failed {
                    Some(_) => ControlFlow::Break(()),
                    None => ControlFlow::Continue(()),
                }
            },
        )
        .map_err(self.rank_error)?;
        failed.map_or(Ok(Method::Servo), Err)
    }
}

/// Newton on `h(q, 0, t) - Phi_q^T lambda - B tau = 0`, `Phi(q, t) = 0`,
/// `y(q, t) = p` for `(q, lambda, tau)` (module docs), from `guess` with the
/// prescribed coordinates at their values, the first block's Jacobian by
/// central differences.
fn static_equilibrium(
    outputs: &Selected<'_>,
    p: &DVector<f64>,
    guess: DVector<f64>,
    t: f64,
) -> Result<DVector<f64>, String> {
    let model = outputs.model;
    let (nq, nc, nu) = (model.nq(), model.nc(), model.nu());
    let n = nq + nc + nu;
    let mut b = DMatrix::zeros(nq, nu);
    Equations::actuator_map(model, &mut b);
    let rest = DVector::zeros(nq);
    // Generalized forces at rest, less the constraint forces.
    let load = |q: &DVector<f64>, lambda: &DVector<f64>| {
        let mut h = DVector::zeros(nq);
        let mut phi_q = DMatrix::zeros(nc, nq);
        Equations::bias(model, q, &rest, t, &mut h);
        Equations::constraint_jacobian(model, q, t, &mut phi_q);
        (h - phi_q.transpose() * lambda, phi_q)
    };
    let mut x = DVector::<f64>::zeros(n);
    x.rows_mut(0, nq).copy_from(&guess);
    for (k, o) in outputs.outputs.iter().enumerate() {
        if let Output::Coordinate(i) = *o {
            x[i] = p[k];
        }
    }
    let mut residual_norm = f64::INFINITY;
    for _ in 0..50 {
        let q = x.rows(0, nq).into_owned();
        let lambda = x.rows(nq, nc).into_owned();
        let tau = x.rows(nq + nc, nu).into_owned();
        let (f, phi_q) = load(&q, &lambda);
        let mut phi = DVector::zeros(nc);
        Equations::constraints(model, &q, t, &mut phi);
        let f = f - &b * &tau;
        let y = outputs.at(&q, &rest, t);
        let mut r = DVector::<f64>::zeros(n);
        r.rows_mut(0, nq).copy_from(&f);
        r.rows_mut(nq, nc).copy_from(&phi);
        r.rows_mut(nq + nc, nu).copy_from(&(&y.y - p));
        let scale = 1.0 + f.amax().max(lambda.amax()).max(tau.amax());
        residual_norm = r.amax();
        if !residual_norm.is_finite() {
            break;
        }
        if residual_norm <= 1e-12 * scale {
            return Ok(q);
        }
        let mut jac = DMatrix::<f64>::zeros(n, n);
        for j in 0..nq {
            let d = 1e-6 * q[j].abs().max(1e-3);
            let (mut qp, mut qm) = (q.clone(), q.clone());
            qp[j] += d;
            qm[j] -= d;
            let column = (load(&qp, &lambda).0 - load(&qm, &lambda).0) / (2.0 * d);
            jac.view_mut((0, j), (nq, 1)).copy_from(&column);
        }
        for i in 0..nc {
            for j in 0..nq {
                jac[(nq + i, j)] = phi_q[(i, j)];
                jac[(j, nq + i)] = -phi_q[(i, j)];
            }
        }
        for k in 0..nu {
            for j in 0..nq {
                jac[(j, nq + nc + k)] = -b[(j, k)];
                jac[(nq + nc + k, j)] = y.y_q[(k, j)];
            }
        }
        let dx = jac
            .full_piv_lu()
            .solve(&(-&r))
            .filter(|d| d.iter().all(|v| v.is_finite()))
            .ok_or_else(|| {
                "the static equilibrium under the prescription is singular (the prescription \
                 does not determine the inputs, or the pose is singular)"
                    .to_string()
            })?;
        x += dx;
    }
    Err(format!(
        "the static equilibrium under the prescription did not converge (residual \
         {residual_norm:.3e}): a pose the prescription cannot reach, or give a better guess \
         with --initial"
    ))
}

/// The initial velocities with `Phi_q qd + Phi_t = 0` and `y' = v`, as
/// `free_rates` picks them.
fn initial_velocities(
    outputs: &Selected<'_>,
    v: &DVector<f64>,
    q: &DVector<f64>,
    t: f64,
    free_rates: FreeRates,
) -> Result<DVector<f64>, String> {
    let model = outputs.model;
    let (nq, nc) = (model.nq(), model.nc());
    let mut phi_q = DMatrix::zeros(nc, nq);
    let mut phi_t = DVector::zeros(nc);
    Equations::constraint_jacobian(model, q, t, &mut phi_q);
    Equations::constraint_time_derivative(model, q, t, &mut phi_t);
    // At rest, the outputs' rates are their explicit time derivatives.
    let y = outputs.at(q, &DVector::zeros(nq), t);
    let w = v - &y.rate;
    match free_rates {
        FreeRates::LeastEnergy => {
            let mut m = DMatrix::zeros(nq, nq);
            Equations::mass_matrix(model, q, t, &mut m);
            let (a, rhs) = stacked(&phi_q, &phi_t, &y.y_q, &w);
            least_energy_velocities(m, &a, &rhs, t)
        }
        FreeRates::Zero => needed_velocities(&phi_q, &phi_t, &y.y_q, &w, t),
    }
}

/// The rows of `Phi_q qd = -Phi_t`, then of `Y_q qd = w`.
fn stacked<Q: Dim, C: Dim, N: Dim>(
    phi_q: &OMatrix<f64, C, Q>,
    phi_t: &OVector<f64, C>,
    y_q: &OMatrix<f64, N, Q>,
    w: &OVector<f64, N>,
) -> (DMatrix<f64>, DVector<f64>)
where
    DefaultAllocator: Allocator<C, Q> + Allocator<C> + Allocator<N, Q> + Allocator<N>,
{
    let (nc, nq) = phi_q.shape();
    let np = y_q.nrows();
    let a = DMatrix::from_fn(nc + np, nq, |r, c| match r < nc {
        true => phi_q[(r, c)],
        false => y_q[(r - nc, c)],
    });
    let rhs = DVector::from_fn(nc + np, |r, _| match r < nc {
        true => -phi_t[r],
        false => w[r - nc],
    });
    (a, rhs)
}

/// The velocities of least kinetic energy `qd^T M qd / 2` with `a qd = rhs`.
fn least_energy_velocities(
    m: DMatrix<f64>,
    a: &DMatrix<f64>,
    rhs: &DVector<f64>,
    t: f64,
) -> Result<DVector<f64>, String> {
    let singular = || format!("at t = {t} s: the initial velocities are not determined");
    let m_inv = m.try_inverse().ok_or_else(singular)?;
    let schur = a * &m_inv * a.transpose();
    let y = schur.full_piv_lu().solve(rhs).ok_or_else(singular)?;
    Ok(m_inv * a.transpose() * y)
}

/// The velocities with `Phi_q qd + Phi_t = 0` and `Y_q qd = w` (the
/// prescribed outputs' Jacobian and rates less their explicit time
/// derivatives), nonzero only on the first columns of `Phi_q` stacked on
/// `Y_q` (in order) that are independent: the rates the velocity
/// constraints and the prescription need, every other one zero
/// ([`FreeRates::Zero`]; a prescribed coordinate's column is always kept).
/// An error names `t` when the rows cannot be met so. Any sizes (the
/// parallel-robot example calls it with fixed ones).
pub fn needed_velocities<Q: Dim, C: Dim, N: Dim>(
    phi_q: &OMatrix<f64, C, Q>,
    phi_t: &OVector<f64, C>,
    y_q: &OMatrix<f64, N, Q>,
    w: &OVector<f64, N>,
    t: f64,
) -> Result<OVector<f64, Q>, String>
where
    DefaultAllocator:
        Allocator<C, Q> + Allocator<C> + Allocator<N, Q> + Allocator<N> + Allocator<Q>,
{
    let (a, rhs) = stacked(phi_q, phi_t, y_q, w);
    let (rows, nq) = a.shape();
    // Greedy: keep a column when it is independent of the kept ones
    // (Gram-Schmidt, twice, against an orthonormal basis of them).
    let mut basis: Vec<DVector<f64>> = Vec::with_capacity(rows);
    let mut needed = Vec::with_capacity(rows);
    for j in 0..nq {
        if basis.len() == rows {
            break;
        }
        let column = a.column(j).into_owned();
        let mut r = column.clone();
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
    let kept = DMatrix::from_fn(rows, needed.len(), |r, c| a[(r, needed[c])]);
    let x = kept
        .svd(true, true)
        .solve(&rhs, 1e-12)
        .map_err(|e| format!("at t = {t} s: the initial velocities are not determined: {e}"))?;
    let mut qd = OVector::<f64, Q>::zeros_generic(phi_q.shape_generic().1, U1);
    for (c, &i) in needed.iter().enumerate() {
        qd[i] = x[c];
    }
    let residual = (&a * DVector::from_column_slice(qd.as_slice()) - &rhs).amax();
    if residual.is_nan() || residual > 1e-9 * (1.0 + rhs.amax()) {
        return Err(format!(
            "at t = {t} s: the velocity constraints cannot be met with the prescribed rates \
             (residual {residual:.3e})"
        ));
    }
    Ok(qd)
}
