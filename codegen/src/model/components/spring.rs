//! `spring`: a linear spring of stiffness `k` on the stretch `e - rest`,
//! `V = k (e - rest)^2 / 2`, with `e` its `expression` or the distance
//! between its ends `a` and `b`.

use super::{measure, required, Energies, Kind, Measured, Terms};
use crate::error::Error;
use crate::load::scene::{ComponentDef, SScalar};
use crate::model::context::Context;

pub(super) const KIND: Kind = Kind {
    name: "spring",
    fields: &["stiffness", "expression", "rest", "a", "b"],
    adds_coordinates: false,
    read,
};

struct Spring {
    stiffness: SScalar,
    measured: Measured,
    rest: Option<SScalar>,
}

fn read(cx: &Context, c: &ComponentDef, _: &str, ctx: &str) -> Result<Box<dyn Energies>, Error> {
    Ok(Box::new(Spring {
        stiffness: required(cx, c, &c.stiffness, ctx, "stiffness")?.clone(),
        measured: Measured::of(c),
        rest: c.rest.clone(),
    }))
}

impl Energies for Spring {
    fn energies(&self, cx: &mut Context, ctx: &str) -> Result<Terms, Error> {
        let zero = cx.graph.constant(0.0);
        let k = cx.positive(&self.stiffness, ctx, "stiffness", false)?;
        let e = measure(cx, &self.measured, ctx)?;
        let rest = match &self.rest {
            Some(r) => cx.scalar(r, Some(ctx), false)?,
            None => zero,
        };
        let g = &mut cx.graph;
        let stretch = g.sub(e, rest);
        let s2 = g.powi(stretch, 2);
        let ks2 = g.mul(k, s2);
        Ok([zero, g.scale(ks2, 0.5), zero].into())
    }
}
