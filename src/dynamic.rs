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

use flexdyn_runtime::{Equations, Model};
use nalgebra::{DMatrix, DVector, Dyn, SMatrix, SVector};

/// A generated model with its dimensions erased.
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
    /// Mass matrix (`nq x nq`).
    fn mass_matrix(&self, q: &[f64], t: f64, m: &mut [f64]);
    /// Bias forces (`nq`).
    fn bias(&self, q: &[f64], qd: &[f64], t: f64, h: &mut [f64]);
    /// Constraint residuals (`nc`).
    fn constraints(&self, q: &[f64], t: f64, phi: &mut [f64]);
    /// Constraint Jacobian (`nc x nq`).
    fn constraint_jacobian(&self, q: &[f64], t: f64, phi_q: &mut [f64]);
    /// Explicit time derivative of the constraints (`nc`).
    fn constraint_time_derivative(&self, q: &[f64], t: f64, phi_t: &mut [f64]);
    /// Acceleration right-hand side (`nc`).
    fn constraint_rhs(&self, q: &[f64], qd: &[f64], t: f64, gamma: &mut [f64]);
    /// `Phi` and `Phi_q` from the fused `constraints_and_jacobian` program.
    fn constraints_and_jacobian(&self, q: &[f64], t: f64, phi: &mut [f64], phi_q: &mut [f64]);
    /// `M`, `h`, `Phi_q` and `gamma` from the fused `dynamics_terms` program.
    fn dynamics_terms(&self, q: &[f64], qd: &[f64], t: f64, out: Fused<'_>);
    /// Inverse dynamics `M qdd + h` (`nq`).
    fn inverse_dynamics(&self, q: &[f64], qd: &[f64], qdd: &[f64], t: f64, tau: &mut [f64]);
    /// Actuator map (`nq x nu`).
    fn actuator_map(&self, b: &mut [f64]);
    /// Kinetic energy.
    fn kinetic_energy(&self, q: &[f64], qd: &[f64], t: f64) -> f64;
    /// Potential energy.
    fn potential_energy(&self, q: &[f64], t: f64) -> f64;
    /// Names of the runtime parameters.
    fn parameters(&self) -> Vec<&str>;
    /// Set a runtime parameter; `false` if there is none of that name.
    fn set_parameter(&mut self, name: &str, value: f64) -> bool;
    /// Coriolis forces (`nq`); `false` (nothing written) when not generated.
    fn coriolis_forces(&self, q: &[f64], qd: &[f64], t: f64, out: &mut [f64]) -> bool;
    /// Gravity and elastic forces (`nq`), when generated.
    fn potential_forces(&self, q: &[f64], t: f64, out: &mut [f64]) -> bool;
    /// Damping forces (`nq`), when generated.
    fn damping_forces(&self, q: &[f64], qd: &[f64], t: f64, out: &mut [f64]) -> bool;
    /// Coriolis matrix (`nq x nq`), when generated.
    fn coriolis_matrix(&self, q: &[f64], qd: &[f64], t: f64, out: &mut [f64]) -> bool;
    /// Bias-force Jacobians `dh/dq`, `dh/dqd` (each `nq x nq`), when generated.
    fn bias_jacobians(
        &self,
        q: &[f64],
        qd: &[f64],
        t: f64,
        h_q: &mut [f64],
        h_qd: &mut [f64],
    ) -> bool;
    /// Inverse dynamics and its derivatives `d tau/dq`, `d tau/dqd` at
    /// `qdd` (each `nq x nq`), when generated.
    fn inverse_dynamics_derivatives(
        &self,
        q: &[f64],
        qd: &[f64],
        qdd: &[f64],
        t: f64,
        out: IdDerivatives<'_>,
    ) -> bool;
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
    ) -> bool;
    /// Marker names, in index order.
    fn markers(&self) -> Vec<&str>;
    /// Position (3) and rotation (3 x 3) of marker `marker`; `false`
    /// (nothing written) when there is no such marker.
    fn marker_pose(
        &self,
        marker: usize,
        q: &[f64],
        t: f64,
        position: &mut [f64],
        rotation: &mut [f64],
    ) -> bool;
    /// Position, rotation and Jacobian (6 x nq) of marker `marker`.
    fn marker_jacobian(&self, marker: usize, q: &[f64], t: f64, out: MarkerPose<'_>) -> bool;
    /// Velocity (6) and acceleration bias (6) of marker `marker`.
    fn marker_motion(
        &self,
        marker: usize,
        q: &[f64],
        qd: &[f64],
        t: f64,
        velocity: &mut [f64],
        acceleration_bias: &mut [f64],
    ) -> bool;
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

/// `out` from a fixed-size result of the same length.
fn store<const R: usize, const C: usize>(from: &SMatrix<f64, R, C>, out: &mut [f64]) {
    out.copy_from_slice(from.as_slice());
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
    fn mass_matrix(&self, q: &[f64], t: f64, out: &mut [f64]) {
        let mut m = SMatrix::<f64, NQ, NQ>::zeros();
        self.0.mass_matrix(&fixed(q), t, &mut m);
        store(&m, out);
    }
    fn bias(&self, q: &[f64], qd: &[f64], t: f64, out: &mut [f64]) {
        let mut h = SVector::<f64, NQ>::zeros();
        self.0.bias(&fixed(q), &fixed(qd), t, &mut h);
        store(&h, out);
    }
    fn inverse_dynamics(&self, q: &[f64], qd: &[f64], qdd: &[f64], t: f64, out: &mut [f64]) {
        let mut tau = SVector::<f64, NQ>::zeros();
        self.0
            .inverse_dynamics(&fixed(q), &fixed(qd), &fixed(qdd), t, &mut tau);
        store(&tau, out);
    }
    fn constraints(&self, q: &[f64], t: f64, out: &mut [f64]) {
        let mut p = SVector::<f64, NC>::zeros();
        self.0.constraints(&fixed(q), t, &mut p);
        store(&p, out);
    }
    fn constraint_jacobian(&self, q: &[f64], t: f64, out: &mut [f64]) {
        let mut j = SMatrix::<f64, NC, NQ>::zeros();
        self.0.constraint_jacobian(&fixed(q), t, &mut j);
        store(&j, out);
    }
    fn constraint_time_derivative(&self, q: &[f64], t: f64, out: &mut [f64]) {
        let mut p = SVector::<f64, NC>::zeros();
        self.0.constraint_time_derivative(&fixed(q), t, &mut p);
        store(&p, out);
    }
    fn constraint_rhs(&self, q: &[f64], qd: &[f64], t: f64, out: &mut [f64]) {
        let mut g = SVector::<f64, NC>::zeros();
        self.0.constraint_rhs(&fixed(q), &fixed(qd), t, &mut g);
        store(&g, out);
    }
    fn constraints_and_jacobian(&self, q: &[f64], t: f64, phi: &mut [f64], phi_q: &mut [f64]) {
        let mut p = SVector::<f64, NC>::zeros();
        let mut j = SMatrix::<f64, NC, NQ>::zeros();
        self.0
            .constraints_and_jacobian(&fixed(q), t, &mut p, &mut j);
        store(&p, phi);
        store(&j, phi_q);
    }
    fn dynamics_terms(&self, q: &[f64], qd: &[f64], t: f64, out: Fused<'_>) {
        let mut m = SMatrix::<f64, NQ, NQ>::zeros();
        let mut h = SVector::<f64, NQ>::zeros();
        let mut j = SMatrix::<f64, NC, NQ>::zeros();
        let mut g = SVector::<f64, NC>::zeros();
        self.0
            .dynamics_terms(&fixed(q), &fixed(qd), t, &mut m, &mut h, &mut j, &mut g);
        store(&m, out.m);
        store(&h, out.h);
        store(&j, out.phi_q);
        store(&g, out.gamma);
    }
    fn actuator_map(&self, out: &mut [f64]) {
        let mut b = SMatrix::<f64, NQ, NU>::zeros();
        self.0.actuator_map(&mut b);
        store(&b, out);
    }
    fn kinetic_energy(&self, q: &[f64], qd: &[f64], t: f64) -> f64 {
        self.0.kinetic_energy(&fixed(q), &fixed(qd), t)
    }
    fn potential_energy(&self, q: &[f64], t: f64) -> f64 {
        self.0.potential_energy(&fixed(q), t)
    }
    fn parameters(&self) -> Vec<&str> {
        M::PARAMETERS.to_vec()
    }
    fn set_parameter(&mut self, name: &str, value: f64) -> bool {
        self.0.set_parameter(name, value)
    }
    fn coriolis_forces(&self, q: &[f64], qd: &[f64], t: f64, out: &mut [f64]) -> bool {
        let mut f = SVector::<f64, NQ>::zeros();
        let given = self.0.coriolis_forces(&fixed(q), &fixed(qd), t, &mut f);
        given.then(|| store(&f, out)).is_some()
    }
    fn potential_forces(&self, q: &[f64], t: f64, out: &mut [f64]) -> bool {
        let mut f = SVector::<f64, NQ>::zeros();
        let given = self.0.potential_forces(&fixed(q), t, &mut f);
        given.then(|| store(&f, out)).is_some()
    }
    fn damping_forces(&self, q: &[f64], qd: &[f64], t: f64, out: &mut [f64]) -> bool {
        let mut f = SVector::<f64, NQ>::zeros();
        let given = self.0.damping_forces(&fixed(q), &fixed(qd), t, &mut f);
        given.then(|| store(&f, out)).is_some()
    }
    fn coriolis_matrix(&self, q: &[f64], qd: &[f64], t: f64, out: &mut [f64]) -> bool {
        let mut c = SMatrix::<f64, NQ, NQ>::zeros();
        let given = self.0.coriolis_matrix(&fixed(q), &fixed(qd), t, &mut c);
        given.then(|| store(&c, out)).is_some()
    }
    fn bias_jacobians(
        &self,
        q: &[f64],
        qd: &[f64],
        t: f64,
        h_q: &mut [f64],
        h_qd: &mut [f64],
    ) -> bool {
        let mut a = SMatrix::<f64, NQ, NQ>::zeros();
        let mut b = SMatrix::<f64, NQ, NQ>::zeros();
        let given = self
            .0
            .bias_jacobians(&fixed(q), &fixed(qd), t, &mut a, &mut b);
        given
            .then(|| {
                store(&a, h_q);
                store(&b, h_qd);
            })
            .is_some()
    }
    fn inverse_dynamics_derivatives(
        &self,
        q: &[f64],
        qd: &[f64],
        qdd: &[f64],
        t: f64,
        out: IdDerivatives<'_>,
    ) -> bool {
        let mut tau = SVector::<f64, NQ>::zeros();
        let mut a = SMatrix::<f64, NQ, NQ>::zeros();
        let mut b = SMatrix::<f64, NQ, NQ>::zeros();
        let (q, qd, qdd) = (fixed(q), fixed(qd), fixed(qdd));
        let given = self
            .0
            .inverse_dynamics_derivatives(&q, &qd, &qdd, t, &mut tau, &mut a, &mut b);
        given
            .then(|| {
                store(&tau, out.tau);
                store(&a, out.tau_q);
                store(&b, out.tau_qd);
            })
            .is_some()
    }
    fn constraint_acceleration_derivatives(
        &self,
        q: &[f64],
        qd: &[f64],
        qdd: &[f64],
        t: f64,
        a_q: &mut [f64],
        a_qd: &mut [f64],
    ) -> bool {
        let mut a = SMatrix::<f64, NC, NQ>::zeros();
        let mut b = SMatrix::<f64, NC, NQ>::zeros();
        let (q, qd, qdd) = (fixed(q), fixed(qd), fixed(qdd));
        let given = self
            .0
            .constraint_acceleration_derivatives(&q, &qd, &qdd, t, &mut a, &mut b);
        given
            .then(|| {
                store(&a, a_q);
                store(&b, a_qd);
            })
            .is_some()
    }
    fn markers(&self) -> Vec<&str> {
        M::MARKERS.to_vec()
    }
    fn marker_pose(
        &self,
        marker: usize,
        q: &[f64],
        t: f64,
        position: &mut [f64],
        rotation: &mut [f64],
    ) -> bool {
        let (mut p, mut r) = (SVector::<f64, 3>::zeros(), SMatrix::<f64, 3, 3>::zeros());
        let given = self.0.marker_pose(marker, &fixed(q), t, &mut p, &mut r);
        given
            .then(|| {
                store(&p, position);
                store(&r, rotation);
            })
            .is_some()
    }
    fn marker_jacobian(&self, marker: usize, q: &[f64], t: f64, out: MarkerPose<'_>) -> bool {
        let (mut p, mut r) = (SVector::<f64, 3>::zeros(), SMatrix::<f64, 3, 3>::zeros());
        let mut j = SMatrix::<f64, 6, NQ>::zeros();
        let given = self
            .0
            .marker_jacobian(marker, &fixed(q), t, &mut p, &mut r, &mut j);
        given
            .then(|| {
                store(&p, out.position);
                store(&r, out.rotation);
                store(&j, out.jacobian);
            })
            .is_some()
    }
    fn marker_motion(
        &self,
        marker: usize,
        q: &[f64],
        qd: &[f64],
        t: f64,
        velocity: &mut [f64],
        acceleration_bias: &mut [f64],
    ) -> bool {
        let (mut v, mut a) = (SVector::<f64, 6>::zeros(), SVector::<f64, 6>::zeros());
        let given = self
            .0
            .marker_motion(marker, &fixed(q), &fixed(qd), t, &mut v, &mut a);
        given
            .then(|| {
                store(&v, velocity);
                store(&a, acceleration_bias);
            })
            .is_some()
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
