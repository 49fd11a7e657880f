//! The data of a scheduled program: expressions ([`Code`]), statements
//! ([`Stmt`]), the program itself ([`Program`]) and its operation count
//! ([`OpCount`]), counted as the emitter writes them.

use std::fmt;
use std::ops::AddAssign;

use crate::expr::{Func, Symbol};

/// Arithmetic operations of a program.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct OpCount {
    /// Additions, subtractions and negations.
    pub adds: usize,
    /// Multiplications.
    pub muls: usize,
    /// Divisions.
    pub divs: usize,
    /// Calls of `sin`, `cos`, `sin_cos`, `tan`, `exp`, `ln`, `sqrt`, `abs`,
    /// `sign`, `step`, `atan2`.
    pub calls: usize,
}

impl OpCount {
    /// All operations.
    pub fn total(&self) -> usize {
        self.adds + self.muls + self.divs + self.calls
    }
}

impl AddAssign for OpCount {
    fn add_assign(&mut self, o: OpCount) {
        self.adds += o.adds;
        self.muls += o.muls;
        self.divs += o.divs;
        self.calls += o.calls;
    }
}

impl fmt::Display for OpCount {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} add, {} mul, {} div, {} call",
            self.adds, self.muls, self.divs, self.calls
        )
    }
}

/// An expression of the emitted program.
#[derive(Debug, Clone, PartialEq)]
pub enum Code {
    /// A local variable.
    Var(u32),
    /// An input.
    Sym(Symbol),
    /// A literal.
    Lit(f64),
    /// `constant + sum(coefficient * term)`.
    Sum {
        /// Constant part.
        constant: f64,
        /// Terms with their coefficients.
        terms: Vec<(f64, Code)>,
    },
    /// `prod(num) / prod(den)`.
    Prod {
        /// Numerator factors.
        num: Vec<Code>,
        /// Denominator factors.
        den: Vec<Code>,
    },
    /// `f(x)`.
    Call(Func, Box<Code>),
    /// `atan2(y, x)`.
    Atan2(Box<Code>, Box<Code>),
}

impl Code {
    /// Whether it reads a local variable (else inputs and literals only).
    pub fn reads_variables(&self) -> bool {
        match self {
            Code::Var(_) => true,
            Code::Sym(_) | Code::Lit(_) => false,
            Code::Sum { terms, .. } => terms.iter().any(|(_, t)| t.reads_variables()),
            Code::Prod { num, den } => num.iter().chain(den).any(Code::reads_variables),
            Code::Call(_, a) => a.reads_variables(),
            Code::Atan2(y, x) => y.reads_variables() || x.reads_variables(),
        }
    }
}

/// A statement of the emitted program.
#[derive(Debug, Clone, PartialEq)]
pub enum Stmt {
    /// `let var = value;`
    Let {
        /// Variable number.
        var: u32,
        /// Its value.
        value: Code,
    },
    /// `let (sin, cos) = sin_cos(arg);`
    SinCos {
        /// Variable receiving the sine.
        sin: u32,
        /// Variable receiving the cosine.
        cos: u32,
        /// The argument.
        arg: Code,
    },
}

/// A straight-line program computing a list of outputs.
#[derive(Debug, Clone, PartialEq)]
pub struct Program {
    /// Statements in order.
    pub stmts: Vec<Stmt>,
    /// One expression per output.
    pub outputs: Vec<Code>,
    /// Operations the program performs.
    pub ops: OpCount,
}

impl Program {
    /// The program of `stmts` and `outputs`, with its operation count.
    pub fn new(stmts: Vec<Stmt>, outputs: Vec<Code>) -> Program {
        let mut ops = OpCount::default();
        for st in &stmts {
            match st {
                Stmt::Let { value, .. } => count(value, &mut ops),
                Stmt::SinCos { arg, .. } => {
                    ops.calls += 1;
                    count(arg, &mut ops);
                }
            }
        }
        for o in &outputs {
            count(o, &mut ops);
        }
        Program {
            stmts,
            outputs,
            ops,
        }
    }
}

/// Count the operations of an expression as it is emitted.
fn count(c: &Code, ops: &mut OpCount) {
    match c {
        Code::Var(_) | Code::Sym(_) | Code::Lit(_) => {}
        Code::Sum { constant, terms } => {
            ops.adds += terms.len() - 1 + usize::from(*constant != 0.0);
            if terms.iter().all(|(c, _)| *c < 0.0) && *constant == 0.0 {
                ops.adds += 1; // leading negation
            }
            for (coef, t) in terms {
                if coef.abs() != 1.0 {
                    ops.muls += 1;
                }
                count(t, ops);
            }
        }
        Code::Prod { num, den } => {
            ops.muls += num.len().saturating_sub(1) + den.len().saturating_sub(1);
            if !den.is_empty() {
                ops.divs += 1;
            }
            for f in num.iter().chain(den) {
                count(f, ops);
            }
        }
        Code::Call(_, a) => {
            ops.calls += 1;
            count(a, ops);
        }
        Code::Atan2(y, x) => {
            ops.calls += 1;
            count(y, ops);
            count(x, ops);
        }
    }
}
