//! A scene's emitted functions evaluated at run time, without compiling
//! Rust: each scheduled straight-line program (the statements the emitter
//! writes, in its order) is lowered once to a compact instruction tape over
//! one array of `f64` slots (inputs, literals, then intermediate values),
//! which [`Tape::eval`] runs with a caller-owned scratch buffer and no
//! allocation once that buffer has grown.
//!
//! The results are bitwise those of the compiled module. The tape performs
//! the IEEE operations of the emitted Rust expression *as Rust parses it*,
//! not of the program's tree, where the two differ:
//!
//! * a sum `c0 + sum(c_k t_k)` is printed positive terms first (left to
//!   right), then the constant (`+ c0` or `- |c0|`), then the negative
//!   terms subtracted (`- |c_k| t_k`); when no positive term or constant
//!   leads, the first negative term is negated (`-|c_k| t_k`);
//! * a term `c * (a * b / d)` is printed without parentheses, so it is the
//!   chain `((c * a) * b) / d`, and a leading minus negates the chain's first
//!   operand (`(-c) * a`, `(-a) * b`);
//! * a product with no numerator factors is `1.0 / d`; one with several
//!   denominator factors divides once by their product (`n / (d1 * d2)`);
//! * literals are the printed (shortest round-trip) values, so exactly the
//!   program's constants, zero always positive;
//! * `sin_cos`, `sin`, ..., `atan2` are the functions of
//!   `flexdyn_runtime::math` that generated code calls, in the same build
//!   (so the same library, `std` or `libm`); where generated code computes
//!   several sines and cosines in one `sin_cos_array` call, that is bitwise
//!   `sin_cos` lane by lane.
//!
//! Operations on two literals are folded while lowering: the compiler folds
//! them in the emitted code, with the same IEEE result.

use std::collections::HashMap;
use std::path::Path;

use flexdyn_runtime::math;

use crate::derive::Equations;
use crate::error::Error;
use crate::expr::{Func, Symbol};
use crate::model::Model;
use crate::schedule::{functions, Code, Function as Scheduled, Output, Shape, Stmt};

/// The functions of a generated model (`flexdyn_runtime::Model`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Function {
    /// `mass_matrix`: `M` (nq x nq).
    MassMatrix,
    /// `bias`: `h` (nq).
    Bias,
    /// `constraints`: `Phi` (nc).
    Constraints,
    /// `constraint_jacobian`: `Phi_q` (nc x nq).
    ConstraintJacobian,
    /// `constraint_time_derivative`: `Phi_t` (nc).
    ConstraintTimeDerivative,
    /// `constraint_rhs`: `gamma` (nc).
    ConstraintRhs,
    /// `constraints_and_jacobian`: `Phi`, then `Phi_q`.
    ConstraintsAndJacobian,
    /// `dynamics_terms`: `M`, `h`, `Phi_q`, `gamma`.
    DynamicsTerms,
    /// `actuator_map`: `B` (nq x nu), constant.
    ActuatorMap,
    /// `kinetic_energy`: `T` (one value).
    KineticEnergy,
    /// `potential_energy`: `V` (one value).
    PotentialEnergy,
    /// `coriolis_forces` (optional output).
    CoriolisForces,
    /// `potential_forces` (optional output).
    PotentialForces,
    /// `damping_forces` (optional output).
    DampingForces,
    /// `coriolis_matrix` (optional output).
    CoriolisMatrix,
    /// `bias_jacobians`: `dh/dq`, then `dh/dqd` (optional output).
    BiasJacobians,
    /// `inverse_dynamics`: `M qdd + h` (nq), reads the accelerations.
    InverseDynamics,
}

impl Function {
    /// Every function, in the order of [`Function::name`].
    const ALL: [Function; 17] = [
        Function::MassMatrix,
        Function::Bias,
        Function::Constraints,
        Function::ConstraintJacobian,
        Function::ConstraintTimeDerivative,
        Function::ConstraintRhs,
        Function::ConstraintsAndJacobian,
        Function::DynamicsTerms,
        Function::ActuatorMap,
        Function::KineticEnergy,
        Function::PotentialEnergy,
        Function::CoriolisForces,
        Function::PotentialForces,
        Function::DampingForces,
        Function::CoriolisMatrix,
        Function::BiasJacobians,
        Function::InverseDynamics,
    ];

    /// The function the emitter writes under `name`.
    fn from_name(name: &str) -> Option<Function> {
        Function::ALL.into_iter().find(|f| f.name() == name)
    }

    /// The method's name in generated code.
    pub fn name(self) -> &'static str {
        match self {
            Function::MassMatrix => "mass_matrix",
            Function::Bias => "bias",
            Function::Constraints => "constraints",
            Function::ConstraintJacobian => "constraint_jacobian",
            Function::ConstraintTimeDerivative => "constraint_time_derivative",
            Function::ConstraintRhs => "constraint_rhs",
            Function::ConstraintsAndJacobian => "constraints_and_jacobian",
            Function::DynamicsTerms => "dynamics_terms",
            Function::ActuatorMap => "actuator_map",
            Function::KineticEnergy => "kinetic_energy",
            Function::PotentialEnergy => "potential_energy",
            Function::CoriolisForces => "coriolis_forces",
            Function::PotentialForces => "potential_forces",
            Function::DampingForces => "damping_forces",
            Function::CoriolisMatrix => "coriolis_matrix",
            Function::BiasJacobians => "bias_jacobians",
            Function::InverseDynamics => "inverse_dynamics",
        }
    }
}

/// Tape operations. Unary operations read `a`; `SinCos` writes the sine to
/// `dst` and the cosine to `b`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Op {
    Add,
    Sub,
    Mul,
    Div,
    Neg,
    Call(Func),
    SinCos,
    Atan2,
}

impl Op {
    /// The arithmetic of two values, for folding literals (`None` for calls).
    fn fold(self, x: f64, y: f64) -> Option<f64> {
        match self {
            Op::Add => Some(x + y),
            Op::Sub => Some(x - y),
            Op::Mul => Some(x * y),
            Op::Div => Some(x / y),
            Op::Neg => Some(-x),
            _ => None,
        }
    }
}

/// One instruction: slots `a`, `b` in, slot `dst` out.
#[derive(Debug, Clone, Copy)]
struct Instr {
    op: Op,
    dst: u32,
    a: u32,
    b: u32,
}

/// One emitted function as an instruction tape.
///
/// Slots: `q` (nq), `qd` (nq), `qdd` (nq), `t`, the runtime parameters, the literals,
/// then intermediate values (reused once dead). The outputs are written to
/// one buffer, one after the other, matrices column-major (nalgebra's
/// layout), entries the function does not compute set to zero.
#[derive(Debug, Clone)]
pub struct Tape {
    nq: usize,
    params: usize,
    uses_qd: bool,
    uses_qdd: bool,
    literals: Vec<f64>,
    code: Vec<Instr>,
    /// `(slot, position in the output buffer)`.
    writes: Vec<(u32, u32)>,
    /// Whether some output entries are not written (they are zero).
    zero_first: bool,
    /// `(rows, columns)` of each output.
    shapes: Vec<(usize, usize)>,
    slots: usize,
}

impl Tape {
    /// `(rows, columns)` of each output in order (a vector has one column,
    /// a value is 1 x 1).
    pub fn shapes(&self) -> &[(usize, usize)] {
        &self.shapes
    }

    /// Length of the output buffer: all outputs together.
    pub fn output_len(&self) -> usize {
        self.shapes.iter().map(|(r, c)| r * c).sum()
    }

    /// Whether the function reads the velocities.
    pub fn uses_qd(&self) -> bool {
        self.uses_qd
    }

    /// Number of instructions.
    pub fn instructions(&self) -> usize {
        self.code.len()
    }

    /// Evaluate at `(q, qd, t)` with runtime parameter values `params`
    /// (in the scene's order), writing [`Tape::output_len`] values to `out`.
    /// `qd` may be empty when the function does not read it. `scratch` grows
    /// to the tape's size on first use and is reused after that.
    ///
    /// # Panics
    ///
    /// When a slice's length differs from the scene's dimensions (callers
    /// check states first, as `flexdyn eval` does).
    pub fn eval(
        &self,
        q: &[f64],
        qd: &[f64],
        t: f64,
        params: &[f64],
        scratch: &mut Vec<f64>,
        out: &mut [f64],
    ) {
        self.eval_with_accelerations(q, qd, &[], t, params, scratch, out);
    }

    /// Whether the function reads the accelerations (`inverse_dynamics`).
    pub fn uses_qdd(&self) -> bool {
        self.uses_qdd
    }

    /// [`Tape::eval`] with the accelerations `qdd` too (which may be empty
    /// when the function does not read them).
    ///
    /// # Panics
    ///
    /// As [`Tape::eval`].
    #[allow(clippy::too_many_arguments)]
    pub fn eval_with_accelerations(
        &self,
        q: &[f64],
        qd: &[f64],
        qdd: &[f64],
        t: f64,
        params: &[f64],
        scratch: &mut Vec<f64>,
        out: &mut [f64],
    ) {
        let nq = self.nq;
        assert_eq!(q.len(), nq, "expected {nq} positions, got {}", q.len());
        assert!(
            qd.len() == nq || (qd.is_empty() && !self.uses_qd),
            "expected {nq} velocities, got {}",
            qd.len()
        );
        assert!(
            qdd.len() == nq || (qdd.is_empty() && !self.uses_qdd),
            "expected {nq} accelerations, got {}",
            qdd.len()
        );
        assert_eq!(
            params.len(),
            self.params,
            "expected {} runtime parameters, got {}",
            self.params,
            params.len()
        );
        let len = self.output_len();
        assert_eq!(out.len(), len, "expected {len} outputs, got {}", out.len());
        if scratch.len() < self.slots {
            scratch.resize(self.slots, 0.0);
        }
        let s = &mut scratch[..self.slots];
        s[..nq].copy_from_slice(q);
        if self.uses_qd {
            s[nq..2 * nq].copy_from_slice(qd);
        }
        if self.uses_qdd {
            s[2 * nq..3 * nq].copy_from_slice(qdd);
        }
        s[3 * nq] = t;
        let lit = 3 * nq + 1 + self.params;
        s[3 * nq + 1..lit].copy_from_slice(params);
        s[lit..lit + self.literals.len()].copy_from_slice(&self.literals);
        for i in &self.code {
            let x = s[i.a as usize];
            let y = s[i.b as usize];
            let v = match i.op {
                Op::Add => x + y,
                Op::Sub => x - y,
                Op::Mul => x * y,
                Op::Div => x / y,
                Op::Neg => -x,
                Op::Call(f) => call(f, x),
                Op::Atan2 => math::atan2(x, y),
                Op::SinCos => {
                    let (sin, cos) = math::sin_cos(x);
                    s[i.b as usize] = cos;
                    sin
                }
            };
            s[i.dst as usize] = v;
        }
        if self.zero_first {
            out.fill(0.0);
        }
        for &(slot, pos) in &self.writes {
            out[pos as usize] = s[slot as usize];
        }
    }
}

/// `f(x)` by the function generated code calls.
fn call(f: Func, x: f64) -> f64 {
    match f {
        Func::Sin => math::sin(x),
        Func::Cos => math::cos(x),
        Func::Tan => math::tan(x),
        Func::Exp => math::exp(x),
        Func::Ln => math::ln(x),
        Func::Sqrt => math::sqrt(x),
    }
}

/// A scene's functions as tapes, built from its file at run time.
#[derive(Debug, Clone)]
pub struct Interpreted {
    name: String,
    coordinates: Vec<String>,
    actuators: Vec<String>,
    nc: usize,
    parameters: Vec<(String, f64)>,
    tapes: Vec<(Function, Tape)>,
}

impl Interpreted {
    /// Read, derive and schedule a scene file (the generator's own errors
    /// when it has any), and lower every function it would emit.
    pub fn load(path: &Path) -> Result<Interpreted, Error> {
        let mut model = Model::load(path)?;
        let eq = model.equations()?;
        Ok(Interpreted::new(&model, &eq))
    }

    /// The tapes of a derived model.
    pub(crate) fn new(model: &Model, eq: &Equations) -> Interpreted {
        let (nq, nc, nu) = (model.nq(), model.constraints.len(), model.actuators.len());
        let params = model.runtime_parameters.len();
        let mut tapes: Vec<(Function, Tape)> = functions(model, eq)
            .iter()
            .filter_map(|f| Some((Function::from_name(f.sig.name)?, lower(nq, params, f))))
            .collect();
        tapes.push((
            Function::ActuatorMap,
            constant_matrix(&eq.actuator_map, nq, nu, params),
        ));
        Interpreted {
            name: model.name.clone(),
            coordinates: model.coordinates.iter().map(|c| c.name.clone()).collect(),
            actuators: model.actuators.iter().map(|a| a.name.clone()).collect(),
            nc,
            parameters: model
                .runtime_parameters
                .iter()
                .map(|p| (p.name.clone(), p.value))
                .collect(),
            tapes,
        }
    }

    /// Scene name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Coordinate names.
    pub fn coordinates(&self) -> &[String] {
        &self.coordinates
    }

    /// Actuator names.
    pub fn actuators(&self) -> &[String] {
        &self.actuators
    }

    /// Number of coordinates.
    pub fn nq(&self) -> usize {
        self.coordinates.len()
    }

    /// Number of constraints.
    pub fn nc(&self) -> usize {
        self.nc
    }

    /// Number of actuators.
    pub fn nu(&self) -> usize {
        self.actuators.len()
    }

    /// Runtime parameters with their nominal values, in the order
    /// [`Tape::eval`] takes them.
    pub fn parameters(&self) -> &[(String, f64)] {
        &self.parameters
    }

    /// The tape of a function; `None` for an optional output the scene does
    /// not generate.
    pub fn tape(&self, f: Function) -> Option<&Tape> {
        self.tapes.iter().find(|(g, _)| *g == f).map(|(_, t)| t)
    }
}

/// `(rows, columns)` of an output: a vector's entries are its one row;
/// matrices have `nq` columns.
fn shape(o: &Output, nq: usize) -> (usize, usize) {
    match o.shape {
        Shape::Vector => (o.entries.first().map_or(0, Vec::len), 1),
        Shape::Matrix { .. } => (o.entries.len(), nq),
    }
}

/// The constant actuator map as a tape of literal writes.
fn constant_matrix(b: &[Vec<f64>], nq: usize, nu: usize, params: usize) -> Tape {
    let mut l = Lowering::new(nq, params);
    let mut writes = Vec::new();
    for (i, row) in b.iter().enumerate() {
        for (j, &g) in row.iter().enumerate() {
            if g != 0.0 {
                writes.push((l.literal(g), i + j * nq));
            }
        }
    }
    l.finish((false, false), writes, vec![(nq, nu)])
}

/// Lower one function's program to a tape.
/// A function's outputs and where each computed entry goes; a function
/// returning one scalar has one output vector of length one.
fn outputs_of(f: &Scheduled) -> (Vec<Output>, Vec<(usize, usize, usize)>) {
    if f.is_scalar() {
        let out = Output {
            name: "out",
            shape: Shape::Vector,
            entries: vec![f.ids.clone()],
        };
        (vec![out], vec![(0, 0, 0)])
    } else {
        (f.outputs.clone(), f.slots.clone())
    }
}

fn lower(nq: usize, params: usize, f: &Scheduled) -> Tape {
    let (outputs, slots) = outputs_of(f);
    let (program, uses) = (&f.program, (f.sig.with_qd, f.sig.with_qdd));
    let shapes: Vec<(usize, usize)> = outputs.iter().map(|o| shape(o, nq)).collect();
    let offsets: Vec<usize> = shapes
        .iter()
        .scan(0, |at, (r, c)| {
            let start = *at;
            *at += r * c;
            Some(start)
        })
        .collect();
    let mut l = Lowering::new(nq, params);
    for s in &program.stmts {
        match s {
            Stmt::Let { var, value } => {
                let v = l.value(value);
                l.vars.insert(*var, v);
            }
            Stmt::SinCos { sin, cos, arg } => {
                let a = l.value(arg);
                let (s, c) = (l.temp(), l.temp());
                l.code.push(Pre {
                    op: Op::SinCos,
                    dst: s,
                    a,
                    b: c,
                });
                l.vars.insert(*sin, s);
                l.vars.insert(*cos, c);
            }
        }
    }
    let mut writes = Vec::new();
    for (code, &(k, i, j)) in program.outputs.iter().zip(&slots) {
        let v = l.value(code);
        let rows = shapes[k].0;
        match outputs[k].shape {
            Shape::Vector => writes.push((v, offsets[k] + j)),
            Shape::Matrix { symmetric } => {
                writes.push((v, offsets[k] + i + j * rows));
                if symmetric && i != j {
                    writes.push((v, offsets[k] + j + i * rows));
                }
            }
        }
    }
    l.finish(uses, writes, shapes)
}

/// A value while lowering: an input, a literal or an intermediate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Ref {
    Input(u32),
    Literal(u32),
    Temp(u32),
}

/// An instruction before slots are assigned (`b` is the cosine's
/// destination for `SinCos`, equal to `a` for other unary operations).
#[derive(Debug, Clone, Copy)]
struct Pre {
    op: Op,
    dst: Ref,
    a: Ref,
    b: Ref,
}

impl Pre {
    /// The intermediates it reads, each once.
    fn reads(&self) -> impl Iterator<Item = u32> {
        let b = (self.op != Op::SinCos && self.b != self.a).then_some(self.b);
        [Some(self.a), b].into_iter().flatten().filter_map(temp)
    }

    /// The intermediates it writes.
    fn writes(&self) -> impl Iterator<Item = u32> {
        let b = (self.op == Op::SinCos).then_some(self.b);
        [Some(self.dst), b].into_iter().flatten().filter_map(temp)
    }
}

fn temp(r: Ref) -> Option<u32> {
    match r {
        Ref::Temp(t) => Some(t),
        _ => None,
    }
}

struct Lowering {
    nq: usize,
    params: usize,
    literals: Vec<f64>,
    literal_index: HashMap<u64, u32>,
    vars: HashMap<u32, Ref>,
    code: Vec<Pre>,
    temps: u32,
}

impl Lowering {
    fn new(nq: usize, params: usize) -> Lowering {
        Lowering {
            nq,
            params,
            literals: Vec::new(),
            literal_index: HashMap::new(),
            vars: HashMap::new(),
            code: Vec::new(),
            temps: 0,
        }
    }

    fn temp(&mut self) -> Ref {
        self.temps += 1;
        Ref::Temp(self.temps - 1)
    }

    /// A literal as the emitter prints it (zero without sign).
    fn literal(&mut self, x: f64) -> Ref {
        let x = if x == 0.0 { 0.0 } else { x };
        let next = self.literals.len() as u32;
        let k = *self.literal_index.entry(x.to_bits()).or_insert(next);
        if k == next {
            self.literals.push(x);
        }
        Ref::Literal(k)
    }

    fn input(&self, s: Symbol) -> Ref {
        let nq = self.nq as u32;
        Ref::Input(match s {
            Symbol::Q(i) => i,
            Symbol::Qd(i) => nq + i,
            Symbol::Qdd(i) => 2 * nq + i,
            Symbol::Time => 3 * nq,
            Symbol::Param(i) => 3 * nq + 1 + i,
        })
    }

    /// `op(a, b)`, folded when both are literals.
    fn op(&mut self, op: Op, a: Ref, b: Ref) -> Ref {
        if let (Ref::Literal(x), Ref::Literal(y)) = (a, b) {
            let (x, y) = (self.literals[x as usize], self.literals[y as usize]);
            if let Some(v) = op.fold(x, y) {
                return self.literal(v);
            }
        }
        let dst = self.temp();
        self.code.push(Pre { op, dst, a, b });
        dst
    }

    fn neg(&mut self, a: Ref) -> Ref {
        self.op(Op::Neg, a, a)
    }

    /// The value of `c` as a whole (the emitter prints it parenthesised
    /// wherever its precedence requires).
    fn value(&mut self, c: &Code) -> Ref {
        match c {
            Code::Var(v) => self.vars[v],
            Code::Sym(s) => self.input(*s),
            Code::Lit(x) => self.literal(*x),
            Code::Sum { constant, terms } => self.sum(*constant, terms),
            Code::Prod { num, den } => self.chain(None, false, num, den),
            Code::Call(f, a) => {
                let a = self.value(a);
                self.op(Op::Call(*f), a, a)
            }
            Code::Atan2(y, x) => {
                let (y, x) = (self.value(y), self.value(x));
                self.op(Op::Atan2, y, x)
            }
        }
    }

    /// `[lead *] n1 * n2 * ... [/ d | / (d1 * d2 ...)]` evaluated left to
    /// right, `1.0` standing for an empty numerator, the first operand
    /// negated when `negate`.
    fn chain(&mut self, lead: Option<f64>, negate: bool, num: &[Code], den: &[Code]) -> Ref {
        let mut operands: Vec<Ref> = lead.map(|c| self.literal(c)).into_iter().collect();
        if num.is_empty() {
            operands.push(self.literal(1.0));
        }
        for f in num {
            operands.push(self.value(f));
        }
        let mut acc = operands[0];
        if negate {
            acc = self.neg(acc);
        }
        for &f in &operands[1..] {
            acc = self.op(Op::Mul, acc, f);
        }
        let Some((first, rest)) = den.split_first() else {
            return acc;
        };
        let mut d = self.value(first);
        for f in rest {
            let f = self.value(f);
            d = self.op(Op::Mul, d, f);
        }
        self.op(Op::Div, acc, d)
    }

    /// `|coef| * t` as printed in a sum (negated when `negate`).
    fn term(&mut self, coef: f64, t: &Code, negate: bool) -> Ref {
        let lead = (coef.abs() != 1.0).then_some(coef.abs());
        match t {
            Code::Prod { num, den } => self.chain(lead, negate, num, den),
            _ if lead.is_some() => self.chain(lead, negate, std::slice::from_ref(t), &[]),
            _ => {
                let v = self.value(t);
                if negate {
                    self.neg(v)
                } else {
                    v
                }
            }
        }
    }

    /// A sum as printed: positive terms, the constant, negative terms.
    fn sum(&mut self, constant: f64, terms: &[(f64, Code)]) -> Ref {
        let mut acc: Option<Ref> = None;
        for (c, t) in terms.iter().filter(|(c, _)| *c > 0.0) {
            let v = self.term(*c, t, false);
            acc = Some(match acc {
                None => v,
                Some(a) => self.op(Op::Add, a, v),
            });
        }
        acc = match acc {
            None if constant != 0.0 => Some(self.literal(constant)),
            Some(a) if constant > 0.0 => {
                let k = self.literal(constant);
                Some(self.op(Op::Add, a, k))
            }
            Some(a) if constant < 0.0 => {
                let k = self.literal(-constant);
                Some(self.op(Op::Sub, a, k))
            }
            other => other,
        };
        for (c, t) in terms.iter().filter(|(c, _)| *c < 0.0) {
            acc = Some(match acc {
                None => self.term(*c, t, true),
                Some(a) => {
                    let v = self.term(*c, t, false);
                    self.op(Op::Sub, a, v)
                }
            });
        }
        acc.unwrap_or_else(|| self.literal(0.0))
    }

    /// Assign slots (intermediates reuse the slots of dead ones) and build
    /// the tape writing `writes` (value, output position).
    /// The tape, `uses` saying whether it reads the velocities and the
    /// accelerations.
    fn finish(
        self,
        uses: (bool, bool),
        writes: Vec<(Ref, usize)>,
        shapes: Vec<(usize, usize)>,
    ) -> Tape {
        const LIVE: usize = usize::MAX;
        let inputs = 3 * self.nq + 1 + self.params;
        let first_temp = inputs + self.literals.len();
        // Last instruction reading each intermediate (outputs: to the end).
        let mut last: Vec<Option<usize>> = vec![None; self.temps as usize];
        for (k, p) in self.code.iter().enumerate() {
            for t in p.reads() {
                last[t as usize] = Some(k);
            }
        }
        for (r, _) in &writes {
            if let Some(t) = temp(*r) {
                last[t as usize] = Some(LIVE);
            }
        }
        let mut slot_of: Vec<u32> = vec![0; self.temps as usize];
        let mut free: Vec<u32> = Vec::new();
        let mut slots = first_temp;
        let slot = |r: Ref, slot_of: &[u32]| match r {
            Ref::Input(i) => i,
            Ref::Literal(k) => (inputs as u32) + k,
            Ref::Temp(t) => slot_of[t as usize],
        };
        let mut code = Vec::with_capacity(self.code.len());
        for (k, p) in self.code.iter().enumerate() {
            let (a, b) = (slot(p.a, &slot_of), slot(p.b, &slot_of));
            // Operands are read before the result is stored: a slot dying
            // here can take the result.
            for t in p.reads() {
                if last[t as usize] == Some(k) {
                    free.push(slot_of[t as usize]);
                }
            }
            for t in p.writes() {
                slot_of[t as usize] = free.pop().unwrap_or_else(|| {
                    slots += 1;
                    (slots - 1) as u32
                });
            }
            for t in p.writes().filter(|&t| last[t as usize].is_none()) {
                free.push(slot_of[t as usize]);
            }
            let dst = slot(p.dst, &slot_of);
            let b = if p.op == Op::SinCos {
                slot(p.b, &slot_of)
            } else {
                b
            };
            code.push(Instr {
                op: p.op,
                dst,
                a,
                b,
            });
        }
        let total: usize = shapes.iter().map(|(r, c)| r * c).sum();
        let zero_first = writes.len() < total;
        let writes = writes
            .into_iter()
            .map(|(r, pos)| (slot(r, &slot_of), pos as u32))
            .collect();
        Tape {
            nq: self.nq,
            params: self.params,
            uses_qd: uses.0,
            uses_qdd: uses.1,
            literals: self.literals,
            code,
            writes,
            zero_first,
            shapes,
            slots,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene(name: &str) -> std::path::PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../scenes")
            .join(format!("{name}.toml"))
    }

    /// Every function's tape against the expression graph evaluated node by
    /// node (no scheduling, sharing or printing), at states spread over the
    /// coordinates and with runtime parameters away from their nominal
    /// values: equal to rounding.
    #[test]
    fn tapes_compute_the_derived_terms() {
        for name in ["pendulum", "four_bar", "slider_crank", "spin_up_beam"] {
            let mut model = Model::load(&scene(name)).unwrap();
            let eq = model.equations().unwrap();
            let it = Interpreted::new(&model, &eq);
            let (nq, np) = (it.nq(), it.parameters().len());
            let mut scratch = Vec::new();
            for k in 0..5 {
                let x = |i: usize, s: f64| ((k * 7 + i * 3) as f64 * s).sin() * 1.3;
                let q: Vec<f64> = (0..nq).map(|i| x(i, 0.37)).collect();
                let qd: Vec<f64> = (0..nq).map(|i| x(i, 0.91)).collect();
                let qdd: Vec<f64> = (0..nq).map(|i| x(i, 1.73)).collect();
                let t = 0.25 * k as f64;
                let params: Vec<f64> = it
                    .parameters()
                    .iter()
                    .enumerate()
                    .map(|(i, (_, v))| v * 1.1 + 0.05 * (i + 1) as f64)
                    .collect();
                assert_eq!(params.len(), np);
                let env = |s: Symbol| match s {
                    Symbol::Q(i) => q[i as usize],
                    Symbol::Qd(i) => qd[i as usize],
                    Symbol::Qdd(i) => qdd[i as usize],
                    Symbol::Time => t,
                    Symbol::Param(i) => params[i as usize],
                };
                let mut checked = 0;
                for scheduled in functions(&model, &eq) {
                    let f = Function::from_name(scheduled.sig.name).unwrap();
                    let (outputs, _) = outputs_of(&scheduled);
                    let tape = it.tape(f).unwrap();
                    let mut got = vec![f64::NAN; tape.output_len()];
                    tape.eval_with_accelerations(&q, &qd, &qdd, t, &params, &mut scratch, &mut got);
                    let mut want = Vec::new();
                    for o in &outputs {
                        let (rows, cols) = shape(o, nq);
                        for j in 0..cols {
                            for i in 0..rows {
                                let id = match o.shape {
                                    Shape::Vector => o.entries[0][i],
                                    Shape::Matrix { .. } => o.entries[i][j],
                                };
                                want.push(model.graph.eval(&[id], &env)[0]);
                            }
                        }
                    }
                    assert_eq!(got.len(), want.len(), "{name} {}", f.name());
                    let scale = want.iter().fold(1.0f64, |m, w| m.max(w.abs()));
                    for (p, (a, b)) in got.iter().zip(&want).enumerate() {
                        assert!(
                            (a - b).abs() <= 1e-14 * scale,
                            "{name} {} entry {p}: {a} vs {b}",
                            f.name()
                        );
                    }
                    checked += 1;
                }
                assert!(checked >= 10, "{name}: {checked} functions");
                let b = it.tape(Function::ActuatorMap).unwrap();
                let mut got = vec![f64::NAN; b.output_len()];
                b.eval(&q, &[], t, &params, &mut scratch, &mut got);
                for (i, row) in eq.actuator_map.iter().enumerate() {
                    for (j, &g) in row.iter().enumerate() {
                        assert_eq!(got[i + j * nq], g);
                    }
                }
            }
        }
    }

    /// The printed association, not the program's tree: `2 a b` is
    /// `(2 a) b`, a leading negative term negates its first operand, the
    /// constant comes after the positive terms. Chosen so that the tree's
    /// association rounds differently.
    #[test]
    fn sums_and_products_associate_as_printed() {
        let var = |v| Code::Var(v);
        let mut l = Lowering::new(0, 0);
        let (a, b) = (0.1, 3.0f64.sqrt());
        let ra = l.literal(a);
        let rb = l.literal(b);
        // Variables 0 and 1 stand for literals, so that everything folds.
        l.vars.insert(0, ra);
        l.vars.insert(1, rb);
        let prod = Code::Prod {
            num: vec![var(0), var(1)],
            den: vec![],
        };
        let term = |c: f64| Code::Sum {
            constant: 0.0,
            terms: vec![(c, prod.clone())],
        };
        let value = |l: &mut Lowering, c: &Code| {
            let Ref::Literal(k) = l.value(c) else {
                panic!("literals fold")
            };
            l.literals[k as usize]
        };
        assert_eq!(value(&mut l, &term(0.3)), 0.3 * a * b);
        assert_ne!(0.3 * a * b, 0.3 * (a * b), "the example distinguishes");
        assert_eq!(value(&mut l, &term(-0.3)), -0.3 * a * b);
        let sum = Code::Sum {
            constant: 0.3,
            terms: vec![(-1.0, var(1)), (1.0, var(0))],
        };
        assert_eq!(value(&mut l, &sum), a + 0.3 - b);
        let lead_negative = Code::Sum {
            constant: -0.7,
            terms: vec![(-1.0, var(1)), (-2.0, var(0))],
        };
        assert_eq!(value(&mut l, &lead_negative), -0.7 - b - 2.0 * a);
        let quotient = Code::Prod {
            num: vec![],
            den: vec![var(0), var(1)],
        };
        assert_eq!(value(&mut l, &quotient), 1.0 / (a * b));
    }

    #[test]
    fn intermediate_slots_are_reused() {
        let mut model = Model::load(&scene("slider_crank")).unwrap();
        let eq = model.equations().unwrap();
        let it = Interpreted::new(&model, &eq);
        let tape = it.tape(Function::DynamicsTerms).unwrap();
        let inputs = 2 * it.nq() + 1 + it.parameters().len() + tape.literals.len();
        assert!(
            tape.slots - inputs < tape.instructions() / 2,
            "{} slots for {} instructions",
            tape.slots - inputs,
            tape.instructions()
        );
    }

    #[test]
    fn a_scene_with_errors_gives_the_generators_error() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.toml");
        std::fs::write(
            &path,
            "name = \"bad\"\n[[coordinates]]\nname = \"a\"\n\
             [[components]]\nname = \"m\"\ntype = \"point_mass\"\nmass = 1\n\
             position = [\"a*\", 0, 0]\n",
        )
        .unwrap();
        let e = Interpreted::load(&path).unwrap_err().to_string();
        let generator = crate::generate_scene(&path).unwrap_err().to_string();
        assert_eq!(e, generator);
        assert!(e.contains("bad.toml"), "{e}");
    }
}
