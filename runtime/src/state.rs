//! Simulation state, finiteness checks, constraint drift and energy.

use crate::error::{Error, ErrorKind, Quantity};
use crate::linalg::first_non_finite;
use crate::model::Model;
use nalgebra::{SMatrix, SVector};

/// State of a simulation: generalized coordinates, velocities and time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct State<const NQ: usize> {
    /// Generalized coordinates `q`.
    pub q: SVector<f64, NQ>,
    /// Generalized velocities `qd`.
    pub qd: SVector<f64, NQ>,
    /// Time `t`.
    pub t: f64,
}

impl<const NQ: usize> State<NQ> {
    /// Creates a state.
    pub fn new(q: SVector<f64, NQ>, qd: SVector<f64, NQ>, t: f64) -> Self {
        State { q, qd, t }
    }

    /// Checks that `q`, `qd` and `t` are finite.
    pub fn check_finite(&self) -> Result<(), Error> {
        if !self.t.is_finite() {
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
        self.t.to_bits() == other.t.to_bits()
            && self
                .q
                .iter()
                .zip(other.q.iter())
                .all(|(a, b)| a.to_bits() == b.to_bits())
            && self
                .qd
                .iter()
                .zip(other.qd.iter())
                .all(|(a, b)| a.to_bits() == b.to_bits())
    }
}

/// Constraint drift of a state: infinity norms of the position residual
/// `Phi(q, t)` and of the velocity residual `Phi_q qd + Phi_t`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Drift {
    /// `max_i |Phi_i(q, t)|`.
    pub position: f64,
    /// `max_i |(Phi_q qd + Phi_t)_i|`.
    pub velocity: f64,
}

/// Measures the constraint drift of `state`. Non-finite model outputs give a
/// non-finite drift (no error: this is a diagnostic).
pub fn constraint_drift<M, const NQ: usize, const NC: usize, const NU: usize>(
    model: &M,
    state: &State<NQ>,
) -> Drift
where
    M: Model<NQ, NC, NU>,
{
    if NC == 0 {
        return Drift::default();
    }
    let mut phi = SVector::<f64, NC>::zeros();
    let mut phi_q = SMatrix::<f64, NC, NQ>::zeros();
    let mut phi_t = SVector::<f64, NC>::zeros();
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
pub fn total_energy<M, const NQ: usize, const NC: usize, const NU: usize>(
    model: &M,
    state: &State<NQ>,
) -> f64
where
    M: Model<NQ, NC, NU>,
{
    model.kinetic_energy(&state.q, &state.qd, state.t) + model.potential_energy(&state.q, state.t)
}

/// Infinity norm of a vector (NaN if any entry is NaN; 0 for an empty vector).
pub(crate) fn inf_norm<const N: usize>(v: &SVector<f64, N>) -> f64 {
    crate::linalg::max_abs(v)
}
