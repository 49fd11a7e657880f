//! The interface between generated equations of motion and the solvers.
//!
//! A generated scene module implements [`Model`] for its model struct. The
//! equations of motion it describes are
//!
//! ```text
//! M(q, t) qdd + h(q, qd, t) = Phi_q(q, t)^T lambda + B tau
//! Phi(q, t) = 0
//! ```
//!
//! with `h` the bias forces (Coriolis/centrifugal, gravity, elastic and
//! damping forces, all moved to the left-hand side). Every method writes into
//! caller-provided fixed-size storage, allocates nothing and never panics;
//! non-finite inputs propagate as non-finite outputs for the solver to detect.

use crate::scalar::Scalar;
use nalgebra::allocator::Allocator;
use nalgebra::{Const, DefaultAllocator, Dim, OMatrix, OVector, SMatrix, SVector};

/// Equations of motion of one scene: `NQ` generalized coordinates, `NC`
/// holonomic constraints and `NU` actuator inputs, computed in `T`
/// (`f64` unless named; see [`Scalar`]).
pub trait Model<const NQ: usize, const NC: usize, const NU: usize, T: Scalar = f64> {
    /// The scene's name.
    const NAME: &'static str;
    /// Names of the generalized coordinates, in order.
    const COORDINATES: [&'static str; NQ];
    /// Names of the actuator inputs, in order.
    const ACTUATORS: [&'static str; NU];

    /// Mass matrix `M(q, t)` (symmetric, positive definite).
    fn mass_matrix(&self, q: &SVector<T, NQ>, t: T, m: &mut SMatrix<T, NQ, NQ>);

    /// Bias forces `h(q, qd, t)`: Coriolis/centrifugal terms plus the gradient
    /// of the potential energy plus damping forces.
    fn bias(&self, q: &SVector<T, NQ>, qd: &SVector<T, NQ>, t: T, h: &mut SVector<T, NQ>);

    /// Constraint residuals `Phi(q, t)`.
    fn constraints(&self, q: &SVector<T, NQ>, t: T, phi: &mut SVector<T, NC>);

    /// Constraint Jacobian `Phi_q(q, t)`.
    fn constraint_jacobian(&self, q: &SVector<T, NQ>, t: T, phi_q: &mut SMatrix<T, NC, NQ>);

    /// Explicit time derivative of the constraints, `Phi_t(q, t)`; the velocity
    /// constraint is `Phi_q qd + Phi_t = 0`.
    fn constraint_time_derivative(&self, q: &SVector<T, NQ>, t: T, phi_t: &mut SVector<T, NC>);

    /// Acceleration right-hand side `gamma = -(Phi_q qd)_q qd - 2 Phi_qt qd - Phi_tt`,
    /// so that `Phi_q qdd = gamma` on the constraint manifold.
    fn constraint_rhs(
        &self,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        t: T,
        gamma: &mut SVector<T, NC>,
    );

    /// Actuator map `B`: actuator `j` contributes `B[:, j] * tau[j]` to the
    /// generalized forces.
    fn actuator_map(&self, b: &mut SMatrix<T, NQ, NU>);

    /// Optional generalized forces of the actuators, `f = B tau`, written
    /// from the non-zero entries of `B` (generated: one product per
    /// actuator, where forming `B` and multiplying costs `NQ NU`); returns
    /// `true`. The default returns `false` (the solvers then form `B tau`
    /// from [`Model::actuator_map`]).
    fn actuator_forces(&self, tau: &SVector<T, NU>, f: &mut SVector<T, NQ>) -> bool {
        let _ = (tau, f);
        false
    }

    /// Kinetic energy `T(q, qd, t)`.
    fn kinetic_energy(&self, q: &SVector<T, NQ>, qd: &SVector<T, NQ>, t: T) -> T;

    /// Potential energy `V(q, t)` (gravity and elastic).
    fn potential_energy(&self, q: &SVector<T, NQ>, t: T) -> T;

    /// Optional analytic Jacobians of the bias forces: writes `h_q = dh/dq`
    /// and `h_qd = dh/dqd` (each `NQ x NQ`, entry `(i, j) = d h_i / d x_j`) and
    /// returns `true`. The default returns `false`, meaning "not provided":
    /// solvers then use finite differences of [`Model::bias`] (and of the mass
    /// matrix and constraint Jacobian). Implicit integrators use these for
    /// their Newton iteration matrix.
    fn bias_jacobians(
        &self,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        t: T,
        h_q: &mut SMatrix<T, NQ, NQ>,
        h_qd: &mut SMatrix<T, NQ, NQ>,
    ) -> bool {
        let _ = (q, qd, t, h_q, h_qd);
        false
    }

    /// Optional exact derivatives of the inverse dynamics: writes `tau = M
    /// qdd + h`, `tau_q = d tau/dq` and `tau_qd = d tau/dqd` at the
    /// accelerations `qdd` (each `NQ x NQ`, entry `(i, j) = d tau_i / d
    /// x_j`; `d tau/dqdd` is `M`) and returns `true`. Generated where the
    /// scene asks for `dynamics_derivatives`; the default returns `false`
    /// (not provided). [`crate::forward_dynamics_derivatives`] builds the
    /// derivatives of the forward dynamics from them.
    #[allow(clippy::too_many_arguments)]
    fn inverse_dynamics_derivatives(
        &self,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        qdd: &SVector<T, NQ>,
        t: T,
        tau: &mut SVector<T, NQ>,
        tau_q: &mut SMatrix<T, NQ, NQ>,
        tau_qd: &mut SMatrix<T, NQ, NQ>,
    ) -> bool {
        let _ = (q, qd, qdd, t, tau, tau_q, tau_qd);
        false
    }

    /// Optional exact derivatives of the acceleration constraint `a = Phi_q
    /// qdd - gamma` (the second time derivative of `Phi` along the motion):
    /// writes `a_q = da/dq` and `a_qd = da/dqd` (each `NC x NQ`) at the
    /// accelerations `qdd` and returns `true`. Generated for constrained
    /// scenes that ask for `dynamics_derivatives`; the default returns
    /// `false`. `a` is linear in `qdd`, and `a_qd = 2 d(Phi_q qd +
    /// Phi_t)/dq`.
    fn constraint_acceleration_derivatives(
        &self,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        qdd: &SVector<T, NQ>,
        t: T,
        a_q: &mut SMatrix<T, NC, NQ>,
        a_qd: &mut SMatrix<T, NC, NQ>,
    ) -> bool {
        let _ = (q, qd, qdd, t, a_q, a_qd);
        false
    }

    /// Optional forward dynamics of an unconstrained scene as one program:
    /// writes `qdd = M^-1 (f - h)` for the generalized forces `f` (`B tau`
    /// plus any others) and the pivots of `M = L^T D L`, each relative to
    /// its diagonal entry of `M` (`d`, in `(0, 1]` for a positive definite
    /// `M`), and returns `true`. The result is valid only where every
    /// relative pivot is finite and above the precision's epsilon
    /// ([`crate::accelerations`] checks them and otherwise factors `M`
    /// itself, which reports it). Generated for unconstrained scenes of at most 40
    /// coordinates; the default returns `false`.
    fn forward_dynamics(
        &self,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        f: &SVector<T, NQ>,
        t: T,
        qdd: &mut SVector<T, NQ>,
        d: &mut SVector<T, NQ>,
    ) -> bool {
        let _ = (q, qd, f, t, qdd, d);
        false
    }

    /// Optional forward dynamics with its exact derivatives, as one
    /// program: `qdd` and `d` as [`Model::forward_dynamics`] writes them,
    /// `qdd_q = d qdd/dq`, `qdd_qd = d qdd/dqd` at the generalized forces
    /// `f`, and `qdd_f = d qdd/df = M^-1`, every solve on the factors of
    /// `M`; valid where `forward_dynamics` is. Generated for unconstrained
    /// scenes of at most 40 coordinates that ask for
    /// `dynamics_derivatives`; the default returns `false`.
    #[allow(clippy::too_many_arguments)]
    fn forward_dynamics_derivatives(
        &self,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        f: &SVector<T, NQ>,
        t: T,
        qdd: &mut SVector<T, NQ>,
        d: &mut SVector<T, NQ>,
        qdd_q: &mut SMatrix<T, NQ, NQ>,
        qdd_qd: &mut SMatrix<T, NQ, NQ>,
        qdd_f: &mut SMatrix<T, NQ, NQ>,
    ) -> bool {
        let _ = (q, qd, f, t, qdd, d, qdd_q, qdd_qd, qdd_f);
        false
    }

    /// Names of the runtime parameters (fields of the model struct), in order.
    const PARAMETERS: &'static [&'static str] = &[];

    /// Set a runtime parameter by name; `false` when the model has no such
    /// parameter (nothing changes then).
    fn set_parameter(&mut self, name: &str, value: T) -> bool {
        let _ = (name, value);
        false
    }

    /// Names of the scene's markers (`[[markers]]`), in index order: the
    /// `marker` argument of [`Model::marker_pose`],
    /// [`Model::marker_jacobian`] and [`Model::marker_motion`].
    const MARKERS: &'static [&'static str] = &[];

    /// World position of marker `marker` and its rotation (marker axes to
    /// world axes). Returns `false` (writing nothing) when the scene has no
    /// marker of that index. Generated modules compute the pose alone; the
    /// default takes it from [`Model::marker_jacobian`] (so that a wrapper
    /// forwarding that one has both).
    fn marker_pose(
        &self,
        marker: usize,
        q: &SVector<T, NQ>,
        t: T,
        position: &mut SVector<T, 3>,
        rotation: &mut SMatrix<T, 3, 3>,
    ) -> bool {
        let mut jacobian = SMatrix::<T, 6, NQ>::zeros();
        self.marker_jacobian(marker, q, t, position, rotation, &mut jacobian)
    }

    /// [`Model::marker_pose`] and the marker's Jacobian, from one program:
    /// `v = J qd (+ explicit time terms)` with `v` the velocity of the marker
    /// point (rows 0-2) and the angular velocity (rows 3-5), both in world
    /// axes (Pinocchio's `LOCAL_WORLD_ALIGNED`). `false` (nothing written)
    /// when the scene has no marker of that index.
    fn marker_jacobian(
        &self,
        marker: usize,
        q: &SVector<T, NQ>,
        t: T,
        position: &mut SVector<T, 3>,
        rotation: &mut SMatrix<T, 3, 3>,
        jacobian: &mut SMatrix<T, 6, NQ>,
    ) -> bool {
        let _ = (marker, q, t, position, rotation, jacobian);
        false
    }

    /// Velocity of marker `marker` (as in [`Model::marker_jacobian`],
    /// explicit time terms included) and its acceleration bias: its
    /// acceleration when `qdd = 0`, so that the point's classical
    /// acceleration and the angular acceleration are `J qdd +
    /// acceleration_bias`. `false` (nothing written) when the scene has no
    /// marker of that index.
    fn marker_motion(
        &self,
        marker: usize,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        t: T,
        velocity: &mut SVector<T, 6>,
        acceleration_bias: &mut SVector<T, 6>,
    ) -> bool {
        let _ = (marker, q, qd, t, velocity, acceleration_bias);
        false
    }

    /// Optional output (scene `outputs = ["forces"]`): Coriolis/centrifugal
    /// forces `C(q, qd) qd`, the part of [`Model::bias`] from the kinetic
    /// energy. Returns `false` (writing nothing) when not generated.
    fn coriolis_forces(
        &self,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        t: T,
        out: &mut SVector<T, NQ>,
    ) -> bool {
        let _ = (q, qd, t, out);
        false
    }

    /// Optional output (`forces`): gravity and elastic forces `dV/dq`.
    fn potential_forces(&self, q: &SVector<T, NQ>, t: T, out: &mut SVector<T, NQ>) -> bool {
        let _ = (q, t, out);
        false
    }

    /// Optional output (`forces`): damping forces `dD/dqd`.
    fn damping_forces(
        &self,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        t: T,
        out: &mut SVector<T, NQ>,
    ) -> bool {
        let _ = (q, qd, t, out);
        false
    }

    /// Optional output (`coriolis_matrix`): the Coriolis matrix from
    /// Christoffel symbols, with `C qd` the Coriolis forces and
    /// `dM/dt - 2 C` skew-symmetric.
    fn coriolis_matrix(
        &self,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        t: T,
        out: &mut SMatrix<T, NQ, NQ>,
    ) -> bool {
        let _ = (q, qd, t, out);
        false
    }

    /// `Phi` and `Phi_q` at one position, in one call (what a Newton
    /// iteration on the constraints needs at its last iterate). Generated
    /// models override it with one program that computes the trigonometric
    /// functions of the coordinates once for both; the default calls the two
    /// methods.
    fn constraints_and_jacobian(
        &self,
        q: &SVector<T, NQ>,
        t: T,
        phi: &mut SVector<T, NC>,
        phi_q: &mut SMatrix<T, NC, NQ>,
    ) {
        self.constraints(q, t, phi);
        self.constraint_jacobian(q, t, phi_q);
    }

    /// `M`, `h`, `Phi_q` and `gamma` at one state, in one call. Generated
    /// models override it with a single program that shares the common
    /// subexpressions of all four (the trigonometric functions of the
    /// coordinates, above all); the default calls the four methods.
    #[allow(clippy::too_many_arguments)]
    fn dynamics_terms(
        &self,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        t: T,
        m: &mut SMatrix<T, NQ, NQ>,
        h: &mut SVector<T, NQ>,
        phi_q: &mut SMatrix<T, NC, NQ>,
        gamma: &mut SVector<T, NC>,
    ) {
        self.mass_matrix(q, t, m);
        self.bias(q, qd, t, h);
        self.constraint_jacobian(q, t, phi_q);
        self.constraint_rhs(q, qd, t, gamma);
    }

    /// Inverse dynamics: the generalized forces `tau = M qdd + h` that give
    /// the accelerations `qdd` at `(q, qd, t)`, constraint forces left out.
    /// Generated models override it with one program (the time derivative of
    /// the momenta along the motion, cheaper than forming `M`); the default
    /// forms `M` and `h` and multiplies.
    fn inverse_dynamics(
        &self,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        qdd: &SVector<T, NQ>,
        t: T,
        tau: &mut SVector<T, NQ>,
    ) {
        let mut m = SMatrix::<T, NQ, NQ>::zeros();
        self.mass_matrix(q, t, &mut m);
        self.bias(q, qd, t, tau);
        tau.gemv(T::one(), &m, qdd, T::one());
    }
}

/// Inside an `impl Model<NQ, NC, NU> for Wrapper` block, forwards the items a
/// wrapper model usually leaves alone to the wrapped model `$M` stored in
/// field `$inner` (by value or by reference): the names, `mass_matrix`, the
/// four constraint terms with `constraints_and_jacobian`, `actuator_map`,
/// the two energies and the markers (a wrapper does not move them:
/// `marker_jacobian` and `marker_motion`, `marker_pose` by its default). The
/// wrapper
/// writes `bias` (and, where it changes them, `dynamics_terms` and the other
/// provided methods) itself. `$NQ`, `$NC`, `$NU` are the impl's dimensions.
#[macro_export]
macro_rules! forward_model {
    ($inner:tt: $M:ty, $NQ:tt, $NC:tt, $NU:tt) => {
        $crate::forward_model!($inner: $M, $NQ, $NC, $NU, f64);
    };
    ($inner:tt: $M:ty, $NQ:tt, $NC:tt, $NU:tt, $T:ty) => {
        const NAME: &'static str = <$M as $crate::Model<$NQ, $NC, $NU, $T>>::NAME;
        const COORDINATES: [&'static str; $NQ] = <$M as $crate::Model<$NQ, $NC, $NU, $T>>::COORDINATES;
        const ACTUATORS: [&'static str; $NU] = <$M as $crate::Model<$NQ, $NC, $NU, $T>>::ACTUATORS;
        fn mass_matrix(
            &self,
            q: &$crate::nalgebra::SVector<$T, $NQ>,
            t: $T,
            m: &mut $crate::nalgebra::SMatrix<$T, $NQ, $NQ>,
        ) {
            self.$inner.mass_matrix(q, t, m)
        }
        fn constraints(
            &self,
            q: &$crate::nalgebra::SVector<$T, $NQ>,
            t: $T,
            phi: &mut $crate::nalgebra::SVector<$T, $NC>,
        ) {
            self.$inner.constraints(q, t, phi)
        }
        fn constraint_jacobian(
            &self,
            q: &$crate::nalgebra::SVector<$T, $NQ>,
            t: $T,
            phi_q: &mut $crate::nalgebra::SMatrix<$T, $NC, $NQ>,
        ) {
            self.$inner.constraint_jacobian(q, t, phi_q)
        }
        fn constraints_and_jacobian(
            &self,
            q: &$crate::nalgebra::SVector<$T, $NQ>,
            t: $T,
            phi: &mut $crate::nalgebra::SVector<$T, $NC>,
            phi_q: &mut $crate::nalgebra::SMatrix<$T, $NC, $NQ>,
        ) {
            self.$inner.constraints_and_jacobian(q, t, phi, phi_q)
        }
        fn constraint_time_derivative(
            &self,
            q: &$crate::nalgebra::SVector<$T, $NQ>,
            t: $T,
            phi_t: &mut $crate::nalgebra::SVector<$T, $NC>,
        ) {
            self.$inner.constraint_time_derivative(q, t, phi_t)
        }
        fn constraint_rhs(
            &self,
            q: &$crate::nalgebra::SVector<$T, $NQ>,
            qd: &$crate::nalgebra::SVector<$T, $NQ>,
            t: $T,
            gamma: &mut $crate::nalgebra::SVector<$T, $NC>,
        ) {
            self.$inner.constraint_rhs(q, qd, t, gamma)
        }
        fn actuator_map(&self, b: &mut $crate::nalgebra::SMatrix<$T, $NQ, $NU>) {
            self.$inner.actuator_map(b)
        }
        fn actuator_forces(
            &self,
            tau: &$crate::nalgebra::SVector<$T, $NU>,
            f: &mut $crate::nalgebra::SVector<$T, $NQ>,
        ) -> bool {
            self.$inner.actuator_forces(tau, f)
        }
        fn kinetic_energy(
            &self,
            q: &$crate::nalgebra::SVector<$T, $NQ>,
            qd: &$crate::nalgebra::SVector<$T, $NQ>,
            t: $T,
        ) -> $T {
            self.$inner.kinetic_energy(q, qd, t)
        }
        fn potential_energy(&self, q: &$crate::nalgebra::SVector<$T, $NQ>, t: $T) -> $T {
            self.$inner.potential_energy(q, t)
        }
        const MARKERS: &'static [&'static str] = <$M as $crate::Model<$NQ, $NC, $NU, $T>>::MARKERS;
        fn marker_jacobian(
            &self,
            marker: usize,
            q: &$crate::nalgebra::SVector<$T, $NQ>,
            t: $T,
            position: &mut $crate::nalgebra::SVector<$T, 3>,
            rotation: &mut $crate::nalgebra::SMatrix<$T, 3, 3>,
            jacobian: &mut $crate::nalgebra::SMatrix<$T, 6, $NQ>,
        ) -> bool {
            self.$inner.marker_jacobian(marker, q, t, position, rotation, jacobian)
        }
        fn marker_motion(
            &self,
            marker: usize,
            q: &$crate::nalgebra::SVector<$T, $NQ>,
            qd: &$crate::nalgebra::SVector<$T, $NQ>,
            t: $T,
            velocity: &mut $crate::nalgebra::SVector<$T, 6>,
            acceleration_bias: &mut $crate::nalgebra::SVector<$T, 6>,
        ) -> bool {
            self.$inner.marker_motion(marker, q, qd, t, velocity, acceleration_bias)
        }
    };
}

/// Inside an `impl Equations<Q, C, U, T> for Wrapper` block, forwards to
/// the wrapped model in field `$inner` what a wrapper that changes only the
/// bias forces leaves alone: `sizes`, `mass_matrix`, the constraint terms
/// with `constraints_and_jacobian`, `actuator_map` with `actuator_forces`
/// and the two energies.
macro_rules! forward_equations {
    ($inner:ident, $Q:ty, $C:ty, $U:ty, $T:ty) => {
        fn sizes(&self) -> ($Q, $C, $U) {
            self.$inner.sizes()
        }
        fn mass_matrix(
            &self,
            q: &nalgebra::OVector<$T, $Q>,
            t: $T,
            m: &mut nalgebra::OMatrix<$T, $Q, $Q>,
        ) {
            self.$inner.mass_matrix(q, t, m)
        }
        fn constraints(
            &self,
            q: &nalgebra::OVector<$T, $Q>,
            t: $T,
            phi: &mut nalgebra::OVector<$T, $C>,
        ) {
            self.$inner.constraints(q, t, phi)
        }
        fn constraint_jacobian(
            &self,
            q: &nalgebra::OVector<$T, $Q>,
            t: $T,
            phi_q: &mut nalgebra::OMatrix<$T, $C, $Q>,
        ) {
            self.$inner.constraint_jacobian(q, t, phi_q)
        }
        fn constraint_time_derivative(
            &self,
            q: &nalgebra::OVector<$T, $Q>,
            t: $T,
            phi_t: &mut nalgebra::OVector<$T, $C>,
        ) {
            self.$inner.constraint_time_derivative(q, t, phi_t)
        }
        fn constraint_rhs(
            &self,
            q: &nalgebra::OVector<$T, $Q>,
            qd: &nalgebra::OVector<$T, $Q>,
            t: $T,
            gamma: &mut nalgebra::OVector<$T, $C>,
        ) {
            self.$inner.constraint_rhs(q, qd, t, gamma)
        }
        fn actuator_map(&self, b: &mut nalgebra::OMatrix<$T, $Q, $U>) {
            self.$inner.actuator_map(b)
        }
        fn actuator_forces(
            &self,
            tau: &nalgebra::OVector<$T, $U>,
            f: &mut nalgebra::OVector<$T, $Q>,
        ) -> bool {
            self.$inner.actuator_forces(tau, f)
        }
        fn kinetic_energy(
            &self,
            q: &nalgebra::OVector<$T, $Q>,
            qd: &nalgebra::OVector<$T, $Q>,
            t: $T,
        ) -> $T {
            self.$inner.kinetic_energy(q, qd, t)
        }
        fn potential_energy(&self, q: &nalgebra::OVector<$T, $Q>, t: $T) -> $T {
            self.$inner.potential_energy(q, t)
        }
        fn constraints_and_jacobian(
            &self,
            q: &nalgebra::OVector<$T, $Q>,
            t: $T,
            phi: &mut nalgebra::OVector<$T, $C>,
            phi_q: &mut nalgebra::OMatrix<$T, $C, $Q>,
        ) {
            self.$inner.constraints_and_jacobian(q, t, phi, phi_q)
        }
    };
}
pub(crate) use forward_equations;

/// A model with its generated bias Jacobians hidden (the required methods,
/// the runtime parameters and the fused `dynamics_terms` forwarded): the
/// generalized-alpha integrator then builds its Newton matrix by finite
/// differences (`NQ` residual evaluations). For measuring what the generated
/// Jacobians save on a given model.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct FiniteDifferenceJacobians<M>(pub M);

impl<M, const NQ: usize, const NC: usize, const NU: usize, T: Scalar> Model<NQ, NC, NU, T>
    for FiniteDifferenceJacobians<M>
where
    M: Model<NQ, NC, NU, T>,
{
    crate::forward_model!(0: M, NQ, NC, NU, T);
    fn bias(&self, q: &SVector<T, NQ>, qd: &SVector<T, NQ>, t: T, h: &mut SVector<T, NQ>) {
        self.0.bias(q, qd, t, h)
    }
    const PARAMETERS: &'static [&'static str] = M::PARAMETERS;
    fn set_parameter(&mut self, name: &str, value: T) -> bool {
        self.0.set_parameter(name, value)
    }
    fn dynamics_terms(
        &self,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        t: T,
        m: &mut SMatrix<T, NQ, NQ>,
        h: &mut SVector<T, NQ>,
        phi_q: &mut SMatrix<T, NC, NQ>,
        gamma: &mut SVector<T, NC>,
    ) {
        self.0.dynamics_terms(q, qd, t, m, h, phi_q, gamma)
    }
    fn inverse_dynamics(
        &self,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        qdd: &SVector<T, NQ>,
        t: T,
        tau: &mut SVector<T, NQ>,
    ) {
        self.0.inverse_dynamics(q, qd, qdd, t, tau)
    }
}

/// The allocations the solvers make for `Q` coordinates, `C` constraints
/// and `U` inputs: every vector and matrix shape they use. Implemented by
/// nalgebra's `DefaultAllocator` for any dimensions it can allocate: fixed
/// ones (`Const<N>`, on the stack, no heap) always, run-time ones (`Dyn`)
/// where nalgebra's `alloc` feature is on (the command line). Generic code
/// states `where DefaultAllocator: Sizes<Q, C, U>` once for all of them.
pub trait Sizes<Q: Dim, C: Dim, U: Dim>:
    Allocator<Q>
    + Allocator<C>
    + Allocator<U>
    + Allocator<Q, Q>
    + Allocator<C, Q>
    + Allocator<Q, C>
    + Allocator<C, C>
    + Allocator<Q, U>
    + Allocator<U, Q>
    + Allocator<U, U>
    + Allocator<U, C>
    + Allocator<C, U>
{
}

impl<Q: Dim, C: Dim, U: Dim> Sizes<Q, C, U> for DefaultAllocator where
    DefaultAllocator: Allocator<Q>
        + Allocator<C>
        + Allocator<U>
        + Allocator<Q, Q>
        + Allocator<C, Q>
        + Allocator<Q, C>
        + Allocator<C, C>
        + Allocator<Q, U>
        + Allocator<U, Q>
        + Allocator<U, U>
        + Allocator<U, C>
        + Allocator<C, U>
{
}

/// [`Sizes`] and the shapes that `P` prescribed coordinates or outputs add
/// ([`crate::InverseDynamicsOf`], [`crate::control::Servo`]).
pub trait PrescribedSizes<Q: Dim, C: Dim, U: Dim, P: Dim>:
    Sizes<Q, C, U>
    + Allocator<P>
    + Allocator<P, Q>
    + Allocator<C, P>
    + Allocator<P, P>
    + Allocator<P, U>
{
}

impl<Q: Dim, C: Dim, U: Dim, P: Dim> PrescribedSizes<Q, C, U, P> for DefaultAllocator where
    DefaultAllocator: Sizes<Q, C, U>
        + Allocator<P>
        + Allocator<P, Q>
        + Allocator<C, P>
        + Allocator<P, P>
        + Allocator<P, U>
{
}

/// The equations of motion over dimensions `Q` (coordinates), `C`
/// (constraints), `U` (inputs) that are either fixed (`Const<N>`) or known
/// only at run time (`Dyn`): what every solver of this crate calls. A
/// generated [`Model`] is one with fixed dimensions (the blanket
/// implementation below forwards every method); a model of run-time size
/// (the command line's interpreted scenes) implements it with `Dyn`. The
/// methods mean what [`Model`]'s of the same name mean, and write into
/// storage the caller sized ([`Equations::sizes`]).
pub trait Equations<Q: Dim, C: Dim, U: Dim, T: Scalar = f64>
where
    DefaultAllocator: Sizes<Q, C, U>,
{
    /// The numbers of coordinates, constraints and inputs.
    fn sizes(&self) -> (Q, C, U);
    /// [`Model::mass_matrix`].
    fn mass_matrix(&self, q: &OVector<T, Q>, t: T, m: &mut OMatrix<T, Q, Q>);
    /// [`Model::bias`].
    fn bias(&self, q: &OVector<T, Q>, qd: &OVector<T, Q>, t: T, h: &mut OVector<T, Q>);
    /// [`Model::constraints`].
    fn constraints(&self, q: &OVector<T, Q>, t: T, phi: &mut OVector<T, C>);
    /// [`Model::constraint_jacobian`].
    fn constraint_jacobian(&self, q: &OVector<T, Q>, t: T, phi_q: &mut OMatrix<T, C, Q>);
    /// [`Model::constraint_time_derivative`].
    fn constraint_time_derivative(&self, q: &OVector<T, Q>, t: T, phi_t: &mut OVector<T, C>);
    /// [`Model::constraint_rhs`].
    fn constraint_rhs(
        &self,
        q: &OVector<T, Q>,
        qd: &OVector<T, Q>,
        t: T,
        gamma: &mut OVector<T, C>,
    );
    /// [`Model::actuator_map`].
    fn actuator_map(&self, b: &mut OMatrix<T, Q, U>);
    /// [`Model::actuator_forces`] (`false`, not provided, by default).
    fn actuator_forces(&self, tau: &OVector<T, U>, f: &mut OVector<T, Q>) -> bool {
        let _ = (tau, f);
        false
    }
    /// [`Model::kinetic_energy`].
    fn kinetic_energy(&self, q: &OVector<T, Q>, qd: &OVector<T, Q>, t: T) -> T;
    /// [`Model::potential_energy`].
    fn potential_energy(&self, q: &OVector<T, Q>, t: T) -> T;
    /// [`Model::bias_jacobians`].
    fn bias_jacobians(
        &self,
        q: &OVector<T, Q>,
        qd: &OVector<T, Q>,
        t: T,
        h_q: &mut OMatrix<T, Q, Q>,
        h_qd: &mut OMatrix<T, Q, Q>,
    ) -> bool;
    /// [`Model::inverse_dynamics_derivatives`] (`false`, not provided, by
    /// default: a wrapper that changes the forces does not forward it).
    #[allow(clippy::too_many_arguments)]
    fn inverse_dynamics_derivatives(
        &self,
        q: &OVector<T, Q>,
        qd: &OVector<T, Q>,
        qdd: &OVector<T, Q>,
        t: T,
        tau: &mut OVector<T, Q>,
        tau_q: &mut OMatrix<T, Q, Q>,
        tau_qd: &mut OMatrix<T, Q, Q>,
    ) -> bool {
        let _ = (q, qd, qdd, t, tau, tau_q, tau_qd);
        false
    }
    /// [`Model::constraint_acceleration_derivatives`] (`false`, not
    /// provided, by default).
    fn constraint_acceleration_derivatives(
        &self,
        q: &OVector<T, Q>,
        qd: &OVector<T, Q>,
        qdd: &OVector<T, Q>,
        t: T,
        a_q: &mut OMatrix<T, C, Q>,
        a_qd: &mut OMatrix<T, C, Q>,
    ) -> bool {
        let _ = (q, qd, qdd, t, a_q, a_qd);
        false
    }
    /// [`Model::forward_dynamics`] (`false`, not provided, by default: a
    /// wrapper that changes the forces does not forward it).
    fn forward_dynamics(
        &self,
        q: &OVector<T, Q>,
        qd: &OVector<T, Q>,
        f: &OVector<T, Q>,
        t: T,
        qdd: &mut OVector<T, Q>,
        d: &mut OVector<T, Q>,
    ) -> bool {
        let _ = (q, qd, f, t, qdd, d);
        false
    }
    /// [`Model::forward_dynamics_derivatives`] (`false`, not provided, by
    /// default).
    #[allow(clippy::too_many_arguments)]
    fn forward_dynamics_derivatives(
        &self,
        q: &OVector<T, Q>,
        qd: &OVector<T, Q>,
        f: &OVector<T, Q>,
        t: T,
        qdd: &mut OVector<T, Q>,
        d: &mut OVector<T, Q>,
        qdd_q: &mut OMatrix<T, Q, Q>,
        qdd_qd: &mut OMatrix<T, Q, Q>,
        qdd_f: &mut OMatrix<T, Q, Q>,
    ) -> bool {
        let _ = (q, qd, f, t, qdd, d, qdd_q, qdd_qd, qdd_f);
        false
    }
    /// [`Model::constraints_and_jacobian`].
    fn constraints_and_jacobian(
        &self,
        q: &OVector<T, Q>,
        t: T,
        phi: &mut OVector<T, C>,
        phi_q: &mut OMatrix<T, C, Q>,
    );
    /// [`Model::dynamics_terms`].
    #[allow(clippy::too_many_arguments)]
    fn dynamics_terms(
        &self,
        q: &OVector<T, Q>,
        qd: &OVector<T, Q>,
        t: T,
        m: &mut OMatrix<T, Q, Q>,
        h: &mut OVector<T, Q>,
        phi_q: &mut OMatrix<T, C, Q>,
        gamma: &mut OVector<T, C>,
    );
    /// [`Model::inverse_dynamics`].
    fn inverse_dynamics(
        &self,
        q: &OVector<T, Q>,
        qd: &OVector<T, Q>,
        qdd: &OVector<T, Q>,
        t: T,
        tau: &mut OVector<T, Q>,
    );
}

/// Every generated model is one of fixed size (stack storage only).
impl<M, T: Scalar, const NQ: usize, const NC: usize, const NU: usize>
    Equations<Const<NQ>, Const<NC>, Const<NU>, T> for M
where
    M: Model<NQ, NC, NU, T>,
{
    #[inline]
    fn sizes(&self) -> (Const<NQ>, Const<NC>, Const<NU>) {
        (Const, Const, Const)
    }
    #[inline]
    fn mass_matrix(&self, q: &SVector<T, NQ>, t: T, m: &mut SMatrix<T, NQ, NQ>) {
        Model::mass_matrix(self, q, t, m)
    }
    #[inline]
    fn bias(&self, q: &SVector<T, NQ>, qd: &SVector<T, NQ>, t: T, h: &mut SVector<T, NQ>) {
        Model::bias(self, q, qd, t, h)
    }
    #[inline]
    fn constraints(&self, q: &SVector<T, NQ>, t: T, phi: &mut SVector<T, NC>) {
        Model::constraints(self, q, t, phi)
    }
    #[inline]
    fn constraint_jacobian(&self, q: &SVector<T, NQ>, t: T, phi_q: &mut SMatrix<T, NC, NQ>) {
        Model::constraint_jacobian(self, q, t, phi_q)
    }
    #[inline]
    fn constraint_time_derivative(&self, q: &SVector<T, NQ>, t: T, phi_t: &mut SVector<T, NC>) {
        Model::constraint_time_derivative(self, q, t, phi_t)
    }
    #[inline]
    fn constraint_rhs(
        &self,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        t: T,
        gamma: &mut SVector<T, NC>,
    ) {
        Model::constraint_rhs(self, q, qd, t, gamma)
    }
    #[inline]
    fn actuator_map(&self, b: &mut SMatrix<T, NQ, NU>) {
        Model::actuator_map(self, b)
    }
    #[inline]
    fn actuator_forces(&self, tau: &SVector<T, NU>, f: &mut SVector<T, NQ>) -> bool {
        Model::actuator_forces(self, tau, f)
    }
    #[inline]
    fn kinetic_energy(&self, q: &SVector<T, NQ>, qd: &SVector<T, NQ>, t: T) -> T {
        Model::kinetic_energy(self, q, qd, t)
    }
    #[inline]
    fn potential_energy(&self, q: &SVector<T, NQ>, t: T) -> T {
        Model::potential_energy(self, q, t)
    }
    #[inline]
    fn bias_jacobians(
        &self,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        t: T,
        h_q: &mut SMatrix<T, NQ, NQ>,
        h_qd: &mut SMatrix<T, NQ, NQ>,
    ) -> bool {
        Model::bias_jacobians(self, q, qd, t, h_q, h_qd)
    }
    #[inline]
    fn inverse_dynamics_derivatives(
        &self,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        qdd: &SVector<T, NQ>,
        t: T,
        tau: &mut SVector<T, NQ>,
        tau_q: &mut SMatrix<T, NQ, NQ>,
        tau_qd: &mut SMatrix<T, NQ, NQ>,
    ) -> bool {
        Model::inverse_dynamics_derivatives(self, q, qd, qdd, t, tau, tau_q, tau_qd)
    }
    #[inline]
    fn constraint_acceleration_derivatives(
        &self,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        qdd: &SVector<T, NQ>,
        t: T,
        a_q: &mut SMatrix<T, NC, NQ>,
        a_qd: &mut SMatrix<T, NC, NQ>,
    ) -> bool {
        Model::constraint_acceleration_derivatives(self, q, qd, qdd, t, a_q, a_qd)
    }
    #[inline]
    fn forward_dynamics(
        &self,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        f: &SVector<T, NQ>,
        t: T,
        qdd: &mut SVector<T, NQ>,
        d: &mut SVector<T, NQ>,
    ) -> bool {
        Model::forward_dynamics(self, q, qd, f, t, qdd, d)
    }
    #[inline]
    fn forward_dynamics_derivatives(
        &self,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        f: &SVector<T, NQ>,
        t: T,
        qdd: &mut SVector<T, NQ>,
        d: &mut SVector<T, NQ>,
        qdd_q: &mut SMatrix<T, NQ, NQ>,
        qdd_qd: &mut SMatrix<T, NQ, NQ>,
        qdd_f: &mut SMatrix<T, NQ, NQ>,
    ) -> bool {
        Model::forward_dynamics_derivatives(self, q, qd, f, t, qdd, d, qdd_q, qdd_qd, qdd_f)
    }
    #[inline]
    fn constraints_and_jacobian(
        &self,
        q: &SVector<T, NQ>,
        t: T,
        phi: &mut SVector<T, NC>,
        phi_q: &mut SMatrix<T, NC, NQ>,
    ) {
        Model::constraints_and_jacobian(self, q, t, phi, phi_q)
    }
    #[inline]
    fn dynamics_terms(
        &self,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        t: T,
        m: &mut SMatrix<T, NQ, NQ>,
        h: &mut SVector<T, NQ>,
        phi_q: &mut SMatrix<T, NC, NQ>,
        gamma: &mut SVector<T, NC>,
    ) {
        Model::dynamics_terms(self, q, qd, t, m, h, phi_q, gamma)
    }
    #[inline]
    fn inverse_dynamics(
        &self,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        qdd: &SVector<T, NQ>,
        t: T,
        tau: &mut SVector<T, NQ>,
    ) {
        Model::inverse_dynamics(self, q, qd, qdd, t, tau)
    }
}
