//! `spring`: a linear spring of stiffness `k` on the stretch
//! `expression - rest`: `V = k (e - rest)^2 / 2`.

use super::{required, Energies, Kind, Terms};
use crate::error::Error;
use crate::load::scene::{ComponentDef, SScalar};
use crate::model::context::Context;

pub(super) const KIND: Kind = Kind {
    name: "spring",
    fields: &["stiffness", "expression", "rest"],
    adds_coordinates: false,
    read,
};

struct Spring {
    stiffness: SScalar,
    expression: SScalar,
    rest: Option<SScalar>,
}

fn read(cx: &Context, c: &ComponentDef, _: &str, ctx: &str) -> Result<Box<dyn Energies>, Error> {
    Ok(Box::new(Spring {
        stiffness: required(cx, c, &c.stiffness, ctx, "stiffness")?.clone(),
        expression: required(cx, c, &c.expression, ctx, "expression")?.clone(),
        rest: c.rest.clone(),
    }))
}

impl Energies for Spring {
    fn energies(&self, cx: &mut Context, ctx: &str) -> Result<Terms, Error> {
        let zero = cx.graph.constant(0.0);
        let k = cx.positive(&self.stiffness, ctx, "stiffness", false)?;
        let e = cx.scalar(&self.expression, Some(ctx), false)?;
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
