//! A scene of run-time size ([`DynModel`]) as a fixed-size runtime model
//! ([`flexdyn_runtime::Model`]), so that every runtime solver (integrators,
//! projection, inverse dynamics, control) runs on any scene file.
//!
//! [`Padded`] embeds a model with `nq`, `nc`, `nu` coordinates, constraints
//! and inputs into capacities `NQ >= nq + (NC - nc) + (NU - nu)`, `NC >=
//! nc`, `NU >= nu`. The real coordinates come first; each pad coordinate has
//! unit mass and no forces, so from rest at 0 it stays there. Each pad
//! constraint is `q_p = 0` on a pad coordinate of its own (so `Phi_q` keeps
//! full row rank), and each pad input acts with unit gain on another pad
//! coordinate of its own ([`Padded::pad_input_coordinates`]: a servo or an
//! inverse-dynamics solve prescribes those to 0 and stays square). The
//! equations of the real coordinates are unchanged: `M` is block diagonal
//! and the pad rows of `Phi_q`, `B` touch only pad coordinates.
//!
//! [`with_padding`] picks the smallest capacities of a short ladder that fit
//! a scene and runs caller code generic over them ([`Sized`]); each rung is
//! one monomorphisation of that code, so the ladder is kept short.

use flexdyn_runtime::Model;
use nalgebra::{DMatrix, DVector, SMatrix, SVector};

use crate::dynamic::{matrix, vector, DynModel, Fused};

/// `model` padded to `NQ` coordinates, `NC` constraints, `NU` inputs.
pub struct Padded<'a, const NQ: usize, const NC: usize, const NU: usize> {
    model: &'a dyn DynModel,
    nq: usize,
    nc: usize,
    nu: usize,
}

impl<'a, const NQ: usize, const NC: usize, const NU: usize> Padded<'a, NQ, NC, NU> {
    /// Pad `model`; an error when it does not fit the capacities.
    pub fn new(model: &'a dyn DynModel) -> Result<Self, String> {
        let (nq, nc, nu) = (model.nq(), model.nc(), model.nu());
        if !fits((nq, nc, nu), (NQ, NC, NU)) {
            return Err(format!(
                "scene `{}` ({nq} coordinates, {nc} constraints, {nu} actuators) does not fit \
                 {NQ} coordinates (with one per padded constraint and input), {NC} constraints, \
                 {NU} actuators",
                model.name()
            ));
        }
        Ok(Padded { model, nq, nc, nu })
    }

    /// The model inside (names, sizes).
    pub fn model(&self) -> &'a dyn DynModel {
        self.model
    }

    /// Number of real coordinates.
    pub fn nq(&self) -> usize {
        self.nq
    }

    /// Number of real constraints.
    pub fn nc(&self) -> usize {
        self.nc
    }

    /// Number of real inputs.
    pub fn nu(&self) -> usize {
        self.nu
    }

    /// The pad coordinate of each pad input (inputs `nu..NU` in order).
    pub fn pad_input_coordinates(&self) -> Vec<usize> {
        let first = self.nq + (NC - self.nc);
        (first..first + (NU - self.nu)).collect()
    }

    /// A full-size vector from the real coordinates' values (pads 0).
    pub fn pad(&self, x: &[f64]) -> SVector<f64, NQ> {
        let mut out = SVector::<f64, NQ>::zeros();
        out.rows_mut(0, self.nq).copy_from_slice(&x[..self.nq]);
        out
    }

    fn real<'v>(&self, x: &'v SVector<f64, NQ>) -> &'v [f64] {
        &x.as_slice()[..self.nq]
    }

    fn pad_constraints(&self, q: &SVector<f64, NQ>, phi: &mut SVector<f64, NC>) {
        for k in 0..NC - self.nc {
            phi[self.nc + k] = q[self.nq + k];
        }
    }

    fn pad_jacobian(&self, phi_q: &mut SMatrix<f64, NC, NQ>) {
        for k in 0..NC - self.nc {
            phi_q[(self.nc + k, self.nq + k)] = 1.0;
        }
    }
}

/// Whether sizes `(nq, nc, nu)` fit capacities `(NQ, NC, NU)`.
fn fits((nq, nc, nu): (usize, usize, usize), (cq, cc, cu): (usize, usize, usize)) -> bool {
    nc <= cc && nu <= cu && nq + (cc - nc) + (cu - nu) <= cq
}

fn copy_vector<const N: usize>(from: &DVector<f64>, to: &mut SVector<f64, N>) {
    to.rows_mut(0, from.len()).copy_from(from);
}

fn copy_matrix<const R: usize, const C: usize>(from: &DMatrix<f64>, to: &mut SMatrix<f64, R, C>) {
    to.view_mut((0, 0), from.shape()).copy_from(from);
}

impl<const NQ: usize, const NC: usize, const NU: usize> Model<NQ, NC, NU>
    for Padded<'_, NQ, NC, NU>
{
    const NAME: &'static str = "padded";
    /// Names are the inner model's ([`Padded::model`]).
    const COORDINATES: [&'static str; NQ] = [""; NQ];
    const ACTUATORS: [&'static str; NU] = [""; NU];

    fn mass_matrix(&self, q: &SVector<f64, NQ>, t: f64, m: &mut SMatrix<f64, NQ, NQ>) {
        m.fill_with_identity();
        let n = self.nq;
        copy_matrix(
            &matrix(n, n, |o| self.model.mass_matrix(self.real(q), t, o)),
            m,
        );
    }

    fn bias(&self, q: &SVector<f64, NQ>, qd: &SVector<f64, NQ>, t: f64, h: &mut SVector<f64, NQ>) {
        h.fill(0.0);
        let real = vector(self.nq, |o| {
            self.model.bias(self.real(q), self.real(qd), t, o)
        });
        copy_vector(&real, h);
    }

    /// The real coordinates' from the inner model; a pad's is its
    /// acceleration (unit mass, no bias).
    fn inverse_dynamics(
        &self,
        q: &SVector<f64, NQ>,
        qd: &SVector<f64, NQ>,
        qdd: &SVector<f64, NQ>,
        t: f64,
        tau: &mut SVector<f64, NQ>,
    ) {
        tau.copy_from(qdd);
        let real = vector(self.nq, |o| {
            let (q, qd, qdd) = (self.real(q), self.real(qd), self.real(qdd));
            self.model.inverse_dynamics(q, qd, qdd, t, o)
        });
        copy_vector(&real, tau);
    }

    fn constraints(&self, q: &SVector<f64, NQ>, t: f64, phi: &mut SVector<f64, NC>) {
        copy_vector(
            &vector(self.nc, |o| self.model.constraints(self.real(q), t, o)),
            phi,
        );
        self.pad_constraints(q, phi);
    }

    fn constraint_jacobian(&self, q: &SVector<f64, NQ>, t: f64, phi_q: &mut SMatrix<f64, NC, NQ>) {
        phi_q.fill(0.0);
        let real = matrix(self.nc, self.nq, |o| {
            self.model.constraint_jacobian(self.real(q), t, o)
        });
        copy_matrix(&real, phi_q);
        self.pad_jacobian(phi_q);
    }

    fn constraint_time_derivative(
        &self,
        q: &SVector<f64, NQ>,
        t: f64,
        phi_t: &mut SVector<f64, NC>,
    ) {
        phi_t.fill(0.0);
        let real = vector(self.nc, |o| {
            self.model.constraint_time_derivative(self.real(q), t, o)
        });
        copy_vector(&real, phi_t);
    }

    fn constraint_rhs(
        &self,
        q: &SVector<f64, NQ>,
        qd: &SVector<f64, NQ>,
        t: f64,
        gamma: &mut SVector<f64, NC>,
    ) {
        gamma.fill(0.0);
        let real = vector(self.nc, |o| {
            self.model.constraint_rhs(self.real(q), self.real(qd), t, o)
        });
        copy_vector(&real, gamma);
    }

    fn actuator_map(&self, b: &mut SMatrix<f64, NQ, NU>) {
        b.fill(0.0);
        copy_matrix(&matrix(self.nq, self.nu, |o| self.model.actuator_map(o)), b);
        for (j, i) in self.pad_input_coordinates().into_iter().enumerate() {
            b[(i, self.nu + j)] = 1.0;
        }
    }

    fn kinetic_energy(&self, q: &SVector<f64, NQ>, qd: &SVector<f64, NQ>, t: f64) -> f64 {
        let pads = qd.rows(self.nq, NQ - self.nq).norm_squared();
        self.model.kinetic_energy(self.real(q), self.real(qd), t) + 0.5 * pads
    }

    fn potential_energy(&self, q: &SVector<f64, NQ>, t: f64) -> f64 {
        self.model.potential_energy(self.real(q), t)
    }

    fn bias_jacobians(
        &self,
        q: &SVector<f64, NQ>,
        qd: &SVector<f64, NQ>,
        t: f64,
        h_q: &mut SMatrix<f64, NQ, NQ>,
        h_qd: &mut SMatrix<f64, NQ, NQ>,
    ) -> bool {
        let (mut a, mut b) = (
            DMatrix::zeros(self.nq, self.nq),
            DMatrix::zeros(self.nq, self.nq),
        );
        let (sq, sqd) = (self.real(q), self.real(qd));
        if !self
            .model
            .bias_jacobians(sq, sqd, t, a.as_mut_slice(), b.as_mut_slice())
        {
            return false;
        }
        h_q.fill(0.0);
        h_qd.fill(0.0);
        copy_matrix(&a, h_q);
        copy_matrix(&b, h_qd);
        true
    }

    fn constraints_and_jacobian(
        &self,
        q: &SVector<f64, NQ>,
        t: f64,
        phi: &mut SVector<f64, NC>,
        phi_q: &mut SMatrix<f64, NC, NQ>,
    ) {
        let (mut p, mut j) = (DVector::zeros(self.nc), DMatrix::zeros(self.nc, self.nq));
        let sq = self.real(q);
        self.model
            .constraints_and_jacobian(sq, t, p.as_mut_slice(), j.as_mut_slice());
        copy_vector(&p, phi);
        self.pad_constraints(q, phi);
        phi_q.fill(0.0);
        copy_matrix(&j, phi_q);
        self.pad_jacobian(phi_q);
    }

    fn dynamics_terms(
        &self,
        q: &SVector<f64, NQ>,
        qd: &SVector<f64, NQ>,
        t: f64,
        m: &mut SMatrix<f64, NQ, NQ>,
        h: &mut SVector<f64, NQ>,
        phi_q: &mut SMatrix<f64, NC, NQ>,
        gamma: &mut SVector<f64, NC>,
    ) {
        let (nq, nc) = (self.nq, self.nc);
        let (mut mm, mut hh) = (DMatrix::zeros(nq, nq), DVector::zeros(nq));
        let (mut j, mut g) = (DMatrix::zeros(nc, nq), DVector::zeros(nc));
        let out = Fused {
            m: mm.as_mut_slice(),
            h: hh.as_mut_slice(),
            phi_q: j.as_mut_slice(),
            gamma: g.as_mut_slice(),
        };
        self.model
            .dynamics_terms(self.real(q), self.real(qd), t, out);
        m.fill_with_identity();
        copy_matrix(&mm, m);
        h.fill(0.0);
        copy_vector(&hh, h);
        phi_q.fill(0.0);
        copy_matrix(&j, phi_q);
        self.pad_jacobian(phi_q);
        gamma.fill(0.0);
        copy_vector(&g, gamma);
    }
}

/// Caller code generic over the capacities [`with_padding`] picks.
pub trait Sized {
    /// What the code returns.
    type Output;
    /// Run on the padded model.
    fn run<const NQ: usize, const NC: usize, const NU: usize>(
        self,
        model: &Padded<'_, NQ, NC, NU>,
    ) -> Self::Output;
}

/// The capacities `(NQ, NC, NU)` of [`with_padding`], smallest first.
pub const LADDER: [(usize, usize, usize); 4] = [(6, 2, 2), (16, 10, 4), (40, 20, 8), (64, 24, 8)];

/// Run `s` on `model` padded to the smallest rung of [`LADDER`] it fits;
/// an error naming the sizes when it fits none. The largest rung (sized for
/// the flexible parallel robot, 39 coordinates, 12 constraints, 3 actuators,
/// with room to spare) has solvers that keep matrices of up to 128 x 128 on
/// the stack: call this on a thread with a few MiB of stack (the main
/// thread's is enough).
pub fn with_padding<S: Sized>(model: &dyn DynModel, s: S) -> Result<S::Output, String> {
    let sizes = (model.nq(), model.nc(), model.nu());
    if fits(sizes, LADDER[0]) {
        Ok(s.run(&Padded::<6, 2, 2>::new(model)?))
    } else if fits(sizes, LADDER[1]) {
        Ok(s.run(&Padded::<16, 10, 4>::new(model)?))
    } else if fits(sizes, LADDER[2]) {
        Ok(s.run(&Padded::<40, 20, 8>::new(model)?))
    } else {
        Ok(s.run(&Padded::<64, 24, 8>::new(model)?))
    }
}

#[cfg(test)]
mod tests {
    use flexdyn_runtime::{accelerations, DynamicsConfig};

    use super::*;

    /// Accelerations and multipliers of the compiled model and of its
    /// padded dynamic twin at the same state.
    fn compare<M, const NQ: usize, const NC: usize, const NU: usize>(
        model: M,
        q: &[f64],
        qd: &[f64],
    ) where
        M: Model<NQ, NC, NU> + Clone + 'static,
    {
        let dynamic = crate::dynamic::erase(model.clone());
        let tau = SVector::<f64, NU>::from_fn(|i, _| 0.3 + i as f64);
        let (sq, sqd) = (
            SVector::from_column_slice(q),
            SVector::from_column_slice(qd),
        );
        let cfg = DynamicsConfig::default();
        let direct = accelerations(&model, &cfg, &sq, &sqd, 0.2, &tau).unwrap();
        struct Check<'a, const NQ: usize, const NU: usize> {
            q: &'a [f64],
            qd: &'a [f64],
            tau: SVector<f64, NU>,
            expected: SVector<f64, NQ>,
        }
        impl<const RQ: usize, const RU: usize> Sized for Check<'_, RQ, RU> {
            type Output = ();
            fn run<const NQ: usize, const NC: usize, const NU: usize>(
                self,
                m: &Padded<'_, NQ, NC, NU>,
            ) {
                let mut tau = SVector::<f64, NU>::zeros();
                tau.rows_mut(0, RU).copy_from(&self.tau);
                let cfg = DynamicsConfig::default();
                let a = accelerations(m, &cfg, &m.pad(self.q), &m.pad(self.qd), 0.2, &tau).unwrap();
                let scale = self.expected.amax().max(1.0);
                for i in 0..RQ {
                    assert!(
                        (a.qdd[i] - self.expected[i]).abs() <= 1e-12 * scale,
                        "qdd[{i}]: padded {} vs compiled {}",
                        a.qdd[i],
                        self.expected[i]
                    );
                }
                assert!(a.qdd.rows(RQ, NQ - RQ).amax() == 0.0, "pads accelerate");
            }
        }
        let check = Check::<NQ, NU> {
            q,
            qd,
            tau,
            expected: direct.qdd,
        };
        with_padding(&*dynamic, check).unwrap();
    }

    #[test]
    fn padded_models_accelerate_like_the_compiled_ones() {
        use crate::scenes::{five_bar, slider_crank};
        compare(
            slider_crank::SliderCrank,
            &[0.4, 0.1, 0.3],
            &[1.0, -0.5, 0.2],
        );
        compare(
            five_bar::FiveBar,
            &[0.9, 2.2, 1.4, 0.8, 0.3],
            &[0.5, -0.2, 0.1, 0.3, 0.0],
        );
    }

    #[test]
    fn too_large_scenes_and_pad_inputs_are_reported() {
        assert!(fits((1, 0, 1), LADDER[0]) && fits((12, 9, 3), LADDER[1]));
        assert!(!fits((41, 0, 0), LADDER[2]) && !fits((3, 21, 0), LADDER[2]));
        // The flexible parallel robot (39 coordinates, 12 constraints, 3
        // actuators) fits the largest rung.
        assert!(!fits((39, 12, 3), LADDER[2]) && fits((39, 12, 3), LADDER[3]));
        assert!(!fits((65, 0, 0), LADDER[3]) && !fits((3, 25, 0), LADDER[3]));
        let dynamic = crate::dynamic::erase(crate::scenes::pendulum::Pendulum::default());
        let p = Padded::<6, 2, 2>::new(&*dynamic).unwrap();
        assert_eq!(p.pad_input_coordinates(), vec![3]);
        let too_small = Padded::<2, 2, 2>::new(&*dynamic).err().unwrap();
        assert!(too_small.contains("does not fit"), "{too_small}");
    }
}
