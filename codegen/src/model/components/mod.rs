//! The component kinds: the registry, one line per kind, and what a kind
//! provides. Each kind lives in a file of its own: its fields, its typed
//! value converted once from the TOML table ([`ComponentDef`]), and its
//! energies `T`, `V`, `D`. Adding a kind is one file plus one line in
//! [`KINDS`].

mod damper;
mod energy;
mod flexible_joint;
mod flexible_link;
mod point_mass;
mod rigid_body;
mod rod;
mod spring;

pub(super) use flexible_link::station_frame;

use super::context::Context;
use super::{Body, Coordinate, FlexibleLink};
use crate::error::Error;
use crate::expr::Id;
use crate::load::scene::{ComponentDef, ConstraintEnd, SScalar};
use toml::Spanned;

/// Every component kind, in the order the error messages list them.
const KINDS: &[Kind] = &[
    energy::KIND,
    point_mass::KIND,
    rod::KIND,
    rigid_body::KIND,
    spring::KIND,
    damper::KIND,
    flexible_link::KIND,
    flexible_joint::KIND,
];

/// A component kind.
pub(super) struct Kind {
    /// Its `type` in the scene file.
    name: &'static str,
    /// The fields it accepts besides `name` and `type`.
    fields: &'static [&'static str],
    /// Whether it adds coordinates, so that it is read (and prepared) before
    /// the frames, which may use them.
    adds_coordinates: bool,
    /// Its reader.
    read: ReadFn,
}

/// Converts a component's TOML table into its kind's typed value, given the
/// component's name and error context.
type ReadFn = fn(&Context, &ComponentDef, &str, &str) -> Result<Box<dyn Energies>, Error>;

/// A component read into its kind's typed value.
pub(super) trait Energies {
    /// Work before the frames are built: a flexible link builds its
    /// finite-element model and appends its modal coordinates.
    fn prepare(
        &mut self,
        _cx: &mut Context,
        _coordinates: &mut Vec<Coordinate>,
        _ctx: &str,
    ) -> Result<(), Error> {
        Ok(())
    }

    /// The finite-element data of a flexible link, once prepared.
    fn flexible_link(&self) -> Option<&FlexibleLink> {
        None
    }

    /// Kinetic energy `T`, potential energy `V` and dissipation function
    /// `D`, and the rigid-body form of `T` where it has one.
    fn energies(&self, cx: &mut Context, ctx: &str) -> Result<Terms, Error>;
}

/// What a component contributes to the model.
pub(super) struct Terms {
    /// `[T, V, D]`.
    pub(super) energies: [Id; 3],
    /// `T` in rigid-body form (a rigid body, a point mass).
    pub(super) bodies: Vec<Body>,
    /// The bodies' weight, a part of `V` ([`crate::model::Component::weight`]).
    pub(super) weight: Option<Id>,
}

impl From<[Id; 3]> for Terms {
    fn from(energies: [Id; 3]) -> Terms {
        Terms {
            energies,
            bodies: Vec::new(),
            weight: None,
        }
    }
}

/// A component with its name, kind and error context, read into its typed
/// value.
pub(super) struct Read {
    /// Component name (given, or the kind and its index).
    pub(super) name: String,
    /// Its kind's name.
    pub(super) kind: &'static str,
    /// Context for error messages.
    pub(super) ctx: String,
    /// The typed value.
    pub(super) value: Box<dyn Energies>,
}

/// Whether a component's kind adds coordinates (it is then read before the
/// frames).
pub(super) fn adds_coordinates(c: &ComponentDef) -> bool {
    KINDS
        .iter()
        .any(|k| k.name == c.kind.get_ref() && k.adds_coordinates)
}

/// Read component `index`: its name, its kind, its fields.
pub(super) fn read(cx: &Context, index: usize, c: &ComponentDef) -> Result<Read, Error> {
    let kind = c.kind.get_ref();
    let name = match &c.name {
        Some(n) => {
            crate::load::check_ident(cx.source, n, "component")?;
            n.get_ref().clone()
        }
        None => format!("{kind}{index}"),
    };
    let ctx = format!("component `{name}`");
    let Some(k) = KINDS.iter().find(|k| k.name == kind) else {
        let known: Vec<&str> = KINDS.iter().map(|k| k.name).collect();
        return Err(cx.err(
            c.kind.span().start,
            Some(&ctx),
            format!(
                "unknown component type `{kind}` (known: {})",
                known.join(", ")
            ),
        ));
    };
    check_fields(cx, c, k.fields, &ctx)?;
    let value = (k.read)(cx, c, &name, &ctx)?;
    Ok(Read {
        name,
        kind: k.name,
        ctx,
        value,
    })
}

/// The scalar a `spring` or `damper` acts on: its `expression`, or the
/// distance between its ends `a` and `b` (`b` the world's origin when left
/// out), never both.
pub(super) fn measure(cx: &mut Context, c: &Measured, ctx: &str) -> Result<Id, Error> {
    if let (None, Some(b)) = (&c.a, &c.b) {
        return Err(cx.err(b.span().start, Some(ctx), "`b` needs `a`"));
    }
    match (&c.expression, &c.a) {
        (Some(e), None) => cx.scalar(e, Some(ctx), false),
        (None, Some(a)) => {
            let pa = cx.point_end(a, ctx)?;
            let pb = match &c.b {
                Some(b) => cx.point_end(b, ctx)?,
                None => [cx.graph.constant(0.0); 3],
            };
            let g = &mut cx.graph;
            let d: [Id; 3] = std::array::from_fn(|k| g.sub(pa[k], pb[k]));
            let squared = g.dot(d, d);
            Ok(g.sqrt(squared))
        }
        (Some(e), Some(_)) => Err(cx.err(
            e.span().start,
            Some(ctx),
            "give `expression` or the ends `a` and `b`, not both",
        )),
        (None, None) => Err(cx.err(
            c.at,
            Some(ctx),
            format!(
                "a `{}` component needs `expression`, or the ends `a` (and `b`, default the \
                 world's origin)",
                c.kind
            ),
        )),
    }
}

/// What a `spring` or `damper` acts on, as written.
pub(super) struct Measured {
    kind: String,
    at: usize,
    expression: Option<SScalar>,
    a: Option<Spanned<ConstraintEnd>>,
    b: Option<Spanned<ConstraintEnd>>,
}

impl Measured {
    pub(super) fn of(c: &ComponentDef) -> Measured {
        Measured {
            kind: c.kind.get_ref().clone(),
            at: c.kind.span().start,
            expression: c.expression.clone(),
            a: c.a.clone(),
            b: c.b.clone(),
        }
    }
}

/// The value of a required field of component `c`, or an error at its
/// `type` naming the field.
pub(super) fn required<'c, T>(
    cx: &Context,
    c: &ComponentDef,
    value: &'c Option<T>,
    ctx: &str,
    field: &str,
) -> Result<&'c T, Error> {
    value.as_ref().ok_or_else(|| {
        cx.err(
            c.kind.span().start,
            Some(ctx),
            format!("a `{}` component needs `{field}`", c.kind.get_ref()),
        )
    })
}

fn check_fields(cx: &Context, c: &ComponentDef, allowed: &[&str], ctx: &str) -> Result<(), Error> {
    let span = |s: &Option<SScalar>| s.as_ref().map(|s| s.span().start);
    let present: [(&str, Option<usize>); 28] = [
        ("kinetic", c.kinetic.as_ref().map(|s| s.span().start)),
        ("potential", c.potential.as_ref().map(|s| s.span().start)),
        (
            "dissipation",
            c.dissipation.as_ref().map(|s| s.span().start),
        ),
        ("mass", c.mass.as_ref().map(|s| s.span().start)),
        ("frame", c.frame.as_ref().map(|s| s.span().start)),
        ("position", c.position.as_ref().map(|s| s.span().start)),
        ("from", c.from.as_ref().map(|s| s.span().start)),
        ("to", c.to.as_ref().map(|s| s.span().start)),
        ("inertia", c.inertia.as_ref().map(|s| s.span().start)),
        (
            "inertia_rpy",
            c.inertia_rpy.as_ref().map(|s| s.span().start),
        ),
        (
            "allow_unphysical_inertia",
            c.allow_unphysical_inertia.as_ref().map(|s| s.span().start),
        ),
        ("stiffness", c.stiffness.as_ref().map(|s| s.span().start)),
        ("damping", c.damping.as_ref().map(|s| s.span().start)),
        ("expression", c.expression.as_ref().map(|s| s.span().start)),
        ("rest", c.rest.as_ref().map(|s| s.span().start)),
        ("axis", c.axis.as_ref().map(|s| s.span().start)),
        ("length", span(&c.length)),
        ("material", c.material.as_ref().map(|s| s.span().start)),
        ("section", c.section.as_ref().map(|s| s.span().start)),
        ("elements", span(&c.elements)),
        ("modes", span(&c.modes)),
        ("max_frequency", span(&c.max_frequency)),
        ("boundary", c.boundary.as_ref().map(|s| s.span().start)),
        (
            "end_stiffness",
            c.end_stiffness.as_ref().map(|s| s.span().start),
        ),
        (
            "damping_ratio",
            c.damping_ratio.as_ref().map(|s| s.span().start),
        ),
        (
            "geometric_stiffening",
            c.geometric_stiffening.as_ref().map(|s| s.span().start),
        ),
        ("a", c.a.as_ref().map(|s| s.span().start)),
        ("b", c.b.as_ref().map(|s| s.span().start)),
    ];
    for (field, at) in present {
        if let Some(at) = at {
            if !allowed.contains(&field) {
                return Err(cx.err(
                    at,
                    Some(ctx),
                    format!(
                        "field `{field}` does not apply to a `{}` component (allowed: {})",
                        c.kind.get_ref(),
                        allowed.join(", ")
                    ),
                ));
            }
        }
    }
    Ok(())
}
