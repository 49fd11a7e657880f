//! Scene models behind one object-safe interface of run-time size, for
//! tools that pick a scene at run time (the command line, validation):
//! compiled ones ([`erase`]) and interpreted ones ([`crate::interpreted`]).
//!
//! Every method writes into storage the caller owns and sized (column-major
//! slices: `nq` entries for a vector of coordinates, `nq * nq` for `M`, `nc
//! * nq` for `Phi_q`, ...), so a solver that sizes its storage once
//! allocates nothing per call. `dyn DynModel` is the runtime's
//! [`Equations`] over run-time dimensions (`Dyn`), so every runtime solver
//! (integrators, projection, control) runs on any scene file without
//! padding; real-time code uses the generated types and
//! [`flexdyn_runtime::Model`] directly.

pub use flexdyn_codegen::interpret::Function;
use flexdyn_runtime::{Equations, Model};
use nalgebra::{DMatrix, DVector, Dyn, SMatrix, SVector};

/// The arguments of a function of the table: positions, velocities,
/// accelerations (each empty where the function does not read it) and time.
#[derive(Debug, Clone, Copy)]
pub struct At<'a> {
    /// Positions (`nq`).
    pub q: &'a [f64],
    /// Velocities (`nq`, or empty).
    pub qd: &'a [f64],
    /// Accelerations (`nq`, or empty).
    pub qdd: &'a [f64],
    /// Time.
    pub t: f64,
}

impl<'a> At<'a> {
    /// At positions `q` and time `t`.
    pub fn q(q: &'a [f64], t: f64) -> At<'a> {
        At {
            q,
            qd: &[],
            qdd: &[],
            t,
        }
    }

    /// At positions `q`, velocities `qd` and time `t`.
    pub fn qd(q: &'a [f64], qd: &'a [f64], t: f64) -> At<'a> {
        At { q, qd, qdd: &[], t }
    }

    /// At positions, velocities, accelerations and time.
    pub fn qdd(q: &'a [f64], qd: &'a [f64], qdd: &'a [f64], t: f64) -> At<'a> {
        At { q, qd, qdd, t }
    }
}

/// A generated model with its dimensions erased.
///
/// An implementation gives the scene's names and sizes and one evaluation,
/// [`DynModel::call`], of any function of the generator's table
/// ([`Function`]); the typed methods (`mass_matrix`, `bias`, ...) are that
/// call with the function's arguments and outputs named, written once here.
pub trait DynModel {
    /// Scene name.
    fn name(&self) -> &str;
    /// Coordinate names.
    fn coordinates(&self) -> Vec<&str>;
    /// Actuator names.
    fn actuators(&self) -> Vec<&str>;
    /// Number of coordinates.
    fn nq(&self) -> usize {
        self.coordinates().len()
    }
    /// Number of constraints.
    fn nc(&self) -> usize;
    /// Number of actuators.
    fn nu(&self) -> usize {
        self.actuators().len()
    }
    /// Names of the runtime parameters.
    fn parameters(&self) -> Vec<&str>;
    /// Set a runtime parameter; `false` if there is none of that name.
    fn set_parameter(&mut self, name: &str, value: f64) -> bool;
    /// Marker names, in index order.
    fn markers(&self) -> Vec<&str>;

    /// Evaluates function `f` of the table (for marker `marker` when it is
    /// a per-marker function, else `None`) at `at`, writing its outputs, in
    /// the table's order, to `outs` (each column-major and as long as its
    /// output; a scalar is one entry). `false`, nothing written, when the
    /// scene does not generate `f` or has no such marker.
    ///
    /// # Panics
    ///
    /// When `outs` or the arguments do not have the function's shapes.
    fn call(&self, f: Function, marker: Option<usize>, at: At<'_>, outs: &mut [&mut [f64]])
        -> bool;

    /// Mass matrix (`nq x nq`).
    fn mass_matrix(&self, q: &[f64], t: f64, m: &mut [f64]) {
        core(self, Function::MassMatrix, At::q(q, t), &mut [m])
    }
    /// Bias forces (`nq`).
    fn bias(&self, q: &[f64], qd: &[f64], t: f64, h: &mut [f64]) {
        core(self, Function::Bias, At::qd(q, qd, t), &mut [h])
    }
    /// Constraint residuals (`nc`).
    fn constraints(&self, q: &[f64], t: f64, phi: &mut [f64]) {
        core(self, Function::Constraints, At::q(q, t), &mut [phi])
    }
    /// Constraint Jacobian (`nc x nq`).
    fn constraint_jacobian(&self, q: &[f64], t: f64, phi_q: &mut [f64]) {
        core(
            self,
            Function::ConstraintJacobian,
            At::q(q, t),
            &mut [phi_q],
        )
    }
    /// Explicit time derivative of the constraints (`nc`).
    fn constraint_time_derivative(&self, q: &[f64], t: f64, phi_t: &mut [f64]) {
        let f = Function::ConstraintTimeDerivative;
        core(self, f, At::q(q, t), &mut [phi_t])
    }
    /// Acceleration right-hand side (`nc`).
    fn constraint_rhs(&self, q: &[f64], qd: &[f64], t: f64, gamma: &mut [f64]) {
        core(
            self,
            Function::ConstraintRhs,
            At::qd(q, qd, t),
            &mut [gamma],
        )
    }
    /// `Phi` and `Phi_q` from the fused `constraints_and_jacobian` program.
    fn constraints_and_jacobian(&self, q: &[f64], t: f64, phi: &mut [f64], phi_q: &mut [f64]) {
        let f = Function::ConstraintsAndJacobian;
        core(self, f, At::q(q, t), &mut [phi, phi_q])
    }
    /// `M`, `h`, `Phi_q` and `gamma` from the fused `dynamics_terms` program.
    fn dynamics_terms(&self, q: &[f64], qd: &[f64], t: f64, out: Fused<'_>) {
        let outs: &mut [&mut [f64]] = &mut [out.m, out.h, out.phi_q, out.gamma];
        core(self, Function::DynamicsTerms, At::qd(q, qd, t), outs)
    }
    /// Inverse dynamics `M qdd + h` (`nq`).
    fn inverse_dynamics(&self, q: &[f64], qd: &[f64], qdd: &[f64], t: f64, tau: &mut [f64]) {
        let at = At::qdd(q, qd, qdd, t);
        core(self, Function::InverseDynamics, at, &mut [tau])
    }
    /// Actuator map (`nq x nu`).
    fn actuator_map(&self, b: &mut [f64]) {
        core(self, Function::ActuatorMap, At::q(&[], 0.0), &mut [b])
    }
    /// The actuators' generalized forces `B tau` (`nq`) for the inputs
    /// `tau` (`nu`, in the place of the accelerations); `false` where the
    /// model does not compute them itself (an interpreted one: the runtime
    /// forms `B tau` from the actuator map).
    fn actuator_forces(&self, tau: &[f64], f: &mut [f64]) -> bool {
        let at = At::qdd(&[], &[], tau, 0.0);
        self.call(Function::ActuatorForces, None, at, &mut [f])
    }
    /// Kinetic energy.
    fn kinetic_energy(&self, q: &[f64], qd: &[f64], t: f64) -> f64 {
        let mut v = [0.0];
        core(
            self,
            Function::KineticEnergy,
            At::qd(q, qd, t),
            &mut [&mut v],
        );
        v[0]
    }
    /// Potential energy.
    fn potential_energy(&self, q: &[f64], t: f64) -> f64 {
        let mut v = [0.0];
        core(self, Function::PotentialEnergy, At::q(q, t), &mut [&mut v]);
        v[0]
    }
    /// Coriolis forces (`nq`); `false` (nothing written) when not generated.
    fn coriolis_forces(&self, q: &[f64], qd: &[f64], t: f64, out: &mut [f64]) -> bool {
        self.call(Function::CoriolisForces, None, At::qd(q, qd, t), &mut [out])
    }
    /// Gravity and elastic forces (`nq`), when generated.
    fn potential_forces(&self, q: &[f64], t: f64, out: &mut [f64]) -> bool {
        self.call(Function::PotentialForces, None, At::q(q, t), &mut [out])
    }
    /// Damping forces (`nq`), when generated.
    fn damping_forces(&self, q: &[f64], qd: &[f64], t: f64, out: &mut [f64]) -> bool {
        self.call(Function::DampingForces, None, At::qd(q, qd, t), &mut [out])
    }
    /// Coriolis matrix (`nq x nq`), when generated.
    fn coriolis_matrix(&self, q: &[f64], qd: &[f64], t: f64, out: &mut [f64]) -> bool {
        self.call(Function::CoriolisMatrix, None, At::qd(q, qd, t), &mut [out])
    }
    /// Bias-force Jacobians `dh/dq`, `dh/dqd` (each `nq x nq`), when generated.
    fn bias_jacobians(
        &self,
        q: &[f64],
        qd: &[f64],
        t: f64,
        h_q: &mut [f64],
        h_qd: &mut [f64],
    ) -> bool {
        let f = Function::BiasJacobians;
        self.call(f, None, At::qd(q, qd, t), &mut [h_q, h_qd])
    }
    /// Inverse dynamics and its derivatives `d tau/dq`, `d tau/dqd` at
    /// `qdd` (each `nq x nq`), when generated.
    fn inverse_dynamics_derivatives(
        &self,
        q: &[f64],
        qd: &[f64],
        qdd: &[f64],
        t: f64,
        out: IdDerivatives<'_>,
    ) -> bool {
        let f = Function::InverseDynamicsDerivatives;
        let outs: &mut [&mut [f64]] = &mut [out.tau, out.tau_q, out.tau_qd];
        self.call(f, None, At::qdd(q, qd, qdd, t), outs)
    }
    /// Derivatives `da/dq`, `da/dqd` (each `nc x nq`) of the acceleration
    /// constraint `a = Phi_q qdd - gamma`, when generated.
    fn constraint_acceleration_derivatives(
        &self,
        q: &[f64],
        qd: &[f64],
        qdd: &[f64],
        t: f64,
        a_q: &mut [f64],
        a_qd: &mut [f64],
    ) -> bool {
        let f = Function::ConstraintAccelerationDerivatives;
        self.call(f, None, At::qdd(q, qd, qdd, t), &mut [a_q, a_qd])
    }
    /// Forward dynamics `qdd = M^-1 (f - h)` of an unconstrained scene for
    /// the generalized forces `f`, with the pivots `d` of `M = L^T D L`
    /// relative to `M`'s diagonal (valid where all are above epsilon), when
    /// generated.
    fn forward_dynamics(
        &self,
        q: &[f64],
        qd: &[f64],
        f: &[f64],
        t: f64,
        qdd: &mut [f64],
        d: &mut [f64],
    ) -> bool {
        self.call(
            Function::ForwardDynamics,
            None,
            At::qdd(q, qd, f, t),
            &mut [qdd, d],
        )
    }
    /// [`DynModel::forward_dynamics`] with the derivatives of `qdd`: `d
    /// qdd/dq`, `d qdd/dqd` at the forces `f` and `d qdd/df = M^-1` (each
    /// `nq x nq`), when generated.
    fn forward_dynamics_derivatives(
        &self,
        q: &[f64],
        qd: &[f64],
        f: &[f64],
        t: f64,
        out: FdDerivatives<'_>,
    ) -> bool {
        let outs: &mut [&mut [f64]] = &mut [out.qdd, out.d, out.qdd_q, out.qdd_qd, out.qdd_f];
        self.call(
            Function::ForwardDynamicsDerivatives,
            None,
            At::qdd(q, qd, f, t),
            outs,
        )
    }
    /// Position (3) and rotation (3 x 3) of marker `marker`; `false`
    /// (nothing written) when there is no such marker.
    fn marker_pose(
        &self,
        marker: usize,
        q: &[f64],
        t: f64,
        position: &mut [f64],
        rotation: &mut [f64],
    ) -> bool {
        let outs: &mut [&mut [f64]] = &mut [position, rotation];
        self.call(Function::MarkerPose, Some(marker), At::q(q, t), outs)
    }
    /// Position, rotation and Jacobian (6 x nq) of marker `marker`.
    fn marker_jacobian(&self, marker: usize, q: &[f64], t: f64, out: MarkerPose<'_>) -> bool {
        let outs: &mut [&mut [f64]] = &mut [out.position, out.rotation, out.jacobian];
        self.call(Function::MarkerJacobian, Some(marker), At::q(q, t), outs)
    }
    /// Velocity (6) and acceleration bias (6) of marker `marker`.
    fn marker_motion(
        &self,
        marker: usize,
        q: &[f64],
        qd: &[f64],
        t: f64,
        velocity: &mut [f64],
        acceleration_bias: &mut [f64],
    ) -> bool {
        let outs: &mut [&mut [f64]] = &mut [velocity, acceleration_bias];
        self.call(Function::MarkerMotion, Some(marker), At::qd(q, qd, t), outs)
    }
}

/// [`DynModel::call`] of a function every scene generates.
fn core<M: DynModel + ?Sized>(model: &M, f: Function, at: At<'_>, outs: &mut [&mut [f64]]) {
    let done = model.call(f, None, at, outs);
    assert!(done, "`{}` is generated for every scene", f.name());
}

/// Where `marker_jacobian` writes `(position, rotation, jacobian)`.
pub struct MarkerPose<'a> {
    /// Position (3).
    pub position: &'a mut [f64],
    /// Rotation (3 x 3).
    pub rotation: &'a mut [f64],
    /// Jacobian (6 x nq).
    pub jacobian: &'a mut [f64],
}

/// Where `inverse_dynamics_derivatives` writes `(tau, tau_q, tau_qd)`.
pub struct IdDerivatives<'a> {
    /// `tau = M qdd + h` (`nq`).
    pub tau: &'a mut [f64],
    /// `d tau / d q` (`nq x nq`).
    pub tau_q: &'a mut [f64],
    /// `d tau / d qd` (`nq x nq`).
    pub tau_qd: &'a mut [f64],
}

/// Where `forward_dynamics_derivatives` writes `(qdd, d, qdd_q, qdd_qd,
/// qdd_f)`.
pub struct FdDerivatives<'a> {
    /// `qdd = M^-1 (f - h)` (`nq`).
    pub qdd: &'a mut [f64],
    /// The pivots of `M = L^T D L` relative to `M`'s diagonal (`nq`).
    pub d: &'a mut [f64],
    /// `d qdd / d q` (`nq x nq`).
    pub qdd_q: &'a mut [f64],
    /// `d qdd / d qd` (`nq x nq`).
    pub qdd_qd: &'a mut [f64],
    /// `d qdd / d f = M^-1` (`nq x nq`).
    pub qdd_f: &'a mut [f64],
}

/// Where `dynamics_terms` writes `(M, h, Phi_q, gamma)`.
pub struct Fused<'a> {
    /// `M` (`nq x nq`).
    pub m: &'a mut [f64],
    /// `h` (`nq`).
    pub h: &'a mut [f64],
    /// `Phi_q` (`nc x nq`).
    pub phi_q: &'a mut [f64],
    /// `gamma` (`nc`).
    pub gamma: &'a mut [f64],
}

/// A fresh `rows x cols` matrix filled by `f` (for callers that keep the
/// result, e.g. evaluation to JSON).
pub fn matrix(rows: usize, cols: usize, f: impl FnOnce(&mut [f64])) -> DMatrix<f64> {
    let mut m = DMatrix::zeros(rows, cols);
    f(m.as_mut_slice());
    m
}

/// A fresh vector of `n` entries filled by `f`.
pub fn vector(n: usize, f: impl FnOnce(&mut [f64])) -> DVector<f64> {
    let mut v = DVector::zeros(n);
    f(v.as_mut_slice());
    v
}

/// What a failed factorisation of the mass matrix says about `model`'s
/// coordinates: `" (coordinate `c`: ...)"` for a pivot that is not positive,
/// empty for any other error.
pub fn no_mass_hint(model: &dyn DynModel, e: &flexdyn_runtime::Error) -> String {
    match e.kind {
        flexdyn_runtime::ErrorKind::MassMatrixNotPositiveDefinite { pivot, .. } => model
            .coordinates()
            .get(pivot)
            .map(|c| {
                format!(
                    " (coordinate `{c}`: no mass or inertia moves with it apart from the \
                     coordinates before it)"
                )
            })
            .unwrap_or_default(),
        _ => String::new(),
    }
}

/// A model with its dimensions as const parameters.
pub struct Erased<M, const NQ: usize, const NC: usize, const NU: usize>(pub M);

/// Wrap a model for dynamic use.
pub fn erase<M, const NQ: usize, const NC: usize, const NU: usize>(model: M) -> Box<dyn DynModel>
where
    M: Model<NQ, NC, NU> + 'static,
{
    Box::new(Erased::<M, NQ, NC, NU>(model))
}

/// A fixed-size vector from `N` values (a wrong length is a caller bug).
fn fixed<const N: usize>(x: &[f64]) -> SVector<f64, N> {
    assert_eq!(x.len(), N, "expected {N} values, got {}", x.len());
    SVector::from_column_slice(x)
}

/// Copies `from` (each output's values) to `outs`; `true`.
fn put(outs: &mut [&mut [f64]], from: &[&[f64]]) -> bool {
    assert_eq!(outs.len(), from.len(), "one storage per output");
    for (out, from) in outs.iter_mut().zip(from) {
        out.copy_from_slice(from);
    }
    true
}

impl<M, const NQ: usize, const NC: usize, const NU: usize> DynModel for Erased<M, NQ, NC, NU>
where
    M: Model<NQ, NC, NU>,
{
    fn name(&self) -> &str {
        M::NAME
    }
    fn coordinates(&self) -> Vec<&str> {
        M::COORDINATES.to_vec()
    }
    fn actuators(&self) -> Vec<&str> {
        M::ACTUATORS.to_vec()
    }
    fn nc(&self) -> usize {
        NC
    }
    fn parameters(&self) -> Vec<&str> {
        M::PARAMETERS.to_vec()
    }
    fn set_parameter(&mut self, name: &str, value: f64) -> bool {
        self.0.set_parameter(name, value)
    }
    fn markers(&self) -> Vec<&str> {
        M::MARKERS.to_vec()
    }

    /// The compiled module's method of each function: one arm each (a new
    /// function of the table does not compile until it has one).
    fn call(
        &self,
        f: Function,
        marker: Option<usize>,
        at: At<'_>,
        outs: &mut [&mut [f64]],
    ) -> bool {
        let m = &self.0;
        let t = at.t;
        let q = || fixed::<NQ>(at.q);
        let qd = || fixed::<NQ>(at.qd);
        let qdd = || fixed::<NQ>(at.qdd);
        let vector = SVector::<f64, NQ>::zeros;
        let square = SMatrix::<f64, NQ, NQ>::zeros;
        let rows = SVector::<f64, NC>::zeros;
        let jacobian = SMatrix::<f64, NC, NQ>::zeros;
        let (point, rotation) = (SVector::<f64, 3>::zeros, SMatrix::<f64, 3, 3>::zeros);
        match f {
            Function::MassMatrix => {
                let mut a = square();
                m.mass_matrix(&q(), t, &mut a);
                put(outs, &[a.as_slice()])
            }
            Function::Bias => {
                let mut h = vector();
                m.bias(&q(), &qd(), t, &mut h);
                put(outs, &[h.as_slice()])
            }
            Function::Constraints => {
                let mut c = rows();
                m.constraints(&q(), t, &mut c);
                put(outs, &[c.as_slice()])
            }
            Function::ConstraintJacobian => {
                let mut j = jacobian();
                m.constraint_jacobian(&q(), t, &mut j);
                put(outs, &[j.as_slice()])
            }
            Function::ConstraintsAndJacobian => {
                let (mut c, mut j) = (rows(), jacobian());
                m.constraints_and_jacobian(&q(), t, &mut c, &mut j);
                put(outs, &[c.as_slice(), j.as_slice()])
            }
            Function::ConstraintTimeDerivative => {
                let mut c = rows();
                m.constraint_time_derivative(&q(), t, &mut c);
                put(outs, &[c.as_slice()])
            }
            Function::ConstraintRhs => {
                let mut c = rows();
                m.constraint_rhs(&q(), &qd(), t, &mut c);
                put(outs, &[c.as_slice()])
            }
            Function::DynamicsTerms => {
                let (mut a, mut h, mut j, mut g) = (square(), vector(), jacobian(), rows());
                m.dynamics_terms(&q(), &qd(), t, &mut a, &mut h, &mut j, &mut g);
                put(
                    outs,
                    &[a.as_slice(), h.as_slice(), j.as_slice(), g.as_slice()],
                )
            }
            Function::InverseDynamics => {
                let mut tau = vector();
                m.inverse_dynamics(&q(), &qd(), &qdd(), t, &mut tau);
                put(outs, &[tau.as_slice()])
            }
            Function::ActuatorMap => {
                let mut b = SMatrix::<f64, NQ, NU>::zeros();
                m.actuator_map(&mut b);
                put(outs, &[b.as_slice()])
            }
            Function::ActuatorForces => {
                let mut f = vector();
                m.actuator_forces(&fixed::<NU>(at.qdd), &mut f) && put(outs, &[f.as_slice()])
            }
            Function::KineticEnergy => put(outs, &[&[m.kinetic_energy(&q(), &qd(), t)]]),
            Function::PotentialEnergy => put(outs, &[&[m.potential_energy(&q(), t)]]),
            Function::CoriolisForces => {
                let mut v = vector();
                m.coriolis_forces(&q(), &qd(), t, &mut v) && put(outs, &[v.as_slice()])
            }
            Function::PotentialForces => {
                let mut v = vector();
                m.potential_forces(&q(), t, &mut v) && put(outs, &[v.as_slice()])
            }
            Function::DampingForces => {
                let mut v = vector();
                m.damping_forces(&q(), &qd(), t, &mut v) && put(outs, &[v.as_slice()])
            }
            Function::CoriolisMatrix => {
                let mut a = square();
                m.coriolis_matrix(&q(), &qd(), t, &mut a) && put(outs, &[a.as_slice()])
            }
            Function::BiasJacobians => {
                let (mut a, mut b) = (square(), square());
                m.bias_jacobians(&q(), &qd(), t, &mut a, &mut b)
                    && put(outs, &[a.as_slice(), b.as_slice()])
            }
            Function::InverseDynamicsDerivatives => {
                let (mut tau, mut a, mut b) = (vector(), square(), square());
                m.inverse_dynamics_derivatives(&q(), &qd(), &qdd(), t, &mut tau, &mut a, &mut b)
                    && put(outs, &[tau.as_slice(), a.as_slice(), b.as_slice()])
            }
            Function::ConstraintAccelerationDerivatives => {
                let (mut a, mut b) = (jacobian(), jacobian());
                m.constraint_acceleration_derivatives(&q(), &qd(), &qdd(), t, &mut a, &mut b)
                    && put(outs, &[a.as_slice(), b.as_slice()])
            }
            Function::ForwardDynamics => {
                let (mut a, mut d) = (vector(), vector());
                m.forward_dynamics(&q(), &qd(), &qdd(), t, &mut a, &mut d)
                    && put(outs, &[a.as_slice(), d.as_slice()])
            }
            Function::ForwardDynamicsDerivatives => {
                let (mut a, mut d) = (vector(), vector());
                let (mut a_q, mut a_qd, mut a_f) = (square(), square(), square());
                let (q, qd, f) = (q(), qd(), qdd());
                let (d_q, d_qd, d_f) = (&mut a_q, &mut a_qd, &mut a_f);
                m.forward_dynamics_derivatives(&q, &qd, &f, t, &mut a, &mut d, d_q, d_qd, d_f)
                    && put(
                        outs,
                        &[
                            a.as_slice(),
                            d.as_slice(),
                            a_q.as_slice(),
                            a_qd.as_slice(),
                            a_f.as_slice(),
                        ],
                    )
            }
            Function::MarkerPose => marker.is_some_and(|k| {
                let (mut p, mut r) = (point(), rotation());
                m.marker_pose(k, &q(), t, &mut p, &mut r)
                    && put(outs, &[p.as_slice(), r.as_slice()])
            }),
            Function::MarkerJacobian => marker.is_some_and(|k| {
                let (mut p, mut r) = (point(), rotation());
                let mut j = SMatrix::<f64, 6, NQ>::zeros();
                m.marker_jacobian(k, &q(), t, &mut p, &mut r, &mut j)
                    && put(outs, &[p.as_slice(), r.as_slice(), j.as_slice()])
            }),
            Function::MarkerMotion => marker.is_some_and(|k| {
                let (mut v, mut a) = (SVector::<f64, 6>::zeros(), SVector::<f64, 6>::zeros());
                m.marker_motion(k, &q(), &qd(), t, &mut v, &mut a)
                    && put(outs, &[v.as_slice(), a.as_slice()])
            }),
        }
    }
}

/// Any model as the runtime's equations over run-time dimensions: the
/// solvers size their storage from [`Equations::sizes`] and every call
/// writes into it.
impl Equations<Dyn, Dyn, Dyn> for dyn DynModel + '_ {
    fn sizes(&self) -> (Dyn, Dyn, Dyn) {
        (Dyn(self.nq()), Dyn(self.nc()), Dyn(self.nu()))
    }
    fn mass_matrix(&self, q: &DVector<f64>, t: f64, m: &mut DMatrix<f64>) {
        DynModel::mass_matrix(self, q.as_slice(), t, m.as_mut_slice())
    }
    fn bias(&self, q: &DVector<f64>, qd: &DVector<f64>, t: f64, h: &mut DVector<f64>) {
        DynModel::bias(self, q.as_slice(), qd.as_slice(), t, h.as_mut_slice())
    }
    fn constraints(&self, q: &DVector<f64>, t: f64, phi: &mut DVector<f64>) {
        DynModel::constraints(self, q.as_slice(), t, phi.as_mut_slice())
    }
    fn constraint_jacobian(&self, q: &DVector<f64>, t: f64, phi_q: &mut DMatrix<f64>) {
        DynModel::constraint_jacobian(self, q.as_slice(), t, phi_q.as_mut_slice())
    }
    fn constraint_time_derivative(&self, q: &DVector<f64>, t: f64, phi_t: &mut DVector<f64>) {
        DynModel::constraint_time_derivative(self, q.as_slice(), t, phi_t.as_mut_slice())
    }
    fn constraint_rhs(
        &self,
        q: &DVector<f64>,
        qd: &DVector<f64>,
        t: f64,
        gamma: &mut DVector<f64>,
    ) {
        DynModel::constraint_rhs(self, q.as_slice(), qd.as_slice(), t, gamma.as_mut_slice())
    }
    fn actuator_map(&self, b: &mut DMatrix<f64>) {
        DynModel::actuator_map(self, b.as_mut_slice())
    }
    fn actuator_forces(&self, tau: &DVector<f64>, f: &mut DVector<f64>) -> bool {
        DynModel::actuator_forces(self, tau.as_slice(), f.as_mut_slice())
    }
    fn kinetic_energy(&self, q: &DVector<f64>, qd: &DVector<f64>, t: f64) -> f64 {
        DynModel::kinetic_energy(self, q.as_slice(), qd.as_slice(), t)
    }
    fn potential_energy(&self, q: &DVector<f64>, t: f64) -> f64 {
        DynModel::potential_energy(self, q.as_slice(), t)
    }
    fn bias_jacobians(
        &self,
        q: &DVector<f64>,
        qd: &DVector<f64>,
        t: f64,
        h_q: &mut DMatrix<f64>,
        h_qd: &mut DMatrix<f64>,
    ) -> bool {
        DynModel::bias_jacobians(
            self,
            q.as_slice(),
            qd.as_slice(),
            t,
            h_q.as_mut_slice(),
            h_qd.as_mut_slice(),
        )
    }
    fn inverse_dynamics_derivatives(
        &self,
        q: &DVector<f64>,
        qd: &DVector<f64>,
        qdd: &DVector<f64>,
        t: f64,
        tau: &mut DVector<f64>,
        tau_q: &mut DMatrix<f64>,
        tau_qd: &mut DMatrix<f64>,
    ) -> bool {
        let out = IdDerivatives {
            tau: tau.as_mut_slice(),
            tau_q: tau_q.as_mut_slice(),
            tau_qd: tau_qd.as_mut_slice(),
        };
        let (q, qd, qdd) = (q.as_slice(), qd.as_slice(), qdd.as_slice());
        DynModel::inverse_dynamics_derivatives(self, q, qd, qdd, t, out)
    }
    fn constraint_acceleration_derivatives(
        &self,
        q: &DVector<f64>,
        qd: &DVector<f64>,
        qdd: &DVector<f64>,
        t: f64,
        a_q: &mut DMatrix<f64>,
        a_qd: &mut DMatrix<f64>,
    ) -> bool {
        let (q, qd, qdd) = (q.as_slice(), qd.as_slice(), qdd.as_slice());
        let (a_q, a_qd) = (a_q.as_mut_slice(), a_qd.as_mut_slice());
        DynModel::constraint_acceleration_derivatives(self, q, qd, qdd, t, a_q, a_qd)
    }
    fn forward_dynamics(
        &self,
        q: &DVector<f64>,
        qd: &DVector<f64>,
        f: &DVector<f64>,
        t: f64,
        qdd: &mut DVector<f64>,
        d: &mut DVector<f64>,
    ) -> bool {
        let (q, qd, f) = (q.as_slice(), qd.as_slice(), f.as_slice());
        DynModel::forward_dynamics(self, q, qd, f, t, qdd.as_mut_slice(), d.as_mut_slice())
    }
    fn forward_dynamics_derivatives(
        &self,
        q: &DVector<f64>,
        qd: &DVector<f64>,
        f: &DVector<f64>,
        t: f64,
        qdd: &mut DVector<f64>,
        d: &mut DVector<f64>,
        qdd_q: &mut DMatrix<f64>,
        qdd_qd: &mut DMatrix<f64>,
        qdd_f: &mut DMatrix<f64>,
    ) -> bool {
        let out = FdDerivatives {
            qdd: qdd.as_mut_slice(),
            d: d.as_mut_slice(),
            qdd_q: qdd_q.as_mut_slice(),
            qdd_qd: qdd_qd.as_mut_slice(),
            qdd_f: qdd_f.as_mut_slice(),
        };
        let (q, qd, f) = (q.as_slice(), qd.as_slice(), f.as_slice());
        DynModel::forward_dynamics_derivatives(self, q, qd, f, t, out)
    }
    fn constraints_and_jacobian(
        &self,
        q: &DVector<f64>,
        t: f64,
        phi: &mut DVector<f64>,
        phi_q: &mut DMatrix<f64>,
    ) {
        DynModel::constraints_and_jacobian(
            self,
            q.as_slice(),
            t,
            phi.as_mut_slice(),
            phi_q.as_mut_slice(),
        )
    }
    fn dynamics_terms(
        &self,
        q: &DVector<f64>,
        qd: &DVector<f64>,
        t: f64,
        m: &mut DMatrix<f64>,
        h: &mut DVector<f64>,
        phi_q: &mut DMatrix<f64>,
        gamma: &mut DVector<f64>,
    ) {
        let out = Fused {
            m: m.as_mut_slice(),
            h: h.as_mut_slice(),
            phi_q: phi_q.as_mut_slice(),
            gamma: gamma.as_mut_slice(),
        };
        DynModel::dynamics_terms(self, q.as_slice(), qd.as_slice(), t, out)
    }
    fn inverse_dynamics(
        &self,
        q: &DVector<f64>,
        qd: &DVector<f64>,
        qdd: &DVector<f64>,
        t: f64,
        tau: &mut DVector<f64>,
    ) {
        DynModel::inverse_dynamics(
            self,
            q.as_slice(),
            qd.as_slice(),
            qdd.as_slice(),
            t,
            tau.as_mut_slice(),
        )
    }
}

#[cfg(test)]
mod tests {
    use flexdyn_runtime::{
        accelerations, project, DynamicsConfig, GeneralizedAlpha, GeneralizedAlphaConfig,
        GeneralizedAlphaOf, IntegratorOf, ProjectionConfig, State, StateOf, StepSettings,
    };
    use nalgebra::SVector;

    use super::*;

    /// The runtime's solvers over run-time sizes (`dyn DynModel`, `Dyn`)
    /// give bitwise the numbers they give over the compiled model's fixed
    /// sizes: the accelerations at a state, the projection onto the
    /// constraints and 50 generalized-alpha steps of the slider-crank (3
    /// coordinates, 2 constraints, 1 actuator).
    #[test]
    fn run_time_sizes_give_the_fixed_sizes_bits() {
        let model = crate::scenes::slider_crank::SliderCrank;
        let dynamic = erase(model);
        let dynamic: &dyn DynModel = &*dynamic;
        let (q, qd) = ([0.4, 0.1, 0.3], [1.0, -0.5, 0.2]);
        let cfg = DynamicsConfig::default();
        let tau = SVector::<f64, 1>::new(0.3);
        let fixed = accelerations(&model, &cfg, &q.into(), &qd.into(), 0.2, &tau).unwrap();
        let (dq, dqd) = (DVector::from_row_slice(&q), DVector::from_row_slice(&qd));
        let dtau = DVector::from_element(1, 0.3);
        let run_time = accelerations(dynamic, &cfg, &dq, &dqd, 0.2, &dtau).unwrap();
        assert_eq!(fixed.qdd.as_slice(), run_time.qdd.as_slice());
        assert_eq!(fixed.lambda.as_slice(), run_time.lambda.as_slice());

        let mut s = State::<3>::new(q.into(), qd.into(), 0.0);
        let mut d = StateOf::new(dq, dqd, 0.0);
        let pc = ProjectionConfig::default();
        project(&model, &mut s, &pc).unwrap();
        project(dynamic, &mut d, &pc).unwrap();
        let settings = StepSettings::with_projection();
        let mut g = GeneralizedAlpha::<3, 2>::new(settings, GeneralizedAlphaConfig::default());
        let mut h = GeneralizedAlphaOf::new(settings, GeneralizedAlphaConfig::default());
        for _ in 0..50 {
            g.step(&model, &mut s, &tau, 1e-3).unwrap();
            h.step(dynamic, &mut d, &dtau, 1e-3).unwrap();
        }
        assert!(s.q.as_slice() != q.as_slice(), "the crank moves");
        assert_eq!(
            (s.q.as_slice(), s.qd.as_slice()),
            (d.q.as_slice(), d.qd.as_slice())
        );
    }
}
