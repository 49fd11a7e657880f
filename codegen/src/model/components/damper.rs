//! `damper`: a linear damper of coefficient `d` on the rate of `e`, its
//! `expression` or the distance between its ends `a` and `b`: `D = d
//! (de/dt)^2 / 2`.

use super::{measure, required, Energies, Kind, Measured, Terms};
use crate::error::Error;
use crate::load::scene::{ComponentDef, SScalar};
use crate::model::context::Context;

pub(super) const KIND: Kind = Kind {
    name: "damper",
    fields: &["damping", "expression", "a", "b"],
    adds_coordinates: false,
    read,
};

struct Damper {
    damping: SScalar,
    measured: Measured,
}

fn read(cx: &Context, c: &ComponentDef, _: &str, ctx: &str) -> Result<Box<dyn Energies>, Error> {
    Ok(Box::new(Damper {
        damping: required(cx, c, &c.damping, ctx, "damping")?.clone(),
        measured: Measured::of(c),
    }))
}

impl Energies for Damper {
    fn energies(&self, cx: &mut Context, ctx: &str) -> Result<Terms, Error> {
        let zero = cx.graph.constant(0.0);
        let d = cx.positive(&self.damping, ctx, "damping", false)?;
        let e = measure(cx, &self.measured, ctx)?;
        let g = &mut cx.graph;
        let rate = g.time_derivative_at_zero_acceleration(&[e])[0];
        let r2 = g.powi(rate, 2);
        let dr2 = g.mul(d, r2);
        Ok([zero, zero, g.scale(dr2, 0.5)].into())
    }
}
