//! One emitted function as an instruction tape over one array of `f64`
//! slots, and its interpretation with a caller-owned [`Scratch`] and no
//! allocation once that has grown (the public calls, [`Tape::eval`] and
//! [`Tape::eval_batch`], are in `eval`). The instructions come
//! in runs of one operation, dispatched once per run. `sin_cos`, `sin`,
//! ..., `atan2` are the functions of `flexdyn_runtime::math` that generated
//! code calls, in the same build (so the same library, `std` or `libm`).

use std::sync::atomic::{AtomicU64, Ordering};

use flexdyn_runtime::math;

use crate::expr::Func;
use crate::schedule::{Binary, Fused};

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

impl From<Fused> for Instruction {
    fn from(form: Fused) -> Instruction {
        match form {
            Fused::AddMul | Fused::MulAdd => Instruction::MulAdd,
            Fused::SubMul => Instruction::SubMul,
            Fused::MulSub => Instruction::MulSub,
        }
    }
}

/// Tape operations, one flat enum (one dispatch per run of instructions).
/// Unary operations read `a`; `SinCos` writes the sine to `dst` and the
/// cosine to `b`; the fused operations are the two roundings of their
/// unfused form, in the same order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub(super) enum Instruction {
    Add,
    Sub,
    Mul,
    Div,
    Neg,
    Call(Func),
    SinCos,
    Atan2,
    /// `c + a b`.
    MulAdd,
    /// `c - a b`.
    SubMul,
    /// `a b - c`.
    MulSub,
}

impl Instruction {
    /// Whether it reads a third operand `c`.
    pub(super) fn fused(self) -> bool {
        matches!(
            self,
            Instruction::MulAdd | Instruction::SubMul | Instruction::MulSub
        )
    }
}

/// One instruction of a run (the run says which operation): slots `a`, `b`
/// (and `c` for the fused operations) in, slot `dst` out.
#[derive(Debug, Clone, Copy)]
pub(super) struct Instr {
    pub(super) dst: u32,
    pub(super) a: u32,
    pub(super) b: u32,
    pub(super) c: u32,
}

/// States a batched evaluation ([`Tape::eval_batch`]) runs side by side:
/// every instruction is applied to this many states at once (a loop the
/// compiler turns into SIMD), which spreads the dispatch over them.
pub const LANES: usize = 8;

/// The slots tapes evaluate in, owned by the caller and reused from call to
/// call: they grow to a tape's size on first use, and remember whose
/// literals they hold, so that calls of one tape after another copy only
/// the arguments. One scratch serves any number of tapes (switching tapes
/// copies the literals again). Each slot holds `L` values, one per state
/// evaluated side by side: `L = 1` for [`Tape::eval`], [`LANES`] for
/// [`Tape::eval_batch`].
#[derive(Debug, Clone)]
pub struct Scratch<const L: usize = 1> {
    slots: Vec<[f64; L]>,
    /// The [`Tape::id`] whose literals are in place (0: none).
    holds: u64,
}

impl<const L: usize> Default for Scratch<L> {
    fn default() -> Self {
        Scratch {
            slots: Vec::new(),
            holds: 0,
        }
    }
}

/// A number no other tape of this process has (never 0).
pub(super) fn next_id() -> u64 {
    static NEXT: AtomicU64 = AtomicU64::new(1);
    NEXT.fetch_add(1, Ordering::Relaxed)
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
    /// Runs of one operation: the operation and the end of its run in
    /// `code` (the next run starts there). An instruction may read what an
    /// earlier one of its run computed, except in runs of `SinCos`.
    pub(super) runs: Vec<(Instruction, u32)>,
    /// `(slot, position in the output buffer)`, every position once
    /// (entries the function does not compute from a zero literal).
    pub(super) writes: Vec<(u32, u32)>,
    /// This tape's number, which [`Scratch`] remembers to know whose
    /// literals it holds.
    pub(super) id: u64,
    /// Its position among its scene's tapes.
    pub(super) index: usize,
    /// `(rows, columns)` of each output.
    pub(super) shapes: Vec<(usize, usize)>,
    pub(super) slots: usize,
    /// The tape as machine code, compiled on first evaluation (`None`
    /// inside where it could not be: the tape is then interpreted).
    #[cfg(feature = "jit")]
    pub(super) native: std::sync::OnceLock<Option<super::machine::Machine>>,
    /// The same for two states side by side, compiled on the first batch.
    #[cfg(feature = "jit")]
    pub(super) native_pairs: std::sync::OnceLock<Option<super::machine::Machine>>,
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

    /// Its position among its scene's tapes, below
    /// [`super::Interpreted::tape_count`]: for keeping one [`Scratch`] per
    /// tape, which then always holds that tape's literals.
    pub fn index(&self) -> usize {
        self.index
    }

    /// Whether the function reads the velocities.
    pub fn uses_qd(&self) -> bool {
        self.uses_qd
    }

    /// Number of instructions.
    pub fn instructions(&self) -> usize {
        self.code.len()
    }

    /// Whether the function reads the accelerations (`inverse_dynamics`).
    pub fn uses_qdd(&self) -> bool {
        self.uses_qdd
    }

    /// Runs the tape on the interpreter (what [`Tape::eval`] does where the
    /// tape has no machine code), the arguments' lengths checked.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn interpret(
        &self,
        q: &[f64],
        qd: &[f64],
        qdd: &[f64],
        t: f64,
        params: &[f64],
        scratch: &mut Scratch,
        out: &mut [f64],
    ) {
        let nq = self.nq;
        let s = self.slots(scratch);
        let input = |offset: usize, values: &[f64], s: &mut [[f64; 1]]| {
            for (slot, &v) in s[offset..offset + values.len()].iter_mut().zip(values) {
                *slot = [v];
            }
        };
        input(0, q, s);
        if self.uses_qd {
            input(nq, qd, s);
        }
        if self.uses_qdd {
            input(2 * nq, qdd, s);
        }
        input(3 * nq, &[t], s);
        input(3 * nq + 1, params, s);
        self.run(s);
        for &(slot, pos) in &self.writes {
            out[pos as usize] = s[slot as usize][0];
        }
    }

    /// [`Tape::eval_batch`] on the interpreter, [`LANES`] states side by
    /// side, the arguments' lengths checked.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn interpret_batch(
        &self,
        q: &[f64],
        qd: &[f64],
        qdd: &[f64],
        t: &[f64],
        params: &[f64],
        scratch: &mut Scratch<LANES>,
        out: &mut [f64],
    ) {
        let (nq, n, len) = (self.nq, t.len(), self.output_len());
        let s = self.slots(scratch);
        for (k, p) in params.iter().enumerate() {
            s[3 * nq + 1 + k] = [*p; LANES];
        }
        for first in (0..n).step_by(LANES) {
            // Lanes past the last state repeat it (their results are dropped).
            let state = |l: usize| (first + l).min(n - 1);
            let input = |offset: usize, x: &[f64], width: usize, s: &mut [[f64; LANES]]| {
                for i in 0..width {
                    s[offset + i] = core::array::from_fn(|l| x[state(l) * width + i]);
                }
            };
            input(0, q, nq, s);
            if self.uses_qd {
                input(nq, qd, nq, s);
            }
            if self.uses_qdd {
                input(2 * nq, qdd, nq, s);
            }
            input(3 * nq, t, 1, s);
            self.run_lanes(s);
            for l in 0..LANES.min(n - first) {
                let o = &mut out[(first + l) * len..(first + l + 1) * len];
                for &(slot, pos) in &self.writes {
                    o[pos as usize] = s[slot as usize][l];
                }
            }
        }
    }

    /// The tape's slots in `scratch`, a power of two long, its literals in
    /// place.
    fn slots<'s, const L: usize>(&self, scratch: &'s mut Scratch<L>) -> &'s mut [[f64; L]] {
        let size = self.slots.next_power_of_two();
        if scratch.holds != self.id {
            if scratch.slots.len() < size {
                scratch.slots.resize(size, [0.0; L]);
            }
            let lit = 3 * self.nq + 1 + self.params;
            for (slot, &v) in scratch.slots[lit..lit + self.literals.len()]
                .iter_mut()
                .zip(&self.literals)
            {
                *slot = [v; L];
            }
            scratch.holds = self.id;
        }
        &mut scratch.slots[..size]
    }

    /// [`Tape::run`] of a batch, with AVX2's registers of four `f64` where
    /// the processor has them (the same IEEE operations as SSE2's, so the
    /// same bits; no fused multiply-adds).
    fn run_lanes(&self, s: &mut [[f64; LANES]]) {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor has AVX2, checked above.
            unsafe { self.run_avx2(s) };
            return;
        }
        self.run(s);
    }

    /// [`Tape::run`] compiled for AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn run_avx2(&self, s: &mut [[f64; LANES]]) {
        for (op, run) in self.each_run() {
            run_op_inlined(op, run, s);
        }
    }

    /// Every run, in order, over the slots.
    fn run<const L: usize>(&self, s: &mut [[f64; L]]) {
        for (op, run) in self.each_run() {
            run_op(op, run, s);
        }
    }

    /// The runs: each operation with its instructions.
    fn each_run(&self) -> impl Iterator<Item = (Instruction, &[Instr])> {
        let starts = core::iter::once(0).chain(self.runs.iter().map(|&(_, end)| end as usize));
        self.runs
            .iter()
            .zip(starts)
            .map(|(&(op, end), start)| (op, &self.code[start..end as usize]))
    }
}

/// [`run_op_inlined`] as a function of its own, where the compiler keeps
/// the masked indices free of bounds checks (inlined into the loop over
/// the runs, it checked every index).
fn run_op<const L: usize>(op: Instruction, run: &[Instr], s: &mut [[f64; L]]) {
    run_op_inlined(op, run, s);
}

/// One run of operation `op` over the slots `s`, each slot `L` states side
/// by side: one dispatch, then a loop the processor predicts, over the
/// lanes a loop the compiler vectorises. Sines and cosines go several at a
/// time through [`math::sin_cos_array`] (bitwise [`math::sin_cos`] lane by
/// lane, as generated code batches them): four instructions of the run for
/// one state (the instructions of a `SinCos` run are independent, so
/// reading four arguments before writing their results changes nothing),
/// the lanes of one instruction for several.
#[inline(always)]
fn run_op_inlined<const L: usize>(op: Instruction, run: &[Instr], s: &mut [[f64; L]]) {
    // `s` is a power of two long and every index below its length, so
    // masking changes no index and lets the compiler drop the bounds checks.
    let m = s.len() - 1;
    let s = &mut s[..=m];
    macro_rules! each {
        (|$x:ident, $y:ident| $v:expr) => {
            for i in run {
                let (x, y) = (s[i.a as usize & m], s[i.b as usize & m]);
                s[i.dst as usize & m] = core::array::from_fn(|l| {
                    let ($x, $y) = (x[l], y[l]);
                    $v
                });
            }
        };
        (|$x:ident, $y:ident, $z:ident| $v:expr) => {
            for i in run {
                let (x, y) = (s[i.a as usize & m], s[i.b as usize & m]);
                let z = s[i.c as usize & m];
                s[i.dst as usize & m] = core::array::from_fn(|l| {
                    let ($x, $y, $z) = (x[l], y[l], z[l]);
                    $v
                });
            }
        };
    }
    match op {
        Instruction::Add => each!(|x, y| x + y),
        Instruction::Sub => each!(|x, y| x - y),
        Instruction::Mul => each!(|x, y| x * y),
        Instruction::Div => each!(|x, y| x / y),
        Instruction::Neg => each!(|x, _y| -x),
        Instruction::Call(f) => each!(|x, _y| call(f, x)),
        Instruction::Atan2 => each!(|x, y| math::atan2(x, y)),
        Instruction::MulAdd => each!(|x, y, z| z + x * y),
        Instruction::SubMul => each!(|x, y, z| z - x * y),
        Instruction::MulSub => each!(|x, y, z| x * y - z),
        Instruction::SinCos if L == 1 => {
            let mut fours = run.chunks_exact(4);
            for four in &mut fours {
                let sc = math::sin_cos_array([0, 1, 2, 3].map(|k| s[four[k].a as usize & m][0]));
                for (i, (sin, cos)) in four.iter().zip(sc) {
                    s[i.dst as usize & m] = [sin; L];
                    s[i.b as usize & m] = [cos; L];
                }
            }
            for i in fours.remainder() {
                let (sin, cos) = math::sin_cos(s[i.a as usize & m][0]);
                s[i.dst as usize & m] = [sin; L];
                s[i.b as usize & m] = [cos; L];
            }
        }
        Instruction::SinCos => {
            for i in run {
                let sc = math::sin_cos_array(s[i.a as usize & m]);
                s[i.dst as usize & m] = sc.map(|(sin, _)| sin);
                s[i.b as usize & m] = sc.map(|(_, cos)| cos);
            }
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
