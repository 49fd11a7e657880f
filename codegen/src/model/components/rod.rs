//! `rod`: a uniform thin rod of mass `m` from `from` to `to` (in `frame`, or
//! the world): `T = m/6 (|va|^2 + va.vb + |vb|^2)`, gravity at its middle.
//! In rigid-body form ([`crate::model::Body`]) it is two bodies without
//! rotational inertia: `T = m |v_mid|^2 / 2 + (m/12) |vb - va|^2 / 2`, the
//! mass at the middle and a twelfth of it moving with the rod's vector
//! (the ends need not keep their distance).

use toml::Spanned;

use super::{required, Energies, Kind, Terms};
use crate::error::Error;
use crate::expr::Id;
use crate::load::scene::{ComponentDef, SScalar};
use crate::model::context::Context;
use crate::model::Body;

pub(super) const KIND: Kind = Kind {
    name: "rod",
    fields: &["mass", "from", "to", "frame"],
    adds_coordinates: false,
    read,
};

struct Rod {
    mass: SScalar,
    from: Spanned<Vec<SScalar>>,
    to: Spanned<Vec<SScalar>>,
    frame: Option<Spanned<String>>,
}

fn read(cx: &Context, c: &ComponentDef, _: &str, ctx: &str) -> Result<Box<dyn Energies>, Error> {
    Ok(Box::new(Rod {
        mass: required(cx, c, &c.mass, ctx, "mass")?.clone(),
        from: required(cx, c, &c.from, ctx, "from")?.clone(),
        to: required(cx, c, &c.to, ctx, "to")?.clone(),
        frame: c.frame.clone(),
    }))
}

impl Energies for Rod {
    fn energies(&self, cx: &mut Context, ctx: &str) -> Result<Terms, Error> {
        let zero = cx.graph.constant(0.0);
        let m = cx.positive(&self.mass, ctx, "mass", true)?;
        let a = cx.point(self.frame.as_ref(), &self.from, ctx)?;
        let b = cx.point(self.frame.as_ref(), &self.to, ctx)?;
        let (va, vb) = (a.velocity, b.velocity);
        let omega = match &self.frame {
            Some(name) => cx.lookup_frame(name, ctx)?.omega,
            None => [zero; 3],
        };
        let g = &mut cx.graph;
        // T = m |v_mid|^2 / 2 + (m / 12) |vb - va|^2 / 2: two bodies.
        let middle: [Id; 3] = std::array::from_fn(|k| {
            let s = g.add(va[k], vb[k]);
            g.scale(s, 0.5)
        });
        let along: [Id; 3] = std::array::from_fn(|k| g.sub(vb[k], va[k]));
        let twelfth = g.scale(m, 1.0 / 12.0);
        let bodies = vec![
            Body {
                mass: m,
                velocity: middle,
                omega,
                inertia: None,
                attached: None,
            },
            Body {
                mass: twelfth,
                velocity: along,
                omega,
                inertia: None,
                attached: None,
            },
        ];
        let aa = g.dot(va, va);
        let ab = g.dot(va, vb);
        let bb = g.dot(vb, vb);
        let s = g.sum(&[aa, ab, bb]);
        let ms = g.mul(m, s);
        let kinetic = g.scale(ms, 1.0 / 6.0);
        let mid: [Id; 3] = std::array::from_fn(|k| {
            let ab = g.add(a.position[k], b.position[k]);
            g.scale(ab, 0.5)
        });
        let potential = cx.gravity_potential(m, mid);
        Ok(Terms {
            energies: [kinetic, potential, zero],
            bodies,
            weight: None,
        })
    }
}
