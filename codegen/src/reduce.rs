//! Model only what a scene needs: reductions of a scene's model.
//!
//! A derived scene file names a `base` scene and a `[reduce]` table:
//!
//! * `modes = k` / `max_frequency = f`: keep only the lowest `k` modes (or
//!   those below `f` Hz) of every flexible link. Because the elastic
//!   displacement is the mode shapes times the modal coordinates, holding the
//!   dropped modal coordinates at zero in the energies is exactly the Galerkin
//!   projection on the kept modes: the same model as one built with fewer modes.
//! * `freeze = [names]`: hold coordinates at zero (position and velocity),
//!   for example the twists of flexible joints, which makes those joints rigid
//!   while their members keep their inertia.
//! * `drop_below = tol`: after the derivation, drop summands of the mass
//!   matrix and the bias forces whose largest magnitude over sample states
//!   drawn from the declared coordinate and velocity ranges stays below `tol`
//!   of the term's scale (see [`prune`]). Constraints are never pruned; the
//!   bias Jacobians stay those of the exact forces.
//!
//! The structural reductions ([`apply`]) act on the symbolic energies before
//! the derivation; pruning acts on the derived terms.

use crate::error::{Error, Source};
use crate::expr::{Graph, Id, Node, Symbol};
use crate::fem::{Invariants, ModeSelection};
use crate::model::{Coordinate, Model, RuntimeParameter};
use crate::scene::DerivedSceneDef;

/// Number of sample states the pruning bound is taken over.
pub const PRUNE_SAMPLES: usize = 64;

/// Apply a derived scene's structural reductions (modes, frozen coordinates)
/// to its base model and record its pruning tolerance.
pub fn apply(mut model: Model, def: &DerivedSceneDef, source: &Source) -> Result<Model, Error> {
    let r = def.reduce.get_ref();
    let ctx = Some("reduce");
    let n = model.nq();
    let mut frozen = vec![false; n];

    // Modes of every flexible link.
    let selection = match (&r.modes, &r.max_frequency) {
        (Some(_), Some(f)) => {
            return Err(source.error_at(
                f.span().start,
                ctx,
                "give either `modes` or `max_frequency`, not both",
            ))
        }
        (Some(k), None) => {
            let v = *k.get_ref();
            if v < 0 {
                return Err(source.error_at(
                    k.span().start,
                    ctx,
                    format!("`modes` must be 0 or more, found {v}"),
                ));
            }
            Some(ModeSelection::First(v as usize))
        }
        (None, Some(f)) => {
            let v = *f.get_ref();
            if !(v.is_finite() && v > 0.0) {
                return Err(source.error_at(
                    f.span().start,
                    ctx,
                    format!("`max_frequency` must be a positive number of Hz, found {v}"),
                ));
            }
            Some(ModeSelection::BelowHz(v))
        }
        (None, None) => None,
    };
    if let (Some(sel), true) = (selection, model.flexible_links.is_empty()) {
        let at = match sel {
            ModeSelection::First(_) => r.modes.as_ref().map(|k| k.span().start),
            _ => r.max_frequency.as_ref().map(|f| f.span().start),
        };
        return Err(source.error_at(
            at.unwrap_or(0),
            ctx,
            "the base scene has no flexible link whose modes could be dropped",
        ));
    }
    let mut kept_modes = Vec::with_capacity(model.flexible_links.len());
    for link in &model.flexible_links {
        let basis = match selection {
            Some(sel) => link.basis.select(sel),
            None => link.basis.clone(),
        };
        // Both selections keep a prefix of the ascending modes.
        let k = basis.len();
        for f in &mut frozen[link.first_coordinate + k..link.first_coordinate + link.modes()] {
            *f = true;
        }
        kept_modes.push(basis);
    }

    // Frozen coordinates by name.
    for name in &r.freeze {
        let Some(i) = model
            .coordinates
            .iter()
            .position(|c| c.name == *name.get_ref())
        else {
            return Err(source.error_at(
                name.span().start,
                ctx,
                format!(
                    "coordinate `{}` is not declared in the base scene",
                    name.get_ref()
                ),
            ));
        };
        if let Some(link) = model
            .flexible_links
            .iter()
            .find(|l| (l.first_coordinate..l.first_coordinate + l.modes()).contains(&i))
        {
            return Err(source.error_at(
                name.span().start,
                ctx,
                format!(
                    "`{}` is a modal coordinate of flexible link `{}`: drop modes with `modes` \
                     or `max_frequency`",
                    name.get_ref(),
                    link.name
                ),
            ));
        }
        frozen[i] = true;
    }
    if let Some(a) = model.actuators.iter().find(|a| frozen[a.coordinate]) {
        return Err(source.error_at(
            def.reduce.span().start,
            ctx,
            format!(
                "actuator `{}` drives coordinate `{}`, which the reduction freezes",
                a.name, model.coordinates[a.coordinate].name
            ),
        ));
    }
    if frozen.iter().all(|&f| f) {
        return Err(source.error_at(
            def.reduce.span().start,
            ctx,
            "the reduction freezes every coordinate",
        ));
    }

    // New numbering of the kept coordinates.
    let mut index = vec![None; n];
    let mut next = 0u32;
    for (i, f) in frozen.iter().enumerate() {
        if !f {
            index[i] = Some(next);
            next += 1;
        }
    }
    let roots = model.input_roots();
    let g = &mut model.graph;
    let zero = g.constant(0.0);
    let q: Vec<Id> = index
        .iter()
        .map(|j| j.map_or(zero, |j| g.symbol(Symbol::Q(j))))
        .collect();
    let qd: Vec<Id> = index
        .iter()
        .map(|j| j.map_or(zero, |j| g.symbol(Symbol::Qd(j))))
        .collect();
    let map = |s: Symbol| match s {
        Symbol::Q(i) => Some(q[i as usize]),
        Symbol::Qd(i) => Some(qd[i as usize]),
        Symbol::Time | Symbol::Param(_) => None,
    };
    let new = g.substitute(&roots, &map);
    let mut it = new.into_iter();
    for c in &mut model.components {
        c.kinetic = it.next().unwrap_or(zero);
        c.potential = it.next().unwrap_or(zero);
        c.dissipation = it.next().unwrap_or(zero);
    }
    for c in &mut model.constraints {
        c.residual = it.next().unwrap_or(zero);
    }
    for a in &mut model.actuators {
        // Checked above: actuated coordinates are kept.
        a.coordinate = index[a.coordinate].map_or(a.coordinate, |j| j as usize);
    }
    for (link, basis) in model.flexible_links.iter_mut().zip(kept_modes) {
        let k = basis.len();
        link.first_coordinate = index[..link.first_coordinate]
            .iter()
            .filter(|i| i.is_some())
            .count();
        link.invariants = Invariants::new(&link.fe, &basis);
        link.basis = basis;
        link.damping_ratio.truncate(k);
        if let Some(kg) = &mut link.geometric_stiffness {
            *kg = kg.view((0, 0), (k, k)).into_owned();
        }
    }
    model.coordinates = model
        .coordinates
        .into_iter()
        .zip(&frozen)
        .filter(|(_, &f)| !f)
        .map(|(c, _)| c)
        .collect();
    model.name = def.name.get_ref().clone();
    if let Some(tol) = &r.drop_below {
        let v = *tol.get_ref();
        if !(v.is_finite() && v > 0.0 && v < 1.0) {
            return Err(source.error_at(
                tol.span().start,
                ctx,
                format!("`drop_below` must lie strictly between 0 and 1, found {v}"),
            ));
        }
        if let Some(c) = model
            .coordinates
            .iter()
            .find(|c| c.range.is_none() || c.velocity_range.is_none())
        {
            return Err(source.error_at(
                tol.span().start,
                ctx,
                format!(
                    "`drop_below` samples the declared ranges, but coordinate `{}` has no \
                     `range` or `velocity_range` in the base scene",
                    c.name
                ),
            ));
        }
        model.drop_below = Some(v);
    }
    Ok(model)
}

/// Sample states for pruning: coordinates and velocities uniform in their
/// declared ranges, time in `[0, 10]` s, runtime parameters at their nominal
/// values; a fixed-seed generator, so generation is reproducible.
struct Samples {
    /// `values[s][symbol slot]`: slots `2 i` (q_i), `2 i + 1` (qd_i).
    values: Vec<Vec<f64>>,
    time: Vec<f64>,
}

impl Samples {
    fn new(coordinates: &[Coordinate]) -> Samples {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut uniform = |[a, b]: [f64; 2]| {
            // xorshift64*
            state ^= state >> 12;
            state ^= state << 25;
            state ^= state >> 27;
            let u = (state.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64;
            a + (b - a) * u
        };
        let mut values = Vec::with_capacity(PRUNE_SAMPLES);
        let mut time = Vec::with_capacity(PRUNE_SAMPLES);
        for _ in 0..PRUNE_SAMPLES {
            let mut v = Vec::with_capacity(2 * coordinates.len());
            for c in coordinates {
                v.push(uniform(c.range.unwrap_or([-1.0, 1.0])));
                v.push(uniform(c.velocity_range.unwrap_or([-1.0, 1.0])));
            }
            values.push(v);
            time.push(uniform([0.0, 10.0]));
        }
        Samples { values, time }
    }

    /// Evaluate `roots` at every sample, handing each sample's values to `f`.
    fn each(
        &self,
        g: &Graph,
        roots: &[Id],
        params: &[RuntimeParameter],
        mut f: impl FnMut(Vec<f64>),
    ) {
        for (v, &t) in self.values.iter().zip(&self.time) {
            f(g.eval(roots, &|s| match s {
                Symbol::Q(i) => v[2 * i as usize],
                Symbol::Qd(i) => v[2 * i as usize + 1],
                Symbol::Time => t,
                Symbol::Param(i) => params[i as usize].value,
            }));
        }
    }

    /// Largest magnitude of each of `roots` over the samples (infinite where
    /// a value is not finite).
    fn max_abs(&self, g: &Graph, roots: &[Id], params: &[RuntimeParameter]) -> Vec<f64> {
        let mut out = vec![0.0f64; roots.len()];
        self.each(g, roots, params, |values| {
            for (o, x) in out.iter_mut().zip(values) {
                *o = o.max(if x.is_finite() {
                    x.abs()
                } else {
                    f64::INFINITY
                });
            }
        });
        out
    }
}

/// The summands of a node: the terms of a sum (its constant is kept), or the
/// node itself.
fn summands(g: &Graph, e: Id) -> (Vec<(Id, f64)>, f64) {
    match g.node(e) {
        Node::Sum(ts, k) => (ts.iter().map(|&(t, c)| (t, c.get())).collect(), k.get()),
        Node::Const(k) => (Vec::new(), k.get()),
        _ => (vec![(e, 1.0)], 0.0),
    }
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

/// Prune the mass matrix and the parts (Coriolis, potential, damping) of the
/// bias forces of a model whose `drop_below` is `tol`, given the exact bias
/// forces `bias` (their sum):
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
pub fn prune(
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
