//! Simulation state, finiteness checks, constraint drift and energy.

use crate::error::{Error, ErrorKind, Quantity};
use crate::linalg::first_non_finite;
use crate::model::{Equations, Sizes};
use crate::scalar::Scalar;
use nalgebra::allocator::Allocator;
use nalgebra::{Const, DefaultAllocator, Dim, OVector};

/// State of a simulation: generalized coordinates, velocities and time, for
/// `Q` coordinates of fixed or run-time size ([`State`]: fixed).
#[derive(Clone, Debug, PartialEq)]
pub struct StateOf<T: Scalar, Q: Dim>
where
    DefaultAllocator: Allocator<Q>,
{
    /// Generalized coordinates `q`.
    pub q: OVector<T, Q>,
    /// Generalized velocities `qd`.
    pub qd: OVector<T, Q>,
    /// Time `t`.
    pub t: T,
}

impl<T: Scalar, const NQ: usize> Copy for StateOf<T, Const<NQ>> {}

/// [`StateOf`] of a model of fixed size: `NQ` coordinates on the stack.
pub type State<const NQ: usize, T = f64> = StateOf<T, Const<NQ>>;

impl<T: Scalar, Q: Dim> StateOf<T, Q>
where
    DefaultAllocator: Allocator<Q>,
{
    /// Creates a state.
    pub fn new(q: OVector<T, Q>, qd: OVector<T, Q>, t: T) -> Self {
        StateOf { q, qd, t }
    }

    /// Checks that `q`, `qd` and `t` are finite.
    pub fn check_finite(&self) -> Result<(), Error> {
        if !self.t.finite() {
            return Err(Error::new(
                ErrorKind::NonFiniteState {
                    quantity: Quantity::Time,
                    index: 0,
                },
                self.t,
            ));
        }
        if let Some(index) = first_non_finite(&self.q) {
            return Err(Error::new(
                ErrorKind::NonFiniteState {
                    quantity: Quantity::Position,
                    index,
                },
                self.t,
            ));
        }
        if let Some(index) = first_non_finite(&self.qd) {
            return Err(Error::new(
                ErrorKind::NonFiniteState {
                    quantity: Quantity::Velocity,
                    index,
                },
                self.t,
            ));
        }
        Ok(())
    }

    /// True if the two states are bit-for-bit identical (used to validate
    /// integrator memory).
    pub(crate) fn same_bits(&self, other: &Self) -> bool {
        bits(self.t) == bits(other.t)
            && self
                .q
                .iter()
                .zip(other.q.iter())
                .all(|(a, b)| bits(*a) == bits(*b))
            && self
                .qd
                .iter()
                .zip(other.qd.iter())
                .all(|(a, b)| bits(*a) == bits(*b))
    }
}

/// Constraint drift of a state: infinity norms of the position residual
/// `Phi(q, t)` and of the velocity residual `Phi_q qd + Phi_t`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Drift<T: Scalar = f64> {
    /// `max_i |Phi_i(q, t)|`.
    pub position: T,
    /// `max_i |(Phi_q qd + Phi_t)_i|`.
    pub velocity: T,
}

/// Measures the constraint drift of `state`. Non-finite model outputs give a
/// non-finite drift (no error: this is a diagnostic).
pub fn constraint_drift<M, T: Scalar, Q: Dim, C: Dim, U: Dim>(
    model: &M,
    state: &StateOf<T, Q>,
) -> Drift<T>
where
    M: Equations<Q, C, U, T> + ?Sized,
    DefaultAllocator: Sizes<Q, C, U>,
{
    let (nq, nc, _) = model.sizes();
    if nc.value() == 0 {
        return Drift::default();
    }
    let mut phi = OVector::<T, C>::zeros_generic(nc, nalgebra::U1);
    let mut phi_q = nalgebra::OMatrix::<T, C, Q>::zeros_generic(nc, nq);
    let mut phi_t = OVector::<T, C>::zeros_generic(nc, nalgebra::U1);
    model.constraints(&state.q, state.t, &mut phi);
    model.constraint_jacobian(&state.q, state.t, &mut phi_q);
    model.constraint_time_derivative(&state.q, state.t, &mut phi_t);
    let vel = phi_q * &state.qd + phi_t;
    Drift {
        position: inf_norm(&phi),
        velocity: inf_norm(&vel),
    }
}

/// Total mechanical energy `T + V` of `state`.
pub fn total_energy<M, T: Scalar, Q: Dim, C: Dim, U: Dim>(model: &M, state: &StateOf<T, Q>) -> T
where
    M: Equations<Q, C, U, T> + ?Sized,
    DefaultAllocator: Sizes<Q, C, U>,
{
    model.kinetic_energy(&state.q, &state.qd, state.t) + model.potential_energy(&state.q, state.t)
}

/// Infinity norm of a vector (NaN if any entry is NaN; 0 for an empty vector).
pub(crate) fn inf_norm<T: Scalar, N: Dim>(v: &OVector<T, N>) -> T
where
    DefaultAllocator: Allocator<N>,
{
    crate::linalg::max_abs(v)
}

/// The bits of `x` widened to `f64` (exact, so equal bits mean equal values).
fn bits<T: Scalar>(x: T) -> u64 {
    let x: f64 = x.into();
    x.to_bits()
}
