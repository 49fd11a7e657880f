//! `point_mass`: a mass `m` at `position` (in `frame`, or the world):
//! `T = m |v|^2 / 2`, `V = -m g . r`.

use toml::Spanned;

use super::rigid_body::body_terms;
use super::{required, Energies, Kind, Terms};
use crate::error::Error;
use crate::load::scene::{ComponentDef, SScalar};
use crate::model::context::Context;

pub(super) const KIND: Kind = Kind {
    name: "point_mass",
    fields: &["mass", "position", "frame"],
    adds_coordinates: false,
    read,
};

struct PointMass {
    mass: SScalar,
    position: Spanned<Vec<SScalar>>,
    frame: Option<Spanned<String>>,
}

fn read(cx: &Context, c: &ComponentDef, _: &str, ctx: &str) -> Result<Box<dyn Energies>, Error> {
    Ok(Box::new(PointMass {
        mass: required(cx, c, &c.mass, ctx, "mass")?.clone(),
        position: required(cx, c, &c.position, ctx, "position")?.clone(),
        frame: c.frame.clone(),
    }))
}

impl Energies for PointMass {
    fn energies(&self, cx: &mut Context, ctx: &str) -> Result<Terms, Error> {
        let zero = cx.graph.constant(0.0);
        let m = cx.positive(&self.mass, ctx, "mass", true)?;
        let p = cx.point(self.frame.as_ref(), &self.position, ctx)?;
        let omega = match &self.frame {
            Some(name) => cx.lookup_frame(name, ctx)?.omega,
            None => [zero; 3],
        };
        Ok(body_terms(cx, m, &p, omega, None))
    }
}
