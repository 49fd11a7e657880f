//! Redundant constraints, found and dropped before the derivation (model
//! only what a scene needs): real mechanisms are often written with more
//! constraint rows than they remove freedoms (a planar loop closed with a
//! 3-D `coincident` constraint, whose out-of-plane row is identically zero;
//! over-constrained parallel mechanisms), and the runtime's constraint
//! solves need independent rows.
//!
//! - A residual that is the constant zero is dropped; a nonzero constant is
//!   an error (no configuration satisfies it).
//! - The others are checked numerically, on the constraint manifold: sample
//!   configurations from the declared ranges ([`Samples`]) are projected
//!   onto `Phi(q, t) = 0` by Gauss-Newton with minimum-norm steps, and at
//!   each projected configuration the rows of the Jacobian `Phi_q` are
//!   taken in the scene's order, a row being dependent when its part
//!   orthogonal to the rows kept before it is below [`DEPENDENT`] of its
//!   norm. A row dependent at every projected configuration (at least
//!   [`AGREEING`] of them) is dropped, with a note naming it and the rows it
//!   depends on. Where no configuration can be projected and some rows
//!   depend on others there, the set is inconsistent: an error naming them.
//!
//! Runtime parameters are taken at their nominal values.

use std::cmp::Ordering;

use nalgebra::{DMatrix, DVector};

use crate::expr::{Graph, Id, Node, Symbol};
use crate::model::{Constraint, Model};
use crate::samples::Samples;

/// A row is dependent on the rows before it when its part orthogonal to
/// them is below this fraction of its norm.
pub const DEPENDENT: f64 = 1e-8;

/// Projected configurations that must agree before a row is dropped.
pub const AGREEING: usize = 3;

/// Starting configurations tried.
const STARTS: usize = 8;

/// Gauss-Newton iterations per start.
const ITERATIONS: usize = 60;

/// Most sweeps of one SVD.
const SVD_SWEEPS: usize = 200;

/// A constraint set no configuration satisfies: where (the definition of
/// the first constraint named), which constraint, and why.
pub(crate) struct Unsatisfiable {
    /// Byte offset of the constraint's definition in the scene file.
    pub(crate) at: usize,
    /// `constraint `name``.
    pub(crate) context: String,
    /// What is wrong.
    pub(crate) message: String,
}

/// Drops `model`'s redundant constraints, noting each in `model.notes`; an
/// error naming the constraints of a set no configuration satisfies.
pub(crate) fn drop_redundant(model: &mut Model) -> Result<(), Unsatisfiable> {
    let mut kept = Vec::with_capacity(model.constraints.len());
    for c in std::mem::take(&mut model.constraints) {
        match *model.graph.node(c.residual) {
            Node::Const(k) if k.get() == 0.0 => model.notes.push(format!(
                "constraint `{}` dropped: its residual is identically zero (a planar \
                 mechanism's out-of-plane row, for example)",
                c.name
            )),
            Node::Const(k) => {
                return Err(Unsatisfiable {
                    at: c.at,
                    context: format!("constraint `{}`", c.name),
                    message: format!(
                        "its residual is the constant {:e}, which no configuration can make zero",
                        k.get()
                    ),
                })
            }
            _ => kept.push(c),
        }
    }
    model.constraints = kept;
    if model.constraints.len() < 2 {
        return Ok(());
    }
    // On a copy of the graph: the Jacobian's nodes must not change the
    // numbering, and so the order of sums, of what is derived later.
    let mut graph = model.graph.clone();
    let manifold = Manifold::new(model, &mut graph);
    let mut dependent: Option<Vec<bool>> = None;
    let mut projected = 0;
    let mut stuck: Vec<(DVector<f64>, Vec<bool>)> = Vec::new();
    for (q, t) in Samples::new(&model.coordinates).positions().take(STARTS) {
        let (q, converged) = manifold.project(&graph, q, t);
        let rows = manifold.dependent_rows(&graph, &q, t);
        if converged {
            projected += 1;
            let d = dependent.get_or_insert_with(|| rows.clone());
            d.iter_mut().zip(&rows).for_each(|(a, b)| *a &= b);
        } else {
            stuck.push((manifold.residuals(&graph, &q, t), rows));
        }
    }
    let names = |rows: &mut dyn Iterator<Item = usize>| {
        rows.map(|j| format!("`{}`", model.constraints[j].name))
            .collect::<Vec<_>>()
            .join(", ")
    };
    if projected == 0 {
        // Nowhere consistent: an inconsistent set when the same rows depend
        // on others at every least-squares point the iteration stopped at
        // (contradicting equations), else left to the runtime (the ranges
        // may miss the mechanism's closure, or the starts its basin).
        let same = stuck.iter().all(|(_, rows)| *rows == stuck[0].1);
        if let Some((r, rows)) = stuck
            .first()
            .filter(|(_, rows)| same && rows.contains(&true))
        {
            let deps: Vec<usize> = (0..rows.len()).filter(|&j| rows[j]).collect();
            let largest = (0..r.len())
                .max_by(|&a, &b| r[a].abs().total_cmp(&r[b].abs()))
                .unwrap_or(0);
            let first = &model.constraints[deps[0]];
            return Err(Unsatisfiable {
                at: first.at,
                context: format!("constraint `{}`", first.name),
                message: format!(
                    "the constraints cannot all hold: from {STARTS} configurations of the \
                     declared ranges, Gauss-Newton stops where the Jacobian rows of {} are \
                     combinations of the rows before them and the residuals stay (largest: `{}` \
                     = {:e}); the set contradicts itself",
                    names(&mut deps.into_iter()),
                    model.constraints[largest].name,
                    r[largest]
                ),
            });
        }
        return Ok(());
    }
    let Some(dependent) = dependent.filter(|_| projected >= AGREEING) else {
        return Ok(());
    };
    if !dependent.iter().any(|&d| d) {
        return Ok(());
    }
    let independent: Vec<usize> = (0..dependent.len()).filter(|&j| !dependent[j]).collect();
    for (j, _) in dependent.iter().enumerate().filter(|(_, &d)| d) {
        let before: Vec<usize> = independent.iter().copied().filter(|&i| i < j).collect();
        let row = match before.is_empty() {
            true => "zero".to_owned(),
            false => format!("a combination of {}", names(&mut before.into_iter())),
        };
        model.notes.push(format!(
            "constraint `{}` dropped: redundant, its Jacobian row {row} at every one of \
             {projected} configurations on the constraints (its force is carried by the others)",
            model.constraints[j].name,
        ));
    }
    let mut j = 0;
    model.constraints.retain(|_| {
        j += 1;
        !dependent[j - 1]
    });
    Ok(())
}

/// The constraints' residuals and Jacobian as graph nodes.
struct Manifold {
    residuals: Vec<Id>,
    /// Row-major `m x n`.
    jacobian: Vec<Id>,
    n: usize,
    params: Vec<f64>,
}

impl Manifold {
    /// The terms of `model`'s constraints, built in `g` (a copy of its
    /// graph).
    fn new(model: &Model, g: &mut Graph) -> Manifold {
        let n = model.nq();
        let residuals: Vec<Id> = model
            .constraints
            .iter()
            .map(|c: &Constraint| c.residual)
            .collect();
        let mut jacobian = Vec::with_capacity(residuals.len() * n);
        for &r in &residuals {
            for i in 0..n {
                jacobian.push(g.diff(r, Symbol::Q(i as u32)));
            }
        }
        let params = model.runtime_parameters.iter().map(|p| p.value).collect();
        Manifold {
            residuals,
            jacobian,
            n,
            params,
        }
    }

    fn eval(&self, g: &Graph, roots: &[Id], q: &DVector<f64>, t: f64) -> Vec<f64> {
        g.eval(roots, &|s| match s {
            Symbol::Q(i) => q[i as usize],
            Symbol::Time => t,
            Symbol::Param(i) => self.params[i as usize],
            Symbol::Qd(_) | Symbol::Qdd(_) => 0.0,
        })
    }

    fn residuals(&self, g: &Graph, q: &DVector<f64>, t: f64) -> DVector<f64> {
        DVector::from_vec(self.eval(g, &self.residuals, q, t))
    }

    fn jacobian(&self, g: &Graph, q: &DVector<f64>, t: f64) -> DMatrix<f64> {
        let m = self.residuals.len();
        DMatrix::from_row_slice(m, self.n, &self.eval(g, &self.jacobian, q, t))
    }

    /// `q` moved onto the constraints by Gauss-Newton with minimum-norm
    /// steps (halved while they do not reduce the residual), and whether it
    /// got there (residual within `1e-10 (1 + |Phi_q|)`).
    fn project(&self, g: &Graph, q: Vec<f64>, t: f64) -> (DVector<f64>, bool) {
        let mut q = DVector::from_vec(q);
        let mut r = self.residuals(g, &q, t);
        for _ in 0..ITERATIONS {
            let j = self.jacobian(g, &q, t);
            let scale = 1.0 + j.amax();
            // Small, or not a number.
            if r.amax().partial_cmp(&(1e-10 * scale)) != Some(Ordering::Greater) {
                return (q, r.amax() <= 1e-10 * scale);
            }
            // A non-finite Jacobian or residual ends the iteration (the
            // SVD's sweeps would not converge on it), and so does an SVD
            // that does not converge in a bounded number of sweeps.
            let finite = j.iter().chain(r.iter()).all(|x| x.is_finite());
            let Some(svd) = finite
                .then(|| j.try_svd(true, true, f64::EPSILON, SVD_SWEEPS))
                .flatten()
            else {
                break;
            };
            let Ok(step) = svd.solve(&r, 1e-12 * scale) else {
                break;
            };
            let mut h = 1.0;
            loop {
                let trial = &q - h * &step;
                let rt = self.residuals(g, &trial, t);
                if rt.norm() < r.norm() || h < 1e-3 {
                    (q, r) = (trial, rt);
                    break;
                }
                h *= 0.5;
            }
        }
        let scale = 1.0 + self.jacobian(g, &q, t).amax();
        let done = r.amax() <= 1e-10 * scale;
        (q, done)
    }

    /// The rows of `Phi_q` at `q` that depend on the rows before them.
    fn dependent_rows(&self, g: &Graph, q: &DVector<f64>, t: f64) -> Vec<bool> {
        dependent_rows(&self.jacobian(g, q, t))
    }
}

/// The rows of `jacobian` that depend on the rows before them: whose part
/// orthogonal to the independent rows before them is below [`DEPENDENT`]
/// of their norm (zero rows included). Taken in order, so of a dependent
/// set the last row is named.
pub fn dependent_rows(jacobian: &DMatrix<f64>) -> Vec<bool> {
    let mut basis: Vec<DVector<f64>> = Vec::new();
    let mut dependent = Vec::with_capacity(jacobian.nrows());
    for row in jacobian.row_iter() {
        let mut v: DVector<f64> = row.transpose();
        let norm = v.norm();
        // Twice, for orthogonality to round-off.
        for _ in 0..2 {
            for b in &basis {
                let c = b.dot(&v);
                v -= c * b;
            }
        }
        let rest = v.norm();
        if norm == 0.0 || rest.partial_cmp(&(DEPENDENT * norm)) != Some(Ordering::Greater) {
            dependent.push(true);
        } else {
            dependent.push(false);
            basis.push(v / rest);
        }
    }
    dependent
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use crate::error::Source;
    use crate::model::Model;

    /// A point mass in the plane, `x` and `y`, with the given constraints
    /// (TOML of `[[constraints]]` tables).
    fn model(constraints: &str) -> Result<Model, String> {
        let text = format!(
            "name = \"p\"\n[[coordinates]]\nname = \"x\"\n[[coordinates]]\nname = \"y\"\n\
             [[coordinates]]\nname = \"z\"\n[[components]]\nname = \"m\"\ntype = \
             \"point_mass\"\nmass = 1\nposition = [\"x\", \"y\", \"z\"]\n{constraints}"
        );
        Model::from_source(&Source::new(Path::new("p.toml"), text)).map_err(|e| e.to_string())
    }

    fn names(m: &Model) -> Vec<&str> {
        m.constraints.iter().map(|c| c.name.as_str()).collect()
    }

    #[test]
    fn zero_rows_are_dropped_and_nonzero_constants_refused() {
        // A circle in the plane z = 0 written as a coincident constraint of
        // the world origin with itself is all zero rows.
        let m = model(
            "[[constraints]]\nname = \"circle\"\nexpression = \"x*x + y*y - 1\"\n\
             [[constraints]]\nname = \"same\"\ntype = \"coincident\"\na = {}\n",
        )
        .unwrap();
        assert_eq!(names(&m), ["circle"]);
        assert_eq!(m.notes.len(), 3, "{:?}", m.notes);
        assert!(m.notes[0].contains("`same_x` dropped: its residual is identically zero"));
        let e = model("[[constraints]]\nname = \"two\"\nexpression = \"x - x + 2\"\n").unwrap_err();
        assert!(
            e.starts_with("p.toml:")
                && e.contains("in constraint `two`: its residual is the constant 2e0"),
            "{e}"
        );
    }

    #[test]
    fn dependent_rows_are_dropped_naming_what_they_depend_on() {
        // On the sphere's equator: the third row is a combination of the
        // first two everywhere on the constraints (not away from them:
        // 2 z (z) vs z there).
        let m = model(
            "[[constraints]]\nname = \"sphere\"\nexpression = \"x*x + y*y + z*z - 1\"\n\
             [[constraints]]\nname = \"plane\"\nexpression = \"z\"\n\
             [[constraints]]\nname = \"cylinder\"\nexpression = \"x*x + y*y - 1\"\n",
        )
        .unwrap();
        assert_eq!(names(&m), ["sphere", "plane"], "{:?}", m.notes);
        assert!(
            m.notes[0].contains(
                "`cylinder` dropped: redundant, its Jacobian row a combination \
                                 of `sphere`, `plane` at every one of 8 configurations"
            ),
            "{:?}",
            m.notes
        );
        // Independent rows stay, without notes.
        let m = model(
            "[[constraints]]\nname = \"a\"\nexpression = \"x - y\"\n\
             [[constraints]]\nname = \"b\"\nexpression = \"y - z*z\"\n",
        )
        .unwrap();
        assert_eq!(names(&m), ["a", "b"]);
        assert!(m.notes.is_empty());
    }

    #[test]
    fn contradicting_constraints_are_named() {
        let e = model(
            "[[constraints]]\nname = \"here\"\nexpression = \"x + y\"\n\
             [[constraints]]\nname = \"there\"\nexpression = \"2*x + 2*y - 1\"\n",
        )
        .unwrap_err();
        assert!(
            e.contains("p.toml")
                && e.contains("the constraints cannot all hold")
                && e.contains("Jacobian rows of `there` are combinations")
                && e.contains("contradicts itself"),
            "{e}"
        );
    }
}
