//! `energy`: energies written out as expressions: kinetic `T(q, qd, t)`,
//! potential `V(q, t)` and dissipation `D(q, qd, t)`, at least one of them.

use super::{Energies, Kind, Terms};
use crate::error::Error;
use crate::load::scene::{ComponentDef, SScalar};
use crate::model::context::Context;

pub(super) const KIND: Kind = Kind {
    name: "energy",
    fields: &["kinetic", "potential", "dissipation"],
    adds_coordinates: false,
    read,
};

struct Energy {
    kinetic: Option<SScalar>,
    potential: Option<SScalar>,
    dissipation: Option<SScalar>,
}

fn read(cx: &Context, c: &ComponentDef, _: &str, ctx: &str) -> Result<Box<dyn Energies>, Error> {
    if c.kinetic.is_none() && c.potential.is_none() && c.dissipation.is_none() {
        return Err(cx.err(
            c.kind.span().start,
            Some(ctx),
            "an `energy` component needs `kinetic`, `potential` or `dissipation`",
        ));
    }
    Ok(Box::new(Energy {
        kinetic: c.kinetic.clone(),
        potential: c.potential.clone(),
        dissipation: c.dissipation.clone(),
    }))
}

impl Energies for Energy {
    fn energies(&self, cx: &mut Context, ctx: &str) -> Result<Terms, Error> {
        let zero = cx.graph.constant(0.0);
        let mut out = [zero; 3];
        if let Some(t) = &self.kinetic {
            out[0] = cx.scalar(t, Some(ctx), true)?;
        }
        if let Some(v) = &self.potential {
            out[1] = cx.scalar(v, Some(ctx), false)?;
        }
        if let Some(d) = &self.dissipation {
            out[2] = cx.scalar(d, Some(ctx), true)?;
        }
        Ok(out.into())
    }
}
