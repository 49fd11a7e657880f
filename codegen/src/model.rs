//! From a parsed scene to symbolic energies: checks names, parameters and
//! physical data, builds kinematic frames, and turns every component into its
//! kinetic energy `T`, potential energy `V` and dissipation function `D`.
//!
//! Order: coordinates, parameters and gravity; then every `flexible_link`
//! component, whose finite-element model ([`crate::fem`]) is built
//! numerically and whose modal coordinates `<name>_eta<j>` are appended to
//! the declared ones; then the frames in file order (a frame with `station`
//! follows a flexible link's deformed centre line); then the components'
//! energies, the constraints (`expression`, or the vector constraints
//! `coincident` and `perpendicular` between frames) and the actuators.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use nalgebra::DMatrix;
use toml::Spanned;

use crate::error::{Error, Source};
use crate::expr::{Graph, Id, Symbol};
use crate::fem::{
    Beam, BoundaryConditions, FeModel, Invariants, Material, ModalBasis, ModeSelection, Section,
    RY, RZ, UX,
};
use crate::parse::{parse_expr, Binding, Scope, RESERVED};
use crate::scene::{
    parse_scene_file, AxisDef, ComponentDef, ConstraintDef, ConstraintEnd, EndStiffnessDef,
    FrameDef, MaterialDef, ParameterDef, SScalar, Scalar, ScalarList, SceneDef, SceneFile,
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
    /// Exact Jacobians of the bias forces, `dh/dq` and `dh/dqd` (for the
    /// Newton matrix of implicit integrators).
    pub bias_jacobians: bool,
}

/// The finite-element data behind a `flexible_link` component, built
/// numerically when the scene is read.
#[derive(Debug, Clone)]
pub struct FlexibleLink {
    /// Component name.
    pub name: String,
    /// Name of its reference frame.
    pub frame: String,
    /// Index in [`Model::coordinates`] of its first modal coordinate; the
    /// `k` modal coordinates follow in mode order.
    pub first_coordinate: usize,
    /// The constrained finite-element model.
    pub fe: FeModel,
    /// The kept modes.
    pub basis: ModalBasis,
    /// Their inertia invariants.
    pub invariants: Invariants,
    /// Modal damping ratio of each kept mode.
    pub damping_ratio: Vec<f64>,
    /// `Phi^T Kg1 Phi` for the centrifugal axial force per unit squared
    /// transverse spin rate, when geometric stiffening is on.
    pub geometric_stiffness: Option<DMatrix<f64>>,
}

impl FlexibleLink {
    /// Number of kept modes.
    pub fn modes(&self) -> usize {
        self.basis.len()
    }
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
    /// Finite-element data of the flexible links, in component order.
    pub flexible_links: Vec<FlexibleLink>,
    /// Relative tolerance below which summands of the mass matrix and bias
    /// forces are dropped after the derivation (a derived scene's
    /// `reduce.drop_below`; see [`crate::reduce`]).
    pub drop_below: Option<f64>,
    /// Every file the model was read from (a derived scene and its base).
    pub sources: Vec<PathBuf>,
}

impl Model {
    /// Number of coordinates.
    pub fn nq(&self) -> usize {
        self.coordinates.len()
    }

    /// The scene's symbolic inputs: `T`, `V`, `D` of every component in
    /// order, then every constraint residual.
    pub fn input_roots(&self) -> Vec<Id> {
        let mut roots: Vec<Id> = Vec::new();
        for c in &self.components {
            roots.extend([c.kinetic, c.potential, c.dissipation]);
        }
        roots.extend(self.constraints.iter().map(|c| c.residual));
        roots
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

    /// Build the model from a scene file's text. A derived scene (one with a
    /// top-level `base`) loads its base from the same directory and applies
    /// its reductions ([`crate::reduce`]).
    pub fn from_source(source: &Source) -> Result<Model, Error> {
        match parse_scene_file(source)? {
            SceneFile::Full(def) => Builder::new(source).build(&def),
            SceneFile::Derived(def) => {
                check_ident(source, &def.name, "scene name")?;
                check_lower_case(source, &def.name)?;
                let base = def.base.get_ref();
                let plain = Path::new(base)
                    .file_name()
                    .is_some_and(|f| f == std::ffi::OsStr::new(base))
                    && base.ends_with(".toml");
                if !plain {
                    return Err(source.error_at(
                        def.base.span().start,
                        None,
                        format!(
                            "base `{base}` must be the file name of a scene (`*.toml`) in the \
                             same directory"
                        ),
                    ));
                }
                let path = source.path().with_file_name(base);
                let text = std::fs::read_to_string(&path).map_err(|e| {
                    source.error_at(
                        def.base.span().start,
                        None,
                        format!("cannot read base scene {}: {e}", path.display()),
                    )
                })?;
                let base_source = Source::new(&path, text);
                let SceneFile::Full(base_def) = parse_scene_file(&base_source)? else {
                    return Err(source.error_at(
                        def.base.span().start,
                        None,
                        format!(
                            "base `{base}` is itself a derived scene; derive from a full scene"
                        ),
                    ));
                };
                let mut model = Builder::new(&base_source).build(&base_def)?;
                model.sources.insert(0, source.path().to_path_buf());
                crate::reduce::apply(model, &def, source)
            }
        }
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

/// Scene names name Rust modules: lower case.
fn check_lower_case(source: &Source, name: &Spanned<String>) -> Result<(), Error> {
    if name.get_ref().chars().any(|c| c.is_ascii_uppercase()) {
        return Err(source.error_at(
            name.span().start,
            None,
            "scene name must be lower case (it names a Rust module)",
        ));
    }
    Ok(())
}

/// Fields of a `flexible_link` component.
const FLEXIBLE_LINK_FIELDS: &[&str] = &[
    "frame",
    "length",
    "material",
    "section",
    "elements",
    "modes",
    "max_frequency",
    "boundary",
    "end_stiffness",
    "damping_ratio",
    "geometric_stiffening",
];

/// Most finite elements of one flexible link.
pub const MAX_ELEMENTS: usize = 200;
/// Most modes of one flexible link.
pub const MAX_MODES: usize = 60;

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
    /// Flexible links with the index of their component.
    flexible: Vec<(usize, FlexibleLink)>,
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
            flexible: Vec::new(),
        }
    }

    fn err(&self, offset: usize, ctx: Option<&str>, msg: impl Into<String>) -> Error {
        self.source.error_at(offset, ctx, msg)
    }

    fn build(mut self, def: &SceneDef) -> Result<Model, Error> {
        check_ident(self.source, &def.name, "scene name")?;
        check_lower_case(self.source, &def.name)?;
        let mut coordinates = self.coordinates(def)?;
        let runtime_parameters = self.parameters(def)?;
        self.gravity = match &def.gravity {
            Some(v) => self.vector(v, None, false)?,
            None => {
                let zero = self.graph.constant(0.0);
                let g = self.graph.constant(-9.81);
                [zero, zero, g]
            }
        };
        // Flexible links first: their finite-element models are built
        // numerically and their modal coordinates appended to the declared
        // ones, so that frames (stations), components and constraints below
        // can use them.
        for (i, c) in def.components.iter().enumerate() {
            if c.kind.get_ref() == "flexible_link" {
                let link = self.flexible_link(i, c, &mut coordinates)?;
                self.flexible.push((i, link));
            }
        }
        self.frames(&def.frames)?;
        let mut components = Vec::new();
        for (i, c) in def.components.iter().enumerate() {
            components.push(self.component(i, c)?);
        }
        let mut constraints = Vec::new();
        for (i, c) in def.constraints.iter().enumerate() {
            self.constraint(i, c, &mut constraints)?;
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
                "bias_jacobians" => outputs.bias_jacobians = true,
                other => {
                    return Err(self.err(
                        o.span().start,
                        None,
                        format!(
                        "unknown output `{other}` (known: coriolis_matrix, forces, bias_jacobians)"
                    ),
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
            flexible_links: self.flexible.into_iter().map(|(_, l)| l).collect(),
            drop_below: None,
            sources: vec![self.source.path().to_path_buf()],
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
            let mut parent = match &f.parent {
                Some(p) => self.lookup_frame(p, &ctx)?,
                None => self.world(),
            };
            if let Some(station) = &f.station {
                parent = self.station_frame(f, station, &parent, &ctx)?;
            }
            let translation = match &f.translation {
                Some(t) => self.vector(t, Some(&ctx), false)?,
                None => [self.graph.constant(0.0); 3],
            };
            let mut rotations = Vec::with_capacity(f.rotation.len());
            for r in &f.rotation {
                let axis = self.axis(&r.axis, &ctx)?;
                let angle = self.scalar(&r.angle, Some(&ctx), false)?;
                rotations.push((axis, angle));
            }
            let frame = self.child_frame(&parent, translation, &rotations);
            self.frames.insert(f.name.get_ref().clone(), frame);
        }
        Ok(())
    }

    /// The frame at `translation` (in `parent`'s axes) from `parent`'s
    /// origin, rotated from `parent` by `rotations` in turn (intrinsic).
    fn child_frame(
        &mut self,
        parent: &Frame,
        translation: [Id; 3],
        rotations: &[([f64; 3], Id)],
    ) -> Frame {
        let offset = self.rotate(&parent.rotation, translation);
        let origin: [Id; 3] = std::array::from_fn(|k| self.graph.add(parent.origin[k], offset[k]));
        // Origin velocity in parent axes: v_parent + w_parent x t + dt/dt.
        let mut velocity = self.moving_point_velocity(parent, translation);
        let mut rotation = parent.rotation;
        let mut omega = parent.omega;
        for &(axis, angle) in rotations {
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
        Frame {
            rotation,
            origin,
            velocity,
            omega,
        }
    }

    /// The frame that follows a flexible link at a station: origin at the
    /// deformed centre line `u0(x) + Phi_t(x) eta`, axes rotated by the small
    /// elastic rotation `theta = Phi_r(x) eta` as elementary rotations about
    /// x, y, z in turn (orthogonal; `I + skew(theta)` to first order).
    fn station_frame(
        &mut self,
        f: &FrameDef,
        station: &SScalar,
        parent: &Frame,
        ctx: &str,
    ) -> Result<Frame, Error> {
        let at = station.span().start;
        let Some(parent_name) = &f.parent else {
            return Err(self.err(
                at,
                Some(ctx),
                "a `station` needs `parent`: the reference frame of a flexible link",
            ));
        };
        let links: Vec<usize> = (0..self.flexible.len())
            .filter(|&i| self.flexible[i].1.frame == *parent_name.get_ref())
            .collect();
        let link = match links.as_slice() {
            [i] => *i,
            [] => {
                return Err(self.err(
                    at,
                    Some(ctx),
                    format!(
                        "frame `{}` is not the reference frame of a flexible link, so it has no stations",
                        parent_name.get_ref()
                    ),
                ))
            }
            _ => {
                let names: Vec<&str> = links
                    .iter()
                    .map(|&i| self.flexible[i].1.name.as_str())
                    .collect();
                return Err(self.err(
                    at,
                    Some(ctx),
                    format!(
                        "frame `{}` is the reference frame of several flexible links ({}); give each its own frame",
                        parent_name.get_ref(),
                        names.join(", ")
                    ),
                ));
            }
        };
        let length = self.flexible[link].1.basis.beam.length;
        let x = match station.get_ref() {
            Scalar::Expr(e) if e.trim() == "start" => 0.0,
            Scalar::Expr(e) if e.trim() == "end" => length,
            _ => self.constant_value(station, ctx, "station")?,
        };
        if !(x >= 0.0 && x <= length * (1.0 + 1e-12)) {
            return Err(self.err(
                at,
                Some(ctx),
                format!(
                    "station x = {x} is outside the link `{}` (0 to {length})",
                    self.flexible[link].1.name
                ),
            ));
        }
        let link = &self.flexible[link].1;
        let st = link
            .basis
            .station(x.min(length))
            .map_err(|e| self.err(at, Some(ctx), e))?;
        let first = link.first_coordinate;
        let eta: Vec<Id> = (0..st.translation.ncols())
            .map(|j| self.graph.q(first + j))
            .collect();
        let row = |m: &DMatrix<f64>, a: usize| -> Vec<f64> { m.row(a).iter().copied().collect() };
        let (tr, rot) = (st.translation.clone(), st.rotation.clone());
        let translation: [Id; 3] = std::array::from_fn(|a| {
            let u0 = if a == 0 { x } else { 0.0 };
            let coeffs = row(&tr, a);
            self.modal_linear(u0, &coeffs, &eta)
        });
        let mut rotations = Vec::new();
        for a in 0..3 {
            let coeffs = row(&rot, a);
            let angle = self.modal_linear(0.0, &coeffs, &eta);
            if !self.graph.is_const(angle, 0.0) {
                let mut axis = [0.0; 3];
                axis[a] = 1.0;
                rotations.push((axis, angle));
            }
        }
        Ok(self.child_frame(parent, translation, &rotations))
    }

    /// `constant + sum_j coeffs[j] vars[j]`, dropping the coefficients below
    /// `1e-14` of the largest (round-off of entries that are zero).
    fn modal_linear(&mut self, constant: f64, coeffs: &[f64], vars: &[Id]) -> Id {
        let scale = coeffs.iter().fold(0.0f64, |m, c| m.max(c.abs()));
        let terms: Vec<(Id, f64)> = coeffs
            .iter()
            .zip(vars)
            .filter(|(c, _)| c.abs() > 1e-14 * scale)
            .map(|(&c, &v)| (v, c))
            .collect();
        self.graph.linear(&terms, constant)
    }

    /// A constant: numbers and folded parameters only (the finite-element
    /// model of a flexible link is built when the code is generated).
    fn constant_value(&mut self, s: &SScalar, ctx: &str, what: &str) -> Result<f64, Error> {
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

    fn constant_positive(&mut self, s: &SScalar, ctx: &str, what: &str) -> Result<f64, Error> {
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
    fn constant_count(
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
    fn material(&mut self, material: &Spanned<MaterialDef>, ctx: &str) -> Result<Material, Error> {
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

    /// Reads a `flexible_link` component, builds its finite-element model
    /// and modes, and appends its modal coordinates `<name>_eta<j>`.
    fn flexible_link(
        &mut self,
        index: usize,
        c: &ComponentDef,
        coordinates: &mut Vec<Coordinate>,
    ) -> Result<FlexibleLink, Error> {
        let kind = "flexible_link";
        let name = match &c.name {
            Some(n) => {
                check_ident(self.source, n, "component")?;
                n.get_ref().clone()
            }
            None => format!("{kind}{index}"),
        };
        let ctx = format!("component `{name}`");
        let ctx = ctx.as_str();
        self.check_fields(c, FLEXIBLE_LINK_FIELDS, ctx)?;
        let kind_at = c.kind.span().start;
        let frame = self.required(c, &c.frame, ctx, "frame")?;
        let length = self.required(c, &c.length, ctx, "length")?;
        let length = self.constant_positive(length, ctx, "length")?;
        let material = self.required(c, &c.material, ctx, "material")?;
        let section = self.required(c, &c.section, ctx, "section")?;
        let boundary = self.required(c, &c.boundary, ctx, "boundary")?;

        let material = self.material(material, ctx)?;

        // Section.
        let sd = section.get_ref();
        let section_at = section.span().start;
        let section = match (&sd.radius, &sd.area, &sd.outer_radius, &sd.inner_radius) {
            (Some(r), None, None, None) => {
                Section::circle(self.constant_positive(r, ctx, "radius")?)
            }
            (None, Some(a), None, None) => {
                Section::circle_with_area(self.constant_positive(a, ctx, "area")?)
            }
            (None, None, Some(ro), Some(ri)) => {
                let ro_v = self.constant_positive(ro, ctx, "outer radius")?;
                let ri_v = self.constant_positive(ri, ctx, "inner radius")?;
                if ri_v >= ro_v {
                    return Err(self.err(
                        ri.span().start,
                        Some(ctx),
                        format!("inner radius {ri_v} must be smaller than the outer radius {ro_v}"),
                    ));
                }
                Section::tube(ro_v, ri_v)
            }
            (None, None, Some(_), None) | (None, None, None, Some(_)) => {
                return Err(self.err(
                    section_at,
                    Some(ctx),
                    "a tube section needs both `outer_radius` and `inner_radius`",
                ))
            }
            (None, None, None, None) => {
                return Err(self.err(
                    section_at,
                    Some(ctx),
                    "the section needs `radius`, `area`, or `outer_radius` and `inner_radius`",
                ))
            }
            _ => {
                return Err(self.err(
                    section_at,
                    Some(ctx),
                    "give one of `radius`, `area`, or `outer_radius` with `inner_radius`",
                ))
            }
        }
        .map_err(|e| self.err(section_at, Some(ctx), e))?;

        let elements = match &c.elements {
            Some(n) => self.constant_count(n, ctx, "elements", 1, MAX_ELEMENTS)?,
            None => 20,
        };
        let beam = Beam::new(length, material, section, elements)
            .map_err(|e| self.err(kind_at, Some(ctx), e))?;

        // Boundary conditions.
        let b_at = boundary.span().start;
        let mut bc = match boundary.get_ref().as_str() {
            "pinned_pinned" | "pinned_pinned_elastic" => BoundaryConditions::pinned_pinned(),
            "clamped_free" => BoundaryConditions::clamped_free(),
            "clamped_clamped" => BoundaryConditions::clamped_clamped(),
            "free_free" => BoundaryConditions::free_free(),
            other => {
                return Err(self.err(
                    b_at,
                    Some(ctx),
                    format!(
                        "unknown boundary `{other}` (known: pinned_pinned, clamped_free, \
                         clamped_clamped, free_free, pinned_pinned_elastic)"
                    ),
                ))
            }
        };
        let elastic = boundary.get_ref() == "pinned_pinned_elastic";
        match (&c.end_stiffness, elastic) {
            (Some(k), false) => {
                return Err(self.err(
                    k.span().start,
                    Some(ctx),
                    "`end_stiffness` applies only to `boundary = \"pinned_pinned_elastic\"`",
                ))
            }
            (None, true) => {
                return Err(self.err(
                    b_at,
                    Some(ctx),
                    "`pinned_pinned_elastic` needs `end_stiffness = [k_y, k_z]`",
                ))
            }
            (Some(k), true) => {
                let pair = |b: &mut Self, v: &Spanned<Vec<SScalar>>| -> Result<[f64; 2], Error> {
                    if v.get_ref().len() != 2 {
                        return Err(b.err(
                            v.span().start,
                            Some(ctx),
                            format!(
                                "end stiffness must be two numbers [k_y, k_z], found {}",
                                v.get_ref().len()
                            ),
                        ));
                    }
                    let mut out = [0.0; 2];
                    for (o, s) in out.iter_mut().zip(v.get_ref()) {
                        *o = b.constant_value(s, ctx, "end stiffness")?;
                        if o.is_nan() || *o < 0.0 {
                            return Err(b.err(
                                s.span().start,
                                Some(ctx),
                                format!("end stiffness must be non-negative, found {o}"),
                            ));
                        }
                    }
                    Ok(out)
                };
                let (start, end) = match k.get_ref() {
                    EndStiffnessDef::Both(v) => {
                        let both = pair(self, &Spanned::new(k.span(), v.clone()))?;
                        (Some(both), Some(both))
                    }
                    EndStiffnessDef::PerEnd(t) => {
                        let start = t.start.as_ref().map(|v| pair(self, v)).transpose()?;
                        let end = t.end.as_ref().map(|v| pair(self, v)).transpose()?;
                        (start, end)
                    }
                };
                if let Some([ky, kz]) = start {
                    bc.start = bc.start.with_spring(RY, ky).with_spring(RZ, kz);
                }
                if let Some([ky, kz]) = end {
                    bc.end = bc.end.with_spring(RY, ky).with_spring(RZ, kz);
                }
            }
            (None, false) => {}
        }
        let fe = FeModel::new(&beam, &bc).map_err(|e| self.err(b_at, Some(ctx), e))?;
        let all = fe.modes().map_err(|e| self.err(b_at, Some(ctx), e))?;

        // Modes kept.
        let selection = match (&c.modes, &c.max_frequency) {
            (Some(_), Some(f)) => {
                return Err(self.err(
                    f.span().start,
                    Some(ctx),
                    "give either `modes` or `max_frequency`, not both",
                ))
            }
            (Some(k), None) => {
                let n = self.constant_count(k, ctx, "modes", 0, MAX_MODES)?;
                if n > all.len() {
                    return Err(self.err(
                        k.span().start,
                        Some(ctx),
                        format!(
                            "{n} modes asked for, but the mesh of {elements} elements has only {} \
                             elastic modes",
                            all.len()
                        ),
                    ));
                }
                ModeSelection::First(n)
            }
            (None, Some(f)) => {
                ModeSelection::BelowHz(self.constant_positive(f, ctx, "max_frequency")?)
            }
            (None, None) => ModeSelection::First(6.min(all.len())),
        };
        let basis = all.select(selection);
        if basis.len() > MAX_MODES {
            let at = c.max_frequency.as_ref().map_or(kind_at, |f| f.span().start);
            return Err(self.err(
                at,
                Some(ctx),
                format!(
                    "{} modes lie below max_frequency; at most {MAX_MODES} are supported",
                    basis.len()
                ),
            ));
        }
        let k = basis.len();
        let invariants = Invariants::new(&fe, &basis);

        // Damping.
        let damping_ratio = match &c.damping_ratio {
            None => vec![0.0; k],
            Some(d) => {
                let at = d.span().start;
                let values: Vec<(f64, usize)> = match d.get_ref() {
                    ScalarList::One(v) => {
                        let s = Spanned::new(d.span(), v.clone());
                        let z = self.constant_value(&s, ctx, "damping ratio")?;
                        vec![(z, at); k]
                    }
                    ScalarList::Many(list) => {
                        if list.len() != k {
                            return Err(self.err(
                                at,
                                Some(ctx),
                                format!(
                                    "damping_ratio has {} values but {k} modes are kept \
                                     (give one value for all modes, or one per mode)",
                                    list.len()
                                ),
                            ));
                        }
                        let mut out = Vec::with_capacity(k);
                        for s in list {
                            let z = self.constant_value(s, ctx, "damping ratio")?;
                            out.push((z, s.span().start));
                        }
                        out
                    }
                };
                let mut out = Vec::with_capacity(k);
                for (z, at) in values {
                    if z.is_nan() || z < 0.0 {
                        return Err(self.err(
                            at,
                            Some(ctx),
                            format!("damping ratio must be non-negative, found {z}"),
                        ));
                    }
                    out.push(z);
                }
                out
            }
        };

        // Centrifugal stiffening.
        let geometric_stiffness = match &c.geometric_stiffening {
            Some(g) if *g.get_ref() => {
                if !bc.start.fixed[UX] || bc.end.fixed[UX] {
                    return Err(self.err(
                        g.span().start,
                        Some(ctx),
                        format!(
                            "geometric_stiffening is supported only for links held axially at \
                             the start and free axially at the end (clamped_free, pinned_pinned, \
                             pinned_pinned_elastic), not `{}`",
                            boundary.get_ref()
                        ),
                    ));
                }
                let rho_a = beam.mass_per_length();
                let kg = fe.geometric_stiffness(|x| 0.5 * rho_a * (length * length - x * x));
                Some(basis.project(&kg))
            }
            _ => None,
        };

        // Modal coordinates.
        let name_at = c.name.as_ref().map_or(kind_at, |n| n.span().start);
        let first_coordinate = coordinates.len();
        let g0 = 9.81;
        for j in 0..k {
            let cname = format!("{name}_eta{}", j + 1);
            if coordinates.iter().any(|o| o.name == cname)
                || self.scope.parameters.contains_key(&cname)
            {
                return Err(self.err(
                    name_at,
                    Some(ctx),
                    format!(
                        "the modal coordinate `{cname}` of this link has the name of a \
                         coordinate or parameter declared already"
                    ),
                ));
            }
            let w = basis.omega[j];
            let amplitude = 10.0 * g0 * invariants.mass.sqrt() / (w * w);
            coordinates.push(Coordinate {
                name: cname.clone(),
                range: Some([-amplitude, amplitude]),
                velocity_range: Some([-w * amplitude, w * amplitude]),
            });
            self.scope.coordinates.push(cname);
        }
        Ok(FlexibleLink {
            name,
            frame: frame.get_ref().clone(),
            first_coordinate,
            fe,
            basis,
            invariants,
            damping_ratio,
            geometric_stiffness,
        })
    }

    /// `sum_ij q[i][j] a_i b_j`, dropping entries below `1e-14 * scale`.
    fn modal_bilinear(&mut self, q: &DMatrix<f64>, a: &[Id], b: &[Id], scale: f64) -> Id {
        let mut terms = Vec::new();
        for i in 0..q.nrows() {
            for j in 0..q.ncols() {
                let v = q[(i, j)];
                if v.abs() > 1e-14 * scale {
                    terms.push((self.graph.mul(a[i], b[j]), v));
                }
            }
        }
        self.graph.linear(&terms, 0.0)
    }

    /// `sum_ij q[i][j] a_i a_j`, dropping the entries below `1e-14` of
    /// `bound[i][j]`.
    fn modal_projected(&mut self, q: &DMatrix<f64>, bound: &DMatrix<f64>, a: &[Id]) -> Id {
        let mut terms = Vec::new();
        for i in 0..q.nrows() {
            for j in 0..q.ncols() {
                let v = q[(i, j)];
                if v.abs() > 1e-14 * bound[(i, j)] {
                    terms.push((self.graph.mul(a[i], a[j]), v));
                }
            }
        }
        self.graph.linear(&terms, 0.0)
    }

    /// `T`, `V` and `D` of a flexible link in the floating frame of
    /// reference (see the [`crate::fem`] module docs for the formulas).
    #[allow(clippy::needless_range_loop)]
    fn flexible_energies(&mut self, link: &FlexibleLink, frame: &Frame) -> (Id, Id, Id) {
        let inv = &link.invariants;
        let k = link.modes();
        let eta: Vec<Id> = (0..k)
            .map(|j| self.graph.q(link.first_coordinate + j))
            .collect();
        let etad: Vec<Id> = (0..k)
            .map(|j| self.graph.qd(link.first_coordinate + j))
            .collect();
        let amax = |m: &DMatrix<f64>| m.amax();
        let s1_scale = amax(&inv.s1);
        let i1_scale = inv.i1.iter().flatten().fold(0.0f64, |m, v| m.max(v.amax()));
        let i2_scale = inv.i2.iter().flatten().fold(0.0f64, |m, v| m.max(v.amax()));
        let drop = |v: f64, scale: f64| if v.abs() > 1e-14 * scale { v } else { 0.0 };
        // First moment c(eta) = S0 + S1 eta.
        let c: [Id; 3] = std::array::from_fn(|a| {
            let coeffs: Vec<f64> = (0..k).map(|j| drop(inv.s1[(a, j)], s1_scale)).collect();
            self.modal_linear(inv.s0[a], &coeffs, &eta)
        });
        // Second moments J_ab(eta).
        let i0_scale = inv.i0.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
        let mut j = [[self.graph.constant(0.0); 3]; 3];
        for a in 0..3 {
            for b in a..3 {
                let coeffs: Vec<f64> = (0..k)
                    .map(|m| drop(inv.i1[a][b][m] + inv.i1[b][a][m], i1_scale))
                    .collect();
                let lin = self.modal_linear(drop(inv.i0[a][b], i0_scale), &coeffs, &eta);
                let quad = self.modal_bilinear(&inv.i2[a][b], &eta, &eta, i2_scale);
                j[a][b] = self.graph.add(lin, quad);
                j[b][a] = j[a][b];
            }
        }
        let trace = self.graph.sum(&[j[0][0], j[1][1], j[2][2]]);
        let theta: [[Id; 3]; 3] = std::array::from_fn(|a| {
            std::array::from_fn(|b| {
                if a == b {
                    self.graph.sub(trace, j[a][a])
                } else {
                    self.graph.neg(j[a][b])
                }
            })
        });
        // h = sum eps_abc (I1[b][c].eta_dot + eta^T I2[b][c] eta_dot).
        let mut g = [[self.graph.constant(0.0); 3]; 3];
        for b in 0..3 {
            for cc in 0..3 {
                if b == cc {
                    continue;
                }
                let coeffs: Vec<f64> = (0..k).map(|m| drop(inv.i1[b][cc][m], i1_scale)).collect();
                let lin = self.modal_linear(0.0, &coeffs, &etad);
                let quad = self.modal_bilinear(&inv.i2[b][cc], &eta, &etad, i2_scale);
                g[b][cc] = self.graph.add(lin, quad);
            }
        }
        let h = [
            self.graph.sub(g[1][2], g[2][1]),
            self.graph.sub(g[2][0], g[0][2]),
            self.graph.sub(g[0][1], g[1][0]),
        ];
        let (v, w) = (frame.velocity, frame.omega);
        let m = self.graph.constant(inv.mass);
        let vv = self.dot(v, v);
        let t_trans = self.graph.mul(m, vv);
        let wc = self.cross(w, c);
        let t_coupling = self.dot(v, wc);
        let mut rot_terms = Vec::new();
        for a in 0..3 {
            for b in 0..3 {
                let ww = self.graph.mul(w[a], w[b]);
                rot_terms.push((self.graph.mul(ww, theta[a][b]), 0.5));
            }
        }
        let t_rot = self.graph.linear(&rot_terms, 0.0);
        let s1_ed: [Id; 3] = std::array::from_fn(|a| {
            let coeffs: Vec<f64> = (0..k).map(|j| drop(inv.s1[(a, j)], s1_scale)).collect();
            self.modal_linear(0.0, &coeffs, &etad)
        });
        let t_vf = self.dot(v, s1_ed);
        let t_wh = self.dot(w, h);
        // Mff and Kff are projections Phi^T A Phi of the whole mesh's
        // matrices: an entry is round-off of zero when it is below 1e-14 of
        // the sum of the absolute values of its products,
        // (|Phi|^T |A| |Phi|)_ij (the off-diagonal entries of the
        // orthogonal modes, mathematically zero).
        let abs_phi = link.basis.shapes.abs();
        let bound = |a: &DMatrix<f64>| abs_phi.transpose() * a.abs() * &abs_phi;
        let mff_bound = bound(&link.fe.mass);
        let kff_bound = bound(&link.fe.stiffness);
        let t_ff = self.modal_projected(&inv.mff, &mff_bound, &etad);
        let mut kinetic = self.graph.linear(
            &[
                (t_trans, 0.5),
                (t_coupling, 1.0),
                (t_rot, 1.0),
                (t_vf, 1.0),
                (t_wh, 1.0),
                (t_ff, 0.5),
            ],
            0.0,
        );
        if let Some(kg) = &link.geometric_stiffness {
            // Centrifugal stiffening, a velocity-dependent potential
            // 1/2 (w_y^2 + w_z^2) eta^T Kg1 eta, enters the Lagrangian T - V
            // as part of T with a minus sign.
            let stiff = self.modal_bilinear(kg, &eta, &eta, kg.amax());
            let wy2 = self.graph.powi(w[1], 2);
            let wz2 = self.graph.powi(w[2], 2);
            let spin = self.graph.add(wy2, wz2);
            let u = self.graph.mul(spin, stiff);
            kinetic = self.graph.linear(&[(kinetic, 1.0), (u, -0.5)], 0.0);
        }
        // Strain and gravity: 1/2 eta^T Kff eta - g.(m R + A c(eta)).
        let strain = self.modal_projected(&inv.kff, &kff_bound, &eta);
        let ac = self.rotate(&frame.rotation, c);
        let mr: [Id; 3] = std::array::from_fn(|a| {
            let mo = self.graph.mul(m, frame.origin[a]);
            self.graph.add(mo, ac[a])
        });
        let gp = self.dot(self.gravity, mr);
        let potential = self.graph.linear(&[(strain, 0.5), (gp, -1.0)], 0.0);
        // Modal damping: D = sum zeta_j w_j eta_dot_j^2.
        let mut d_terms = Vec::new();
        for (jj, &z) in link.damping_ratio.iter().enumerate() {
            if z > 0.0 {
                let e2 = self.graph.powi(etad[jj], 2);
                d_terms.push((e2, z * link.basis.omega[jj]));
            }
        }
        let dissipation = self.graph.linear(&d_terms, 0.0);
        (kinetic, potential, dissipation)
    }

    fn cross(&mut self, a: [Id; 3], b: [Id; 3]) -> [Id; 3] {
        std::array::from_fn(|k| {
            let (i, j) = ((k + 1) % 3, (k + 2) % 3);
            let p = self.graph.mul(a[i], b[j]);
            let q = self.graph.mul(a[j], b[i]);
            self.graph.sub(p, q)
        })
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
            None => self.world(),
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
            let r = self.rotate(&frame.rotation, local);
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
            Ok(self.rotate(&frame.rotation, local))
        }
    }

    fn constraint(
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
            out.push(Constraint { name, residual });
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
        let (Some(a), Some(b)) = (&c.a, &c.b) else {
            let missing = if c.a.is_none() { "a" } else { "b" };
            return Err(self.err(
                kind.span().start,
                Some(&ctx),
                format!("a `{}` constraint needs `{missing}`", kind.get_ref()),
            ));
        };
        let pa = self.constraint_end(a, &ctx, point)?;
        let pb = self.constraint_end(b, &ctx, point)?;
        if point {
            for (k, axis) in ["x", "y", "z"].iter().enumerate() {
                let residual = self.graph.sub(pa[k], pb[k]);
                out.push(Constraint {
                    name: format!("{name}_{axis}"),
                    residual,
                });
            }
        } else {
            let residual = self.dot(pa, pb);
            out.push(Constraint { name, residual });
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
            "flexible_link" => FLEXIBLE_LINK_FIELDS,
            "flexible_joint" => &[
                "mass",
                "position",
                "frame",
                "length",
                "material",
                "axis",
                "expression",
                "stiffness",
            ],
            _ => {
                return Err(self.err(
                    c.kind.span().start,
                    Some(&ctx),
                    format!(
                        "unknown component type `{kind}` (known: energy, point_mass, rod, rigid_body, spring, damper, flexible_link, flexible_joint)"
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
                (kinetic, potential) = self.body_energies(m, &com, &frame, &inertia);
            }
            "flexible_joint" => {
                (kinetic, potential) = self.flexible_joint(c, &ctx)?;
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
            "flexible_link" => {
                // Read and checked before the frames (`flexible_link`).
                let pos = self
                    .flexible
                    .iter()
                    .position(|(i, _)| *i == index)
                    .expect("flexible links are prepared first");
                let link = self.flexible[pos].1.clone();
                let frame_name = c.frame.as_ref().expect("checked when prepared");
                let frame = self.lookup_frame(frame_name, &ctx)?;
                (kinetic, potential, dissipation) = self.flexible_energies(&link, &frame);
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

    /// Kinetic energy `(m v.v + w.I w) / 2` and gravity potential of a rigid
    /// body of mass `m` with centre of mass `com`, turning with `frame`,
    /// inertia about its centre in frame axes.
    fn body_energies(
        &mut self,
        m: Id,
        com: &Point,
        frame: &Frame,
        inertia: &[[Id; 3]; 3],
    ) -> (Id, Id) {
        let v2 = self.dot(com.velocity, com.velocity);
        let w = frame.omega;
        let iw = self.rotate(inertia, w);
        let wiw = self.dot(w, iw);
        let mv2 = self.graph.mul(m, v2);
        let total = self.graph.add(mv2, wiw);
        let kinetic = self.graph.scale(total, 0.5);
        (kinetic, self.gravity_potential(m, com.position))
    }

    /// The value of a required field of component `c`, or an error at its
    /// `type` naming the field.
    fn required<'c, T>(
        &self,
        c: &ComponentDef,
        value: &'c Option<T>,
        ctx: &str,
        field: &str,
    ) -> Result<&'c T, Error> {
        value.as_ref().ok_or_else(|| {
            self.err(
                c.kind.span().start,
                Some(ctx),
                format!("a `{}` component needs `{field}`", c.kind.get_ref()),
            )
        })
    }

    /// A flexible joint (the paper's): a joint member, a solid circular
    /// shaft of mass `m`, length `l` and `material`, turning with `frame`
    /// about its `axis`, with a linear torsion spring on its twist
    /// `expression`. Radius from `A = m / (rho l)`, inertia `m r^2 / 2` about
    /// the axis and `m (3 r^2 + l^2) / 12` across it, stiffness
    /// `G Ip / l` (`fem::shaft_joint_stiffness`) unless `stiffness` is given.
    fn flexible_joint(&mut self, c: &ComponentDef, ctx: &str) -> Result<(Id, Id), Error> {
        let frame_name = self.required(c, &c.frame, ctx, "frame")?;
        let mass = self.required(c, &c.mass, ctx, "mass")?;
        let length = self.required(c, &c.length, ctx, "length")?;
        let material = self.required(c, &c.material, ctx, "material")?;
        let axis = self.required(c, &c.axis, ctx, "axis")?;
        let twist = self.required(c, &c.expression, ctx, "expression")?;
        let a = match axis.get_ref().as_str() {
            "x" => 0,
            "y" => 1,
            "z" => 2,
            other => {
                return Err(self.err(
                    axis.span().start,
                    Some(ctx),
                    format!("axis must be `x`, `y` or `z`, found `{other}`"),
                ))
            }
        };
        let m = self.constant_positive(mass, ctx, "mass")?;
        let l = self.constant_positive(length, ctx, "length")?;
        let material = self.material(material, ctx)?;
        let shaft = crate::fem::shaft_joint_stiffness(&material, m, l)
            .map_err(|e| self.err(c.kind.span().start, Some(ctx), e))?;
        let r2 = m / (material.density * l * std::f64::consts::PI);
        let mut inertia = [[self.graph.constant(0.0); 3]; 3];
        for (i, row) in inertia.iter_mut().enumerate() {
            row[i] = self.graph.constant(if i == a {
                m * r2 / 2.0
            } else {
                m * (3.0 * r2 + l * l) / 12.0
            });
        }
        let frame = self.lookup_frame(frame_name, ctx)?;
        let com = match &c.position {
            Some(p) => self.point(c, p, ctx)?,
            None => Point {
                position: frame.origin,
                velocity: frame.velocity,
            },
        };
        let m_id = self.graph.constant(m);
        let (kinetic, gravity) = self.body_energies(m_id, &com, &frame, &inertia);
        let k = match &c.stiffness {
            Some(k) => self.positive(k, ctx, "stiffness", true)?,
            None => self.graph.constant(shaft.torsional),
        };
        let e = self.scalar(twist, Some(ctx), false)?;
        let e2 = self.graph.powi(e, 2);
        let ke2 = self.graph.mul(k, e2);
        let spring = self.graph.scale(ke2, 0.5);
        Ok((kinetic, self.graph.add(gravity, spring)))
    }

    fn check_fields(&self, c: &ComponentDef, allowed: &[&str], ctx: &str) -> Result<(), Error> {
        let span = |s: &Option<SScalar>| s.as_ref().map(|s| s.span().start);
        let present: [(&str, Option<usize>); 24] = [
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
