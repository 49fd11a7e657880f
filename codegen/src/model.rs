//! From a parsed scene to symbolic energies: checks names, parameters and
//! physical data, builds kinematic frames, and turns every component into its
//! kinetic energy `T`, potential energy `V` and dissipation function `D`.

use std::collections::BTreeMap;
use std::path::Path;

use toml::Spanned;

use crate::error::{Error, Source};
use crate::expr::{Graph, Id, Symbol};
use crate::parse::{parse_expr, Binding, Scope, RESERVED};
use crate::scene::{
    parse_scene, AxisDef, ComponentDef, FrameDef, ParameterDef, SScalar, Scalar, SceneDef,
};

/// A generalized coordinate.
#[derive(Debug, Clone, PartialEq)]
pub struct Coordinate {
    /// Its name.
    pub name: String,
    /// Declared position range.
    pub range: Option<[f64; 2]>,
    /// Declared velocity range.
    pub velocity_range: Option<[f64; 2]>,
}

/// A parameter left as an input of the generated model.
#[derive(Debug, Clone, PartialEq)]
pub struct RuntimeParameter {
    /// Field name in the generated model struct.
    pub name: String,
    /// Nominal value (the struct's default).
    pub value: f64,
}

/// The energies of one component.
#[derive(Debug, Clone)]
pub struct Component {
    /// Name for reports.
    pub name: String,
    /// Kind (`rod`, `energy`, ...).
    pub kind: String,
    /// Kinetic energy.
    pub kinetic: Id,
    /// Potential energy.
    pub potential: Id,
    /// Rayleigh dissipation function.
    pub dissipation: Id,
}

/// A holonomic constraint.
#[derive(Debug, Clone)]
pub struct Constraint {
    /// Name for reports.
    pub name: String,
    /// Residual `Phi(q, t)`.
    pub residual: Id,
}

/// An actuator input.
#[derive(Debug, Clone, PartialEq)]
pub struct Actuator {
    /// Name.
    pub name: String,
    /// Coordinate it drives.
    pub coordinate: usize,
    /// Generalized force per unit input.
    pub gain: f64,
}

/// Optional outputs a scene may ask for.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Outputs {
    /// The Coriolis matrix from Christoffel symbols.
    pub coriolis_matrix: bool,
    /// Coriolis, potential and damping forces as separate functions.
    pub forces: bool,
}

/// A scene turned into symbolic energies.
#[derive(Debug, Clone)]
pub struct Model {
    /// Scene name (an identifier).
    pub name: String,
    /// The expression graph holding every expression below.
    pub graph: Graph,
    /// Coordinates in order.
    pub coordinates: Vec<Coordinate>,
    /// Runtime parameters, in the order of `Symbol::Param` indices.
    pub runtime_parameters: Vec<RuntimeParameter>,
    /// Nominal value of every parameter, folded or runtime, by name.
    pub parameters: BTreeMap<String, f64>,
    /// Components.
    pub components: Vec<Component>,
    /// Constraints.
    pub constraints: Vec<Constraint>,
    /// Actuators.
    pub actuators: Vec<Actuator>,
    /// Optional outputs.
    pub outputs: Outputs,
}

impl Model {
    /// Number of coordinates.
    pub fn nq(&self) -> usize {
        self.coordinates.len()
    }

    /// Load a scene file.
    pub fn load(path: &Path) -> Result<Model, Error> {
        let text = std::fs::read_to_string(path).map_err(|e| Error {
            file: path.to_path_buf(),
            line: 0,
            column: 0,
            context: None,
            message: format!("cannot read scene file: {e}"),
        })?;
        Model::from_source(&Source::new(path, text))
    }

    /// Build the model from a scene file's text.
    pub fn from_source(source: &Source) -> Result<Model, Error> {
        let def = parse_scene(source)?;
        Builder::new(source).build(&def)
    }
}

/// Whether `name` is a valid identifier for scene items.
fn check_ident(source: &Source, name: &Spanned<String>, what: &str) -> Result<(), Error> {
    let s = name.get_ref();
    let ok = s.len() <= 64
        && s.chars().next().is_some_and(|c| c.is_ascii_alphabetic())
        && s.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
    if !ok {
        return Err(source.error_at(
            name.span().start,
            None,
            format!(
                "{what} `{s}` is not a valid name (a letter, then letters, digits or `_`, at most 64)"
            ),
        ));
    }
    if RESERVED.contains(&s.as_str()) || RUST_KEYWORDS.contains(&s.as_str()) {
        return Err(source.error_at(
            name.span().start,
            None,
            format!("{what} `{s}` is a reserved word"),
        ));
    }
    Ok(())
}

const RUST_KEYWORDS: &[&str] = &[
    "as", "async", "await", "break", "const", "continue", "crate", "dyn", "else", "enum", "extern",
    "false", "fn", "for", "gen", "if", "impl", "in", "let", "loop", "match", "mod", "move", "mut",
    "pub", "ref", "return", "self", "Self", "static", "struct", "super", "trait", "true", "type",
    "unsafe", "use", "where", "while", "abstract", "become", "box", "do", "final", "macro",
    "override", "priv", "try", "typeof", "unsized", "virtual", "yield", "union",
];

/// World-frame pose of a frame, with the velocity of its origin and its
/// angular velocity both in the frame's own axes. Keeping velocities in local
/// axes means constant rotations (a chain placed at 120 degrees) never enter
/// the kinetic energy, which stays as simple as the mechanism.
#[derive(Debug, Clone)]
struct Frame {
    rotation: [[Id; 3]; 3],
    origin: [Id; 3],
    /// Velocity of the origin in the frame's own axes.
    velocity: [Id; 3],
    /// Angular velocity in the frame's own axes.
    omega: [Id; 3],
}

/// A material point: world position, and velocity in the axes of the frame
/// it was given in (all points of one component share those axes).
struct Point {
    position: [Id; 3],
    velocity: [Id; 3],
}

struct Builder<'a> {
    source: &'a Source,
    graph: Graph,
    scope: Scope,
    frames: BTreeMap<String, Frame>,
    gravity: [Id; 3],
    nominal: Vec<f64>,
    parameter_values: BTreeMap<String, f64>,
}

impl<'a> Builder<'a> {
    fn new(source: &'a Source) -> Builder<'a> {
        let mut graph = Graph::new();
        let zero = graph.constant(0.0);
        Builder {
            source,
            graph,
            scope: Scope::default(),
            frames: BTreeMap::new(),
            gravity: [zero; 3],
            nominal: Vec::new(),
            parameter_values: BTreeMap::new(),
        }
    }

    fn err(&self, offset: usize, ctx: Option<&str>, msg: impl Into<String>) -> Error {
        self.source.error_at(offset, ctx, msg)
    }

    fn build(mut self, def: &SceneDef) -> Result<Model, Error> {
        check_ident(self.source, &def.name, "scene name")?;
        if !def.name.get_ref().chars().all(|c| !c.is_ascii_uppercase()) {
            return Err(self.err(
                def.name.span().start,
                None,
                "scene name must be lower case (it names a Rust module)",
            ));
        }
        let coordinates = self.coordinates(def)?;
        let runtime_parameters = self.parameters(def)?;
        self.gravity = match &def.gravity {
            Some(v) => self.vector(v, None, false)?,
            None => {
                let zero = self.graph.constant(0.0);
                let g = self.graph.constant(-9.81);
                [zero, zero, g]
            }
        };
        self.frames(&def.frames)?;
        let mut components = Vec::new();
        for (i, c) in def.components.iter().enumerate() {
            components.push(self.component(i, c)?);
        }
        let mut constraints = Vec::new();
        for (i, c) in def.constraints.iter().enumerate() {
            let name = c
                .name
                .as_ref()
                .map_or_else(|| format!("constraint{i}"), |n| n.get_ref().clone());
            let ctx = format!("constraint `{name}`");
            let residual = self.scalar(&c.expression, Some(&ctx), false)?;
            constraints.push(Constraint { name, residual });
        }
        let mut actuators = Vec::new();
        for a in &def.actuators {
            check_ident(self.source, &a.name, "actuator")?;
            let Some(coordinate) = coordinates
                .iter()
                .position(|c| c.name == *a.coordinate.get_ref())
            else {
                return Err(self.err(
                    a.coordinate.span().start,
                    Some(&format!("actuator `{}`", a.name.get_ref())),
                    format!("coordinate `{}` is not declared", a.coordinate.get_ref()),
                ));
            };
            let gain = a.gain.as_ref().map_or(1.0, |g| *g.get_ref());
            if !gain.is_finite() {
                let at = a.gain.as_ref().map_or(0, |g| g.span().start);
                return Err(self.err(at, None, "actuator gain is not finite"));
            }
            actuators.push(Actuator {
                name: a.name.get_ref().clone(),
                coordinate,
                gain,
            });
        }
        let mut outputs = Outputs::default();
        for o in &def.outputs {
            match o.get_ref().as_str() {
                "coriolis_matrix" => outputs.coriolis_matrix = true,
                "forces" => outputs.forces = true,
                other => {
                    return Err(self.err(
                        o.span().start,
                        None,
                        format!("unknown output `{other}` (known: coriolis_matrix, forces)"),
                    ))
                }
            }
        }
        Ok(Model {
            name: def.name.get_ref().clone(),
            graph: self.graph,
            coordinates,
            runtime_parameters,
            parameters: self.parameter_values,
            components,
            constraints,
            actuators,
            outputs,
        })
    }

    fn coordinates(&mut self, def: &SceneDef) -> Result<Vec<Coordinate>, Error> {
        if def.coordinates.is_empty() {
            return Err(self.source.error("the scene declares no coordinates"));
        }
        let mut out: Vec<Coordinate> = Vec::new();
        for c in &def.coordinates {
            check_ident(self.source, &c.name, "coordinate")?;
            if out.iter().any(|o| o.name == *c.name.get_ref()) {
                return Err(self.err(
                    c.name.span().start,
                    None,
                    format!("coordinate `{}` is declared twice", c.name.get_ref()),
                ));
            }
            let range = |r: &Option<Spanned<[f64; 2]>>| -> Result<Option<[f64; 2]>, Error> {
                match r {
                    Some(r) => {
                        let [a, b] = *r.get_ref();
                        if !(a.is_finite() && b.is_finite() && a < b) {
                            return Err(self.err(
                                r.span().start,
                                None,
                                "a range must be two finite numbers, low < high",
                            ));
                        }
                        Ok(Some([a, b]))
                    }
                    None => Ok(None),
                }
            };
            out.push(Coordinate {
                name: c.name.get_ref().clone(),
                range: range(&c.range)?,
                velocity_range: range(&c.velocity_range)?,
            });
        }
        self.scope.coordinates = out.iter().map(|c| c.name.clone()).collect();
        Ok(out)
    }

    fn parameters(&mut self, def: &SceneDef) -> Result<Vec<RuntimeParameter>, Error> {
        let mut runtime = Vec::new();
        for (name, p) in &def.parameters {
            check_ident(self.source, name, "parameter")?;
            if self.scope.coordinates.contains(name.get_ref()) {
                return Err(self.err(
                    name.span().start,
                    None,
                    format!(
                        "parameter `{}` has the name of a coordinate",
                        name.get_ref()
                    ),
                ));
            }
            let (value, is_runtime) = match p.get_ref() {
                ParameterDef::Value(v) => (*v, false),
                ParameterDef::Table(t) => (t.value, t.runtime),
            };
            if !value.is_finite() {
                return Err(self.err(
                    p.span().start,
                    Some(&format!("parameter `{}`", name.get_ref())),
                    format!("value is not finite ({value})"),
                ));
            }
            let binding = if is_runtime {
                runtime.push(RuntimeParameter {
                    name: name.get_ref().clone(),
                    value,
                });
                self.nominal.push(value);
                Binding::Runtime(runtime.len() as u32 - 1)
            } else {
                Binding::Value(value)
            };
            self.scope
                .parameters
                .insert(name.get_ref().clone(), binding);
            self.parameter_values.insert(name.get_ref().clone(), value);
        }
        Ok(runtime)
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

    fn scalar(&mut self, s: &SScalar, ctx: Option<&str>, velocity: bool) -> Result<Id, Error> {
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

    fn vector(
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
    fn nominal_value(&self, id: Id, at: usize, ctx: &str, what: &str) -> Result<f64, Error> {
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

    fn positive(&mut self, s: &SScalar, ctx: &str, what: &str, strict: bool) -> Result<Id, Error> {
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

    fn frames(&mut self, defs: &[FrameDef]) -> Result<(), Error> {
        for f in defs {
            check_ident(self.source, &f.name, "frame")?;
            let ctx = format!("frame `{}`", f.name.get_ref());
            if f.name.get_ref() == "world" || self.frames.contains_key(f.name.get_ref()) {
                return Err(self.err(f.name.span().start, Some(&ctx), "frame is defined twice"));
            }
            let parent = match &f.parent {
                Some(p) => self.lookup_frame(p, &ctx)?,
                None => self.world(),
            };
            let translation = match &f.translation {
                Some(t) => self.vector(t, Some(&ctx), false)?,
                None => [self.graph.constant(0.0); 3],
            };
            let offset = self.rotate(&parent.rotation, translation);
            let origin: [Id; 3] =
                std::array::from_fn(|k| self.graph.add(parent.origin[k], offset[k]));
            // Origin velocity in parent axes: v_parent + w_parent x t + dt/dt.
            let mut velocity = self.moving_point_velocity(&parent, translation);
            let mut rotation = parent.rotation;
            let mut omega = parent.omega;
            for r in &f.rotation {
                let axis = self.axis(&r.axis, &ctx)?;
                let angle = self.scalar(&r.angle, Some(&ctx), false)?;
                let local = self.axis_rotation(axis, angle);
                rotation = self.matmul(&rotation, &local);
                // omega_child = R_local^T omega_parent + axis * angle_dot
                let rate = self.graph.time_derivative_at_zero_acceleration(&[angle])[0];
                velocity = self.rotate_transpose(&local, velocity);
                let rotated = self.rotate_transpose(&local, omega);
                omega = std::array::from_fn(|k| {
                    let a = self.graph.constant(axis[k]);
                    let term = self.graph.mul(a, rate);
                    self.graph.add(rotated[k], term)
                });
            }
            self.frames.insert(
                f.name.get_ref().clone(),
                Frame {
                    rotation,
                    origin,
                    velocity,
                    omega,
                },
            );
        }
        Ok(())
    }

    fn world(&mut self) -> Frame {
        let zero = self.graph.constant(0.0);
        let one = self.graph.constant(1.0);
        let mut rotation = [[zero; 3]; 3];
        for (k, row) in rotation.iter_mut().enumerate() {
            row[k] = one;
        }
        Frame {
            rotation,
            origin: [zero; 3],
            velocity: [zero; 3],
            omega: [zero; 3],
        }
    }

    fn lookup_frame(&mut self, name: &Spanned<String>, ctx: &str) -> Result<Frame, Error> {
        if name.get_ref() == "world" {
            return Ok(self.world());
        }
        self.frames.get(name.get_ref()).cloned().ok_or_else(|| {
            self.err(
                name.span().start,
                Some(ctx),
                format!("frame `{}` is not defined above", name.get_ref()),
            )
        })
    }

    fn axis(&self, a: &Spanned<AxisDef>, ctx: &str) -> Result<[f64; 3], Error> {
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

    /// Rotation by `angle` about the unit vector `u` (Rodrigues).
    fn axis_rotation(&mut self, u: [f64; 3], angle: Id) -> [[Id; 3]; 3] {
        let c = self.graph.cos(angle);
        let s = self.graph.sin(angle);
        std::array::from_fn(|i| {
            std::array::from_fn(|j| {
                // R = c I + s [u]x + (1 - c) u u^T
                let uu = u[i] * u[j];
                let cross = match (i, j) {
                    (0, 1) => -u[2],
                    (1, 0) => u[2],
                    (0, 2) => u[1],
                    (2, 0) => -u[1],
                    (1, 2) => -u[0],
                    (2, 1) => u[0],
                    _ => 0.0,
                };
                let diag = if i == j { 1.0 } else { 0.0 };
                // (diag - uu) c + cross s + uu
                self.graph.linear(&[(c, diag - uu), (s, cross)], uu)
            })
        })
    }

    fn matmul(&mut self, a: &[[Id; 3]; 3], b: &[[Id; 3]; 3]) -> [[Id; 3]; 3] {
        std::array::from_fn(|i| {
            std::array::from_fn(|j| {
                let terms: Vec<Id> = (0..3).map(|k| self.graph.mul(a[i][k], b[k][j])).collect();
                self.graph.sum(&terms)
            })
        })
    }

    fn rotate(&mut self, r: &[[Id; 3]; 3], v: [Id; 3]) -> [Id; 3] {
        std::array::from_fn(|i| {
            let terms: Vec<Id> = (0..3).map(|k| self.graph.mul(r[i][k], v[k])).collect();
            self.graph.sum(&terms)
        })
    }

    fn rotate_transpose(&mut self, r: &[[Id; 3]; 3], v: [Id; 3]) -> [Id; 3] {
        std::array::from_fn(|i| {
            let terms: Vec<Id> = (0..3).map(|k| self.graph.mul(r[k][i], v[k])).collect();
            self.graph.sum(&terms)
        })
    }

    fn dot(&mut self, a: [Id; 3], b: [Id; 3]) -> Id {
        let terms: Vec<Id> = (0..3).map(|k| self.graph.mul(a[k], b[k])).collect();
        self.graph.sum(&terms)
    }

    /// A point given in a component's frame (the world when it has none).
    fn point(
        &mut self,
        c: &ComponentDef,
        v: &Spanned<Vec<SScalar>>,
        ctx: &str,
    ) -> Result<Point, Error> {
        let local = self.vector(v, Some(ctx), false)?;
        let frame = match &c.frame {
            None => self.world(),
            Some(name) => self.lookup_frame(name, ctx)?,
        };
        let r = self.rotate(&frame.rotation, local);
        Ok(Point {
            position: std::array::from_fn(|k| self.graph.add(frame.origin[k], r[k])),
            velocity: self.moving_point_velocity(&frame, local),
        })
    }

    /// Velocity, in `frame`'s axes, of a point at `local` (which may itself
    /// move): `v_origin + w x local + d(local)/dt`.
    fn moving_point_velocity(&mut self, frame: &Frame, local: [Id; 3]) -> [Id; 3] {
        let rate = self.graph.time_derivative_at_zero_acceleration(&local);
        let w = frame.omega;
        let cross = [
            (w[1], local[2], w[2], local[1]),
            (w[2], local[0], w[0], local[2]),
            (w[0], local[1], w[1], local[0]),
        ];
        std::array::from_fn(|k| {
            let (a, b, c, d) = cross[k];
            let ab = self.graph.mul(a, b);
            let cd = self.graph.mul(c, d);
            self.graph.linear(
                &[
                    (frame.velocity[k], 1.0),
                    (ab, 1.0),
                    (cd, -1.0),
                    (rate[k], 1.0),
                ],
                0.0,
            )
        })
    }

    /// Gravitational potential of mass `m` at `p`: `-m g . p`.
    fn gravity_potential(&mut self, m: Id, p: [Id; 3]) -> Id {
        let gp = self.dot(self.gravity, p);
        let mgp = self.graph.mul(m, gp);
        self.graph.neg(mgp)
    }

    fn component(&mut self, index: usize, c: &ComponentDef) -> Result<Component, Error> {
        let kind = c.kind.get_ref().clone();
        let name = match &c.name {
            Some(n) => {
                check_ident(self.source, n, "component")?;
                n.get_ref().clone()
            }
            None => format!("{kind}{index}"),
        };
        let ctx = format!("component `{name}`");
        let allowed: &[&str] = match kind.as_str() {
            "energy" => &["kinetic", "potential", "dissipation"],
            "point_mass" => &["mass", "position", "frame"],
            "rod" => &["mass", "from", "to", "frame"],
            "rigid_body" => &["mass", "position", "frame", "inertia"],
            "spring" => &["stiffness", "expression", "rest"],
            "damper" => &["damping", "expression"],
            _ => {
                return Err(self.err(
                    c.kind.span().start,
                    Some(&ctx),
                    format!(
                        "unknown component type `{kind}` (known: energy, point_mass, rod, rigid_body, spring, damper)"
                    ),
                ))
            }
        };
        self.check_fields(c, allowed, &ctx)?;
        let zero = self.graph.constant(0.0);
        let (mut kinetic, mut potential, mut dissipation) = (zero, zero, zero);
        let need = |field: &str| {
            self.err(
                c.kind.span().start,
                Some(&ctx),
                format!("a `{kind}` component needs `{field}`"),
            )
        };
        let req = |o: &Option<SScalar>, field: &str| o.clone().ok_or_else(|| need(field));
        let req_vec =
            |o: &Option<Spanned<Vec<SScalar>>>, field: &str| o.clone().ok_or_else(|| need(field));
        let mass = c.mass.as_ref().map(|_| req(&c.mass, "mass"));
        let position = req_vec(&c.position, "position");
        let from = req_vec(&c.from, "from");
        let to = req_vec(&c.to, "to");
        let stiffness = req(&c.stiffness, "stiffness");
        let damping = req(&c.damping, "damping");
        let expression = req(&c.expression, "expression");
        let mass = mass.unwrap_or_else(|| Err(need("mass")));
        match kind.as_str() {
            "energy" => {
                if c.kinetic.is_none() && c.potential.is_none() && c.dissipation.is_none() {
                    return Err(self.err(
                        c.kind.span().start,
                        Some(&ctx),
                        "an `energy` component needs `kinetic`, `potential` or `dissipation`",
                    ));
                }
                if let Some(t) = &c.kinetic {
                    kinetic = self.scalar(t, Some(&ctx), true)?;
                }
                if let Some(v) = &c.potential {
                    potential = self.scalar(v, Some(&ctx), false)?;
                }
                if let Some(d) = &c.dissipation {
                    dissipation = self.scalar(d, Some(&ctx), true)?;
                }
            }
            "point_mass" => {
                let m = self.positive(&mass.clone()?, &ctx, "mass", true)?;
                let p = self.point(c, &position?, &ctx)?;
                let v2 = self.dot(p.velocity, p.velocity);
                let mv2 = self.graph.mul(m, v2);
                kinetic = self.graph.scale(mv2, 0.5);
                potential = self.gravity_potential(m, p.position);
            }
            "rod" => {
                let m = self.positive(&mass.clone()?, &ctx, "mass", true)?;
                let a = self.point(c, &from?, &ctx)?;
                let b = self.point(c, &to?, &ctx)?;
                let (va, vb) = (a.velocity, b.velocity);
                // Uniform thin rod: T = m/6 (|va|^2 + va.vb + |vb|^2).
                let aa = self.dot(va, va);
                let ab = self.dot(va, vb);
                let bb = self.dot(vb, vb);
                let s = self.graph.sum(&[aa, ab, bb]);
                let ms = self.graph.mul(m, s);
                kinetic = self.graph.scale(ms, 1.0 / 6.0);
                let mid: [Id; 3] = std::array::from_fn(|k| {
                    let ab = self.graph.add(a.position[k], b.position[k]);
                    self.graph.scale(ab, 0.5)
                });
                potential = self.gravity_potential(m, mid);
            }
            "rigid_body" => {
                let m = self.positive(&mass.clone()?, &ctx, "mass", true)?;
                let Some(frame_name) = &c.frame else {
                    return Err(self.err(
                        c.kind.span().start,
                        Some(&ctx),
                        "a `rigid_body` component needs `frame`",
                    ));
                };
                let frame = self.lookup_frame(frame_name, &ctx)?;
                let com = match &c.position {
                    Some(p) => self.point(c, p, &ctx)?,
                    None => Point {
                        position: frame.origin,
                        velocity: frame.velocity,
                    },
                };
                let inertia = self.inertia(c, &ctx)?;
                let v2 = self.dot(com.velocity, com.velocity);
                let w = frame.omega;
                let iw = self.rotate(&inertia, w);
                let wiw = self.dot(w, iw);
                let mv2 = self.graph.mul(m, v2);
                let total = self.graph.add(mv2, wiw);
                kinetic = self.graph.scale(total, 0.5);
                potential = self.gravity_potential(m, com.position);
            }
            "spring" => {
                let k = self.positive(&stiffness?, &ctx, "stiffness", false)?;
                let e = self.scalar(&expression.clone()?, Some(&ctx), false)?;
                let rest = match &c.rest {
                    Some(r) => self.scalar(r, Some(&ctx), false)?,
                    None => zero,
                };
                let stretch = self.graph.sub(e, rest);
                let s2 = self.graph.powi(stretch, 2);
                let ks2 = self.graph.mul(k, s2);
                potential = self.graph.scale(ks2, 0.5);
            }
            "damper" => {
                let d = self.positive(&damping?, &ctx, "damping", false)?;
                let e = self.scalar(&expression.clone()?, Some(&ctx), false)?;
                let rate = self.graph.time_derivative_at_zero_acceleration(&[e])[0];
                let r2 = self.graph.powi(rate, 2);
                let dr2 = self.graph.mul(d, r2);
                dissipation = self.graph.scale(dr2, 0.5);
            }
            _ => unreachable!("kind checked above"),
        }
        Ok(Component {
            name,
            kind,
            kinetic,
            potential,
            dissipation,
        })
    }

    fn check_fields(&self, c: &ComponentDef, allowed: &[&str], ctx: &str) -> Result<(), Error> {
        let present: [(&str, Option<usize>); 13] = [
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
            ("stiffness", c.stiffness.as_ref().map(|s| s.span().start)),
            ("damping", c.damping.as_ref().map(|s| s.span().start)),
            ("expression", c.expression.as_ref().map(|s| s.span().start)),
            ("rest", c.rest.as_ref().map(|s| s.span().start)),
        ];
        for (field, at) in present {
            if let Some(at) = at {
                if !allowed.contains(&field) {
                    return Err(self.err(
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

    /// The inertia tensor: 3x3, parameter-only, symmetric, positive definite.
    fn inertia(&mut self, c: &ComponentDef, ctx: &str) -> Result<[[Id; 3]; 3], Error> {
        let Some(rows) = &c.inertia else {
            return Err(self.err(
                c.kind.span().start,
                Some(ctx),
                "a `rigid_body` component needs `inertia`",
            ));
        };
        let at = rows.span().start;
        if rows.get_ref().len() != 3 || rows.get_ref().iter().any(|r| r.len() != 3) {
            return Err(self.err(at, Some(ctx), "inertia must be a 3x3 array"));
        }
        let mut ids = [[self.graph.constant(0.0); 3]; 3];
        let mut val = [[0.0; 3]; 3];
        for (i, row) in rows.get_ref().iter().enumerate() {
            for (j, s) in row.iter().enumerate() {
                ids[i][j] = self.scalar(s, Some(ctx), false)?;
                val[i][j] = self.nominal_value(ids[i][j], s.span().start, ctx, "inertia")?;
            }
        }
        let scale = val.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
        let asymmetric = [(0, 1), (0, 2), (1, 2)]
            .iter()
            .any(|&(i, j)| (val[i][j] - val[j][i]).abs() > 1e-12 * scale.max(1e-300));
        if asymmetric {
            return Err(self.err(at, Some(ctx), "inertia tensor is not symmetric"));
        }
        if !positive_definite_3x3(&val) {
            return Err(self.err(at, Some(ctx), "inertia tensor is not positive definite"));
        }
        Ok(ids)
    }
}

/// Cholesky test for a symmetric 3x3 matrix.
fn positive_definite_3x3(a: &[[f64; 3]; 3]) -> bool {
    let mut l = [[0.0f64; 3]; 3];
    for i in 0..3 {
        for j in 0..=i {
            let s: f64 = a[i][j] - (0..j).map(|k| l[i][k] * l[j][k]).sum::<f64>();
            if i == j {
                if s.is_nan() || s <= 0.0 {
                    return false;
                }
                l[i][i] = s.sqrt();
            } else {
                l[i][j] = s / l[j][j];
            }
        }
    }
    true
}
