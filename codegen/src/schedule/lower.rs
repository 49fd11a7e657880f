//! One lowering of each scheduled function ([`lower`]) into operations in
//! evaluation order ([`Op`]), which the Rust emitter prints, and the
//! interpreter runs as a tape. Both therefore perform the same IEEE
//! operations in the same association: the operations are those of the
//! emitted Rust expression *as Rust parses it*, not of the program's tree,
//! where the two differ:
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
//! * in `f64`, the sines and cosines of angles that read inputs only come
//!   first, in one batch (`math::sin_cos_array`, bitwise `sin_cos` lane by
//!   lane).
//!
//! Each operand also says whether the printed text parenthesises it
//! ([`Operand::paren`]): where the tree's precedence asks for it, also where
//! the association does not (the emitted text has always been written so).
//! Then the outputs: an output some of whose entries are not computed is
//! zeroed first (the constant actuator map always is), each computed entry
//! is stored at its row and column, and an off-diagonal entry of a
//! symmetric matrix is mirrored.

use super::{Code, Function, Inputs, Scheduled, Shape, Stmt};
use crate::expr::{Func, Symbol};

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

/// Lower a scheduled function; `batch` puts the sines and cosines of angles
/// that read inputs only into one batch first (for `f64` code).
pub fn lower(f: &Scheduled, batch: bool) -> Lowered {
    let spec = f.spec();
    let shapes: Vec<(usize, usize)> = spec.outputs.iter().map(|o| o.shape.size(f.dims)).collect();
    let mut l = Lowering::default();
    let p = &f.program;
    let batched =
        |s: &&Stmt| batch && matches!(s, Stmt::SinCos { arg, .. } if !arg.reads_variables());
    let mut pairs = Vec::new();
    for s in p.stmts.iter().filter(batched) {
        if let Stmt::SinCos { sin, cos, arg } = s {
            let a = l.operand(arg, SUM);
            pairs.push((*sin, *cos, a));
        }
    }
    if !pairs.is_empty() {
        l.ops.push(Op::SinCosArray(pairs));
    }
    for s in p.stmts.iter().filter(|s| !batched(s)) {
        let op = match s {
            Stmt::Let { var, value } => Op::Bind {
                var: *var,
                value: l.operand(value, SUM),
            },
            Stmt::SinCos { sin, cos, arg } => Op::SinCos {
                sin: *sin,
                cos: *cos,
                arg: l.operand(arg, SUM),
            },
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
    Lowered {
        function: f.function,
        shapes,
        ops: l.ops,
        temps: l.temps,
    }
}

#[derive(Default)]
struct Lowering {
    ops: Vec<Op>,
    temps: u32,
}

impl Lowering {
    fn temp(&mut self) -> u32 {
        self.temps += 1;
        self.temps - 1
    }

    fn binary(&mut self, op: Binary, a: Operand, b: Operand) -> Operand {
        let dst = self.temp();
        self.ops.push(Op::Binary { dst, op, a, b });
        Operand::new(Value::Temp(dst))
    }

    fn neg(&mut self, a: Operand) -> Operand {
        let dst = self.temp();
        self.ops.push(Op::Neg { dst, a });
        Operand::new(Value::Temp(dst))
    }

    fn literal(x: f64) -> Operand {
        Operand::new(Value::Literal(x))
    }

    /// `c` printed where precedence `need` is required.
    fn operand(&mut self, c: &Code, need: u8) -> Operand {
        let mut o = self.value(c);
        o.paren |= precedence(c) < need;
        o
    }

    /// The value of `c` as a whole.
    fn value(&mut self, c: &Code) -> Operand {
        match c {
            Code::Var(v) => Operand::new(Value::Var(*v)),
            Code::Sym(s) => Operand::new(Value::Input(*s)),
            Code::Lit(x) => Self::literal(*x),
            Code::Sum { constant, terms } => self.sum(*constant, terms),
            Code::Prod { num, den } => self.chain(None, false, num, den),
            Code::Call(f, a) => {
                let a = self.operand(a, SUM);
                let dst = self.temp();
                self.ops.push(Op::Call { dst, f: *f, a });
                Operand::new(Value::Temp(dst))
            }
            Code::Atan2(y, x) => {
                let (y, x) = (self.operand(y, SUM), self.operand(x, SUM));
                let dst = self.temp();
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

    /// A sum as printed: positive terms, the constant, negative terms.
    fn sum(&mut self, constant: f64, terms: &[(f64, Code)]) -> Operand {
        let mut acc: Option<Operand> = None;
        for (c, t) in terms.iter().filter(|(c, _)| *c > 0.0) {
            let v = self.term(*c, t, false);
            acc = Some(match acc {
                None => v,
                Some(a) => self.binary(Binary::Add, a, v),
            });
        }
        acc = match acc {
            None if constant != 0.0 => Some(Self::literal(constant)),
            Some(a) if constant > 0.0 => Some(self.binary(Binary::Add, a, Self::literal(constant))),
            Some(a) if constant < 0.0 => {
                Some(self.binary(Binary::Sub, a, Self::literal(-constant)))
            }
            other => other,
        };
        for (c, t) in terms.iter().filter(|(c, _)| *c < 0.0) {
            acc = Some(match acc {
                None => self.term(*c, t, true),
                Some(a) => {
                    let v = self.term(*c, t, false);
                    self.binary(Binary::Sub, a, v)
                }
            });
        }
        acc.unwrap_or_else(|| Self::literal(0.0))
    }
}
