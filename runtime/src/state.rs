//! Simulation state, finiteness checks, constraint drift and energy.

use crate::error::{Error, ErrorKind, Quantity};
use crate::linalg::first_non_finite;
use crate::model::Model;
use crate::scalar::Scalar;
use nalgebra::{SMatrix, SVector};

/// State of a simulation: generalized coordinates, velocities and time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct State<const NQ: usize, T: Scalar = f64> {
    /// Generalized coordinates `q`.
    pub q: SVector<T, NQ>,
    /// Generalized velocities `qd`.
    pub qd: SVector<T, NQ>,
    /// Time `t`.
    pub t: T,
}

impl<T: Scalar, const NQ: usize> State<NQ, T> {
    /// Creates a state.
    pub fn new(q: SVector<T, NQ>, qd: SVector<T, NQ>, t: T) -> Self {
        State { q, qd, t }
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
pub fn constraint_drift<M, T: Scalar, const NQ: usize, const NC: usize, const NU: usize>(
    model: &M,
    state: &State<NQ, T>,
) -> Drift<T>
where
    M: Model<NQ, NC, NU, T>,
{
    if NC == 0 {
        return Drift::default();
    }
    let mut phi = SVector::<T, NC>::zeros();
    let mut phi_q = SMatrix::<T, NC, NQ>::zeros();
    let mut phi_t = SVector::<T, NC>::zeros();
    model.constraints(&state.q, state.t, &mut phi);
    model.constraint_jacobian(&state.q, state.t, &mut phi_q);
    model.constraint_time_derivative(&state.q, state.t, &mut phi_t);
    let vel = phi_q * state.qd + phi_t;
    Drift {
        position: inf_norm(&phi),
        velocity: inf_norm(&vel),
    }
}

/// Total mechanical energy `T + V` of `state`.
pub fn total_energy<M, T: Scalar, const NQ: usize, const NC: usize, const NU: usize>(
    model: &M,
    state: &State<NQ, T>,
) -> T
where
    M: Model<NQ, NC, NU, T>,
{
    model.kinetic_energy(&state.q, &state.qd, state.t) + model.potential_energy(&state.q, state.t)
}

/// Infinity norm of a vector (NaN if any entry is NaN; 0 for an empty vector).
pub(crate) fn inf_norm<T: Scalar, const N: usize>(v: &SVector<T, N>) -> T {
    crate::linalg::max_abs(v)
}

/// The bits of `x` widened to `f64` (exact, so equal bits mean equal values).
fn bits<T: Scalar>(x: T) -> u64 {
    let x: f64 = x.into();
    x.to_bits()
}
