//! Whether `f32` resolves a scene's dynamics: the spread of its linearised
//! stiffness, checked before an `f32` module is emitted.
//!
//! At rest the equations of motion linearise to `M x'' + K x = 0` with `K =
//! d(dV/dq)/dq` (gravity and elastic forces; the velocity terms vanish at
//! `qd = 0`). The generalized eigenvalues `lambda_i` of `(K, M)` are the
//! squared frequencies of the modes (negative for gravity-unstable ones,
//! zero for free rigid-body motion). A computation in precision `eps`
//! resolves forces only to `eps` times the largest, so where the stiffest
//! mode's `|lambda_max|` exceeds the softest non-zero one's by more than `1 /
//! eps` (`8.4e6` in `f32`), the soft modes' restoring forces are below the
//! rounding of the stiff ones: the stiff coordinates' deflections under the
//! loads of the slow motion (`load / stiffness`) fall below the resolution
//! of the positions they are added to, and the computed elastic state is
//! rounding noise.
//!
//! The spread is taken at the same sample states as pruning (uniform in the
//! declared coordinate ranges, fixed seed), the largest over them; `M` and
//! `K` are evaluated exactly (symbolic derivatives) in `f64`, whose own
//! resolution (`lambda` below `n eps_64 |lambda_max|`, with a margin of
//! 100) marks the zero modes excluded from the softest.

use crate::derive::Equations;
use crate::expr::Symbol;
use crate::model::Model;
use crate::samples::Samples;
use nalgebra::{DMatrix, SymmetricEigen};

/// The largest stiffness spread an `f32` module is generated for: `1 /
/// eps_32`.
pub(crate) const F32_MAX_STIFFNESS_SPREAD: f64 = 1.0 / f32::EPSILON as f64;

/// The widest stiffness spread of a scene over its sample states.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct StiffnessSpread {
    /// `|lambda_max| / |lambda_min|` (1 with no stiffness at all).
    pub(crate) spread: f64,
    /// The stiffest mode's `|lambda|` (1/s^2) and its three largest
    /// coordinates (by share of the mode's kinetic energy).
    pub(crate) stiff: (f64, Vec<String>),
    /// The softest non-zero mode's `|lambda|` and coordinates.
    pub(crate) soft: (f64, Vec<String>),
}

/// The three coordinates of `names` carrying most of mode `v` of `L^-1 K
/// L^-T` (coordinates `x = L^-T v`, shares `|x_i| sqrt(M_ii)`).
fn main_coordinates(
    l: &DMatrix<f64>,
    m: &DMatrix<f64>,
    v: &[f64],
    names: &[String],
) -> Vec<String> {
    let mut x = DMatrix::from_column_slice(v.len(), 1, v);
    if !l.transpose().solve_upper_triangular_mut(&mut x) {
        return Vec::new();
    }
    let mut share: Vec<(f64, usize)> = (0..v.len())
        .map(|i| (x[i].abs() * m[(i, i)].max(0.0).sqrt(), i))
        .collect();
    share.sort_by(|a, b| b.0.total_cmp(&a.0));
    share
        .iter()
        .take(3)
        .map(|&(_, i)| names[i].clone())
        .collect()
}

/// The widest stiffness spread of `model` over the sample states (module
/// docs); `None` when no sample has a positive definite mass matrix.
pub(crate) fn stiffness_spread(model: &Model, eq: &Equations) -> Option<StiffnessSpread> {
    let n = model.nq();
    let mut g = model.graph.clone();
    let q: Vec<Symbol> = (0..n).map(|i| Symbol::Q(i as u32)).collect();
    let k = g.jacobian(&eq.potential_forces, &q);
    let roots: Vec<_> = eq.mass.iter().chain(&k).flatten().copied().collect();
    let names: Vec<String> = model.coordinates.iter().map(|c| c.name.clone()).collect();
    let mut widest: Option<StiffnessSpread> = None;
    Samples::new(&model.coordinates).each(&g, &roots, &model.runtime_parameters, |values| {
        let m = DMatrix::from_row_slice(n, n, &values[..n * n]);
        let k = DMatrix::from_row_slice(n, n, &values[n * n..]);
        let Some(chol) = m.clone().cholesky() else {
            return;
        };
        let l = chol.l();
        let Some(li) = l.clone().try_inverse() else {
            return;
        };
        let a = &li * k * li.transpose();
        let eigen = SymmetricEigen::new((&a + a.transpose()) * 0.5);
        let size = |j: usize| eigen.eigenvalues[j].abs();
        let Some(stiff) = (0..n).max_by(|&i, &j| size(i).total_cmp(&size(j))) else {
            return;
        };
        let zero = 100.0 * n as f64 * f64::EPSILON * size(stiff);
        let Some(soft) = (0..n)
            .filter(|&j| size(j) > zero)
            .min_by(|&i, &j| size(i).total_cmp(&size(j)))
        else {
            return;
        };
        let spread = size(stiff) / size(soft);
        if !spread.is_finite() || widest.as_ref().is_some_and(|w| w.spread >= spread) {
            return;
        }
        let mode = |j: usize| {
            let v: Vec<f64> = eigen.eigenvectors.column(j).iter().copied().collect();
            (size(j), main_coordinates(&l, &m, &v, &names))
        };
        widest = Some(StiffnessSpread {
            spread,
            stiff: mode(stiff),
            soft: mode(soft),
        });
    });
    widest
}
