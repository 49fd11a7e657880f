//! Stage 3, reduce: model only what a scene needs, by the reductions a
//! derived scene applies to its base scene's model.
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
//! * `drop_below = tol`: recorded in the model; after the derivation, the
//!   prune stage ([`crate::prune`]) drops the summands of the mass matrix
//!   and the bias forces that stay below `tol` of the term's scale.
//!
//! The structural reductions ([`apply`]) act on the symbolic energies of the
//! base scene's model, before the derivation.

use crate::error::{Error, Source};
use crate::expr::{Id, Symbol};
use crate::fem::{Invariants, ModeSelection};
use crate::load::scene::DerivedSceneDef;
use crate::model::Model;

/// Apply a derived scene's structural reductions (modes, frozen coordinates)
/// to its base model and record its pruning tolerance.
pub fn apply(mut model: Model, def: &DerivedSceneDef, source: &Source) -> Result<Model, Error> {
    model.sources.insert(0, source.path().to_path_buf());
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
    let roots = model.roots();
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
        Symbol::Time | Symbol::Param(_) | Symbol::Qdd(_) => None,
    };
    let new = g.substitute(&roots, &map);
    model.set_roots(new);
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
