//! Stage 5, prune: drop the negligible summands of the derived mass matrix
//! and bias forces of a scene whose reduction asks for it (`drop_below`).
//!
//! The largest magnitude of each summand is taken over sample states drawn
//! from the declared coordinate and velocity ranges; summands are dropped
//! smallest first while the bound of [`prune`] holds. Constraints are never
//! pruned; the bias Jacobians stay those of the exact forces.

use crate::derive::{christoffel, Equations};
use crate::expr::{Graph, Id, Node};
use crate::model::{Coordinate, Model, RuntimeParameter};
use crate::samples::Samples;

/// The summands of a node: the terms of a sum, partial sums among them
/// opened in turn (the constants added up and kept), or the node itself.
fn summands(g: &Graph, e: Id) -> (Vec<(Id, f64)>, f64) {
    let (mut terms, mut constant) = (Vec::new(), 0.0);
    let mut open = vec![(e, 1.0)];
    while let Some((id, c)) = open.pop() {
        match g.node(id) {
            Node::Sum(ts, k) => {
                constant += c * k.get();
                open.extend(ts.iter().map(|&(t, ct)| (t, c * ct.get())));
            }
            Node::Const(k) => constant += c * k.get(),
            _ => terms.push((id, c)),
        }
    }
    (terms, constant)
}

/// Drop the smallest summands of each entry while their summed largest
/// magnitudes over the samples stay within that entry's `budget`.
fn prune_entries(
    g: &mut Graph,
    entries: &mut [Id],
    budget: &[f64],
    samples: &Samples,
    params: &[RuntimeParameter],
) {
    let parts: Vec<(Vec<(Id, f64)>, f64)> = entries.iter().map(|&e| summands(g, e)).collect();
    let roots: Vec<Id> = parts
        .iter()
        .flat_map(|(ts, _)| ts.iter().map(|&(t, _)| t))
        .collect();
    let size = samples.max_abs(g, &roots, params);
    let mut at = 0;
    for ((entry, (terms, constant)), &b) in entries.iter_mut().zip(parts).zip(budget) {
        let mut order: Vec<(f64, usize)> = terms
            .iter()
            .enumerate()
            .map(|(j, &(_, c))| (c.abs() * size[at + j], j))
            .collect();
        at += terms.len();
        order.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut spent = 0.0;
        let mut drop = vec![false; terms.len()];
        for (s, j) in order {
            if spent + s > b {
                break;
            }
            spent += s;
            drop[j] = true;
        }
        if drop.contains(&true) {
            let kept: Vec<(Id, f64)> = terms
                .into_iter()
                .zip(&drop)
                .filter(|(_, &d)| !d)
                .map(|(t, _)| t)
                .collect();
            *entry = g.linear(&kept, constant);
        }
    }
}

/// Prune the derived terms of a model whose reduction set `drop_below`: the
/// mass matrix and the parts of the bias forces (see [`prune_terms`]); the
/// bias forces and, when asked for, the Coriolis matrix are recomputed from
/// the pruned terms. Nothing changes without `drop_below`.
pub fn prune(model: &mut Model, eq: &mut Equations) {
    let Some(tol) = model.drop_below else {
        return;
    };
    let g = &mut model.graph;
    prune_terms(
        g,
        &model.coordinates,
        &model.runtime_parameters,
        tol,
        &mut eq.mass,
        &eq.bias,
        [
            &mut eq.coriolis,
            &mut eq.potential_forces,
            &mut eq.damping_forces,
        ],
    );
    eq.bias = (0..model.coordinates.len())
        .map(|i| g.sum(&[eq.coriolis[i], eq.potential_forces[i], eq.damping_forces[i]]))
        .collect();
    if eq.coriolis_matrix.is_some() {
        eq.coriolis_matrix = Some(christoffel(g, &eq.mass));
    }
}

/// Prune the mass matrix and the parts (Coriolis, potential, damping) of the
/// bias forces, given the exact bias forces `bias` (their sum) and the
/// tolerance `tol`:
///
/// * bias forces `h = c + g + d`: each entry of each part may lose summands
///   whose largest magnitudes over the samples add up to at most
///   `tol / 3 * max(1, max |h|)`, so `h` changes by at most
///   `tol * max(1, max |h|)` at the samples;
/// * mass matrix: diagonal entries are kept whole (they carry the inertia of
///   every coordinate); an off-diagonal entry may lose up to
///   `tol * min sqrt(M_ii M_jj)`, so that the normalised matrix
///   `D^-1/2 M D^-1/2` moves by at most `tol` per entry and `M` stays
///   positive definite while `tol (n - 1) < ` its smallest normalised
///   eigenvalue.
///
/// The samples are states drawn from the declared ranges; the bound holds at
/// them, and the CasADi validation checks it at other states.
fn prune_terms(
    g: &mut Graph,
    coordinates: &[Coordinate],
    params: &[RuntimeParameter],
    tol: f64,
    mass: &mut [Vec<Id>],
    bias: &[Id],
    parts: [&mut [Id]; 3],
) {
    let samples = Samples::new(coordinates);
    let n = coordinates.len();

    let scale = samples
        .max_abs(g, bias, params)
        .into_iter()
        .fold(1.0f64, f64::max);
    let budget = vec![tol / 3.0 * scale; n];
    for part in parts {
        prune_entries(g, part, &budget, &samples, params);
    }

    // Smallest diagonal entries over the samples.
    let mut diag_min = vec![f64::INFINITY; n];
    let diag: Vec<Id> = (0..n).map(|i| mass[i][i]).collect();
    samples.each(g, &diag, params, |values| {
        for (m, x) in diag_min.iter_mut().zip(values) {
            *m = m.min(x);
        }
    });
    let mut upper: Vec<Id> = Vec::new();
    let mut budget = Vec::new();
    for i in 0..n {
        for j in i + 1..n {
            upper.push(mass[i][j]);
            let b = (diag_min[i].max(0.0) * diag_min[j].max(0.0)).sqrt();
            budget.push(if b.is_finite() { tol * b } else { 0.0 });
        }
    }
    prune_entries(g, &mut upper, &budget, &samples, params);
    let mut it = upper.into_iter();
    let pairs: Vec<(usize, usize)> = (0..n)
        .flat_map(|i| (i + 1..n).map(move |j| (i, j)))
        .collect();
    for (i, j) in pairs {
        let e = it.next().unwrap_or(mass[i][j]);
        mass[i][j] = e;
        mass[j][i] = e;
    }
}
