//! Stage 4, derive: Lagrange's equations from the scene's energies.
//!
//! With the kinetic energy `T(q, qd, t)`, potential energy `V(q, t)` and
//! dissipation `D(q, qd, t)` summed over the components:
//!
//! * `dT/dq` and the momenta `p = dT/dqd` come from one reverse-mode sweep
//!   over `T` (`Graph::gradient`), whose cost is a small multiple of the size
//!   of `T`; on a serial chain, where rigid bodies share their frames, that
//!   size grows linearly with the number of links. Components that touch at
//!   most [`FORWARD_MAX_COORDINATES`] coordinates are differentiated on
//!   their own in forward mode instead, where the expanded derivatives
//!   simplify further;
//! * Coriolis/centrifugal forces `c = d/dt p|_(qdd=0) - dT/dq`, the time
//!   derivative being one forward-mode sweep over `p` (`q' = qd`, `t' = 1`);
//! * except for rigid bodies, point masses and rods on chains, whose kinetic
//!   energy has the rigid-body form `(m v.v + w.I w) / 2`
//!   ([`crate::model::Body`]; a rod is two such terms): their Lagrange
//!   terms are the virtual work of their Newton-Euler inertial forces,
//!   `J_v^T m (v' + w x v) + J_w^T (I w' + w x I w)`. The bodies fixed in
//!   frames of the scene (the kinematic tree, [`crate::model::Placement`])
//!   take the recursive Newton-Euler algorithm over the frames, their
//!   weight as an upward acceleration of the world, and their mass matrix
//!   by composite inertias ([`tree`]); the others (a rod, a body whose
//!   centre moves in its frame) one forward sweep over their velocities and
//!   one reverse sweep weighted by the forces ([`newton_euler`]), their
//!   momenta `J^T (m v, I w)` one reverse sweep. Operations, from plain
//!   Lagrange to the sweeps to the tree: the Panda arm's bias forces 2,209,
//!   1,157, 1,015, its mass matrix 1,680 with the sweeps, 527 with the
//!   tree; TALOS (30 joints) inverse dynamics 7,215 to 4,669 and mass
//!   matrix 8,698 to 2,435;
//! * the other components' mass matrix `M_ij = dp_i/dqd_j`: one forward
//!   sweep over their momenta `p` per column;
//! * inverse dynamics `M qdd + h = dp/dt - dT/dq + g + d`, the time
//!   derivative along `q' = qd`, `qd' = qdd`, `t' = 1` (`Symbol::Qdd`): one
//!   forward sweep, no mass matrix formed;
//! * potential (gravity and elastic) forces `g = dV/dq`, damping forces
//!   `d = dD/dqd`: one reverse sweep each (for the bias and the inverse
//!   dynamics, `V` less the weight the tree carries).
//!
//! The system is `M qdd + c + g + d = Phi_q^T lambda + B tau`. For the
//! constraints `Phi(q, t)`: `Phi_q`, `Phi_t` and the acceleration right-hand
//! side `gamma = -d/dt(Phi_q qd + Phi_t)|_(qdd=0)`. For each marker: its
//! Jacobian `J = dv/dqd` (its velocity `v` in world axes is linear in `qd`)
//! and its acceleration bias `dv/dt|_(qdd=0)`. `M` is never inverted
//! symbolically; the runtime factorises it numerically.

mod tree;

use std::fmt;

use crate::expr::{Graph, Id, Symbol};
use crate::model::{Body, Component, Coordinate, Model};

/// A matrix of graph nodes, as rows.
pub type Matrix = Vec<Vec<Id>>;

/// Every derived term of a scene, as nodes of the model's graph.
#[derive(Debug, Clone)]
pub struct Equations {
    /// Mass matrix (symmetric; `mass[i][j] == mass[j][i]`).
    pub mass: Vec<Vec<Id>>,
    /// Coriolis/centrifugal forces `C(q, qd) qd` (including explicit time terms).
    pub coriolis: Vec<Id>,
    /// Gravity and elastic forces `dV/dq`.
    pub potential_forces: Vec<Id>,
    /// Damping forces `dD/dqd`.
    pub damping_forces: Vec<Id>,
    /// Bias forces `h = coriolis + potential_forces + damping_forces`.
    pub bias: Vec<Id>,
    /// Inverse dynamics `M qdd + h`, in the accelerations `Symbol::Qdd`.
    pub inverse_dynamics: Vec<Id>,
    /// Coriolis matrix from Christoffel symbols, when asked for.
    pub coriolis_matrix: Option<Vec<Vec<Id>>>,
    /// Jacobians of the bias forces `(dh/dq, dh/dqd)`, when asked for;
    /// entry `[i][j]` is `d h_i / d x_j`.
    pub bias_jacobians: Option<(Matrix, Matrix)>,
    /// Derivatives of the inverse dynamics `(d tau/dq, d tau/dqd)` at the
    /// accelerations `Symbol::Qdd`, when asked for; entry `[i][j]` is
    /// `d tau_i / d x_j`.
    pub inverse_dynamics_derivatives: Option<(Matrix, Matrix)>,
    /// Derivatives `(da/dq, da/dqd)` of the acceleration constraint `a =
    /// Phi_q qdd - gamma` (the second time derivative of `Phi` along the
    /// motion) at the accelerations `Symbol::Qdd`, for a constrained scene
    /// that asks for `dynamics_derivatives`.
    pub constraint_acceleration_derivatives: Option<(Matrix, Matrix)>,
    /// Forward dynamics of an unconstrained scene, `(qdd, pivots)`: `qdd =
    /// M^-1 (f - h)` in the generalized forces `f` (read from the symbols
    /// `Symbol::Qdd`) and the pivots `D` of `M = L^T D L`, each relative to
    /// its diagonal entry of `M`; set after the
    /// prune stage by [`crate::solve::forward_dynamics`].
    pub forward_dynamics: Option<(Vec<Id>, Vec<Id>)>,
    /// Derivatives of that forward dynamics, `(d qdd/dq, d qdd/dqd, d
    /// qdd/df = M^-1)`, for an unconstrained scene that asks for
    /// `dynamics_derivatives`: `-M^-1 d ID/dx` with the inverse dynamics'
    /// derivatives taken at `qdd`, solved on the same factors; set with
    /// `forward_dynamics`.
    pub forward_dynamics_derivatives: Option<(Matrix, Matrix, Matrix)>,
    /// Total kinetic energy.
    pub kinetic_energy: Id,
    /// Total potential energy.
    pub potential_energy: Id,
    /// Constraint residuals.
    pub phi: Vec<Id>,
    /// Constraint Jacobian, `phi_q[i][j] = dPhi_i/dq_j`.
    pub phi_q: Vec<Vec<Id>>,
    /// Explicit time derivative of the constraints.
    pub phi_t: Vec<Id>,
    /// Acceleration right-hand side.
    pub gamma: Vec<Id>,
    /// Actuator map, `actuator_map[i][j]`: force on coordinate `i` per unit input `j`.
    pub actuator_map: Vec<Vec<f64>>,
    /// The generalized forces of the actuators, `B tau`, with the inputs
    /// `tau` read from `Symbol::Qdd` (the inputs of a function of
    /// `Inputs::Actuation`).
    pub actuator_forces: Vec<Id>,
    /// Kinematics of each marker, in scene order.
    pub markers: Vec<MarkerTerms>,
}

/// The kinematics of a marker, as nodes of the model's graph.
#[derive(Debug, Clone)]
pub struct MarkerTerms {
    /// World position of the point.
    pub position: [Id; 3],
    /// Rotation from the marker's axes to world axes.
    pub rotation: [[Id; 3]; 3],
    /// Velocity in world axes: the point's linear velocity, then the
    /// angular velocity.
    pub velocity: [Id; 6],
    /// `J = d(velocity)/dqd` (6 x nq, rows as in `velocity`): Pinocchio's
    /// `LOCAL_WORLD_ALIGNED` frame Jacobian at the point.
    pub jacobian: Matrix,
    /// The time derivative of `velocity` at `qdd = 0`: `J' qd` plus the
    /// explicit time terms (the point's classical acceleration, and the
    /// angular acceleration, when the coordinates do not accelerate).
    pub acceleration_bias: [Id; 6],
}

/// A scene whose energies do not fit the requested derivation.
#[derive(Debug, Clone, PartialEq)]
pub struct DeriveError {
    /// The component (or output) concerned.
    pub context: String,
    /// What is wrong.
    pub message: String,
}

impl fmt::Display for DeriveError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "in {}: {}", self.context, self.message)
    }
}

impl std::error::Error for DeriveError {}

/// Derive the equations of motion of a model.
pub fn derive(model: &mut Model) -> Result<Equations, DeriveError> {
    let n = model.nq();
    let g = &mut model.graph;
    let zero = g.constant(0.0);
    for c in &model.components {
        if c.potential != zero && uses_velocity(g, c.potential) {
            return Err(DeriveError {
                context: format!("component `{}`", c.name),
                message: "potential energy depends on velocities".into(),
            });
        }
    }
    let kinetic: Vec<Id> = model.components.iter().map(|c| c.kinetic).collect();
    let potential: Vec<Id> = model.components.iter().map(|c| c.potential).collect();
    let dissipation: Vec<Id> = model.components.iter().map(|c| c.dissipation).collect();
    let kinetic_energy = g.sum(&kinetic);
    let potential_energy = g.sum(&potential);
    let dissipation = g.sum(&dissipation);

    let q_vars: Vec<Symbol> = (0..n).map(|i| Symbol::Q(i as u32)).collect();
    let qd_vars: Vec<Symbol> = (0..n).map(|i| Symbol::Qd(i as u32)).collect();
    let (on_chain, others) = newton_euler_split(g, &model.components);
    let bodies: Vec<Body> = on_chain
        .iter()
        .flat_map(|c| c.bodies.iter().copied())
        .collect();
    let (dtdq, other_momenta) = kinetic_gradient(g, &others, n);
    let dtdq = &dtdq[..];
    // The bodies fixed in frames of the tree: their mass matrix by
    // composite inertias, their forces by the recursive Newton-Euler
    // algorithm ([`tree`]). The other bodies' momenta J^T (m v, I w) by one
    // reverse sweep over their velocities, their forces by sweeps
    // ([`newton_euler`]).
    let (tree, loose) = tree::Tree::new(g, &model.placements, &bodies);
    let body_momenta = body_momenta(g, &loose, &qd_vars);
    let momenta: Vec<Id> = (0..n)
        .map(|i| g.add(other_momenta[i], body_momenta[i]))
        .collect();
    let one = g.constant(1.0);
    let mut motion: Vec<(Symbol, Id)> = vec![(Symbol::Time, one)];
    for i in 0..n {
        let (qd, qdd) = (g.qd(i), g.symbol(Symbol::Qdd(i as u32)));
        motion.push((Symbol::Q(i as u32), qd));
        motion.push((Symbol::Qd(i as u32), qdd));
    }
    // Gravity on the tree's bodies whose potential energy is their weight
    // alone goes into the recursion as an upward acceleration of the world
    // (for the bias and inverse dynamics); the other potential energies by
    // their gradient.
    let gravity = model.gravity;
    let steady = !g
        .symbols(&gravity)
        .iter()
        .any(|s| matches!(s, Symbol::Q(_) | Symbol::Qd(_)));
    let mut weighed = 0;
    let rest_potential: Vec<Id> = model
        .components
        .iter()
        .map(|c| match c.weight {
            Some(weight)
                if steady
                    && on_chain.iter().any(|o| std::ptr::eq(*o, c))
                    && c.bodies.iter().all(|b| tree::held(g, b).is_some()) =>
            {
                weighed += 1;
                g.sub(c.potential, weight)
            }
            _ => c.potential,
        })
        .collect();
    let world = (weighed > 0).then(|| gravity.map(|x| g.neg(x)));
    let rest_potential = g.sum(&rest_potential);
    let rest_potential_forces = g.gradient(rest_potential, &q_vars);
    let mut body_forces = Vec::with_capacity(3);
    for (m, world) in [(None, None), (None, world), (Some(&motion[..]), world)] {
        let loose_forces = newton_euler(g, &loose, &qd_vars, m);
        let tree_forces = tree.newton_euler(g, n, m, world);
        let forces: Vec<Id> = (0..n)
            .map(|i| g.add(loose_forces[i], tree_forces[i]))
            .collect();
        body_forces.push(forces);
    }
    let [body_forces, weighed_forces, forces_in_motion] =
        <[Vec<Id>; 3]>::try_from(body_forces).expect("three");
    // Coriolis forces: one forward sweep over the other momenta, less
    // dT/dq, and the bodies' forces at zero acceleration.
    let rates = g.time_derivative_at_zero_acceleration(&other_momenta);
    let coriolis: Vec<Id> = (0..n)
        .map(|i| {
            g.linear(
                &[(rates[i], 1.0), (dtdq[i], -1.0), (body_forces[i], 1.0)],
                0.0,
            )
        })
        .collect();
    // Mass matrix: the tree's, and the other momenta's column by column,
    // M_ij = dp_i/dqd_j (upper triangle).
    let mut mass = tree.mass_matrix(g, n);
    for j in 0..n {
        let column = g.jvp(&momenta[..=j], &[(Symbol::Qd(j as u32), one)]);
        for (i, &m) in column.iter().enumerate() {
            let entry = g.add(mass[i][j], m);
            mass[i][j] = entry;
            mass[j][i] = entry;
        }
    }
    let entries: Vec<Id> = mass.iter().flatten().copied().collect();
    if g.symbols(&entries)
        .iter()
        .any(|s| matches!(s, Symbol::Qd(_)))
    {
        return Err(not_quadratic(g, &model.components, &model.coordinates));
    }
    // The potential (gravity and elastic) forces g = dV/dq and damping
    // forces d = dD/dqd: one reverse sweep each.
    let potential_forces = g.gradient(potential_energy, &q_vars);
    let damping_forces = g.gradient(dissipation, &qd_vars);
    // The exact bias forces, gravity on the tree's bodies in their
    // recursion; the prune stage may drop summands of their parts (and
    // recompute them from the parts), while the bias Jacobians (a Newton
    // matrix, which need not be exact) stay those of the exact forces.
    let bias: Vec<Id> = (0..n)
        .map(|i| {
            let terms = [
                (rates[i], 1.0),
                (dtdq[i], -1.0),
                (weighed_forces[i], 1.0),
                (rest_potential_forces[i], 1.0),
                (damping_forces[i], 1.0),
            ];
            g.linear(&terms, 0.0)
        })
        .collect();
    // M qdd + h = dp/dt - dT/dq + g + d along the motion.
    let momentum_rates = g.jvp(&other_momenta, &motion);
    let inverse_dynamics: Vec<Id> = (0..n)
        .map(|i| {
            let terms = [
                (momentum_rates[i], 1.0),
                (dtdq[i], -1.0),
                (forces_in_motion[i], 1.0),
                (rest_potential_forces[i], 1.0),
                (damping_forces[i], 1.0),
            ];
            g.linear(&terms, 0.0)
        })
        .collect();

    let coriolis_matrix = if model.outputs.coriolis_matrix {
        check_quadratic_kinetic(g, kinetic_energy, &model.runtime_parameters)?;
        Some(christoffel(g, &mass))
    } else {
        None
    };

    let bias_jacobians = model
        .outputs
        .bias_jacobians
        .then(|| (g.jacobian(&bias, &q_vars), g.jacobian(&bias, &qd_vars)));

    // d tau/d(q, qd) a row at a time: one reverse sweep per coordinate
    // (n sweeps) rather than forward sweeps per variable (2n): 2.5x fewer
    // operations on Baxter, 18 % fewer on the Panda.
    let inverse_dynamics_derivatives = model.outputs.dynamics_derivatives.then(|| {
        let vars: Vec<Symbol> = q_vars.iter().chain(&qd_vars).copied().collect();
        let rows: Vec<Vec<Id>> = inverse_dynamics
            .iter()
            .map(|&e| g.gradient(e, &vars))
            .collect();
        (
            rows.iter().map(|r| r[..n].to_vec()).collect(),
            rows.iter().map(|r| r[n..].to_vec()).collect(),
        )
    });

    // Constraints.
    let phi: Vec<Id> = model.constraints.iter().map(|c| c.residual).collect();
    for c in &model.constraints {
        if uses_velocity(g, c.residual) {
            return Err(DeriveError {
                context: format!("constraint `{}`", c.name),
                message: "a holonomic constraint cannot depend on velocities".into(),
            });
        }
    }
    let phi_q = g.jacobian(&phi, &q_vars);
    let phi_t = g.diff_many(&phi, Symbol::Time);
    let velocity_residual = g.time_derivative_at_zero_acceleration(&phi);
    let rates = g.time_derivative_at_zero_acceleration(&velocity_residual);
    let gamma: Vec<Id> = rates.iter().map(|&r| g.neg(r)).collect();
    let constraint_acceleration_derivatives =
        (model.outputs.dynamics_derivatives && !phi.is_empty()).then(|| {
            let a = g.jvp(&velocity_residual, &motion);
            (g.jacobian(&a, &q_vars), g.jacobian(&a, &qd_vars))
        });

    let markers = model
        .markers
        .iter()
        .map(|m| {
            let l = m.linear_about_point;
            let velocity = [
                l[0],
                l[1],
                l[2],
                m.velocity[3],
                m.velocity[4],
                m.velocity[5],
            ];
            let jacobian = g.jacobian(&velocity, &qd_vars);
            let rates = g.time_derivative_at_zero_acceleration(&m.velocity);
            MarkerTerms {
                position: m.position,
                rotation: m.rotation,
                velocity: m.velocity,
                jacobian,
                acceleration_bias: std::array::from_fn(|k| rates[k]),
            }
        })
        .collect();

    let mut actuator_map = vec![vec![0.0; model.actuators.len()]; n];
    for (j, a) in model.actuators.iter().enumerate() {
        actuator_map[a.coordinate][j] += a.gain;
    }
    let actuator_forces = actuator_map
        .iter()
        .map(|row| {
            let terms: Vec<(Id, f64)> = row
                .iter()
                .enumerate()
                .filter(|&(_, &b)| b != 0.0)
                .map(|(j, &b)| (g.symbol(Symbol::Qdd(j as u32)), b))
                .collect();
            g.linear(&terms, 0.0)
        })
        .collect();

    Ok(Equations {
        mass,
        coriolis,
        potential_forces,
        damping_forces,
        bias,
        inverse_dynamics,
        coriolis_matrix,
        bias_jacobians,
        inverse_dynamics_derivatives,
        constraint_acceleration_derivatives,
        forward_dynamics: None,
        forward_dynamics_derivatives: None,
        kinetic_energy,
        potential_energy,
        phi,
        phi_q,
        phi_t,
        gamma,
        actuator_map,
        actuator_forces,
        markers,
    })
}

/// Components whose kinetic energy touches at most this many coordinates are
/// differentiated on their own, in forward mode, one partial derivative per
/// coordinate: their expanded derivatives simplify (like terms, `sin^2 +
/// cos^2`) to less than the factored adjoint form. The others (links of a
/// chain, flexible bodies with their modes) go through one reverse sweep
/// together, sharing the frames they have in common.
const FORWARD_MAX_COORDINATES: usize = 4;

/// `(dT/dq, dT/dqd)` of the total kinetic energy: forward mode per small
/// component, one reverse sweep over the sum of the others.
fn kinetic_gradient(g: &mut Graph, components: &[&Component], n: usize) -> (Vec<Id>, Vec<Id>) {
    let zero = g.constant(0.0);
    let (mut dtdq, mut momenta) = (vec![zero; n], vec![zero; n]);
    let mut shared = Vec::new();
    for c in components.iter().filter(|c| c.kinetic != zero) {
        let touched = touched(g, c.kinetic);
        if touched.len() > FORWARD_MAX_COORDINATES {
            shared.push(c.kinetic);
            continue;
        }
        for i in touched {
            let dq = g.diff(c.kinetic, Symbol::Q(i as u32));
            let dqd = g.diff(c.kinetic, Symbol::Qd(i as u32));
            dtdq[i] = g.add(dtdq[i], dq);
            momenta[i] = g.add(momenta[i], dqd);
        }
    }
    let shared = g.sum(&shared);
    let vars: Vec<Symbol> = (0..n)
        .map(|i| Symbol::Q(i as u32))
        .chain((0..n).map(|i| Symbol::Qd(i as u32)))
        .collect();
    let grad = g.gradient(shared, &vars);
    for i in 0..n {
        dtdq[i] = g.add(dtdq[i], grad[i]);
        momenta[i] = g.add(momenta[i], grad[n + i]);
    }
    (dtdq, momenta)
}

/// Bodies that touch at least this many coordinates are written in
/// Newton-Euler form ([`newton_euler`]), and so are the bodies on their
/// chains (touching only coordinates such a body touches): on a chain
/// their velocities are shared by the forward and backward passes. A
/// body touching fewer coordinates on its own (a link of a small closed
/// mechanism) is differentiated like any other component, where its
/// expanded derivatives simplify further (the five-bar: 96 operations for
/// `dynamics_terms` against 118).
const NEWTON_EULER_MIN_COORDINATES: usize = 3;

/// The components whose bodies are written in Newton-Euler form, and the
/// other components.
fn newton_euler_split<'a>(
    g: &Graph,
    components: &'a [Component],
) -> (Vec<&'a Component>, Vec<&'a Component>) {
    let touches: Vec<Vec<usize>> = components.iter().map(|c| touched(g, c.kinetic)).collect();
    let chains: Vec<&Vec<usize>> = components
        .iter()
        .zip(&touches)
        .filter(|(c, t)| !c.bodies.is_empty() && t.len() >= NEWTON_EULER_MIN_COORDINATES)
        .map(|(_, t)| t)
        .collect();
    let (mut on_chain, mut others) = (Vec::new(), Vec::new());
    for (c, t) in components.iter().zip(&touches) {
        let chained = chains
            .iter()
            .any(|chain| t.iter().all(|i| chain.contains(i)));
        if !c.bodies.is_empty() && chained {
            on_chain.push(c);
        } else {
            others.push(c);
        }
    }
    (on_chain, others)
}

/// Each body's velocity and angular velocity, `[v, w]` (frame axes), in
/// order.
fn twists(bodies: &[Body]) -> Vec<Id> {
    bodies
        .iter()
        .flat_map(|b| b.velocity.into_iter().chain(b.omega))
        .collect()
}

/// `I w` of a body (zero for a point mass).
fn angular_momentum(g: &mut Graph, b: &Body, w: [Id; 3]) -> [Id; 3] {
    match &b.inertia {
        Some(inertia) => g.rotate(inertia, w),
        None => [g.constant(0.0); 3],
    }
}

/// The bodies' momenta `p = sum_b J_b^T (m v, I w)`, `J_b = d(v, w)/dqd`:
/// one reverse sweep over the velocities, weighted by the body momenta.
fn body_momenta(g: &mut Graph, bodies: &[Body], qd_vars: &[Symbol]) -> Vec<Id> {
    let mut weights = Vec::with_capacity(6 * bodies.len());
    for b in bodies {
        let linear: [Id; 3] = std::array::from_fn(|k| g.mul(b.mass, b.velocity[k]));
        let angular = angular_momentum(g, b, b.omega);
        weights.extend(linear.into_iter().chain(angular));
    }
    let outputs = twists(bodies);
    g.vjp(&outputs, &weights, qd_vars)
}

/// Lagrange's terms `d/dt dT/dqd - dT/dq` of the bodies, as Newton-Euler
/// forces. For a body with `T = (m v.v + w.I w) / 2` (`v`, `w` in the axes
/// of a frame turning at `w`, `I` constant there):
///
/// ```text
/// d/dt dT/dqd - dT/dq = J_v^T m (v' + w x v) + J_w^T (I w' + w x I w)
/// ```
///
/// with `J_v = dv/dqd`, `J_w = dw/dqd` and `'` the time derivative along the
/// motion: the virtual work of the body's inertial forces (`v' + w x v` is
/// the acceleration of the centre in the turning axes, `I w' + w x I w`
/// Euler's). The rates come from one forward sweep over all velocities
/// (`motion` the tangent `q' = qd, qd' = qdd, t' = 1`, or `None` for zero
/// accelerations) and the projection by one reverse sweep weighted by the
/// forces: the recursive Newton-Euler algorithm's forward and backward
/// passes, written on the graph.
fn newton_euler(
    g: &mut Graph,
    bodies: &[Body],
    qd_vars: &[Symbol],
    motion: Option<&[(Symbol, Id)]>,
) -> Vec<Id> {
    let outputs = twists(bodies);
    let rates = match motion {
        Some(motion) => g.jvp(&outputs, motion),
        None => g.time_derivative_at_zero_acceleration(&outputs),
    };
    let mut weights = Vec::with_capacity(outputs.len());
    for (b, rate) in bodies.iter().zip(rates.chunks(6)) {
        let (v, w) = (b.velocity, b.omega);
        let w_x_v = g.cross(w, v);
        let linear: [Id; 3] = std::array::from_fn(|k| {
            let a = g.add(rate[k], w_x_v[k]);
            g.mul(b.mass, a)
        });
        let w_rate = [rate[3], rate[4], rate[5]];
        let i_w_rate = angular_momentum(g, b, w_rate);
        let i_w = angular_momentum(g, b, w);
        let gyro = g.cross(w, i_w);
        let angular: [Id; 3] = std::array::from_fn(|k| g.add(i_w_rate[k], gyro[k]));
        weights.extend(linear.into_iter().chain(angular));
    }
    g.vjp(&outputs, &weights, qd_vars)
}

/// Indices of the coordinates an expression touches (through `q` or `qd`).
fn touched(g: &Graph, e: Id) -> Vec<usize> {
    let mut out: Vec<usize> = g
        .symbols(&[e])
        .into_iter()
        .filter_map(|s| match s {
            Symbol::Q(i) | Symbol::Qd(i) => Some(i as usize),
            _ => None,
        })
        .collect();
    out.sort_unstable();
    out.dedup();
    out
}

fn uses_velocity(g: &Graph, e: Id) -> bool {
    g.symbols(&[e]).iter().any(|s| matches!(s, Symbol::Qd(_)))
}

/// The Christoffel form `C_ij = sum_k G_ijk qd_k` with
/// `G_ijk = (dM_ij/dq_k + dM_ik/dq_j - dM_jk/dq_i) / 2`.
pub(crate) fn christoffel(g: &mut Graph, mass: &[Vec<Id>]) -> Vec<Vec<Id>> {
    let n = mass.len();
    let flat: Vec<Id> = mass.iter().flatten().copied().collect();
    // dm[k][i*n + j] = dM_ij / dq_k
    let dm: Vec<Vec<Id>> = (0..n)
        .map(|k| g.diff_many(&flat, Symbol::Q(k as u32)))
        .collect();
    (0..n)
        .map(|i| {
            (0..n)
                .map(|j| {
                    let mut terms = Vec::new();
                    for k in 0..n {
                        let a = g.add(dm[k][i * n + j], dm[j][i * n + k]);
                        let s = g.sub(a, dm[i][j * n + k]);
                        let qd = g.qd(k);
                        let t = g.mul(s, qd);
                        terms.push((t, 0.5));
                    }
                    g.linear(&terms, 0.0)
                })
                .collect()
        })
        .collect()
}

/// The error for a mass matrix that depends on velocities: the first
/// component whose kinetic energy has a second derivative in two velocities
/// that does (the generated `mass_matrix` has no velocities to read).
fn not_quadratic(
    g: &mut Graph,
    components: &[Component],
    coordinates: &[Coordinate],
) -> DeriveError {
    for c in components {
        let velocities: Vec<u32> = g
            .symbols(&[c.kinetic])
            .into_iter()
            .filter_map(|s| match s {
                Symbol::Qd(i) => Some(i),
                _ => None,
            })
            .collect();
        for &i in &velocities {
            let di = g.diff(c.kinetic, Symbol::Qd(i));
            for &j in &velocities {
                let dij = g.diff(di, Symbol::Qd(j));
                if uses_velocity(g, dij) {
                    return DeriveError {
                        context: format!("component `{}`", c.name),
                        message: format!(
                            "the kinetic energy is not quadratic in the velocities: its second \
                             derivative in the velocities of `{}` and `{}` (an entry of the mass \
                             matrix) depends on velocities; a kinetic energy has the form \
                             qd.M(q, t).qd / 2 + b(q, t).qd + T0(q, t)",
                            coordinates[i as usize].name, coordinates[j as usize].name
                        ),
                    };
                }
            }
        }
    }
    DeriveError {
        context: "kinetic energy".into(),
        message: "the kinetic energy is not quadratic in the velocities (the mass matrix \
                  depends on them)"
            .into(),
    }
}

/// The Christoffel form needs `T = qd^T M(q) qd / 2`: no explicit time, no
/// terms linear or constant in `qd`. Checked numerically (`T(2 qd) = 4 T(qd)`)
/// and structurally (no `t`).
fn check_quadratic_kinetic(
    g: &Graph,
    kinetic: Id,
    params: &[crate::model::RuntimeParameter],
) -> Result<(), DeriveError> {
    let fail = |message: &str| DeriveError {
        context: "output `coriolis_matrix`".into(),
        message: message.into(),
    };
    if g.symbols(&[kinetic]).contains(&Symbol::Time) {
        return Err(fail(
            "the kinetic energy depends explicitly on time; the Christoffel form does not apply",
        ));
    }
    for trial in 0..3u32 {
        let value = |scale: f64| {
            g.eval(&[kinetic], &|s| match s {
                Symbol::Q(i) => 0.3 + 0.17 * f64::from(i + trial),
                Symbol::Qd(i) => scale * (0.5 - 0.23 * f64::from((i * 7 + trial) % 5)),
                Symbol::Time | Symbol::Qdd(_) => 0.0,
                Symbol::Param(i) => params[i as usize].value,
            })[0]
        };
        let (t1, t2) = (value(1.0), value(2.0));
        if (t2 - 4.0 * t1).abs() > 1e-9 * (t2.abs() + 4.0 * t1.abs()).max(1e-300) {
            return Err(fail(
                "the kinetic energy is not a quadratic form in the velocities; the Christoffel form does not apply",
            ));
        }
    }
    Ok(())
}
