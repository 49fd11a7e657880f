//! Scene models behind one object-safe interface, for tools that pick a scene
//! at run time (the command line, validation): compiled ones ([`erase`]) and
//! interpreted ones ([`crate::interpreted`]). Uses heap-allocated results;
//! real-time code uses the generated types and [`flexdyn_runtime::Model`]
//! directly.

use flexdyn_runtime::Model;
use nalgebra::{DMatrix, DVector, SMatrix, SVector};

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
    /// Mass matrix.
    fn mass_matrix(&self, q: &[f64], t: f64) -> DMatrix<f64>;
    /// Bias forces.
    fn bias(&self, q: &[f64], qd: &[f64], t: f64) -> DVector<f64>;
    /// Constraint residuals.
    fn constraints(&self, q: &[f64], t: f64) -> DVector<f64>;
    /// Constraint Jacobian.
    fn constraint_jacobian(&self, q: &[f64], t: f64) -> DMatrix<f64>;
    /// Explicit time derivative of the constraints.
    fn constraint_time_derivative(&self, q: &[f64], t: f64) -> DVector<f64>;
    /// Acceleration right-hand side.
    fn constraint_rhs(&self, q: &[f64], qd: &[f64], t: f64) -> DVector<f64>;
    /// `(Phi, Phi_q)` from the fused `constraints_and_jacobian` program.
    fn constraints_and_jacobian(&self, q: &[f64], t: f64) -> (DVector<f64>, DMatrix<f64>);
    /// `(M, h, Phi_q, gamma)` from the fused `dynamics_terms` program.
    fn dynamics_terms(&self, q: &[f64], qd: &[f64], t: f64) -> Fused;
    /// Inverse dynamics `M qdd + h`.
    fn inverse_dynamics(&self, q: &[f64], qd: &[f64], qdd: &[f64], t: f64) -> DVector<f64>;
    /// Actuator map.
    fn actuator_map(&self) -> DMatrix<f64>;
    /// Kinetic energy.
    fn kinetic_energy(&self, q: &[f64], qd: &[f64], t: f64) -> f64;
    /// Potential energy.
    fn potential_energy(&self, q: &[f64], t: f64) -> f64;
    /// Names of the runtime parameters.
    fn parameters(&self) -> Vec<&str>;
    /// Set a runtime parameter; `false` if there is none of that name.
    fn set_parameter(&mut self, name: &str, value: f64) -> bool;
    /// Coriolis forces, when generated.
    fn coriolis_forces(&self, q: &[f64], qd: &[f64], t: f64) -> Option<DVector<f64>>;
    /// Gravity and elastic forces, when generated.
    fn potential_forces(&self, q: &[f64], t: f64) -> Option<DVector<f64>>;
    /// Damping forces, when generated.
    fn damping_forces(&self, q: &[f64], qd: &[f64], t: f64) -> Option<DVector<f64>>;
    /// Coriolis matrix, when generated.
    fn coriolis_matrix(&self, q: &[f64], qd: &[f64], t: f64) -> Option<DMatrix<f64>>;
    /// Bias-force Jacobians `(dh/dq, dh/dqd)`, when generated.
    fn bias_jacobians(&self, q: &[f64], qd: &[f64], t: f64)
        -> Option<(DMatrix<f64>, DMatrix<f64>)>;
}

/// `(M, h, Phi_q, gamma)` as computed together by `dynamics_terms`.
pub type Fused = (DMatrix<f64>, DVector<f64>, DMatrix<f64>, DVector<f64>);

/// A model with its dimensions as const parameters.
pub struct Erased<M, const NQ: usize, const NC: usize, const NU: usize>(pub M);

/// Wrap a model for dynamic use.
pub fn erase<M, const NQ: usize, const NC: usize, const NU: usize>(model: M) -> Box<dyn DynModel>
where
    M: Model<NQ, NC, NU> + 'static,
{
    Box::new(Erased::<M, NQ, NC, NU>(model))
}

fn vector<const N: usize>(x: &[f64]) -> SVector<f64, N> {
    assert_eq!(x.len(), N, "expected {N} values, got {}", x.len());
    SVector::from_column_slice(x)
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
    fn mass_matrix(&self, q: &[f64], t: f64) -> DMatrix<f64> {
        let mut m = SMatrix::<f64, NQ, NQ>::zeros();
        self.0.mass_matrix(&vector(q), t, &mut m);
        DMatrix::from_column_slice(NQ, NQ, m.as_slice())
    }
    fn bias(&self, q: &[f64], qd: &[f64], t: f64) -> DVector<f64> {
        let mut h = SVector::<f64, NQ>::zeros();
        self.0.bias(&vector(q), &vector(qd), t, &mut h);
        DVector::from_column_slice(h.as_slice())
    }
    fn inverse_dynamics(&self, q: &[f64], qd: &[f64], qdd: &[f64], t: f64) -> DVector<f64> {
        let mut tau = SVector::<f64, NQ>::zeros();
        self.0
            .inverse_dynamics(&vector(q), &vector(qd), &vector(qdd), t, &mut tau);
        DVector::from_column_slice(tau.as_slice())
    }
    fn constraints(&self, q: &[f64], t: f64) -> DVector<f64> {
        let mut p = SVector::<f64, NC>::zeros();
        self.0.constraints(&vector(q), t, &mut p);
        DVector::from_column_slice(p.as_slice())
    }
    fn constraint_jacobian(&self, q: &[f64], t: f64) -> DMatrix<f64> {
        let mut j = SMatrix::<f64, NC, NQ>::zeros();
        self.0.constraint_jacobian(&vector(q), t, &mut j);
        DMatrix::from_column_slice(NC, NQ, j.as_slice())
    }
    fn constraint_time_derivative(&self, q: &[f64], t: f64) -> DVector<f64> {
        let mut p = SVector::<f64, NC>::zeros();
        self.0.constraint_time_derivative(&vector(q), t, &mut p);
        DVector::from_column_slice(p.as_slice())
    }
    fn constraint_rhs(&self, q: &[f64], qd: &[f64], t: f64) -> DVector<f64> {
        let mut g = SVector::<f64, NC>::zeros();
        self.0.constraint_rhs(&vector(q), &vector(qd), t, &mut g);
        DVector::from_column_slice(g.as_slice())
    }
    fn constraints_and_jacobian(&self, q: &[f64], t: f64) -> (DVector<f64>, DMatrix<f64>) {
        let mut phi = SVector::<f64, NC>::zeros();
        let mut j = SMatrix::<f64, NC, NQ>::zeros();
        self.0
            .constraints_and_jacobian(&vector(q), t, &mut phi, &mut j);
        (
            DVector::from_column_slice(phi.as_slice()),
            DMatrix::from_column_slice(NC, NQ, j.as_slice()),
        )
    }
    fn dynamics_terms(&self, q: &[f64], qd: &[f64], t: f64) -> Fused {
        let mut m = SMatrix::<f64, NQ, NQ>::zeros();
        let mut h = SVector::<f64, NQ>::zeros();
        let mut j = SMatrix::<f64, NC, NQ>::zeros();
        let mut g = SVector::<f64, NC>::zeros();
        self.0
            .dynamics_terms(&vector(q), &vector(qd), t, &mut m, &mut h, &mut j, &mut g);
        (
            DMatrix::from_column_slice(NQ, NQ, m.as_slice()),
            DVector::from_column_slice(h.as_slice()),
            DMatrix::from_column_slice(NC, NQ, j.as_slice()),
            DVector::from_column_slice(g.as_slice()),
        )
    }
    fn actuator_map(&self) -> DMatrix<f64> {
        let mut b = SMatrix::<f64, NQ, NU>::zeros();
        self.0.actuator_map(&mut b);
        DMatrix::from_column_slice(NQ, NU, b.as_slice())
    }
    fn kinetic_energy(&self, q: &[f64], qd: &[f64], t: f64) -> f64 {
        self.0.kinetic_energy(&vector(q), &vector(qd), t)
    }
    fn potential_energy(&self, q: &[f64], t: f64) -> f64 {
        self.0.potential_energy(&vector(q), t)
    }
    fn parameters(&self) -> Vec<&str> {
        M::PARAMETERS.to_vec()
    }
    fn set_parameter(&mut self, name: &str, value: f64) -> bool {
        self.0.set_parameter(name, value)
    }
    fn coriolis_forces(&self, q: &[f64], qd: &[f64], t: f64) -> Option<DVector<f64>> {
        let mut out = SVector::<f64, NQ>::zeros();
        self.0
            .coriolis_forces(&vector(q), &vector(qd), t, &mut out)
            .then(|| DVector::from_column_slice(out.as_slice()))
    }
    fn potential_forces(&self, q: &[f64], t: f64) -> Option<DVector<f64>> {
        let mut out = SVector::<f64, NQ>::zeros();
        self.0
            .potential_forces(&vector(q), t, &mut out)
            .then(|| DVector::from_column_slice(out.as_slice()))
    }
    fn damping_forces(&self, q: &[f64], qd: &[f64], t: f64) -> Option<DVector<f64>> {
        let mut out = SVector::<f64, NQ>::zeros();
        self.0
            .damping_forces(&vector(q), &vector(qd), t, &mut out)
            .then(|| DVector::from_column_slice(out.as_slice()))
    }
    fn coriolis_matrix(&self, q: &[f64], qd: &[f64], t: f64) -> Option<DMatrix<f64>> {
        let mut out = SMatrix::<f64, NQ, NQ>::zeros();
        self.0
            .coriolis_matrix(&vector(q), &vector(qd), t, &mut out)
            .then(|| DMatrix::from_column_slice(NQ, NQ, out.as_slice()))
    }
    fn bias_jacobians(
        &self,
        q: &[f64],
        qd: &[f64],
        t: f64,
    ) -> Option<(DMatrix<f64>, DMatrix<f64>)> {
        let mut h_q = SMatrix::<f64, NQ, NQ>::zeros();
        let mut h_qd = SMatrix::<f64, NQ, NQ>::zeros();
        self.0
            .bias_jacobians(&vector(q), &vector(qd), t, &mut h_q, &mut h_qd)
            .then(|| {
                (
                    DMatrix::from_column_slice(NQ, NQ, h_q.as_slice()),
                    DMatrix::from_column_slice(NQ, NQ, h_qd.as_slice()),
                )
            })
    }
}
