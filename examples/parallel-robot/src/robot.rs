//! The spatial parallel robot of `shared/spec/robot.md`: geometry, the
//! paper's circular motion, and closed-form inverse kinematics on the working
//! branch ("elbow up", `0 < th_i2 - th_i1 < pi`, `|th_i3| < pi/2`).
//!
//! Coordinate order (as in `scenes/parallel_robot_rigid.toml`):
//! `[th11, th12, th13, th21, th22, th23, th31, th32, th33, px, py, pz]`.
//!
//! Inverse and forward dynamics along the circle for every robot scene:
//! the rigid robot's algebraic inverse dynamics ([`inverse_along`]), the
//! flexible scenes' servo-constrained inverse dynamics ([`flexible_inverse`],
//! the runtime's [`flexdyn_runtime::control::Servo`] on the platform centre)
//! and forward runs with the joint-space PD loop ([`simulate_rows`], the
//! runtime's [`flexdyn_runtime::control::JointPd`]), all from the robot in
//! static equilibrium on its path ([`initial_state`]).
//!
//! Each run is streamed: its `stream_` form hands every row to a callback
//! ([`Emit`]) as it is computed, so that a run of any length needs the same
//! memory (the command line writes the rows as they come); the form without
//! the prefix collects them, for the tests and the report.

use std::f64::consts::PI;
use std::fmt;

/// Lengths of the robot, metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Geometry {
    /// Base joint radius.
    pub ra: f64,
    /// Platform joint radius.
    pub rp: f64,
    /// Driving link.
    pub l1: f64,
    /// Intermediate link.
    pub l2: f64,
    /// Driven link.
    pub l3: f64,
}

impl Geometry {
    /// The values fixed by the spec and the paper's Table 1.
    pub const SPEC: Geometry = Geometry {
        ra: 0.4,
        rp: 0.1,
        l1: 0.4,
        l2: 0.1,
        l3: 0.8,
    };

    /// Read the geometry from a scene's parameters (`Ra rp l1 l2 l3`).
    pub fn from_parameters(
        p: &std::collections::BTreeMap<String, f64>,
    ) -> Result<Geometry, String> {
        let get = |k: &str| {
            p.get(k)
                .copied()
                .ok_or_else(|| format!("the scene has no parameter `{k}` (robot geometry)"))
        };
        Ok(Geometry {
            ra: get("Ra")?,
            rp: get("rp")?,
            l1: get("l1")?,
            l2: get("l2")?,
            l3: get("l3")?,
        })
    }
}

/// Azimuth of chain `i` (0-based), radians.
pub fn azimuth(i: usize) -> f64 {
    2.0 * PI * i as f64 / 3.0
}

/// Why a platform position has no inverse kinematics on the working branch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum IkError {
    /// The point is out of reach of `chain` (0-based); `excess` says by how
    /// much the required reach exceeds what the chain can do (metres).
    Unreachable {
        /// Chain index.
        chain: usize,
        /// How far out of reach.
        excess: f64,
    },
    /// The chain would be at (or too close to) a stretched or folded pose:
    /// `condition` is the condition number of its planar 2R Jacobian.
    NearSingular {
        /// Chain index.
        chain: usize,
        /// Condition number.
        condition: f64,
    },
}

impl fmt::Display for IkError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            IkError::Unreachable { chain, excess } => write!(
                f,
                "platform position out of reach of chain {} (by {:.3e} m)",
                chain + 1,
                excess
            ),
            IkError::NearSingular { chain, condition } => write!(
                f,
                "chain {} too close to a singular pose (condition number {:.3e})",
                chain + 1,
                condition
            ),
        }
    }
}

/// Largest condition number of a chain's planar Jacobian accepted by
/// [`inverse_kinematics`].
pub const MAX_CONDITION: f64 = 1e6;

/// Joint angles `[th1, th2, th3]` of chain `i` that put its platform joint at
/// `P + rp u_i`.
pub fn chain_ik(g: &Geometry, i: usize, p: [f64; 3]) -> Result<[f64; 3], IkError> {
    let (s, c) = azimuth(i).sin_cos();
    // Target in the chain frame (x radial, y tangential, z up).
    let x = c * p[0] + s * p[1] + g.rp;
    let y = -s * p[0] + c * p[1];
    let z = p[2];
    if y.abs() >= g.l3 {
        return Err(IkError::Unreachable {
            chain: i,
            excess: y.abs() - g.l3,
        });
    }
    let th3 = (y / g.l3).asin();
    // Remaining planar 2R arm: links l1 and L = l2 + l3 cos th3.
    let big_l = g.l2 + g.l3 * th3.cos();
    let (px, pz) = (x - g.ra, z);
    let d2 = px * px + pz * pz;
    let cos_b = (d2 - g.l1 * g.l1 - big_l * big_l) / (2.0 * g.l1 * big_l);
    if cos_b.abs() > 1.0 {
        let d = d2.sqrt();
        let excess = if cos_b > 1.0 {
            d - (g.l1 + big_l)
        } else {
            (g.l1 - big_l).abs() - d
        };
        return Err(IkError::Unreachable { chain: i, excess });
    }
    let beta = cos_b.acos(); // th2 - th1 in [0, pi]
    let sin_b = beta.sin();
    // Condition number of the planar 2R Jacobian in absolute angles, columns
    // l1 (-s1, c1) and L (-s2, c2): J^T J has trace l1^2 + L^2 and
    // determinant (l1 L sin b)^2.
    let tr = g.l1 * g.l1 + big_l * big_l;
    let det = g.l1 * big_l * sin_b;
    let disc = (tr * tr / 4.0 - det * det).max(0.0).sqrt();
    let (s_max2, s_min2) = (tr / 2.0 + disc, (tr / 2.0 - disc).max(0.0));
    let condition = if s_min2 > 0.0 {
        (s_max2 / s_min2).sqrt()
    } else {
        f64::INFINITY
    };
    if condition.is_nan() || condition >= MAX_CONDITION {
        return Err(IkError::NearSingular {
            chain: i,
            condition,
        });
    }
    let th1 = pz.atan2(px) - (big_l * sin_b).atan2(g.l1 + big_l * cos_b);
    Ok([th1, th1 + beta, th3])
}

/// All twelve coordinates for a platform position.
pub fn inverse_kinematics(g: &Geometry, p: [f64; 3]) -> Result<[f64; 12], IkError> {
    let mut q = [0.0; 12];
    for i in 0..3 {
        let th = chain_ik(g, i, p)?;
        q[3 * i..3 * i + 3].copy_from_slice(&th);
    }
    q[9..12].copy_from_slice(&p);
    Ok(q)
}

/// Position of chain `i`'s platform joint from its joint angles (forward
/// kinematics of the open chain), in world coordinates.
pub fn chain_tip(g: &Geometry, i: usize, th: [f64; 3]) -> [f64; 3] {
    let (s, c) = azimuth(i).sin_cos();
    let (s1, c1) = th[0].sin_cos();
    let (s2, c2) = th[1].sin_cos();
    let (s3, c3) = th[2].sin_cos();
    let x = g.ra + g.l1 * c1 + g.l2 * c2 + g.l3 * c3 * c2;
    let y = g.l3 * s3;
    let z = g.l1 * s1 + g.l2 * s2 + g.l3 * c3 * s2;
    [c * x - s * y, s * x + c * y, z]
}

/// A horizontal circle of the platform centre, the paper's Eq. 23 by
/// default: `P = c + r (cos wt, sin wt, 0)` with `c = (0, 0, 0.7)`,
/// `r = 0.1 m`, `w = 2 rad/s`. At `t = 0` the platform is already moving.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Circle {
    /// Angular rate, rad/s.
    pub omega: f64,
    /// Radius, m.
    pub radius: f64,
    /// Centre, m.
    pub center: [f64; 3],
}

impl Circle {
    /// The paper's circle at angular rate `omega`.
    pub fn paper(omega: f64) -> Circle {
        Circle {
            omega,
            radius: 0.1,
            center: [0.0, 0.0, 0.7],
        }
    }

    /// Position, velocity and acceleration of the platform centre at `t`.
    pub fn at(&self, t: f64) -> [[f64; 3]; 3] {
        let (s, c) = (self.omega * t).sin_cos();
        let (r, w) = (self.radius, self.omega);
        let p = self.center;
        [
            [p[0] + r * c, p[1] + r * s, p[2]],
            [-r * w * s, r * w * c, 0.0],
            [-r * w * w * c, -r * w * w * s, 0.0],
        ]
    }
}

/// Output times `0, dt, 2 dt, ...` up to `duration` (inclusive, to rounding),
/// after checking that the request is sensible: at most `max_steps` steps
/// ([`flexdyn::steps::count`], whose errors name `--dt`, `--duration` and
/// `--max-steps`).
pub fn output_times(duration: f64, dt: f64, max_steps: u64) -> Result<Vec<f64>, String> {
    Ok(each_output_time(duration, dt, max_steps)?.collect())
}

/// The times of [`output_times`] one at a time, never all in memory (the
/// command line's runs, of any length).
pub fn each_output_time(
    duration: f64,
    dt: f64,
    max_steps: u64,
) -> Result<impl ExactSizeIterator<Item = f64> + Clone, String> {
    let steps = flexdyn::steps::count(duration, dt, flexdyn::steps::Last::Within, max_steps)?;
    let count = usize::try_from(steps)
        .ok()
        .and_then(|steps| steps.checked_add(1))
        .ok_or_else(|| format!("{steps} steps: too many for this machine"))?;
    Ok((0..count).map(move |k| k as f64 * dt))
}

/// Where a streamed run hands each row as it is computed: an error stops the
/// run and is its error.
pub type Emit<'a, R> = &'a mut dyn FnMut(R) -> Result<(), String>;

/// The rows that `run` emits, collected; `tick` is called after each.
fn collect_rows<R>(
    tick: &mut dyn FnMut(),
    run: impl FnOnce(Emit<'_, R>) -> Result<(), String>,
) -> Result<Vec<R>, String> {
    let mut rows = Vec::new();
    run(&mut |row| {
        rows.push(row);
        tick();
        Ok(())
    })?;
    Ok(rows)
}

/// Solution of the rigid robot's inverse dynamics at one time.
pub type RigidSolution = flexdyn_runtime::InverseSolution<12, 9, 3>;

/// Inverse dynamics of the rigid robot along `circle` at `times`, through
/// the runtime's real-time path (one [`flexdyn_runtime::InverseDynamics`]
/// call per time, warm-started from the previous one). `tick` is called after
/// each time. Errors name the time and what went wrong. Generic over the
/// dimensions for [`with_robot_model!`]; a scene with more coordinates than
/// the rigid robot's needs [`flexible_inverse`] instead.
pub fn inverse_along<M, const NQ: usize, const NC: usize>(
    model: &M,
    g: &Geometry,
    circle: &Circle,
    times: &[f64],
    tick: &mut dyn FnMut(),
) -> Result<Vec<flexdyn_runtime::InverseSolution<NQ, NC, 3>>, String>
where
    M: flexdyn_runtime::Model<NQ, NC, 3>,
{
    collect_rows(tick, |emit| {
        stream_inverse_along(model, g, circle, times.iter().copied(), emit)
    })
}

/// [`inverse_along`], each solution handed to `emit` as it is computed.
pub fn stream_inverse_along<M, const NQ: usize, const NC: usize>(
    model: &M,
    g: &Geometry,
    circle: &Circle,
    times: impl IntoIterator<Item = f64>,
    emit: Emit<'_, flexdyn_runtime::InverseSolution<NQ, NC, 3>>,
) -> Result<(), String>
where
    M: flexdyn_runtime::Model<NQ, NC, 3>,
{
    use flexdyn_runtime::nalgebra::SVector;
    let layout = Layout::of(model)?;
    let mut times = times.into_iter().peekable();
    let start = times.peek().copied().unwrap_or(0.0);
    let rigid =
        inverse_kinematics(g, circle.at(start)[0]).map_err(|e| format!("at t = {start} s: {e}"))?;
    let mut q0 = SVector::<f64, NQ>::zeros();
    for (k, &i) in layout.rigid.iter().enumerate() {
        q0[i] = rigid[k];
    }
    let mut solver = flexdyn_runtime::InverseDynamics::<NQ, NC, 3, 3>::new(
        layout.platform,
        q0,
        flexdyn_runtime::InverseConfig::default(),
    )
    .map_err(|e| e.to_string())?;
    let mut sol = flexdyn_runtime::InverseSolution::<NQ, NC, 3>::default();
    for t in times {
        let [p, v, a] = circle.at(t);
        // The closed form tells precisely why a point cannot be reached.
        let ik = inverse_kinematics(g, p).map_err(|e| format!("at t = {t} s: {e}"))?;
        let (p, v, a) = (SVector::from(p), SVector::from(v), SVector::from(a));
        let warm = solver.solve(model, t, &p, &v, &a, &mut sol);
        if warm.is_err() || branch_distance(&layout, &sol.q, &ik) > BRANCH_TOLERANCE {
            // Newton, warm-started from the last tick, stalled or crossed a
            // fold into another assembly mode (possible after a large jump
            // or near the workspace edge): start again from the closed
            // form, on the working branch.
            let mut guess = sol.q;
            for (k, &i) in layout.rigid.iter().enumerate() {
                guess[i] = ik[k];
            }
            solver.set_guess(guess);
            solver
                .solve(model, t, &p, &v, &a, &mut sol)
                .map_err(|e| e.to_string())?;
            let d = branch_distance(&layout, &sol.q, &ik);
            if d > BRANCH_TOLERANCE {
                return Err(format!(
                    "at t = {t} s: the solution left the working branch (joint angles {d:.3e} rad \
                     from the closed-form inverse kinematics)"
                ));
            }
        }
        emit(sol)?;
    }
    Ok(())
}

/// How far (rad) the solved joint angles may be from the closed-form
/// inverse kinematics and still count as the working branch: far above the
/// elastic deflections of the flexible scenes, far below the distance to
/// another assembly mode.
const BRANCH_TOLERANCE: f64 = 1e-2;

/// Largest difference, wrapped to `(-pi, pi]`, between the nine joint
/// angles of `q` and the closed-form inverse kinematics `ik`.
fn branch_distance<const NQ: usize>(
    layout: &Layout,
    q: &flexdyn_runtime::nalgebra::SVector<f64, NQ>,
    ik: &[f64; 12],
) -> f64 {
    layout.rigid[..9]
        .iter()
        .zip(ik)
        .map(|(&i, &angle)| {
            let d = (q[i] - angle).rem_euclid(std::f64::consts::TAU);
            d.min(std::f64::consts::TAU - d)
        })
        .fold(0.0, f64::max)
}

/// One row of the robot's inverse dynamics, whatever the scene.
#[derive(Debug, Clone, PartialEq)]
pub struct InverseRow {
    /// Time, s.
    pub t: f64,
    /// Actuator torques, N m.
    pub tau: [f64; 3],
    /// Platform centre, m.
    pub p: [f64; 3],
    /// Platform velocity, m/s.
    pub v: [f64; 3],
    /// Actuated joint angles `th11, th21, th31`, rad.
    pub th: [f64; 3],
    /// Every coordinate.
    pub q: Vec<f64>,
    /// Every velocity.
    pub qd: Vec<f64>,
}

/// Inverse dynamics of any robot scene along `circle` at `times`: the rigid
/// robot's algebraic solve ([`inverse_along`]) when the scene has only the
/// rigid coordinates, the servo-constrained integration of the elastic
/// coordinates ([`flexible_inverse`], one step per interval of
/// `times`) otherwise.
pub fn inverse_rows<M, const NQ: usize, const NC: usize>(
    model: &M,
    g: &Geometry,
    circle: &Circle,
    times: &[f64],
    tick: &mut dyn FnMut(),
) -> Result<Vec<InverseRow>, String>
where
    M: flexdyn_runtime::Model<NQ, NC, 3>,
{
    collect_rows(tick, |emit| {
        stream_inverse_rows(model, g, circle, times.iter().copied(), emit)
    })
}

/// [`inverse_rows`], each row handed to `emit` as it is computed.
pub fn stream_inverse_rows<M, const NQ: usize, const NC: usize>(
    model: &M,
    g: &Geometry,
    circle: &Circle,
    times: impl Iterator<Item = f64> + Clone,
    emit: Emit<'_, InverseRow>,
) -> Result<(), String>
where
    M: flexdyn_runtime::Model<NQ, NC, 3>,
{
    let layout = Layout::of(model)?;
    let row = |t: f64, tau: [f64; 3], q: &[f64], qd: &[f64]| InverseRow {
        t,
        tau,
        p: layout.platform.map(|i| q[i]),
        v: layout.platform.map(|i| qd[i]),
        th: layout.actuated.map(|i| q[i]),
        q: q.to_vec(),
        qd: qd.to_vec(),
    };
    if layout.is_flexible() {
        stream_flexible_inverse(model, &layout, g, circle, times, &mut |s| {
            emit(row(
                s.state.t,
                s.tau.into(),
                s.state.q.as_slice(),
                s.state.qd.as_slice(),
            ))
        })
    } else {
        stream_inverse_along(model, g, circle, times, &mut |s| {
            emit(row(
                s.t,
                [s.tau[0], s.tau[1], s.tau[2]],
                s.q.as_slice(),
                s.qd.as_slice(),
            ))
        })
    }
}

/// Spectral radius at infinite frequency of the generalized-alpha scheme of
/// [`flexible_inverse`] and of forward runs ([`simulate`]): 0 (asymptotic
/// annihilation), so that the elastic and joint modes the step cannot
/// resolve (all of them at 0.005 s: the first link mode is 157 Hz) are
/// damped out within a step or two instead of ringing in the torques; the
/// resolved, slow response stays second-order accurate.
pub const SERVO_RHO_INF: f64 = 0.0;

/// Inverse dynamics of a robot scene with its elastic coordinates
/// integrated: the runtime's servo constraints on the platform centre
/// ([`flexdyn_runtime::control::Servo`], the coordinates `px, py, pz`
/// prescribed along `circle`) integrated by generalized-alpha
/// (`rho_inf` = [`SERVO_RHO_INF`], coordinate projection after every step),
/// one step per interval of `times` (evenly spaced and increasing; the
/// paper's 0.005 s step for the CLI), from the robot in static equilibrium
/// on the path at `times[0]` ([`initial_state`]). Returns the state and the
/// torques at every time; `tick` is called after each.
///
/// Each step is a predictor-corrector pair
/// ([`flexdyn_runtime::control::servo_run`]): a trial step of the servo model
/// gives the torques at the step's end; the step taken is the plain model's
/// under the torques interpolated linearly over the step, from the same
/// integrator memory. So the recorded trajectory is exactly the one that
/// `parallel-robot simulate` reproduces (same scheme and step) from the
/// torque table. The trial step is taken without the coordinate projection
/// ([`flexdyn_runtime::control::ServoConfig::trial_projection`] off), so
/// that the torques are those at the state its Newton iteration converged
/// to: projecting the trial state moves the stiff elastic coordinates off the
/// iteration's accelerations, and the torques there differ by up to 3 N m at
/// 10 rad/s; at the coarse steps of the hard cases (0.05 s) the run then
/// fails (singular Newton matrix after seven steps). For a
/// scene with no elastic coordinates this reproduces the rigid inverse
/// dynamics. Every point of the path is checked against the closed-form
/// inverse kinematics first, which tells precisely why one cannot be reached.
pub fn flexible_inverse<M, const NQ: usize, const NC: usize>(
    model: &M,
    layout: &Layout,
    g: &Geometry,
    circle: &Circle,
    times: &[f64],
    tick: &mut dyn FnMut(),
) -> Result<Vec<flexdyn_runtime::control::ServoSample<NQ, 3>>, String>
where
    M: flexdyn_runtime::Model<NQ, NC, 3>,
{
    collect_rows(tick, |emit| {
        stream_flexible_inverse(model, layout, g, circle, times.iter().copied(), emit)
    })
}

/// [`flexible_inverse`], each sample handed to `emit` as it is computed
/// (`times` is gone through twice before the run, to check it).
pub fn stream_flexible_inverse<M, const NQ: usize, const NC: usize>(
    model: &M,
    layout: &Layout,
    g: &Geometry,
    circle: &Circle,
    times: impl Iterator<Item = f64> + Clone,
    emit: Emit<'_, flexdyn_runtime::control::ServoSample<NQ, 3>>,
) -> Result<(), String>
where
    M: flexdyn_runtime::Model<NQ, NC, 3>,
{
    use flexdyn_runtime::control::{servo_run, Coordinates, Servo, ServoConfig, Target};
    use flexdyn_runtime::integrate::{GeneralizedAlpha, StepSettings};
    let mut later = times.clone();
    let Some(t0) = later.next() else {
        return Ok(());
    };
    let dt = later.clone().next().map_or(0.0, |t1| t1 - t0);
    let (mut before, mut steps) = (t0, 0);
    for t in later {
        let step = t - before;
        if !(step > 0.0 && (step - dt).abs() <= 1e-9 * dt) {
            return Err(format!(
                "the inverse-dynamics times must increase in even steps: t = {t} s after \
                 t = {before} s (step {dt} s from t = {t0} s)"
            ));
        }
        (before, steps) = (t, steps + 1);
    }
    for t in times {
        inverse_kinematics(g, circle.at(t)[0]).map_err(|e| format!("at t = {t} s: {e}"))?;
    }
    let [p0, v0, _] = circle.at(t0);
    let mut state = initial_state(model, layout, g, t0, p0, v0)?;
    let path = |t: f64| {
        let [p, v, a] = circle.at(t);
        Target {
            position: p.into(),
            velocity: v.into(),
            acceleration: a.into(),
        }
    };
    let settings = StepSettings::with_projection();
    // The servo's closure stabilisation must be the integrator's.
    let servo_config = ServoConfig {
        dynamics: settings.dynamics,
        trial_projection: false,
        ..Default::default()
    };
    let servo = Servo::new(model, Coordinates(layout.platform), path, servo_config)
        .map_err(|e| e.to_string())?;
    let config = flexdyn_runtime::GeneralizedAlphaConfig {
        rho_inf: SERVO_RHO_INF,
        filter_start: false,
        ..Default::default()
    };
    let mut integ = GeneralizedAlpha::<NQ, NC>::new(settings, config);
    let mut stopped = Ok(());
    servo_run(&servo, &mut integ, &mut state, dt, steps, |s| {
        match emit(*s) {
            Ok(()) => std::ops::ControlFlow::Continue(()),
            Err(e) => {
                stopped = Err(e);
                std::ops::ControlFlow::Break(())
            }
        }
    })
    .map_err(|e| e.to_string())?;
    stopped
}

/// Actuator torques sampled in time, linearly interpolated between samples
/// and held constant outside them.
#[derive(Debug, Clone, PartialEq)]
pub struct TorqueTable {
    times: Vec<f64>,
    torques: Vec<[f64; 3]>,
}

impl TorqueTable {
    /// From the columns `t, tau_1, tau_2, tau_3` of a table; times must
    /// increase strictly.
    pub fn from_table(table: &flexdyn::table::Table) -> Result<TorqueTable, String> {
        TorqueTable::from_columns(table, ["tau_1", "tau_2", "tau_3"])
    }

    /// From the column `t` and three other columns of a table (any three
    /// quantities sampled in time, e.g. the joint angles `th11, th21, th31`
    /// written by `parallel-robot inverse`); times must increase strictly.
    pub fn from_columns(
        table: &flexdyn::table::Table,
        names: [&str; 3],
    ) -> Result<TorqueTable, String> {
        let times = table.column("t")?;
        let taus = [
            table.column(names[0])?,
            table.column(names[1])?,
            table.column(names[2])?,
        ];
        if times.is_empty() {
            return Err("the torque table has no rows".into());
        }
        if let Some(k) = times
            .windows(2)
            .position(|w| w[1].partial_cmp(&w[0]) != Some(std::cmp::Ordering::Greater))
        {
            return Err(format!(
                "times must increase strictly: row {} has t = {} after t = {}",
                k + 2,
                times[k + 1],
                times[k]
            ));
        }
        let torques = (0..times.len())
            .map(|k| [taus[0][k], taus[1][k], taus[2][k]])
            .collect();
        Ok(TorqueTable { times, torques })
    }

    /// From samples `(t, value)`; times must increase strictly.
    pub fn from_samples(samples: &[(f64, [f64; 3])]) -> Result<TorqueTable, String> {
        if samples.is_empty() {
            return Err("no samples".into());
        }
        if samples
            .windows(2)
            .any(|w| w[1].0.partial_cmp(&w[0].0) != Some(std::cmp::Ordering::Greater))
        {
            return Err("times must increase strictly".into());
        }
        Ok(TorqueTable {
            times: samples.iter().map(|s| s.0).collect(),
            torques: samples.iter().map(|s| s.1).collect(),
        })
    }

    /// First and last sample times.
    pub fn span(&self) -> (f64, f64) {
        (self.times[0], self.times[self.times.len() - 1])
    }

    /// The torques at `t`.
    pub fn at(&self, t: f64) -> [f64; 3] {
        let k = self.times.partition_point(|&x| x <= t);
        if k == 0 {
            return self.torques[0];
        }
        if k == self.times.len() {
            return self.torques[k - 1];
        }
        let (t0, t1) = (self.times[k - 1], self.times[k]);
        let s = (t - t0) / (t1 - t0);
        let (a, b) = (self.torques[k - 1], self.torques[k]);
        std::array::from_fn(|i| a[i] + s * (b[i] - a[i]))
    }

    /// Rate of change at `t`: central differences at the samples (one-sided at
    /// the ends), linearly interpolated; zero outside the sampled span (where
    /// [`TorqueTable::at`] holds the values) and for a single sample. Times
    /// within rounding (`1e-9` of the span) of an end count as that end.
    pub fn rate_at(&self, t: f64) -> [f64; 3] {
        let n = self.times.len();
        if n < 2 {
            return [0.0; 3];
        }
        let (first, last) = (self.times[0], self.times[n - 1]);
        let slack = 1e-9 * (last - first);
        if t < first - slack || t > last + slack {
            return [0.0; 3];
        }
        let t = t.clamp(first, last);
        let node = |k: usize| -> [f64; 3] {
            let (a, b) = (k.saturating_sub(1), (k + 1).min(n - 1));
            let dt = self.times[b] - self.times[a];
            std::array::from_fn(|i| (self.torques[b][i] - self.torques[a][i]) / dt)
        };
        let k = self.times.partition_point(|&x| x <= t).clamp(1, n - 1);
        let (t0, t1) = (self.times[k - 1], self.times[k]);
        let s = ((t - t0) / (t1 - t0)).clamp(0.0, 1.0);
        let (a, b) = (node(k - 1), node(k));
        std::array::from_fn(|i| a[i] + s * (b[i] - a[i]))
    }
}

/// Time integrators offered for forward dynamics.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scheme {
    /// Explicit fourth-order Runge-Kutta.
    Rk4,
    /// Symplectic (semi-implicit) Euler.
    SemiImplicit,
    /// Implicit generalized-alpha with Newton iterations (stiff models).
    GeneralizedAlpha,
}

impl std::str::FromStr for Scheme {
    type Err = String;
    fn from_str(s: &str) -> Result<Scheme, String> {
        match s {
            "rk4" => Ok(Scheme::Rk4),
            "semi-implicit" => Ok(Scheme::SemiImplicit),
            "gen-alpha" => Ok(Scheme::GeneralizedAlpha),
            _ => Err(format!(
                "unknown integrator `{s}` (rk4, semi-implicit, gen-alpha)"
            )),
        }
    }
}

/// State of the rigid robot.
pub type RigidState = flexdyn_runtime::State<12>;

/// The consistent state of the robot with its platform at `p` moving at `v`.
pub fn consistent_state<M>(
    model: &M,
    g: &Geometry,
    t: f64,
    p: [f64; 3],
    v: [f64; 3],
) -> Result<RigidState, String>
where
    M: flexdyn_runtime::Model<12, 9, 3>,
{
    use flexdyn_runtime::nalgebra::SVector;
    let q0 = inverse_kinematics(g, p).map_err(|e| format!("initial state: {e}"))?;
    let mut solver = flexdyn_runtime::InverseDynamics::<12, 9, 3, 3>::new(
        [9, 10, 11],
        SVector::from(q0),
        flexdyn_runtime::InverseConfig::default(),
    )
    .map_err(|e| e.to_string())?;
    let mut sol = RigidSolution::default();
    solver
        .solve(
            model,
            t,
            &SVector::from(p),
            &SVector::from(v),
            &SVector::zeros(),
            &mut sol,
        )
        .map_err(|e| format!("initial state: {e}"))?;
    Ok(RigidState::new(sol.q, sol.qd, t))
}

/// Forward dynamics of a robot model (rigid or flexible; wrap it in
/// [`flexdyn_runtime::control::Feedback`] for a control loop; `name` for
/// its messages) from `state` under
/// `torques`, with steps of `dt`, recording the state every `every` steps
/// (and at the start), for `steps` steps. `tick` is called after each step.
#[allow(clippy::too_many_arguments)]
pub fn simulate<M, const NQ: usize, const NC: usize>(
    (name, model): (&str, &M),
    scheme: Scheme,
    state: flexdyn_runtime::State<NQ>,
    torques: &TorqueTable,
    dt: f64,
    steps: usize,
    every: usize,
    tick: &mut dyn FnMut(),
) -> Result<Vec<flexdyn_runtime::State<NQ>>, String>
where
    M: flexdyn_runtime::Equations<
        flexdyn_runtime::nalgebra::Const<NQ>,
        flexdyn_runtime::nalgebra::Const<NC>,
        flexdyn_runtime::nalgebra::Const<3>,
    >,
{
    collect_rows(&mut || {}, |emit| {
        stream_simulate(
            (name, model),
            scheme,
            state,
            torques,
            (dt, steps, every),
            tick,
            emit,
        )
    })
}

/// [`simulate`], each recorded state handed to `emit` as it is reached;
/// `(dt, steps, every)` as there.
pub fn stream_simulate<M, const NQ: usize, const NC: usize>(
    (name, model): (&str, &M),
    scheme: Scheme,
    mut state: flexdyn_runtime::State<NQ>,
    torques: &TorqueTable,
    (dt, steps, every): (f64, usize, usize),
    tick: &mut dyn FnMut(),
    emit: Emit<'_, flexdyn_runtime::State<NQ>>,
) -> Result<(), String>
where
    M: flexdyn_runtime::Equations<
        flexdyn_runtime::nalgebra::Const<NQ>,
        flexdyn_runtime::nalgebra::Const<NC>,
        flexdyn_runtime::nalgebra::Const<3>,
    >,
{
    use flexdyn_runtime::integrate::{GeneralizedAlpha, Rk4, SemiImplicitEuler, StepSettings};
    use flexdyn_runtime::nalgebra::Const;
    use flexdyn_runtime::{FromFn, IntegratorOf};
    let input = FromFn(|t: f64| flexdyn_runtime::nalgebra::SVector::<f64, 3>::from(torques.at(t)));
    let settings = StepSettings::with_projection();
    emit(state)?;
    let explain = |e: flexdyn_runtime::Error| match e.kind {
        flexdyn_runtime::ErrorKind::StepTooLarge { .. } if scheme == Scheme::Rk4 => format!(
            "{e}: the explicit RK4 scheme is unstable at this step for the stiffest motion \
             of scene `{name}` (elastic modes, stiff joints); use --integrator gen-alpha \
             or a smaller --dt"
        ),
        _ if scheme != Scheme::GeneralizedAlpha && NQ > 12 => format!(
            "{e} (the explicit `{}` scheme is likely unstable at this step on the \
             elastic modes of scene `{name}`; use --integrator gen-alpha)",
            if scheme == Scheme::Rk4 {
                "rk4"
            } else {
                "semi-implicit"
            }
        ),
        _ => e.to_string(),
    };
    let mut run = |integ: &mut dyn FnMut(
        &mut flexdyn_runtime::State<NQ>,
    ) -> Result<(), flexdyn_runtime::Error>| {
        for k in 1..=steps {
            integ(&mut state).map_err(explain)?;
            if k % every.max(1) == 0 {
                emit(state)?;
            }
            tick();
        }
        Ok::<(), String>(())
    };
    match scheme {
        Scheme::Rk4 => {
            let mut g = Rk4::new(settings);
            run(&mut |s| {
                IntegratorOf::<Const<NQ>, Const<NC>, Const<3>>::step(&mut g, model, s, &input, dt)
                    .map(|_| ())
            })?;
        }
        Scheme::SemiImplicit => {
            let mut g = SemiImplicitEuler::new(settings);
            run(&mut |s| {
                IntegratorOf::<Const<NQ>, Const<NC>, Const<3>>::step(&mut g, model, s, &input, dt)
                    .map(|_| ())
            })?;
        }
        Scheme::GeneralizedAlpha => {
            let config = flexdyn_runtime::GeneralizedAlphaConfig {
                rho_inf: SERVO_RHO_INF,
                filter_start: false,
                ..Default::default()
            };
            let mut g = GeneralizedAlpha::<NQ, NC>::new(settings, config);
            run(&mut |s| g.step(model, s, &input, dt).map(|_| ()))?;
        }
    }
    Ok(())
}

/// Expands `$callback!` with every robot scene the robot commands
/// (`inverse`, `simulate`, `report`) drive, as `module => Type` pairs: the
/// rigid robot, its flexible variants and their reductions. The one list
/// behind [`ROBOT_SCENES`] and [`with_robot_model!`].
#[doc(hidden)]
#[macro_export]
macro_rules! robot_scene_list {
    ($callback:ident ! ( $($args:tt)* )) => {
        $crate::$callback!( $($args)* ;
            parallel_robot_rigid => ParallelRobotRigid,
            parallel_robot_flexible => ParallelRobotFlexible,
            parallel_robot_flexible_links => ParallelRobotFlexibleLinks,
            parallel_robot_flexible_joints => ParallelRobotFlexibleJoints,
            parallel_robot_soft => ParallelRobotSoft,
            parallel_robot_flexible_m1 => ParallelRobotFlexibleM1,
            parallel_robot_flexible_m2 => ParallelRobotFlexibleM2,
            parallel_robot_flexible_m3 => ParallelRobotFlexibleM3,
            parallel_robot_flexible_m4 => ParallelRobotFlexibleM4,
            parallel_robot_flexible_m1_rigid_joints => ParallelRobotFlexibleM1RigidJoints,
            parallel_robot_flexible_m2_rigid_joints => ParallelRobotFlexibleM2RigidJoints,
            parallel_robot_flexible_m6_rigid_joints => ParallelRobotFlexibleM6RigidJoints,
            parallel_robot_flexible_pruned => ParallelRobotFlexiblePruned
        )
    };
}

#[doc(hidden)]
#[macro_export]
macro_rules! robot_scene_names {
    (; $($scene:ident => $ty:ident),*) => {
        [$(stringify!($scene)),*]
    };
}

/// The robot scenes the robot commands (`inverse`, `simulate`, `report`)
/// drive: the rigid robot, its flexible variants and their reductions.
pub const ROBOT_SCENES: [&str; 13] = robot_scene_list!(robot_scene_names!());

#[doc(hidden)]
#[macro_export]
macro_rules! robot_scene_dispatch {
    ($name:expr, $m:ident => $body:expr; $($scene:ident => $ty:ident),*) => {{
        let name: &str = $name;
        $(
            if name == stringify!($scene) {
                #[allow(clippy::default_constructed_unit_structs)]
                let $m = $crate::scenes::$scene::$ty::default();
                Some($body)
            } else
        )* {
            None
        }
    }};
}

/// Evaluates `$body` with `$m` bound to the generated model of robot scene
/// `$name` (one of [`ROBOT_SCENES`], at its nominal runtime parameters):
/// `Some(body)`, or `None` for any other name. Each arm is compiled for its
/// own model type, so `$body` may call functions generic over the model's
/// dimensions.
#[macro_export]
macro_rules! with_robot_model {
    ($name:expr, $m:ident => $body:expr) => {
        $crate::robot_scene_list!(robot_scene_dispatch!($name, $m => $body))
    };
}

/// The joint-space PD loop of a forward run: gains and the reference angles
/// of the actuated joints (`th11, th21, th31`) in time.
#[derive(Debug, Clone)]
pub struct PdSettings {
    /// Proportional gain, N m/rad.
    pub kp: f64,
    /// Derivative gain, N m s/rad.
    pub kd: f64,
    /// Reference angles.
    pub reference: TorqueTable,
}

/// One recorded row of a forward run, whatever the scene.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimRow {
    /// Time, s.
    pub t: f64,
    /// Platform centre, m.
    pub p: [f64; 3],
    /// Actuated joint angles, rad.
    pub th: [f64; 3],
    /// Largest closure-constraint residual.
    pub phi_max: f64,
    /// Applied actuator torques (feed-forward plus feedback), N m.
    pub tau: [f64; 3],
}

/// Forward dynamics of any robot scene from the robot in static equilibrium on its path
/// ([`initial_state`]) at `t0` with its platform at `p` moving at `v`, under
/// `torques` plus the PD loop `pd` if given, `steps` steps of `dt`, recording
/// every `every` steps. `tick` is called after each step.
#[allow(clippy::too_many_arguments)]
pub fn simulate_rows<M, const NQ: usize, const NC: usize>(
    model: &M,
    g: &Geometry,
    scheme: Scheme,
    start: (f64, [f64; 3], [f64; 3]),
    torques: &TorqueTable,
    pd: Option<&PdSettings>,
    run: (f64, usize, usize),
    tick: &mut dyn FnMut(),
) -> Result<Vec<SimRow>, String>
where
    M: flexdyn_runtime::Model<NQ, NC, 3>,
{
    collect_rows(&mut || {}, |emit| {
        stream_simulate_rows(model, g, scheme, start, torques, pd, run, tick, emit)
    })
}

/// [`simulate_rows`], each row handed to `emit` as it is recorded.
#[allow(clippy::too_many_arguments)]
pub fn stream_simulate_rows<M, const NQ: usize, const NC: usize>(
    model: &M,
    g: &Geometry,
    scheme: Scheme,
    (t0, p, v): (f64, [f64; 3], [f64; 3]),
    torques: &TorqueTable,
    pd: Option<&PdSettings>,
    run: (f64, usize, usize),
    tick: &mut dyn FnMut(),
    emit: Emit<'_, SimRow>,
) -> Result<(), String>
where
    M: flexdyn_runtime::Model<NQ, NC, 3>,
{
    let layout = Layout::of(model)?;
    let start = initial_state(model, &layout, g, t0, p, v)?;
    use flexdyn_runtime::control::{Feedback, FeedbackLaw, JointPd, Target};
    use flexdyn_runtime::nalgebra::SVector;
    let pd = pd
        .map(|s| {
            let reference = s.reference.clone();
            JointPd::<_, NQ, 3>::new(layout.actuated, [s.kp; 3], [s.kd; 3], move |t: f64| {
                Target {
                    position: reference.at(t).into(),
                    velocity: reference.rate_at(t).into(),
                    acceleration: SVector::zeros(),
                }
            })
            .map_err(|e| match e.kind {
                flexdyn_runtime::ErrorKind::InvalidParameter { what, value, .. } => {
                    format!("invalid PD gain: {what} = {value}")
                }
                _ => e.to_string(),
            })
        })
        .transpose()?;
    let mut record = |s: flexdyn_runtime::State<NQ>| {
        let mut phi = SVector::<f64, NC>::zeros();
        model.constraints(&s.q, s.t, &mut phi);
        let ff = torques.at(s.t);
        let fb = pd
            .as_ref()
            .map_or(SVector::zeros(), |pd| pd.input(&s.q, &s.qd, s.t));
        emit(SimRow {
            t: s.t,
            p: layout.platform.map(|i| s.q[i]),
            th: layout.actuated.map(|i| s.q[i]),
            phi_max: phi.amax(),
            tau: std::array::from_fn(|j| ff[j] + fb[j]),
        })
    };
    match &pd {
        Some(pd) => {
            let closed = Feedback {
                inner: model,
                law: |q: &SVector<f64, NQ>, qd: &SVector<f64, NQ>, t: f64| pd.input(q, qd, t),
            };
            stream_simulate(
                (M::NAME, &closed),
                scheme,
                start,
                torques,
                run,
                tick,
                &mut record,
            )
        }
        None => stream_simulate(
            (M::NAME, model),
            scheme,
            start,
            torques,
            run,
            tick,
            &mut record,
        ),
    }
}

/// The rigid robot's twelve coordinates, in the order of
/// [`inverse_kinematics`]. Every robot scene (rigid or flexible) names its
/// coordinates so; flexible scenes add platform rotations, joint twists and
/// modal coordinates.
pub const RIGID_COORDINATES: [&str; 12] = [
    "th11", "th12", "th13", "th21", "th22", "th23", "th31", "th32", "th33", "px", "py", "pz",
];

/// Where a robot scene keeps the quantities the robot commands need, found
/// by name (coordinates) and from the actuator map (actuated joints).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Layout {
    /// Index of each of [`RIGID_COORDINATES`] among the scene's coordinates.
    pub rigid: [usize; 12],
    /// Indices of the platform centre `px, py, pz`.
    pub platform: [usize; 3],
    /// Index of the coordinate each actuator drives (`th11, th21, th31`).
    pub actuated: [usize; 3],
    /// Number of coordinates of the scene.
    pub nq: usize,
}

impl Layout {
    /// The layout of `model`, or an error naming what the scene lacks.
    pub fn of<M, const NQ: usize, const NC: usize>(model: &M) -> Result<Layout, String>
    where
        M: flexdyn_runtime::Model<NQ, NC, 3>,
    {
        let find = |name: &str| {
            M::COORDINATES
                .iter()
                .position(|c| *c == name)
                .ok_or_else(|| {
                    format!(
                        "scene `{}` has no coordinate `{name}`: a robot scene names its rigid \
                         coordinates {}",
                        M::NAME,
                        RIGID_COORDINATES.join(", ")
                    )
                })
        };
        let mut rigid = [0; 12];
        for (k, name) in RIGID_COORDINATES.iter().enumerate() {
            rigid[k] = find(name)?;
        }
        let mut b = flexdyn_runtime::nalgebra::SMatrix::<f64, NQ, 3>::zeros();
        model.actuator_map(&mut b);
        let mut actuated = [0; 3];
        for j in 0..3 {
            let rows: Vec<usize> = (0..NQ).filter(|&i| b[(i, j)] != 0.0).collect();
            match rows.as_slice() {
                [i] if b[(*i, j)] == 1.0 && *i == rigid[3 * j] => actuated[j] = *i,
                _ => {
                    return Err(format!(
                        "scene `{}`: actuator `{}` must drive coordinate `{}` alone with unit gain",
                        M::NAME,
                        M::ACTUATORS[j],
                        RIGID_COORDINATES[3 * j]
                    ))
                }
            }
        }
        Ok(Layout {
            rigid,
            platform: [rigid[9], rigid[10], rigid[11]],
            actuated,
            nq: NQ,
        })
    }

    /// Whether the scene has coordinates beyond the rigid robot's twelve
    /// (platform rotations, joint twists, modal coordinates).
    pub fn is_flexible(&self) -> bool {
        self.nq > 12
    }
}

/// The state of a robot scene with its platform at `p` moving at `v`.
///
/// Positions: the rigid coordinates from the closed-form inverse kinematics;
/// for a flexible scene, then the static equilibrium under gravity with the
/// platform held at `p` ([`static_equilibrium`]: the elastic coordinates at
/// their gravity sag, the joint angles adjusted to it), so that a run does
/// not start by releasing the undeformed structure under load. Rates: the
/// platform's `v`, and those the velocity constraints need on the first
/// coordinates in the scene's order whose constraint columns are independent
/// ([`flexdyn::prescribed_motion::needed_velocities`], as `flexdyn inverse
/// --free-rates zero`): the joint rates and the platform's rotation rates
/// (the robot scenes list them before the elastic coordinates); the elastic
/// rates are zero. Checked to satisfy the position and velocity constraints
/// to `1e-9`.
pub fn initial_state<M, const NQ: usize, const NC: usize>(
    model: &M,
    layout: &Layout,
    g: &Geometry,
    t: f64,
    p: [f64; 3],
    v: [f64; 3],
) -> Result<flexdyn_runtime::State<NQ>, String>
where
    M: flexdyn_runtime::Model<NQ, NC, 3>,
{
    use flexdyn_runtime::nalgebra::{SMatrix, SVector};
    let rigid = inverse_kinematics(g, p).map_err(|e| format!("initial state: {e}"))?;
    let mut q = SVector::<f64, NQ>::zeros();
    for (k, &i) in layout.rigid.iter().enumerate() {
        q[i] = rigid[k];
    }
    if layout.is_flexible() {
        q = static_equilibrium(model, layout, &q, t)?.0;
    }
    let mut phi_q = SMatrix::<f64, NC, NQ>::zeros();
    let mut phi_t = SVector::<f64, NC>::zeros();
    model.constraint_jacobian(&q, t, &mut phi_q);
    model.constraint_time_derivative(&q, t, &mut phi_t);
    // The platform's rows: its coordinates' rates are `v`.
    let y_q = SMatrix::<f64, 3, NQ>::from_fn(|r, c| f64::from(u8::from(layout.platform[r] == c)));
    let qd = flexdyn::prescribed_motion::needed_velocities(&phi_q, &phi_t, &y_q, &v.into(), t)
        .map_err(|e| format!("initial state: {e}"))?;
    let state = flexdyn_runtime::State::new(q, qd, t);
    let drift = flexdyn_runtime::constraint_drift(model, &state);
    if !(drift.position < 1e-9 && drift.velocity < 1e-9) {
        return Err(format!(
            "initial state: scene `{}` does not close at the rigid robot's pose \
             (constraint residual {:.3e}, velocity residual {:.3e})",
            M::NAME,
            drift.position,
            drift.velocity
        ));
    }
    Ok(state)
}

/// Static equilibrium of a robot scene under gravity with the platform
/// centre held where `start` puts it: Newton on
///
/// ```text
/// dV/dq(q) - Phi_q(q)^T lambda - B tau = 0,   Phi(q) = 0,   S q = S start
/// ```
///
/// (`dV/dq` as the bias forces at rest), with the Jacobian of the first
/// block by forward differences. Returns the positions and the holding
/// torques. From the rigid pose it converges in a few iterations (the
/// elastic forces are linear in the modal coordinates and twists).
pub fn static_equilibrium<M, const NQ: usize, const NC: usize>(
    model: &M,
    layout: &Layout,
    start: &flexdyn_runtime::nalgebra::SVector<f64, NQ>,
    t: f64,
) -> Result<(flexdyn_runtime::nalgebra::SVector<f64, NQ>, [f64; 3]), String>
where
    M: flexdyn_runtime::Model<NQ, NC, 3>,
{
    use flexdyn_runtime::nalgebra::{DMatrix, DVector, SMatrix, SVector};
    let n = NQ + NC + 3;
    let target = layout.platform.map(|i| start[i]);
    let mut b = SMatrix::<f64, NQ, 3>::zeros();
    model.actuator_map(&mut b);
    let rest = SVector::<f64, NQ>::zeros();
    // The q-dependent part: dV/dq - Phi_q^T lambda, and Phi.
    let forces = |q: &SVector<f64, NQ>, lambda: &DVector<f64>| {
        let mut h = SVector::<f64, NQ>::zeros();
        let mut phi_q = SMatrix::<f64, NC, NQ>::zeros();
        let mut phi = SVector::<f64, NC>::zeros();
        model.bias(q, &rest, t, &mut h);
        model.constraint_jacobian(q, t, &mut phi_q);
        model.constraints(q, t, &mut phi);
        let lam = SVector::<f64, NC>::from_iterator(lambda.iter().copied());
        (h - phi_q.transpose() * lam, phi, phi_q)
    };
    let residual = |q: &SVector<f64, NQ>, lambda: &DVector<f64>, tau: &[f64; 3]| {
        let (f, phi, _) = forces(q, lambda);
        let f = f - b * SVector::<f64, 3>::from(*tau);
        DVector::from_fn(n, |r, _| {
            if r < NQ {
                f[r]
            } else if r < NQ + NC {
                phi[r - NQ]
            } else {
                q[layout.platform[r - NQ - NC]] - target[r - NQ - NC]
            }
        })
    };
    let mut q = *start;
    let mut lambda = DVector::<f64>::zeros(NC);
    let mut tau = [0.0; 3];
    for _ in 0..30 {
        let r = residual(&q, &lambda, &tau);
        if !r.iter().all(|x| x.is_finite()) {
            break;
        }
        let (f0, _, phi_q) = forces(&q, &lambda);
        let mut jac = DMatrix::<f64>::zeros(n, n);
        for j in 0..NQ {
            let d = 1e-7 * q[j].abs().max(1e-2);
            let mut qp = q;
            qp[j] += d;
            let (fp, _, _) = forces(&qp, &lambda);
            for i in 0..NQ {
                jac[(i, j)] = (fp[i] - f0[i]) / d;
            }
            for i in 0..NC {
                jac[(NQ + i, j)] = phi_q[(i, j)];
                jac[(j, NQ + i)] = -phi_q[(i, j)];
            }
            for k in 0..3 {
                jac[(j, NQ + NC + k)] = -b[(j, k)];
            }
        }
        for k in 0..3 {
            jac[(NQ + NC + k, layout.platform[k])] = 1.0;
        }
        let dx = jac
            .full_piv_lu()
            .solve(&(-&r))
            .filter(|d| d.iter().all(|x| x.is_finite()))
            .ok_or("initial state: the static equilibrium's Newton matrix is singular")?;
        for i in 0..NQ {
            q[i] += dx[i];
        }
        for i in 0..NC {
            lambda[i] += dx[NQ + i];
        }
        for k in 0..3 {
            tau[k] += dx[NQ + NC + k];
        }
        let step = (0..NQ).map(|i| dx[i].abs()).fold(0.0, f64::max);
        if step < 1e-14 {
            return Ok((q, tau));
        }
    }
    Err(format!(
        "initial state: no static equilibrium of scene `{}` near the rigid pose (Newton did not converge)",
        M::NAME
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reference_pose_of_the_spec() {
        // Spec: at P = (0.1, 0, 0.7) chain 1 has th11 ~ 4.1 deg, th12 ~ 131.7 deg, th13 = 0.
        let q = inverse_kinematics(&Geometry::SPEC, [0.1, 0.0, 0.7]).unwrap();
        assert!(
            (q[0].to_degrees() - 4.1).abs() < 0.05,
            "{}",
            q[0].to_degrees()
        );
        assert!(
            (q[1].to_degrees() - 131.7).abs() < 0.05,
            "{}",
            q[1].to_degrees()
        );
        assert!(q[2].abs() < 1e-12);
    }

    #[test]
    fn ik_closes_every_chain_on_the_working_branch() {
        let g = Geometry::SPEC;
        for k in 0..50 {
            let t = k as f64 * 0.1;
            let p = Circle::paper(2.0).at(t)[0];
            let q = inverse_kinematics(&g, p).unwrap();
            for i in 0..3 {
                let th = [q[3 * i], q[3 * i + 1], q[3 * i + 2]];
                let tip = chain_tip(&g, i, th);
                let (s, c) = azimuth(i).sin_cos();
                let want = [p[0] + g.rp * c, p[1] + g.rp * s, p[2]];
                for a in 0..3 {
                    assert!((tip[a] - want[a]).abs() < 1e-12);
                }
                let beta = th[1] - th[0];
                assert!(beta > 0.0 && beta < PI && th[2].abs() < PI / 2.0);
            }
        }
    }

    #[test]
    fn unreachable_points_are_reported() {
        let g = Geometry::SPEC;
        match inverse_kinematics(&g, [0.0, 0.0, 2.0]) {
            Err(IkError::Unreachable { excess, .. }) => assert!(excess > 0.0),
            other => panic!("{other:?}"),
        }
        match inverse_kinematics(&g, [0.0, 0.9, 0.7]) {
            Err(IkError::Unreachable { .. }) => {}
            other => panic!("{other:?}"),
        }
    }

    /// Issue 8 (workspace-edge hard case): coarse ticks along wide circles
    /// make the warm-started Newton jump far (it stalled at 4 of these 12
    /// reachable circles before the restart from the closed form); every
    /// point is solved, on the closed-form inverse kinematics' working
    /// branch, never silently on another assembly mode.
    #[test]
    fn issue_8_coarse_ticks_are_solved_on_the_working_branch() {
        let model = crate::scenes::parallel_robot_rigid::ParallelRobotRigid;
        let layout = Layout::of(&model).unwrap();
        let g = Geometry::SPEC;
        let mut flips = 0;
        for radius in [0.3, 0.4, 0.5, 0.6] {
            for dt in [0.4, 0.8, 1.2] {
                let circle = Circle {
                    omega: 2.0,
                    radius,
                    center: [0.0, 0.0, 0.7],
                };
                let times: Vec<f64> = (0..12).map(|k| k as f64 * dt).collect();
                let sols = inverse_along(&model, &g, &circle, &times, &mut || {})
                    .unwrap_or_else(|e| panic!("radius {radius}, tick {dt} s: {e}"));
                for (s, &t) in sols.iter().zip(&times) {
                    let ik = inverse_kinematics(&g, circle.at(t)[0]).unwrap();
                    if branch_distance(&layout, &s.q, &ik) > 1e-6 {
                        flips += 1;
                    }
                }
            }
        }
        assert_eq!(flips, 0, "solutions off the working branch");
    }
}
