//! The state of the model stage while a scene is read: the expression
//! graph, the names expressions may use, the frames built so far, gravity,
//! and the reading of scene values (numbers and expressions, vectors,
//! parameter-only and constant values, materials, axes, points) into graph
//! nodes, with errors at the value's position in the file.

use std::collections::BTreeMap;

use toml::Spanned;

use super::{FlexibleLink, Placement};
use crate::error::{Error, Source};
use crate::expr::{Graph, Id, Symbol};
use crate::fem::Material;
use crate::geometry::{Frame, Point};
use crate::load::parse::{parse_expr, Scope};
use crate::load::scene::{AxisDef, MaterialDef, SScalar, Scalar};

/// What the model stage has built so far.
pub(super) struct Context<'a> {
    /// The scene file, for error positions.
    pub(super) source: &'a Source,
    /// The graph every expression goes into.
    pub(super) graph: Graph,
    /// Names expressions may use.
    pub(super) scope: Scope,
    /// Frames defined so far, by name.
    pub(super) frames: BTreeMap<String, Frame>,
    /// Gravity in world axes.
    pub(super) gravity: [Id; 3],
    /// Nominal values of the runtime parameters, by index.
    pub(super) nominal: Vec<f64>,
    /// Nominal value of every parameter, by name.
    pub(super) parameter_values: BTreeMap<String, f64>,
    /// Flexible links read so far, in component order.
    pub(super) flexible: Vec<FlexibleLink>,
    /// The frames' placements so far (the kinematic tree).
    pub(super) placements: Vec<Placement>,
}

impl<'a> Context<'a> {
    pub(super) fn new(source: &'a Source) -> Context<'a> {
        let mut graph = Graph::new();
        let zero = graph.constant(0.0);
        Context {
            source,
            graph,
            scope: Scope::default(),
            frames: BTreeMap::new(),
            gravity: [zero; 3],
            nominal: Vec::new(),
            parameter_values: BTreeMap::new(),
            flexible: Vec::new(),
            placements: Vec::new(),
        }
    }

    /// An error at byte `offset` of the scene file.
    pub(super) fn err(&self, offset: usize, ctx: Option<&str>, msg: impl Into<String>) -> Error {
        self.source.error_at(offset, ctx, msg)
    }

    /// An error at byte `offset` when a constant built since the last
    /// check overflowed `f64` ([`Graph::take_overflow`]): `what` (a
    /// component, a constraint, gravity) has a derived constant beyond
    /// `f64`'s range.
    pub(super) fn check_overflow(
        &mut self,
        offset: usize,
        ctx: Option<&str>,
        what: &str,
    ) -> Result<(), Error> {
        if !self.graph.take_overflow() {
            return Ok(());
        }
        Err(self.err(offset, ctx, overflow_message(what)))
    }

    /// Offset in the file of byte `offset` of the (decoded) text of the
    /// string whose token starts at `span_start`: skips the opening quotes,
    /// the newline a multi-line string drops after them, and escapes.
    fn expr_offset(&self, span_start: usize, offset: usize) -> usize {
        let text = self.source.text();
        let bytes = text.as_bytes();
        let mut raw = span_start.min(text.len());
        let rest = &bytes[raw..];
        let (quote, basic, multi) = if rest.starts_with(b"\"\"\"") {
            (3, true, true)
        } else if rest.starts_with(b"'''") {
            (3, false, true)
        } else if rest.starts_with(b"\"") {
            (1, true, false)
        } else if rest.starts_with(b"'") {
            (1, false, false)
        } else {
            return (raw + offset).min(text.len());
        };
        raw += quote;
        if multi {
            if bytes[raw..].starts_with(b"\r\n") {
                raw += 2;
            } else if bytes[raw..].starts_with(b"\n") {
                raw += 1;
            }
        }
        if !basic {
            return (raw + offset).min(text.len());
        }
        let mut decoded = 0;
        while decoded < offset && raw < bytes.len() {
            if bytes[raw] != b'\\' {
                // Advance by one character of the file.
                let len = text.get(raw..).and_then(|r| r.chars().next());
                let len = len.map_or(1, char::len_utf8);
                raw += len;
                decoded += len;
                continue;
            }
            match bytes.get(raw + 1) {
                Some(&(b'u' | b'U')) => {
                    let digits = if bytes[raw + 1] == b'u' { 4 } else { 8 };
                    let end = (raw + 2 + digits).min(bytes.len());
                    let ch = text
                        .get(raw + 2..end)
                        .and_then(|h| u32::from_str_radix(h, 16).ok())
                        .and_then(char::from_u32);
                    raw = end;
                    decoded += ch.map_or(1, char::len_utf8);
                }
                // A line-ending backslash drops the whitespace that follows.
                Some(&(b' ' | b'\t' | b'\r' | b'\n')) if multi => {
                    raw += 1;
                    while matches!(bytes.get(raw), Some(b' ' | b'\t' | b'\r' | b'\n')) {
                        raw += 1;
                    }
                }
                _ => {
                    raw += 2;
                    decoded += 1;
                }
            }
        }
        raw.min(text.len())
    }

    pub(super) fn scalar(
        &mut self,
        s: &SScalar,
        ctx: Option<&str>,
        velocity: bool,
    ) -> Result<Id, Error> {
        match s.get_ref() {
            Scalar::Number(v) => self.graph.try_constant(*v).ok_or_else(|| {
                self.err(s.span().start, ctx, format!("number is not finite ({v})"))
            }),
            Scalar::Expr(text) => {
                self.scope.allow_velocity = velocity;
                parse_expr(&mut self.graph, text, &self.scope).map_err(|e| {
                    let at = self.expr_offset(s.span().start, e.offset);
                    self.err(at, ctx, e.message)
                })
            }
        }
    }

    pub(super) fn vector(
        &mut self,
        v: &Spanned<Vec<SScalar>>,
        ctx: Option<&str>,
        velocity: bool,
    ) -> Result<[Id; 3], Error> {
        let items = v.get_ref();
        if !(items.len() == 2 || items.len() == 3) {
            return Err(self.err(
                v.span().start,
                ctx,
                format!("expected a vector of 2 or 3 entries, found {}", items.len()),
            ));
        }
        let mut out = [self.graph.constant(0.0); 3];
        for (k, s) in items.iter().enumerate() {
            out[k] = self.scalar(s, ctx, velocity)?;
        }
        Ok(out)
    }

    /// Value of a parameter-only expression at the nominal parameters; an
    /// error when it depends on coordinates or time.
    pub(super) fn nominal_value(
        &self,
        id: Id,
        at: usize,
        ctx: &str,
        what: &str,
    ) -> Result<f64, Error> {
        let symbols = self.graph.symbols(&[id]);
        if symbols.iter().any(|s| !matches!(s, Symbol::Param(_))) {
            return Err(self.err(
                at,
                Some(ctx),
                format!("{what} may depend on parameters only, not on coordinates or time"),
            ));
        }
        let nominal = &self.nominal;
        Ok(self.graph.eval(&[id], &|s| match s {
            Symbol::Param(i) => nominal[i as usize],
            _ => 0.0,
        })[0])
    }

    pub(super) fn positive(
        &mut self,
        s: &SScalar,
        ctx: &str,
        what: &str,
        strict: bool,
    ) -> Result<Id, Error> {
        let id = self.scalar(s, Some(ctx), false)?;
        let v = self.nominal_value(id, s.span().start, ctx, what)?;
        if v < 0.0 || (strict && v == 0.0) {
            let need = if strict { "positive" } else { "non-negative" };
            return Err(self.err(
                s.span().start,
                Some(ctx),
                format!("{what} must be {need}, found {v}"),
            ));
        }
        Ok(id)
    }

    /// A constant: numbers and folded parameters only (the finite-element
    /// model of a flexible link is built when the code is generated).
    pub(super) fn constant_value(
        &mut self,
        s: &SScalar,
        ctx: &str,
        what: &str,
    ) -> Result<f64, Error> {
        let id = self.scalar(s, Some(ctx), false)?;
        if !self.graph.symbols(&[id]).is_empty() {
            return Err(self.err(
                s.span().start,
                Some(ctx),
                format!(
                    "{what} must be a constant (numbers and parameters folded at generation time, \
                     not runtime parameters, coordinates or time): the finite-element model is \
                     built when the code is generated"
                ),
            ));
        }
        Ok(self.graph.eval(&[id], &|_| 0.0)[0])
    }

    pub(super) fn constant_positive(
        &mut self,
        s: &SScalar,
        ctx: &str,
        what: &str,
    ) -> Result<f64, Error> {
        let v = self.constant_value(s, ctx, what)?;
        if v > 0.0 {
            Ok(v)
        } else {
            Err(self.err(
                s.span().start,
                Some(ctx),
                format!("{what} must be positive, found {v}"),
            ))
        }
    }

    /// A whole number in `[min, max]`.
    pub(super) fn constant_count(
        &mut self,
        s: &SScalar,
        ctx: &str,
        what: &str,
        min: usize,
        max: usize,
    ) -> Result<usize, Error> {
        let v = self.constant_value(s, ctx, what)?;
        if v.fract() != 0.0 || v < min as f64 || v > max as f64 {
            return Err(self.err(
                s.span().start,
                Some(ctx),
                format!("{what} must be a whole number from {min} to {max}, found {v}"),
            ));
        }
        Ok(v as usize)
    }

    /// A material: `E`, `poisson` or `shear_modulus`, density; constants.
    pub(super) fn material(
        &mut self,
        material: &Spanned<MaterialDef>,
        ctx: &str,
    ) -> Result<Material, Error> {
        let m = material.get_ref();
        let e = self.constant_positive(&m.youngs_modulus, ctx, "Young's modulus")?;
        let rho = self.constant_positive(&m.density, ctx, "density")?;
        match (&m.poisson, &m.shear_modulus) {
            (Some(nu_s), None) => {
                let nu = self.constant_value(nu_s, ctx, "Poisson's ratio")?;
                if !(nu > -1.0 && nu < 0.5) {
                    return Err(self.err(
                        nu_s.span().start,
                        Some(ctx),
                        format!("Poisson's ratio must lie in (-1, 0.5), found {nu}"),
                    ));
                }
                Material::new(e, nu, rho)
            }
            (None, Some(g_s)) => {
                let g = self.constant_positive(g_s, ctx, "shear modulus")?;
                Material::with_shear_modulus(e, g, rho)
            }
            (Some(_), Some(g_s)) => {
                return Err(self.err(
                    g_s.span().start,
                    Some(ctx),
                    "give either `poisson` or `shear_modulus`, not both",
                ))
            }
            (None, None) => {
                return Err(self.err(
                    material.span().start,
                    Some(ctx),
                    "the material needs `poisson` or `shear_modulus`",
                ))
            }
        }
        .map_err(|e| self.err(material.span().start, Some(ctx), e))
    }

    pub(super) fn lookup_frame(
        &mut self,
        name: &Spanned<String>,
        ctx: &str,
    ) -> Result<Frame, Error> {
        if name.get_ref() == "world" {
            return Ok(self.graph.world_frame());
        }
        self.frames.get(name.get_ref()).cloned().ok_or_else(|| {
            self.err(
                name.span().start,
                Some(ctx),
                format!("frame `{}` is not defined above", name.get_ref()),
            )
        })
    }

    pub(super) fn axis(&self, a: &Spanned<AxisDef>, ctx: &str) -> Result<[f64; 3], Error> {
        let v = match a.get_ref() {
            AxisDef::Named(n) => match n.as_str() {
                "x" => [1.0, 0.0, 0.0],
                "y" => [0.0, 1.0, 0.0],
                "z" => [0.0, 0.0, 1.0],
                _ => {
                    return Err(self.err(
                        a.span().start,
                        Some(ctx),
                        format!("unknown axis `{n}` (use \"x\", \"y\", \"z\" or three numbers)"),
                    ))
                }
            },
            AxisDef::Vector(v) => *v,
        };
        let norm = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        if !(norm.is_finite() && norm > 1e-12) {
            return Err(self.err(
                a.span().start,
                Some(ctx),
                "axis must be a finite nonzero vector",
            ));
        }
        Ok([v[0] / norm, v[1] / norm, v[2] / norm])
    }

    /// A point given in `frame` (the world when there is none).
    pub(super) fn point(
        &mut self,
        frame: Option<&Spanned<String>>,
        v: &Spanned<Vec<SScalar>>,
        ctx: &str,
    ) -> Result<Point, Error> {
        let local = self.vector(v, Some(ctx), false)?;
        let frame = match frame {
            None => self.graph.world_frame(),
            Some(name) => self.lookup_frame(name, ctx)?,
        };
        let r = self.graph.rotate(&frame.rotation, local);
        Ok(Point {
            position: std::array::from_fn(|k| self.graph.add(frame.origin[k], r[k])),
            velocity: self.graph.moving_point_velocity(&frame, local),
            node: frame.node,
            local,
        })
    }

    /// Gravitational potential of mass `m` at `p`: `-m g . p`.
    pub(super) fn gravity_potential(&mut self, m: Id, p: [Id; 3]) -> Id {
        let gp = self.graph.dot(self.gravity, p);
        let mgp = self.graph.mul(m, gp);
        self.graph.neg(mgp)
    }
}

/// What an overflowing constant of `what` means: the scene's numbers are
/// beyond double precision, and the limit.
pub(crate) fn overflow_message(what: &str) -> String {
    format!(
        "{what} gives a constant beyond f64's range (|x| <= {:e}) or not a number: the \
         scene's numbers are too large or too small for double precision (choose other units)",
        f64::MAX
    )
}
