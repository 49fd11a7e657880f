//! `flexible_joint`: a flexible joint (the paper's): a joint member, a
//! solid circular shaft of mass `m`, length `l` and `material`, turning
//! with `frame` about its `axis`, with a linear torsion spring on its twist
//! `expression`. Radius from `A = m / (rho l)`, inertia `m r^2 / 2` about
//! the axis and `m (3 r^2 + l^2) / 12` across it, stiffness `G Ip / l`
//! (`fem::shaft_joint_stiffness`) unless `stiffness` is given.

use toml::Spanned;

use super::rigid_body::{body_terms, centre_of_mass};
use super::{required, Energies, Kind, Terms};
use crate::error::Error;
use crate::load::scene::{ComponentDef, MaterialDef, SScalar};
use crate::model::context::Context;

pub(super) const KIND: Kind = Kind {
    name: "flexible_joint",
    fields: &[
        "mass",
        "position",
        "frame",
        "length",
        "material",
        "axis",
        "expression",
        "stiffness",
    ],
    adds_coordinates: false,
    read,
};

struct FlexibleJoint {
    kind_at: usize,
    frame: Spanned<String>,
    mass: SScalar,
    length: SScalar,
    material: Spanned<MaterialDef>,
    axis: Spanned<String>,
    twist: SScalar,
    position: Option<Spanned<Vec<SScalar>>>,
    stiffness: Option<SScalar>,
}

fn read(cx: &Context, c: &ComponentDef, _: &str, ctx: &str) -> Result<Box<dyn Energies>, Error> {
    Ok(Box::new(FlexibleJoint {
        kind_at: c.kind.span().start,
        frame: required(cx, c, &c.frame, ctx, "frame")?.clone(),
        mass: required(cx, c, &c.mass, ctx, "mass")?.clone(),
        length: required(cx, c, &c.length, ctx, "length")?.clone(),
        material: required(cx, c, &c.material, ctx, "material")?.clone(),
        axis: required(cx, c, &c.axis, ctx, "axis")?.clone(),
        twist: required(cx, c, &c.expression, ctx, "expression")?.clone(),
        position: c.position.clone(),
        stiffness: c.stiffness.clone(),
    }))
}

impl Energies for FlexibleJoint {
    fn energies(&self, cx: &mut Context, ctx: &str) -> Result<Terms, Error> {
        let (frame_name, mass, length, material, axis, twist) = (
            &self.frame,
            &self.mass,
            &self.length,
            &self.material,
            &self.axis,
            &self.twist,
        );
        let a = match axis.get_ref().as_str() {
            "x" => 0,
            "y" => 1,
            "z" => 2,
            other => {
                return Err(cx.err(
                    axis.span().start,
                    Some(ctx),
                    format!("axis must be `x`, `y` or `z`, found `{other}`"),
                ))
            }
        };
        let m = cx.constant_positive(mass, ctx, "mass")?;
        let l = cx.constant_positive(length, ctx, "length")?;
        let material = cx.material(material, ctx)?;
        let shaft = crate::fem::shaft_joint_stiffness(&material, m, l)
            .map_err(|e| cx.err(self.kind_at, Some(ctx), e))?;
        let r2 = m / (material.density * l * std::f64::consts::PI);
        let mut inertia = [[cx.graph.constant(0.0); 3]; 3];
        for (i, row) in inertia.iter_mut().enumerate() {
            row[i] = cx.graph.constant(if i == a {
                m * r2 / 2.0
            } else {
                m * (3.0 * r2 + l * l) / 12.0
            });
        }
        let frame = cx.lookup_frame(frame_name, ctx)?;
        let com = centre_of_mass(cx, frame_name, &frame, self.position.as_ref(), ctx)?;
        let m_id = cx.graph.constant(m);
        let mut terms = body_terms(cx, m_id, &com, frame.omega, Some(inertia));
        let k = match &self.stiffness {
            Some(k) => cx.positive(k, ctx, "stiffness", true)?,
            None => cx.graph.constant(shaft.torsional),
        };
        let e = cx.scalar(twist, Some(ctx), false)?;
        let e2 = cx.graph.powi(e, 2);
        let ke2 = cx.graph.mul(k, e2);
        let spring = cx.graph.scale(ke2, 0.5);
        terms.energies[1] = cx.graph.add(terms.energies[1], spring);
        Ok(terms)
    }
}
