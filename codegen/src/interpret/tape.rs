//! One emitted function as an instruction tape over one array of `f64`
//! slots, and its evaluation ([`Tape::eval`]) with a caller-owned scratch
//! buffer and no allocation once that buffer has grown. `sin_cos`, `sin`,
//! ..., `atan2` are the functions of `flexdyn_runtime::math` that generated
//! code calls, in the same build (so the same library, `std` or `libm`).

use flexdyn_runtime::math;

use crate::expr::Func;
use crate::schedule::Binary;

impl From<Binary> for Instruction {
    fn from(op: Binary) -> Instruction {
        match op {
            Binary::Add => Instruction::Add,
            Binary::Sub => Instruction::Sub,
            Binary::Mul => Instruction::Mul,
            Binary::Div => Instruction::Div,
        }
    }
}

/// Tape operations, one flat enum (one dispatch per instruction). Unary
/// operations read `a`; `SinCos` writes the sine to `dst` and the cosine to
/// `b`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Instruction {
    Add,
    Sub,
    Mul,
    Div,
    Neg,
    Call(Func),
    SinCos,
    Atan2,
}

/// One instruction: slots `a`, `b` in, slot `dst` out.
#[derive(Debug, Clone, Copy)]
pub(super) struct Instr {
    pub(super) op: Instruction,
    pub(super) dst: u32,
    pub(super) a: u32,
    pub(super) b: u32,
}

/// One emitted function as an instruction tape.
///
/// Slots: `q` (nq), `qd` (nq), `qdd` (nq), `t`, the runtime parameters, the literals,
/// then intermediate values (reused once dead). The outputs are written to
/// one buffer, one after the other, matrices column-major (nalgebra's
/// layout), entries the function does not compute set to zero.
#[derive(Debug, Clone)]
pub struct Tape {
    pub(super) nq: usize,
    pub(super) params: usize,
    pub(super) uses_qd: bool,
    pub(super) uses_qdd: bool,
    pub(super) literals: Vec<f64>,
    pub(super) code: Vec<Instr>,
    /// `(slot, position in the output buffer)`.
    pub(super) writes: Vec<(u32, u32)>,
    /// Whether some output entries are not written (they are zero).
    pub(super) zero_first: bool,
    /// `(rows, columns)` of each output.
    pub(super) shapes: Vec<(usize, usize)>,
    pub(super) slots: usize,
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
                Instruction::Add => x + y,
                Instruction::Sub => x - y,
                Instruction::Mul => x * y,
                Instruction::Div => x / y,
                Instruction::Neg => -x,
                Instruction::Call(f) => call(f, x),
                Instruction::Atan2 => math::atan2(x, y),
                Instruction::SinCos => {
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
        Func::Abs => math::abs(x),
        Func::Sign => math::sign(x),
        Func::Step => math::step(x),
    }
}
