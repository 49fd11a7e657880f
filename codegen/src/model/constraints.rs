//! Holonomic constraints `Phi(q, t) = 0`: an `expression`, or the vector
//! constraints between frames, `coincident` (two points, three residuals)
//! and `perpendicular` (two directions, one residual).

use toml::Spanned;

use super::context::Context;
use super::Constraint;
use crate::error::Error;
use crate::expr::Id;
use crate::load::scene::{ConstraintDef, ConstraintEnd};

impl Context<'_> {
    /// The world position of an end of a two-ended spring or damper: a
    /// point of a frame (its origin by default).
    pub(super) fn point_end(
        &mut self,
        end: &Spanned<ConstraintEnd>,
        ctx: &str,
    ) -> Result<[Id; 3], Error> {
        if let Some(a) = &end.get_ref().axis {
            return Err(self.err(
                a.span().start,
                Some(ctx),
                "an end of a spring or damper is a point: give `position`, not `axis`",
            ));
        }
        self.constraint_end(end, ctx, true)
    }

    /// A point or direction of a vector constraint in world axes.
    fn constraint_end(
        &mut self,
        end: &Spanned<ConstraintEnd>,
        ctx: &str,
        point: bool,
    ) -> Result<[Id; 3], Error> {
        let e = end.get_ref();
        let frame = match &e.frame {
            Some(f) => self.lookup_frame(f, ctx)?,
            None => self.graph.world_frame(),
        };
        if point {
            if let Some(a) = &e.axis {
                return Err(self.err(
                    a.span().start,
                    Some(ctx),
                    "a `coincident` constraint joins points: give `position`, not `axis`",
                ));
            }
            let local = match &e.position {
                Some(p) => self.vector(p, Some(ctx), false)?,
                None => [self.graph.constant(0.0); 3],
            };
            let r = self.graph.rotate(&frame.rotation, local);
            Ok(std::array::from_fn(|k| {
                self.graph.add(frame.origin[k], r[k])
            }))
        } else {
            if let Some(p) = &e.position {
                return Err(self.err(
                    p.span().start,
                    Some(ctx),
                    "a `perpendicular` constraint relates directions: give `axis`, not `position`",
                ));
            }
            let Some(axis) = &e.axis else {
                return Err(self.err(
                    end.span().start,
                    Some(ctx),
                    "a `perpendicular` constraint needs `axis` at both ends",
                ));
            };
            let u = self.axis(axis, ctx)?;
            let local = u.map(|x| self.graph.constant(x));
            Ok(self.graph.rotate(&frame.rotation, local))
        }
    }

    pub(super) fn constraint(
        &mut self,
        index: usize,
        c: &ConstraintDef,
        out: &mut Vec<Constraint>,
    ) -> Result<(), Error> {
        let name = c
            .name
            .as_ref()
            .map_or_else(|| format!("constraint{index}"), |n| n.get_ref().clone());
        let ctx = format!("constraint `{name}`");
        let Some(kind) = &c.kind else {
            let Some(expression) = &c.expression else {
                let message = "a constraint needs `expression`, or `type` (coincident, \
                               perpendicular) with `a` and `b`";
                return Err(match &c.name {
                    Some(n) => self.err(n.span().start, Some(&ctx), message),
                    None => Error {
                        context: Some(ctx.clone()),
                        ..self.source.error(message)
                    },
                });
            };
            for (field, at) in [
                ("a", c.a.as_ref().map(|x| x.span().start)),
                ("b", c.b.as_ref().map(|x| x.span().start)),
            ] {
                if let Some(at) = at {
                    return Err(self.err(
                        at,
                        Some(&ctx),
                        format!("field `{field}` needs `type` (coincident, perpendicular); an `expression` constraint has no ends"),
                    ));
                }
            }
            let residual = self.scalar(expression, Some(&ctx), false)?;
            let at = expression.span().start;
            self.check_overflow(at, Some(&ctx), "the constraint")?;
            out.push(Constraint { name, residual, at });
            return Ok(());
        };
        if let Some(e) = &c.expression {
            return Err(self.err(
                e.span().start,
                Some(&ctx),
                format!(
                    "a `{}` constraint is given by `a` and `b`, not `expression`",
                    kind.get_ref()
                ),
            ));
        }
        let point = match kind.get_ref().as_str() {
            "coincident" => true,
            "perpendicular" => false,
            other => {
                return Err(self.err(
                    kind.span().start,
                    Some(&ctx),
                    format!("unknown constraint type `{other}` (known: coincident, perpendicular)"),
                ))
            }
        };
        let needs = |missing: &str| {
            self.err(
                kind.span().start,
                Some(&ctx),
                format!("a `{}` constraint needs `{missing}`", kind.get_ref()),
            )
        };
        let Some(a) = &c.a else {
            return Err(needs("a"));
        };
        // A `coincident` constraint's `b` defaults to the world's origin; a
        // `perpendicular` one needs a direction at both ends.
        let b = match (&c.b, point) {
            (Some(b), _) => Some(b),
            (None, true) => None,
            (None, false) => return Err(needs("b")),
        };
        let pa = self.constraint_end(a, &ctx, point)?;
        let pb = match b {
            Some(b) => self.constraint_end(b, &ctx, point)?,
            None => self.graph.world_frame().origin,
        };
        if point {
            for (k, axis) in ["x", "y", "z"].iter().enumerate() {
                let residual = self.graph.sub(pa[k], pb[k]);
                out.push(Constraint {
                    name: format!("{name}_{axis}"),
                    residual,
                    at: kind.span().start,
                });
            }
        } else {
            let residual = self.graph.dot(pa, pb);
            let at = kind.span().start;
            out.push(Constraint { name, residual, at });
        }
        self.check_overflow(kind.span().start, Some(&ctx), "the constraint")
    }
}
