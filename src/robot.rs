//! The spatial parallel robot of `shared/spec/robot.md`: geometry, the
//! paper's circular motion, and closed-form inverse kinematics on the working
//! branch ("elbow up", `0 < th_i2 - th_i1 < pi`, `|th_i3| < pi/2`).
//!
//! Coordinate order (as in `scenes/parallel_robot_rigid.toml`):
//! `[th11, th12, th13, th21, th22, th23, th31, th32, th33, px, py, pz]`.

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
/// after checking that the request is sensible.
pub fn output_times(duration: f64, dt: f64) -> Result<Vec<f64>, String> {
    if !(dt.is_finite() && dt > 0.0) {
        return Err(format!(
            "the step must be a positive number of seconds, got {dt}"
        ));
    }
    if !(duration.is_finite() && duration >= 0.0) {
        return Err(format!(
            "the duration must be a non-negative number of seconds, got {duration}"
        ));
    }
    let steps = (duration / dt + 1e-9).floor();
    if steps > 1e7 {
        return Err(format!(
            "{duration} s at a step of {dt} s is {steps:.0} steps; at most 10^7 are allowed"
        ));
    }
    Ok((0..=steps as usize).map(|k| k as f64 * dt).collect())
}

/// Solution of the rigid robot's inverse dynamics at one time.
pub type RigidSolution = flexdyn_runtime::InverseSolution<12, 9, 3>;

/// Inverse dynamics of the rigid robot along `circle` at `times`, through
/// the runtime's real-time path (one [`flexdyn_runtime::InverseDynamics`]
/// call per time, warm-started from the previous one). `tick` is called after
/// each time. Errors name the time and what went wrong.
pub fn inverse_along<M>(
    model: &M,
    g: &Geometry,
    circle: &Circle,
    times: &[f64],
    tick: &mut dyn FnMut(),
) -> Result<Vec<RigidSolution>, String>
where
    M: flexdyn_runtime::Model<12, 9, 3>,
{
    use flexdyn_runtime::nalgebra::SVector;
    let start = times.first().copied().unwrap_or(0.0);
    let q0 =
        inverse_kinematics(g, circle.at(start)[0]).map_err(|e| format!("at t = {start} s: {e}"))?;
    let mut solver = flexdyn_runtime::InverseDynamics::<12, 9, 3, 3>::new(
        [9, 10, 11],
        SVector::from(q0),
        flexdyn_runtime::InverseConfig::default(),
    )
    .map_err(|e| e.to_string())?;
    let mut out = Vec::with_capacity(times.len());
    let mut sol = RigidSolution::default();
    for &t in times {
        let [p, v, a] = circle.at(t);
        // The closed form tells precisely why a point cannot be reached.
        inverse_kinematics(g, p).map_err(|e| format!("at t = {t} s: {e}"))?;
        solver
            .solve(
                model,
                t,
                &SVector::from(p),
                &SVector::from(v),
                &SVector::from(a),
                &mut sol,
            )
            .map_err(|e| format!("at t = {t} s: {e}"))?;
        out.push(sol);
        tick();
    }
    Ok(out)
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
    pub fn from_table(table: &crate::table::Table) -> Result<TorqueTable, String> {
        let times = table.column("t")?;
        let taus = [
            table.column("tau_1")?,
            table.column("tau_2")?,
            table.column("tau_3")?,
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

/// Forward dynamics of the rigid robot from `state` under `torques`, with
/// steps of `dt`, recording the state every `every` steps (and at the
/// start), for `steps` steps. `tick` is called after each step.
#[allow(clippy::too_many_arguments)]
pub fn simulate<M>(
    model: &M,
    scheme: Scheme,
    mut state: RigidState,
    torques: &TorqueTable,
    dt: f64,
    steps: usize,
    every: usize,
    tick: &mut dyn FnMut(),
) -> Result<Vec<RigidState>, String>
where
    M: flexdyn_runtime::Model<12, 9, 3>,
{
    use flexdyn_runtime::integrate::{GeneralizedAlpha, Rk4, SemiImplicitEuler, StepSettings};
    use flexdyn_runtime::{FromFn, Integrator};
    let input = FromFn(|t: f64| flexdyn_runtime::nalgebra::SVector::<f64, 3>::from(torques.at(t)));
    let settings = StepSettings::default();
    let mut out = vec![state];
    let mut run = |integ: &mut dyn FnMut(&mut RigidState) -> Result<(), flexdyn_runtime::Error>| {
        for k in 1..=steps {
            integ(&mut state).map_err(|e| e.to_string())?;
            if k % every.max(1) == 0 {
                out.push(state);
            }
            tick();
        }
        Ok::<(), String>(())
    };
    match scheme {
        Scheme::Rk4 => {
            let mut g = Rk4::new(settings);
            run(&mut |s| g.step(model, s, &input, dt).map(|_| ()))?;
        }
        Scheme::SemiImplicit => {
            let mut g = SemiImplicitEuler::new(settings);
            run(&mut |s| g.step(model, s, &input, dt).map(|_| ()))?;
        }
        Scheme::GeneralizedAlpha => {
            let mut g = GeneralizedAlpha::<12, 9>::new(settings, Default::default());
            run(&mut |s| g.step(model, s, &input, dt).map(|_| ()))?;
        }
    }
    Ok(out)
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
}
