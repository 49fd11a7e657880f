//! A lowered function ([`crate::schedule::lower`]) assembled into a tape:
//! its operations become instructions over slots (inputs, literals, then
//! intermediates, whose slots are reused once they are dead), arithmetic on
//! literals is folded (the compiler folds them in the emitted code,
//! with the same IEEE result), program variables and stored values become
//! the slots holding them, and the stores become writes to the output
//! buffer (matrices column-major, nalgebra's layout).

use std::collections::HashMap;

use super::tape::{Instr, Instruction, Tape};
use crate::expr::Symbol;
use crate::schedule::{Inputs, Lowered, Op, Operand, Value};

/// A value while assembling: an input, a literal or an intermediate.
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
    op: Instruction,
    dst: Ref,
    a: Ref,
    b: Ref,
}

impl Pre {
    /// The intermediates it reads, each once.
    fn reads(&self) -> impl Iterator<Item = u32> {
        let b = (self.op != Instruction::SinCos && self.b != self.a).then_some(self.b);
        [Some(self.a), b].into_iter().flatten().filter_map(temp)
    }

    /// The intermediates it writes.
    fn writes(&self) -> impl Iterator<Item = u32> {
        let b = (self.op == Instruction::SinCos).then_some(self.b);
        [Some(self.dst), b].into_iter().flatten().filter_map(temp)
    }
}

fn temp(r: Ref) -> Option<u32> {
    match r {
        Ref::Temp(t) => Some(t),
        _ => None,
    }
}

/// The tape of a lowered function of a scene with `nq` coordinates and
/// `params` runtime parameters.
pub(super) fn assemble(lowered: &Lowered, nq: usize, params: usize) -> Tape {
    let mut a = Assembler {
        nq,
        params,
        literals: Vec::new(),
        literal_index: HashMap::new(),
        vars: HashMap::new(),
        temps: vec![None; lowered.temps as usize],
        stored: HashMap::new(),
        code: Vec::new(),
        writes: Vec::new(),
        slots_used: 0,
    };
    let offsets: Vec<usize> = lowered
        .shapes
        .iter()
        .scan(0, |at, (r, c)| {
            let start = *at;
            *at += r * c;
            Some(start)
        })
        .collect();
    let rows = |k: usize| lowered.shapes[k].0;
    for op in &lowered.ops {
        match op {
            Op::Binary {
                dst,
                op,
                a: x,
                b: y,
            } => {
                let (x, y) = (a.operand(*x), a.operand(*y));
                let v = match (a.constant(x), a.constant(y)) {
                    (Some(x), Some(y)) => a.literal(op.apply(x, y)),
                    _ => a.push(Instruction::from(*op), x, y),
                };
                a.temps[*dst as usize] = Some(v);
            }
            Op::Neg { dst, a: x } => {
                let x = a.operand(*x);
                let v = match a.constant(x) {
                    Some(c) => a.literal(-c),
                    None => a.push(Instruction::Neg, x, x),
                };
                a.temps[*dst as usize] = Some(v);
            }
            Op::Call { dst, f, a: x } => {
                let x = a.operand(*x);
                let v = a.push(Instruction::Call(*f), x, x);
                a.temps[*dst as usize] = Some(v);
            }
            Op::Atan2 { dst, y, x } => {
                let (y, x) = (a.operand(*y), a.operand(*x));
                let v = a.push(Instruction::Atan2, y, x);
                a.temps[*dst as usize] = Some(v);
            }
            Op::Bind { var, value } => {
                let v = a.operand(*value);
                a.vars.insert(*var, v);
            }
            Op::SinCos { sin, cos, arg } => a.sin_cos(*sin, *cos, *arg),
            // Bitwise `sin_cos` lane by lane.
            Op::SinCosArray(batch) => {
                for &(sin, cos, arg) in batch {
                    a.sin_cos(sin, cos, arg);
                }
            }
            Op::Zero { .. } => {}
            Op::Store {
                output,
                row,
                col,
                value,
            } => {
                let v = a.operand(*value);
                a.stored.insert((*output, *row, *col), v);
                a.writes
                    .push((v, offsets[*output] + row + col * rows(*output)));
            }
            Op::Mirror { output, row, col } => {
                let v = a.stored[&(*output, *row, *col)];
                a.writes
                    .push((v, offsets[*output] + col + row * rows(*output)));
            }
        }
    }
    a.finish(lowered)
}

struct Assembler {
    nq: usize,
    params: usize,
    literals: Vec<f64>,
    literal_index: HashMap<u64, u32>,
    /// The program's variables.
    vars: HashMap<u32, Ref>,
    /// The lowered function's intermediates.
    temps: Vec<Option<Ref>>,
    /// The value stored at each `(output, row, column)`.
    stored: HashMap<(usize, usize, usize), Ref>,
    code: Vec<Pre>,
    /// `(value, position in the output buffer)`.
    writes: Vec<(Ref, usize)>,
    /// Intermediates of the tape.
    slots_used: u32,
}

impl Assembler {
    fn temp(&mut self) -> Ref {
        self.slots_used += 1;
        Ref::Temp(self.slots_used - 1)
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

    fn operand(&mut self, o: Operand) -> Ref {
        match o.value {
            Value::Input(s) => self.input(s),
            Value::Literal(x) => self.literal(x),
            Value::Temp(t) => {
                self.temps[t as usize].expect("an intermediate is written before it is read")
            }
            Value::Var(v) => self.vars[&v],
        }
    }

    /// The value of a literal.
    fn constant(&self, r: Ref) -> Option<f64> {
        match r {
            Ref::Literal(k) => Some(self.literals[k as usize]),
            _ => None,
        }
    }

    /// The instruction `op(a, b)`.
    fn push(&mut self, op: Instruction, a: Ref, b: Ref) -> Ref {
        let dst = self.temp();
        self.code.push(Pre { op, dst, a, b });
        dst
    }

    fn sin_cos(&mut self, sin: u32, cos: u32, arg: Operand) {
        let a = self.operand(arg);
        let (s, c) = (self.temp(), self.temp());
        self.code.push(Pre {
            op: Instruction::SinCos,
            dst: s,
            a,
            b: c,
        });
        self.vars.insert(sin, s);
        self.vars.insert(cos, c);
    }

    /// Assign slots (intermediates reuse the slots of dead ones) and build
    /// the tape.
    fn finish(self, lowered: &Lowered) -> Tape {
        let writes = self.writes;
        const LIVE: usize = usize::MAX;
        let inputs = 3 * self.nq + 1 + self.params;
        let first_temp = inputs + self.literals.len();
        // Last instruction reading each intermediate (outputs: to the end).
        let mut last: Vec<Option<usize>> = vec![None; self.slots_used as usize];
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
        let mut slot_of: Vec<u32> = vec![0; self.slots_used as usize];
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
            let b = if p.op == Instruction::SinCos {
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
        let zero_first = lowered.ops.iter().any(|op| matches!(op, Op::Zero { .. }));
        let writes = writes
            .into_iter()
            .map(|(r, pos)| (slot(r, &slot_of), pos as u32))
            .collect();
        Tape {
            nq: self.nq,
            params: self.params,
            uses_qd: lowered.inputs() >= Inputs::Velocities,
            uses_qdd: lowered.inputs() == Inputs::Accelerations,
            literals: self.literals,
            code,
            writes,
            zero_first,
            shapes: lowered.shapes.clone(),
            slots,
        }
    }
}
