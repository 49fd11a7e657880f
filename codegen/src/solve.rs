//! Forward dynamics of unconstrained scenes as one program: `M qdd = f - h`
//! solved on the expression graph, after the prune stage (so that it solves
//! exactly the generated `M` and `h`).
//!
//! `M` is factored as `L^T D L` (`L` unit lower triangular), eliminating
//! from the last coordinate to the first (Featherstone's LTDL, *Rigid Body
//! Dynamics Algorithms*, section 6.5). When every coordinate's ancestors in
//! the mechanism's tree come before it (as the URDF import orders them), the
//! factors keep the sparsity that branches give `M` (no fill-in): entries
//! that are structurally zero stay constant zeros of the graph, and every
//! product with them folds away, so a branched robot's solve costs what its
//! branches do, not `n^3`. In any other order the program is still exact,
//! only denser.

use crate::derive::Equations;
use crate::expr::{Graph, Id, Symbol};

/// Largest scene (coordinates) whose forward dynamics is generated: the
/// dense worst case is `n^3 / 6` products.
pub const MAX_COORDINATES: usize = 40;

/// Sets `eq.forward_dynamics` of an unconstrained scene of at most
/// [`MAX_COORDINATES`] coordinates: `qdd = M^-1 (f - h)` with the
/// generalized forces `f` read from the symbols `Symbol::Qdd` (the program's
/// third input), and the pivots `D` of `M = L^T D L`, each relative to
/// its diagonal entry of `M`.
pub fn forward_dynamics(g: &mut Graph, eq: &mut Equations) {
    let n = eq.mass.len();
    if !eq.phi.is_empty() || n == 0 || n > MAX_COORDINATES {
        return;
    }
    let one = g.constant(1.0);
    let zero = g.constant(0.0);
    let nonzero = |g: &Graph, id: Id| !g.is_const(id, 0.0);
    // H: the lower triangle of M, overwritten by L (below the diagonal)
    // and D (on it).
    let mut h: Vec<Vec<Id>> = (0..n).map(|i| eq.mass[i][..=i].to_vec()).collect();
    let mut inverse = vec![zero; n];
    for k in (0..n).rev() {
        inverse[k] = g.div(one, h[k][k]);
        for i in (0..k).rev() {
            if !nonzero(g, h[k][i]) {
                continue;
            }
            let a = g.mul(h[k][i], inverse[k]);
            let (above, below) = h.split_at_mut(k);
            for (hij, &hkj) in above[i].iter_mut().zip(&below[0][..=i]) {
                if nonzero(g, hkj) {
                    let p = g.mul(hkj, a);
                    *hij = g.sub(*hij, p);
                }
            }
            h[k][i] = a;
        }
    }
    // x = M^-1 (f - h): L^T z = y, then D w = z, then L x = w.
    let mut x: Vec<Id> = (0..n)
        .map(|i| {
            let f = g.symbol(Symbol::Qdd(i as u32));
            g.sub(f, eq.bias[i])
        })
        .collect();
    for i in (0..n).rev() {
        for j in 0..i {
            if nonzero(g, h[i][j]) {
                let p = g.mul(h[i][j], x[i]);
                x[j] = g.sub(x[j], p);
            }
        }
    }
    for (xi, &inv) in x.iter_mut().zip(&inverse) {
        *xi = g.mul(*xi, inv);
    }
    for i in 0..n {
        for j in 0..i {
            if nonzero(g, h[i][j]) {
                let p = g.mul(h[i][j], x[j]);
                x[i] = g.sub(x[i], p);
            }
        }
    }
    // Each pivot relative to its diagonal entry of M (in (0, 1] for a
    // positive definite M), for the runtime's check.
    let pivots = (0..n).map(|k| g.div(h[k][k], eq.mass[k][k])).collect();
    eq.forward_dynamics = Some((x, pivots));
}
