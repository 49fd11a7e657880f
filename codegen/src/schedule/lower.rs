//! One lowering of each scheduled function ([`lower`]) into operations in
//! evaluation order ([`Op`]), which the Rust emitter prints, and the
//! interpreter runs as a tape. Both therefore perform the same IEEE
//! operations in the same association: the operations are those of the
//! emitted Rust expression *as Rust parses it*, not of the program's tree,
//! where the two differ:
//!
//! * a sum `c0 + sum(c_k t_k)` adds its terms (`|c_k| t_k`, the constant
//!   `|c0|`) two at a time, always the two that are ready first in a model
//!   of the processor's latencies (the longest path of operations from the
//!   inputs: 4 cycles an addition or multiplication, 14 a division, 20 a
//!   call), so that its last addition waits only for its latest term rather
//!   than a chain through all of them. Terms ready together are taken in
//!   the order positive terms, the constant, negative terms; in a scene
//!   with mirror-image limbs, first in the order of their shapes (a hash of
//!   the expression that leaves out which coordinate an input is, the
//!   values and signs of literals and coefficients, and the order of a
//!   sum's or product's operands: [`Lowering::shape`]), so that the
//!   statements of two mirror-image limbs are written alike and pair
//!   ([`super::lanes`]). A negative term is subtracted (`a - t`, `t`
//!   possibly a sum of negative terms added first); when no positive term
//!   or constant leads, the first negative term is negated (`-|c_k| t_k`),
//!   and a sum with no positive term leads with its constant, negative or
//!   not;
//! * a term `c * (a * b / d)` is printed without parentheses, so it is the
//!   chain `((c * a) * b) / d`, and a leading minus negates the chain's first
//!   operand (`(-c) * a`, `(-a) * b`);
//! * a product with no numerator factors is `1.0 / d`; one with several
//!   denominator factors divides once by their product (`n / (d1 * d2)`);
//! * in `f64`, the sines and cosines of angles that read inputs only come
//!   first, in one batch (`math::sin_cos_array`, bitwise `sin_cos` lane by
//!   lane).
//!
//! In `f64` code a product added to or subtracted from a value is one
//! operation ([`Op::Fused`]; of two products the second, in a mirrored
//! scene the one of the larger shape): the emitter prints it as the
//! runtime's multiply-add (one rounding where the target fuses them, else
//! exactly the written expression), the interpreter runs it as one
//! instruction computing the written expression. `f32` code computes the
//! same on every target, so it never fuses.
//!
//! Each operand also says whether the printed text parenthesises it
//! ([`Operand::paren`]): where the tree's precedence asks for it, also where
//! the association does not (the emitted text has always been written so).
//! Then the outputs: an output some of whose entries are not computed is
//! zeroed first (the constant actuator map always is), each computed entry
//! is stored at its row and column, and an off-diagonal entry of a
//! symmetric matrix is mirrored.

use std::cmp::Reverse;
use std::collections::{BinaryHeap, HashMap};
use std::hash::{Hash, Hasher};

use super::{Code, Function, Inputs, Program, Scheduled, Shape, Stmt};
use crate::expr::{Func, Symbol};
use crate::hash::FastHasher;

/// A value an operation reads.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Value {
    /// An input (`q[i]`, `qd[i]`, `qdd[i]`, `t`, a runtime parameter).
    Input(Symbol),
    /// A literal.
    Literal(f64),
    /// An intermediate, read once by the operation after the one writing it.
    Temp(u32),
    /// A variable of the program (`v<n>`).
    Var(u32),
}

/// An operand: a value, and whether its printed text is parenthesised.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Operand {
    /// The value.
    pub value: Value,
    /// Whether the printed text puts it in parentheses.
    pub paren: bool,
}

impl Operand {
    fn new(value: Value) -> Operand {
        Operand {
            value,
            paren: false,
        }
    }
}

/// A binary arithmetic operation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Binary {
    /// `a + b`.
    Add,
    /// `a - b`.
    Sub,
    /// `a * b`.
    Mul,
    /// `a / b`.
    Div,
}

impl Binary {
    /// The IEEE operation.
    pub fn apply(self, a: f64, b: f64) -> f64 {
        match self {
            Binary::Add => a + b,
            Binary::Sub => a - b,
            Binary::Mul => a * b,
            Binary::Div => a / b,
        }
    }
}

/// The form of a product `x * y` added to or subtracted from a value `c`,
/// in the order the program writes it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fused {
    /// `c + x * y`.
    AddMul,
    /// `x * y + c`.
    MulAdd,
    /// `c - x * y`.
    SubMul,
    /// `x * y - c`.
    MulSub,
}

impl Fused {
    /// The written expression, two roundings (an addition's operands
    /// commute, so `AddMul` and `MulAdd` are the same bits).
    pub fn apply(self, x: f64, y: f64, c: f64) -> f64 {
        match self {
            Fused::AddMul | Fused::MulAdd => c + x * y,
            Fused::SubMul => c - x * y,
            Fused::MulSub => x * y - c,
        }
    }

    /// The runtime's function for it (`math::add_mul`, ...).
    pub fn name(self) -> &'static str {
        match self {
            Fused::AddMul => "add_mul",
            Fused::MulAdd => "mul_add",
            Fused::SubMul => "sub_mul",
            Fused::MulSub => "mul_sub",
        }
    }
}

/// One operation of a lowered function.
#[derive(Debug, Clone, PartialEq)]
pub enum Op {
    /// `dst = a op b`.
    Binary {
        /// Intermediate written.
        dst: u32,
        /// The operation.
        op: Binary,
        /// Left operand.
        a: Operand,
        /// Right operand.
        b: Operand,
    },
    /// `dst = c + x * y` and the other [`Fused`] forms (`f64` code).
    Fused {
        /// Intermediate written.
        dst: u32,
        /// Which form.
        form: Fused,
        /// First factor.
        x: Operand,
        /// Second factor.
        y: Operand,
        /// The value the product is added to or subtracted from.
        c: Operand,
    },
    /// `dst = -a`.
    Neg {
        /// Intermediate written.
        dst: u32,
        /// Operand.
        a: Operand,
    },
    /// `dst = f(a)` (`math::f`).
    Call {
        /// Intermediate written.
        dst: u32,
        /// The function.
        f: Func,
        /// Argument.
        a: Operand,
    },
    /// `dst = atan2(y, x)`.
    Atan2 {
        /// Intermediate written.
        dst: u32,
        /// First argument.
        y: Operand,
        /// Second argument.
        x: Operand,
    },
    /// `let v<var> = value;`
    Bind {
        /// Variable.
        var: u32,
        /// Its value.
        value: Operand,
    },
    /// `let (v<sin>, v<cos>) = sin_cos(arg);`
    SinCos {
        /// Variable receiving the sine.
        sin: u32,
        /// Variable receiving the cosine.
        cos: u32,
        /// The argument.
        arg: Operand,
    },
    /// `let [(v<sin>, v<cos>), ...] = sin_cos_array([arg, ...]);`: bitwise
    /// `SinCos` of each entry.
    SinCosArray(Vec<(u32, u32, Operand)>),
    /// Output `output` set to zero.
    Zero {
        /// Output index.
        output: usize,
    },
    /// Entry `(row, col)` of output `output` set to `value` (a vector's
    /// entry `row`; a returned value's only entry).
    Store {
        /// Output index.
        output: usize,
        /// Row.
        row: usize,
        /// Column.
        col: usize,
        /// The value.
        value: Operand,
    },
    /// Entry `(col, row)` of output `output` set to its entry `(row, col)`.
    Mirror {
        /// Output index.
        output: usize,
        /// Row of the stored entry.
        row: usize,
        /// Column of the stored entry.
        col: usize,
    },
}

/// A function lowered to operations.
#[derive(Debug, Clone)]
pub struct Lowered {
    /// Which function.
    pub function: Function,
    /// `(rows, columns)` of each output.
    pub shapes: Vec<(usize, usize)>,
    /// The operations in evaluation order.
    pub ops: Vec<Op>,
    /// Number of intermediates.
    pub temps: u32,
}

impl Lowered {
    /// The inputs the operations read.
    pub fn reads(&self) -> impl Iterator<Item = Symbol> + '_ {
        self.ops
            .iter()
            .flat_map(Op::operands)
            .filter_map(|o| match o.value {
                Value::Input(s) => Some(s),
                _ => None,
            })
    }

    /// What the function reads by its signature.
    pub fn inputs(&self) -> Inputs {
        self.function.spec().inputs
    }
}

impl Op {
    /// The operands it reads, in order.
    pub fn operands(&self) -> Vec<Operand> {
        match self {
            Op::Binary { a, b, .. } => vec![*a, *b],
            Op::Fused { x, y, c, .. } => vec![*x, *y, *c],
            Op::Atan2 { y, x, .. } => vec![*y, *x],
            Op::Neg { a, .. } | Op::Call { a, .. } => vec![*a],
            Op::Bind { value, .. } | Op::Store { value, .. } => vec![*value],
            Op::SinCos { arg, .. } => vec![*arg],
            Op::SinCosArray(batch) => batch.iter().map(|(_, _, a)| *a).collect(),
            Op::Zero { .. } | Op::Mirror { .. } => Vec::new(),
        }
    }
}

/// Precedence classes of printed expressions.
const SUM: u8 = 1;
const PRODUCT: u8 = 2;
const ATOM: u8 = 3;

/// The precedence of a program expression as printed.
fn precedence(c: &Code) -> u8 {
    match c {
        Code::Sum { .. } => SUM,
        Code::Prod { .. } => PRODUCT,
        Code::Lit(x) if *x < 0.0 => SUM,
        _ => ATOM,
    }
}

/// Lower a scheduled function; for `f64` code (`double`), the sines and
/// cosines of angles that read inputs only come first in one batch, and
/// products added to or subtracted from a value are fused ([`Op::Fused`]).
/// Where the scene has mirror-image limbs (`mirrored`), terms ready
/// together are added, and of two products the one to fuse chosen, by
/// their shapes ([`Lowering::shape`]), else in the program's order.
pub fn lower(f: &Scheduled, double: bool, mirrored: bool) -> Lowered {
    let spec = f.spec();
    let shapes: Vec<(usize, usize)> = spec.outputs.iter().map(|o| o.shape.size(f.dims)).collect();
    let mut l = Lowering {
        mirrored,
        ..Lowering::default()
    };
    let p = &f.program;
    if double {
        l.inline = products_read_once_as_terms(p);
    }
    let batched =
        |s: &&Stmt| double && matches!(s, Stmt::SinCos { arg, .. } if !arg.reads_variables());
    let mut pairs = Vec::new();
    for s in p.stmts.iter().filter(batched) {
        if let Stmt::SinCos { sin, cos, arg } = s {
            let a = l.operand(arg, SUM);
            l.bound(&[*sin, *cos], a, CALL);
            pairs.push((*sin, *cos, a));
        }
    }
    if !pairs.is_empty() {
        l.ops.push(Op::SinCosArray(pairs));
    }
    for s in p.stmts.iter().filter(|s| !batched(s)) {
        let op = match s {
            Stmt::Let { var, .. } if l.inline.contains_key(var) => continue,
            Stmt::Let { var, value } => {
                let value = l.operand(value, SUM);
                l.bound(&[*var], value, 0);
                Op::Bind { var: *var, value }
            }
            Stmt::SinCos { sin, cos, arg } => {
                let arg = l.operand(arg, SUM);
                l.bound(&[*sin, *cos], arg, CALL);
                Op::SinCos {
                    sin: *sin,
                    cos: *cos,
                    arg,
                }
            }
        };
        l.ops.push(op);
    }
    // Outputs some of whose entries are not computed are zeroed first.
    for (k, o) in spec.outputs.iter().enumerate() {
        let (rows, cols) = shapes[k];
        let full = match o.shape {
            Shape::Matrix {
                symmetric: true, ..
            } => rows * (rows + 1) / 2,
            _ => rows * cols,
        };
        let written = f.slots.iter().filter(|s| s.0 == k).count();
        if full > 0 && (written < full || spec.inputs == Inputs::Constant) {
            l.ops.push(Op::Zero { output: k });
        }
    }
    for (c, &(k, i, j)) in p.outputs.iter().zip(&f.slots) {
        let value = l.operand(c, SUM);
        l.ops.push(Op::Store {
            output: k,
            row: i,
            col: j,
            value,
        });
        if matches!(
            spec.outputs[k].shape,
            Shape::Matrix {
                symmetric: true,
                ..
            }
        ) && i != j
        {
            l.ops.push(Op::Mirror {
                output: k,
                row: i,
                col: j,
            });
        }
    }
    let ops = if double {
        fuse(l.ops, &l.shapes)
    } else {
        l.ops
    };
    Lowered {
        function: f.function,
        shapes,
        ops,
        temps: l.temps,
    }
}

/// `ops` with each addition or subtraction that reads a product (an
/// intermediate, so read by it only) computing that product itself; of
/// two products, the one of the larger shape (`shapes`, by intermediate),
/// else the second (`c + x * y`, `c - x * y`, as Rust's `a + b * c`
/// reads).
fn fuse(mut ops: Vec<Op>, shapes: &[u64]) -> Vec<Op> {
    let mut product: Vec<Option<usize>> = vec![None; shapes.len()];
    for (k, op) in ops.iter().enumerate() {
        if let Op::Binary {
            dst,
            op: Binary::Mul,
            ..
        } = op
        {
            product[*dst as usize] = Some(k);
        }
    }
    let factors = |o: Operand| match o.value {
        Value::Temp(t) => product[t as usize],
        _ => None,
    };
    let mut gone = vec![false; ops.len()];
    let mut fused = Vec::new();
    for (k, op) in ops.iter().enumerate() {
        let Op::Binary {
            dst,
            op: op @ (Binary::Add | Binary::Sub),
            a,
            b,
        } = *op
        else {
            continue;
        };
        let shape = |o: Operand| match o.value {
            Value::Temp(t) => shapes[t as usize],
            _ => 0,
        };
        let first = factors(b).is_none() || shape(a) > shape(b);
        let (form, m, c) = match (op, factors(a).filter(|_| first), factors(b)) {
            (Binary::Add, Some(m), _) => (Fused::MulAdd, m, b),
            (Binary::Sub, Some(m), _) => (Fused::MulSub, m, b),
            (Binary::Add, _, Some(m)) => (Fused::AddMul, m, a),
            (Binary::Sub, _, Some(m)) => (Fused::SubMul, m, a),
            _ => continue,
        };
        let Op::Binary { a: x, b: y, .. } = ops[m] else {
            unreachable!("a product is a binary operation")
        };
        gone[m] = true;
        fused.push((k, Op::Fused { dst, form, x, y, c }));
    }
    for (k, op) in fused {
        ops[k] = op;
    }
    ops.into_iter()
        .zip(gone)
        .filter_map(|(op, gone)| (!gone).then_some(op))
        .collect()
}

/// The variables of `p` bound to a product of inputs, literals and
/// variables that are read once, as a term of a sum: computed where they
/// are read instead (one level deeper), so the sum fuses them.
fn products_read_once_as_terms(p: &Program) -> HashMap<u32, Code> {
    /// `(reads, reads as a term of a sum)` of each variable.
    fn count(c: &Code, term: bool, reads: &mut HashMap<u32, (usize, usize)>) {
        match c {
            Code::Var(v) => {
                let r = reads.entry(*v).or_default();
                r.0 += 1;
                r.1 += usize::from(term);
            }
            Code::Sym(_) | Code::Lit(_) => {}
            Code::Sum { terms, .. } => terms.iter().for_each(|(_, t)| count(t, true, reads)),
            Code::Prod { num, den } => num.iter().chain(den).for_each(|f| count(f, false, reads)),
            Code::Call(_, a) => count(a, false, reads),
            Code::Atan2(y, x) => {
                count(y, false, reads);
                count(x, false, reads);
            }
        }
    }
    let mut reads = HashMap::new();
    for s in &p.stmts {
        match s {
            Stmt::Let { value: c, .. } | Stmt::SinCos { arg: c, .. } => count(c, false, &mut reads),
        }
    }
    p.outputs.iter().for_each(|c| count(c, false, &mut reads));
    let atom = |c: &Code| matches!(c, Code::Var(_) | Code::Sym(_) | Code::Lit(_));
    p.stmts
        .iter()
        .filter_map(|s| match s {
            Stmt::Let {
                var,
                value: value @ Code::Prod { num, den },
            } if den.is_empty() && num.iter().all(atom) && reads.get(var) == Some(&(1, 1)) => {
                Some((*var, value.clone()))
            }
            _ => None,
        })
        .collect()
}

#[derive(Default)]
struct Lowering {
    ops: Vec<Op>,
    temps: u32,
    /// Variables computed where they are read, not bound.
    inline: HashMap<u32, Code>,
    /// When each intermediate is ready ([`Lowering::ready`]).
    ready: Vec<u32>,
    /// When each bound variable is ready.
    var_ready: HashMap<u32, u32>,
    /// Each intermediate's shape ([`Lowering::shape`]).
    shapes: Vec<u64>,
    /// Each bound variable's shape.
    var_shapes: HashMap<u32, u64>,
    /// Whether terms ready together are ordered by their shapes.
    mirrored: bool,
}

/// A hash of a tag and words.
fn mix(tag: impl Hash, words: &[u64]) -> u64 {
    let mut h = FastHasher::default();
    tag.hash(&mut h);
    words.iter().for_each(|w| h.write_u64(*w));
    h.finish()
}

/// Latencies, in cycles of a present-day processor, of the model by which
/// a sum adds its earliest terms first: an addition, subtraction or
/// multiplication; a division; a negation; a call.
const ARITHMETIC: u32 = 4;
const DIVISION: u32 = 14;
const NEGATION: u32 = 1;
const CALL: u32 = 20;

impl Lowering {
    /// A new intermediate of a shape, ready `latency` after `operands`.
    fn temp(&mut self, operands: &[Operand], latency: u32, shape: u64) -> u32 {
        let at = operands.iter().map(|o| self.ready(*o)).max().unwrap_or(0);
        self.ready.push(at + latency);
        self.shapes.push(if self.mirrored { shape } else { 0 });
        self.temps += 1;
        self.temps - 1
    }

    /// When a value is ready, in the model of the latencies above: the
    /// longest path of operations from the function's inputs.
    fn ready(&self, o: Operand) -> u32 {
        match o.value {
            Value::Temp(t) => self.ready[t as usize],
            Value::Var(v) => self.var_ready.get(&v).copied().unwrap_or(0),
            Value::Input(_) | Value::Literal(_) => 0,
        }
    }

    /// The shape of a value: a hash of its expression that leaves out which
    /// coordinate an input belongs to, the values and signs of literals
    /// (the two lanes may differ in them), the signs of terms, and the
    /// order of the operands of a sum or product. The statements of two
    /// mirror-image limbs have the same shapes, so where a sum's terms are
    /// ordered by their shapes (and a product is fused by them) the two are
    /// written alike and can be paired ([`super::lanes`]). In a scene
    /// without mirror-image limbs every shape is `0`, which keeps the
    /// program's order.
    fn shape(&self, o: Operand) -> u64 {
        if !self.mirrored {
            return 0;
        }
        match o.value {
            Value::Temp(t) => self.shapes[t as usize],
            Value::Var(v) => self.var_shapes.get(&v).copied().unwrap_or_default(),
            Value::Input(s) => match s {
                Symbol::Q(_) => mix(1u8, &[]),
                Symbol::Qd(_) => mix(2u8, &[]),
                Symbol::Qdd(_) => mix(3u8, &[]),
                Symbol::Time => mix(4u8, &[]),
                Symbol::Param(i) => mix(5u8, &[i.into()]),
            },
            Value::Literal(_) => mix(6u8, &[]),
        }
    }

    fn binary(&mut self, op: Binary, a: Operand, b: Operand) -> Operand {
        let latency = if op == Binary::Div {
            DIVISION
        } else {
            ARITHMETIC
        };
        let (x, y) = (self.shape(a), self.shape(b));
        let shape = match op {
            Binary::Add | Binary::Sub => mix(7u8, &[x.min(y), x.max(y)]),
            Binary::Mul => mix(8u8, &[x.min(y), x.max(y)]),
            Binary::Div => mix(9u8, &[x, y]),
        };
        let dst = self.temp(&[a, b], latency, shape);
        self.ops.push(Op::Binary { dst, op, a, b });
        Operand::new(Value::Temp(dst))
    }

    fn neg(&mut self, a: Operand) -> Operand {
        let dst = self.temp(&[a], NEGATION, self.shape(a));
        self.ops.push(Op::Neg { dst, a });
        Operand::new(Value::Temp(dst))
    }

    /// Variables `vars` ready `latency` after `value`, of its shape (a
    /// sine and a cosine of it: `vars` two).
    fn bound(&mut self, vars: &[u32], value: Operand, latency: u32) {
        let at = self.ready(value) + latency;
        let shape = self.shape(value);
        for (k, v) in vars.iter().enumerate() {
            self.var_ready.insert(*v, at);
            let shape = if vars.len() == 1 {
                shape
            } else {
                mix(11 + k as u8, &[shape])
            };
            self.var_shapes.insert(*v, shape);
        }
    }

    fn literal(x: f64) -> Operand {
        Operand::new(Value::Literal(x))
    }

    /// `c` printed where precedence `need` is required.
    fn operand(&mut self, c: &Code, need: u8) -> Operand {
        let strength = match c {
            Code::Var(v) => self.inline.get(v).map_or(ATOM, precedence),
            _ => precedence(c),
        };
        let mut o = self.value(c);
        o.paren |= strength < need;
        o
    }

    /// The value of `c` as a whole.
    fn value(&mut self, c: &Code) -> Operand {
        match c {
            Code::Var(v) => match self.inline.remove(v) {
                Some(value) => self.value(&value),
                None => Operand::new(Value::Var(*v)),
            },
            Code::Sym(s) => Operand::new(Value::Input(*s)),
            Code::Lit(x) => Self::literal(*x),
            Code::Sum { constant, terms } => self.sum(*constant, terms),
            Code::Prod { num, den } => self.chain(None, false, num, den),
            Code::Call(f, a) => {
                let a = self.operand(a, SUM);
                let dst = self.temp(&[a], CALL, mix(f, &[self.shape(a)]));
                self.ops.push(Op::Call { dst, f: *f, a });
                Operand::new(Value::Temp(dst))
            }
            Code::Atan2(y, x) => {
                let (y, x) = (self.operand(y, SUM), self.operand(x, SUM));
                let shape = mix(10u8, &[self.shape(y), self.shape(x)]);
                let dst = self.temp(&[y, x], CALL, shape);
                self.ops.push(Op::Atan2 { dst, y, x });
                Operand::new(Value::Temp(dst))
            }
        }
    }

    /// `[lead *] n1 * n2 * ... [/ d | / (d1 * d2 ...)]` evaluated left to
    /// right, `1.0` standing for an empty numerator, the first operand
    /// negated when `negate`.
    fn chain(&mut self, lead: Option<f64>, negate: bool, num: &[Code], den: &[Code]) -> Operand {
        let mut operands: Vec<Operand> = lead.map(Self::literal).into_iter().collect();
        if num.is_empty() {
            operands.push(Self::literal(1.0));
        }
        for f in num {
            operands.push(self.operand(f, ATOM));
        }
        let mut acc = operands[0];
        if negate {
            acc = self.neg(acc);
        }
        for &f in &operands[1..] {
            acc = self.binary(Binary::Mul, acc, f);
        }
        let Some((first, rest)) = den.split_first() else {
            return acc;
        };
        let mut d = self.operand(first, ATOM);
        for f in rest {
            let f = self.operand(f, ATOM);
            d = self.binary(Binary::Mul, d, f);
        }
        d.paren |= !rest.is_empty();
        self.binary(Binary::Div, acc, d)
    }

    /// `|coef| * t` as printed in a sum (negated when `negate`).
    fn term(&mut self, coef: f64, t: &Code, negate: bool) -> Operand {
        let lead = (coef.abs() != 1.0).then_some(coef.abs());
        match t {
            Code::Prod { num, den } => self.chain(lead, negate, num, den),
            _ if lead.is_some() => self.chain(lead, negate, std::slice::from_ref(t), &[]),
            _ => {
                let v = self.operand(t, PRODUCT);
                if negate {
                    self.neg(v)
                } else {
                    v
                }
            }
        }
    }

    /// A sum as printed: its terms (positive ones, then the constant, then
    /// negative ones subtracted) added two at a time, always the two that
    /// are ready first (the earlier one first; between terms ready
    /// together, the one of the smaller shape, else the order above), so
    /// that the sum's last addition waits only
    /// for its latest term, not for a chain of all the others. A partial
    /// sum of subtracted terms is subtracted as one; a positive term or the
    /// constant leads, else the first negative term is negated.
    fn sum(&mut self, constant: f64, terms: &[(f64, Code)]) -> Operand {
        let positive = terms.iter().any(|(c, _)| *c > 0.0);
        // `(value, subtracted)`, in the order above.
        let mut items: Vec<(Operand, bool)> = Vec::new();
        for (c, t) in terms.iter().filter(|(c, _)| *c > 0.0) {
            items.push((self.term(*c, t, false), false));
        }
        if constant != 0.0 {
            items.push(match positive {
                true => (Self::literal(constant.abs()), constant < 0.0),
                false => (Self::literal(constant), false),
            });
        }
        let mut negate = items.is_empty();
        for (c, t) in terms.iter().filter(|(c, _)| *c < 0.0) {
            items.push((self.term(*c, t, negate), !negate));
            negate = false;
        }
        let mut queue: BinaryHeap<Reverse<(u32, u64, usize)>> = items
            .iter()
            .enumerate()
            .map(|(k, (v, _))| Reverse((self.ready(*v), self.shape(*v), k)))
            .collect();
        while let (Some(Reverse((_, _, i))), Some(Reverse((_, _, j)))) = (queue.pop(), queue.pop())
        {
            let ((a, a_sub), (b, b_sub)) = (items[i], items[j]);
            let (value, sub) = match (a_sub, b_sub) {
                (false, false) => (self.binary(Binary::Add, a, b), false),
                (false, true) => (self.binary(Binary::Sub, a, b), false),
                (true, false) => (self.binary(Binary::Sub, b, a), false),
                (true, true) => (self.binary(Binary::Add, a, b), true),
            };
            queue.push(Reverse((self.ready(value), self.shape(value), items.len())));
            items.push((value, sub));
        }
        // What is left is positive: adding to a positive value gives one,
        // and one leads.
        items.last().map_or(Self::literal(0.0), |(v, _)| *v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn q(i: u32) -> Code {
        Code::Sym(Symbol::Q(i))
    }

    fn product(a: Code, b: Code) -> Code {
        Code::Prod {
            num: vec![a, b],
            den: vec![],
        }
    }

    fn sum(terms: Vec<(f64, Code)>) -> Code {
        Code::Sum {
            constant: 0.0,
            terms,
        }
    }

    fn input(i: u32) -> Operand {
        Operand::new(Value::Input(Symbol::Q(i)))
    }

    /// `v0 = q0 q1` is read once, as a term; `v1 = q0 q2` twice. Outputs
    /// `q2 + v0`, `q1 - v1`, `v1`, `q1 q2 - q0`.
    fn scheduled() -> Scheduled {
        let stmts = vec![
            Stmt::Let {
                var: 0,
                value: product(q(0), q(1)),
            },
            Stmt::Let {
                var: 1,
                value: product(q(0), q(2)),
            },
        ];
        let outputs = vec![
            sum(vec![(1.0, q(2)), (1.0, Code::Var(0))]),
            sum(vec![(1.0, q(1)), (-1.0, Code::Var(1))]),
            Code::Var(1),
            sum(vec![(1.0, product(q(1), q(2))), (-1.0, q(0))]),
        ];
        Scheduled::constraints(3, Program::new(stmts, outputs))
    }

    #[test]
    fn products_added_or_subtracted_are_fused_in_f64_code_only() {
        let fused = |l: &Lowered| {
            let f = l.ops.iter().filter_map(|op| match op {
                Op::Fused { form, x, y, c, .. } => Some((*form, *x, *y, *c)),
                _ => None,
            });
            f.collect::<Vec<_>>()
        };
        let binds = |l: &Lowered| {
            let b = l.ops.iter().filter_map(|op| match op {
                Op::Bind { var, .. } => Some(*var),
                _ => None,
            });
            b.collect::<Vec<_>>()
        };
        let double = lower(&scheduled(), true, false);
        // `v0` computed where it is read and fused; `v1` read twice stays
        // a variable, so `q1 - v1` is a plain difference.
        assert_eq!(binds(&double), [1]);
        let q2 = input(2);
        assert_eq!(
            fused(&double),
            [
                (Fused::AddMul, input(0), input(1), q2),
                (Fused::MulSub, input(1), input(2), input(0)),
            ]
        );
        let muls = double.ops.iter().filter(|op| {
            matches!(
                op,
                Op::Binary {
                    op: Binary::Mul,
                    ..
                }
            )
        });
        assert_eq!(muls.count(), 1, "{:?}", double.ops);
        let single = lower(&scheduled(), false, false);
        assert_eq!(binds(&single), [0, 1]);
        assert!(fused(&single).is_empty());
    }

    /// Two sums of the same shape with their terms in other orders and
    /// signs, as two mirror-image limbs give: `q0 qd0 + q0 q0` and `q1 q1 -
    /// q1 qd1`. Where the scene is mirrored both fuse the product of the
    /// same shape, so they can pair; in the program's order they do not.
    #[test]
    fn mirror_images_fuse_alike_where_the_scene_is_mirrored() {
        let qd = |i| Code::Sym(Symbol::Qd(i));
        let outputs = vec![
            sum(vec![
                (1.0, product(q(0), qd(0))),
                (1.0, product(q(0), q(0))),
            ]),
            sum(vec![
                (1.0, product(q(1), q(1))),
                (-1.0, product(q(1), qd(1))),
            ]),
        ];
        let f = Scheduled::constraints(2, Program::new(Vec::new(), outputs));
        // Per fused operation, whether the product it fuses reads a velocity.
        let velocities = |mirrored| {
            let ops = lower(&f, true, mirrored).ops;
            let f = ops.iter().filter_map(|op| match op {
                Op::Fused { x, y, .. } => Some(
                    [x, y]
                        .iter()
                        .any(|o| matches!(o.value, Value::Input(Symbol::Qd(_)))),
                ),
                _ => None,
            });
            f.collect::<Vec<bool>>()
        };
        let alike = velocities(true);
        assert_eq!(alike.len(), 2);
        assert_eq!(alike[0], alike[1]);
        let written = velocities(false);
        assert_ne!(written[0], written[1]);
    }

    /// `sum` lowered alone as an output, `f32`-style (no fusing).
    fn lowered_sum(terms: Vec<(f64, Code)>) -> Vec<Op> {
        let f = Scheduled::constraints(4, Program::new(Vec::new(), vec![sum(terms)]));
        let mut ops = lower(&f, false, false).ops;
        ops.retain(|op| !matches!(op, Op::Store { .. } | Op::Zero { .. }));
        ops
    }

    fn temp(t: u32) -> Operand {
        Operand::new(Value::Temp(t))
    }

    #[test]
    fn sums_add_the_terms_ready_first_first() {
        // Four inputs: a tree of two levels, not a chain of three.
        let ops = lowered_sum((0..4).map(|i| (1.0, q(i))).collect());
        let add = |dst, a, b| Op::Binary {
            dst,
            op: Binary::Add,
            a,
            b,
        };
        assert_eq!(
            ops,
            [
                add(0, input(0), input(1)),
                add(1, input(2), input(3)),
                add(2, temp(0), temp(1)),
            ]
        );
        // `sin(q0) + q1 - q2`: the inputs first, the call's value last.
        let sine = Code::Call(Func::Sin, Box::new(q(0)));
        let ops = lowered_sum(vec![(1.0, sine), (1.0, q(1)), (-1.0, q(2))]);
        let call = ops.iter().find_map(|op| match op {
            Op::Call { dst, .. } => Some(*dst),
            _ => None,
        });
        let (early, late) = match ops.last() {
            Some(Op::Binary {
                op: Binary::Add,
                a,
                b,
                ..
            }) => (a.value, b.value),
            other => panic!("{other:?}"),
        };
        assert_eq!(late, Value::Temp(call.unwrap()));
        let difference = ops.iter().find_map(|op| match op {
            Op::Binary {
                dst,
                op: Binary::Sub,
                a,
                b,
            } if (a.value, b.value) == (input(1).value, input(2).value) => Some(*dst),
            _ => None,
        });
        assert_eq!(Some(early), difference.map(Value::Temp));
    }

    #[test]
    fn fused_forms_compute_their_written_expressions() {
        let (x, y, c) = (0.1, 3.0f64.sqrt(), 0.7);
        assert_eq!(Fused::AddMul.apply(x, y, c), c + x * y);
        assert_eq!(Fused::MulAdd.apply(x, y, c), x * y + c);
        assert_eq!(Fused::SubMul.apply(x, y, c), c - x * y);
        assert_eq!(Fused::MulSub.apply(x, y, c), x * y - c);
    }
}
