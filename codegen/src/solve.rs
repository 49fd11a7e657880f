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
//!
//! A scene that asks for `dynamics_derivatives` also gets the derivatives of
//! that solution, solved with the same factors: each column of `-d ID/dq`
//! and `-d ID/dqd` (the inverse dynamics' derivatives at the solved `qdd`)
//! and of the identity (`M^-1`).

use crate::derive::Equations;
use crate::expr::{Graph, Id, Symbol};

/// Largest scene (coordinates) whose forward dynamics is generated: the
/// dense worst case is `n^3 / 6` products.
pub const MAX_COORDINATES: usize = 40;

/// Sets `eq.forward_dynamics` of an unconstrained scene of at most
/// [`MAX_COORDINATES`] coordinates: `qdd = M^-1 (f - h)` with the
/// generalized forces `f` read from the symbols `Symbol::Qdd` (the program's
/// third input), and the pivots `D` of `M = L^T D L`, each relative to
/// its diagonal entry of `M`; and, where the scene has the inverse
/// dynamics' derivatives, `eq.forward_dynamics_derivatives`: `ID(q, qd,
/// qdd(q, qd, f)) = f` differentiated gives `M d qdd/dx = -d ID/dx` at that
/// `qdd` (`x` = `q`, `qd`) and `d qdd/df = M^-1`, every column solved with
/// the same factors.
pub fn forward_dynamics(g: &mut Graph, eq: &mut Equations) {
    let n = eq.mass.len();
    if !eq.phi.is_empty() || n == 0 || n > MAX_COORDINATES {
        return;
    }
    let factors = Factors::new(g, &eq.mass);
    let forces: Vec<Id> = (0..n)
        .map(|i| {
            let f = g.symbol(Symbol::Qdd(i as u32));
            g.sub(f, eq.bias[i])
        })
        .collect();
    let qdd = factors.solve(g, forces);
    eq.forward_dynamics_derivatives =
        eq.inverse_dynamics_derivatives
            .as_ref()
            .map(|(id_q, id_qd)| {
                let rows: Vec<Id> = id_q.iter().chain(id_qd).flatten().copied().collect();
                let at = g.substitute(&rows, &|s| match s {
                    Symbol::Qdd(i) => Some(qdd[i as usize]),
                    _ => None,
                });
                let zero = g.constant(0.0);
                let one = g.constant(1.0);
                // The n x n matrix whose column j solves M x = column(i, j).
                let solved = |g: &mut Graph, column: &dyn Fn(&mut Graph, usize, usize) -> Id| {
                    let columns: Vec<Vec<Id>> = (0..n)
                        .map(|j| {
                            let rhs = (0..n).map(|i| column(g, i, j)).collect();
                            factors.solve(g, rhs)
                        })
                        .collect();
                    (0..n)
                        .map(|i| columns.iter().map(|c| c[i]).collect())
                        .collect::<Vec<Vec<Id>>>()
                };
                let qdd_q = solved(g, &|g, i, j| g.neg(at[i * n + j]));
                let qdd_qd = solved(g, &|g, i, j| g.neg(at[n * n + i * n + j]));
                let inverse = solved(g, &|_, i, j| if i == j { one } else { zero });
                (qdd_q, qdd_qd, inverse)
            });
    // Each pivot relative to its diagonal entry of M (in (0, 1] for a
    // positive definite M), for the runtime's check.
    let pivots = (0..n)
        .map(|k| g.div(factors.h[k][k], eq.mass[k][k]))
        .collect();
    eq.forward_dynamics = Some((qdd, pivots));
}

/// `M = L^T D L`: `L` below the diagonal of `h`, `D` on it, and the
/// reciprocals of `D`.
struct Factors {
    h: Vec<Vec<Id>>,
    inverse: Vec<Id>,
}

impl Factors {
    /// The factors of the symmetric `mass` (its lower triangle read).
    fn new(g: &mut Graph, mass: &[Vec<Id>]) -> Factors {
        let n = mass.len();
        let one = g.constant(1.0);
        let zero = g.constant(0.0);
        // H: the lower triangle of M, overwritten by L (below the diagonal)
        // and D (on it).
        let mut h: Vec<Vec<Id>> = (0..n).map(|i| mass[i][..=i].to_vec()).collect();
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
        Factors { h, inverse }
    }

    /// `M^-1 y`: `L^T z = y`, then `D w = z`, then `L x = w`.
    fn solve(&self, g: &mut Graph, mut x: Vec<Id>) -> Vec<Id> {
        let (h, n) = (&self.h, x.len());
        for i in (0..n).rev() {
            for j in 0..i {
                if nonzero(g, h[i][j]) && nonzero(g, x[i]) {
                    let p = g.mul(h[i][j], x[i]);
                    x[j] = g.sub(x[j], p);
                }
            }
        }
        for (xi, &inv) in x.iter_mut().zip(&self.inverse) {
            *xi = g.mul(*xi, inv);
        }
        for i in 0..n {
            for j in 0..i {
                if nonzero(g, h[i][j]) && nonzero(g, x[j]) {
                    let p = g.mul(h[i][j], x[j]);
                    x[i] = g.sub(x[i], p);
                }
            }
        }
        x
    }
}

/// Whether a node is not the constant zero.
fn nonzero(g: &Graph, id: Id) -> bool {
    !g.is_const(id, 0.0)
}
