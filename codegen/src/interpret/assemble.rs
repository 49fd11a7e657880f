//! A lowered function ([`crate::schedule::lower`]) assembled into a tape:
//! its operations become instructions over slots (inputs, literals, then
//! intermediates, whose slots are reused once they are dead), arithmetic on
//! literals is folded (the compiler folds them in the emitted code,
//! with the same IEEE result), program variables and stored values become
//! the slots holding them, and the stores become writes to the output
//! buffer (matrices column-major, nalgebra's layout). The lowering's
//! multiply-adds are one instruction each, computing the written
//! expression; the instructions are reordered into runs of one operation
//! (`in_runs`), which changes no result.

use std::collections::HashMap;

use super::tape::{self, Instr, Instruction, Tape};
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
/// destination for `SinCos`, equal to `a` for other unary operations; `c`
/// is the third operand of the fused operations, equal to `a` elsewhere).
#[derive(Debug, Clone, Copy)]
struct Pre {
    op: Instruction,
    dst: Ref,
    a: Ref,
    b: Ref,
    c: Ref,
}

impl Pre {
    /// The intermediates it reads, each once.
    fn reads(&self) -> impl Iterator<Item = u32> {
        let b = (self.op != Instruction::SinCos && self.b != self.a).then_some(self.b);
        let c = (self.op.fused() && self.c != self.a && self.c != self.b).then_some(self.c);
        [Some(self.a), b, c].into_iter().flatten().filter_map(temp)
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
                    _ => a.push(Instruction::from(*op), x, y, x),
                };
                a.temps[*dst as usize] = Some(v);
            }
            Op::Fused { dst, form, x, y, c } => {
                let (x, y, c) = (a.operand(*x), a.operand(*y), a.operand(*c));
                let v = match (a.constant(x), a.constant(y), a.constant(c)) {
                    (Some(x), Some(y), Some(c)) => a.literal(form.apply(x, y, c)),
                    _ => a.push(Instruction::from(*form), x, y, c),
                };
                a.temps[*dst as usize] = Some(v);
            }
            Op::Neg { dst, a: x } => {
                let x = a.operand(*x);
                let v = match a.constant(x) {
                    Some(c) => a.literal(-c),
                    None => a.push(Instruction::Neg, x, x, x),
                };
                a.temps[*dst as usize] = Some(v);
            }
            Op::Call { dst, f, a: x } => {
                let x = a.operand(*x);
                let v = a.push(Instruction::Call(*f), x, x, x);
                a.temps[*dst as usize] = Some(v);
            }
            Op::Atan2 { dst, y, x } => {
                let (y, x) = (a.operand(*y), a.operand(*x));
                let v = a.push(Instruction::Atan2, y, x, y);
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
    /// One instruction into a new intermediate; `c` is read by the fused
    /// forms only (the others pass `a`).
    fn push(&mut self, op: Instruction, a: Ref, b: Ref, c: Ref) -> Ref {
        let dst = self.temp();
        self.code.push(Pre { op, dst, a, b, c });
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
            c: a,
        });
        self.vars.insert(sin, s);
        self.vars.insert(cos, c);
    }

    /// Order the instructions in runs of one operation, assign slots
    /// (intermediates reuse the slots of dead ones) and build the tape.
    fn finish(mut self, lowered: &Lowered) -> Tape {
        // Entries no store writes are zero: written from a zero literal,
        // so a call writes every entry once and clears nothing first.
        let len: usize = lowered.shapes.iter().map(|(r, c)| r * c).sum();
        let mut written = vec![false; len];
        for (_, pos) in &self.writes {
            written[*pos] = true;
        }
        if written.contains(&false) {
            let zero = self.literal(0.0);
            let zeros = written.iter().enumerate().filter(|(_, w)| !**w);
            let zeros: Vec<(Ref, usize)> = zeros.map(|(pos, _)| (zero, pos)).collect();
            self.writes.extend(zeros);
        }
        let writes = self.writes;
        const LIVE: usize = usize::MAX;
        let inputs = 3 * self.nq + 1 + self.params;
        let first_temp = inputs + self.literals.len();
        let pre: Vec<Pre> = in_runs(&self.code, self.slots_used as usize)
            .into_iter()
            .map(|k| self.code[k])
            .collect();
        // Last instruction reading each intermediate (outputs: to the end).
        let mut last: Vec<Option<usize>> = vec![None; self.slots_used as usize];
        for (k, p) in pre.iter().enumerate() {
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
        let mut code: Vec<Instr> = Vec::with_capacity(pre.len());
        let mut runs: Vec<(Instruction, u32)> = Vec::new();
        for (k, p) in pre.iter().enumerate() {
            let (a, b, c) = (
                slot(p.a, &slot_of),
                slot(p.b, &slot_of),
                slot(p.c, &slot_of),
            );
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
            code.push(Instr { dst, a, b, c });
            match runs.last_mut() {
                Some((op, end)) if *op == p.op => *end += 1,
                _ => runs.push((p.op, code.len() as u32)),
            }
        }
        let writes = writes
            .into_iter()
            .map(|(r, pos)| (slot(r, &slot_of), pos as u32))
            .collect();
        Tape {
            nq: self.nq,
            params: self.params,
            uses_qd: lowered.inputs() >= Inputs::Velocities,
            uses_qdd: lowered.inputs() >= Inputs::Accelerations,
            literals: self.literals,
            code,
            runs,
            writes,
            id: tape::next_id(),
            index: 0,
            shapes: lowered.shapes.clone(),
            slots,
            #[cfg(feature = "jit")]
            native: Default::default(),
            #[cfg(feature = "jit")]
            native_pairs: Default::default(),
        }
    }
}

/// An order of `code` (indices) in which every instruction comes after
/// those computing its operands, in runs of one operation as long as the
/// dependencies allow: repeatedly, of the instructions whose operands are
/// computed, all those of the operation most of them share (in program
/// order), followed by those of that operation which they make ready, and
/// so on (a chain of products is one run). The tape then dispatches once
/// per run. A run of sines and cosines takes only instructions that are
/// ready together, which are independent of each other (the tape computes
/// them four at a time). Each instruction computes what it computed in
/// program order, so results are bitwise the same.
fn in_runs(code: &[Pre], temps: usize) -> Vec<usize> {
    let mut producer: Vec<usize> = vec![usize::MAX; temps];
    for (k, p) in code.iter().enumerate() {
        for t in p.writes() {
            producer[t as usize] = k;
        }
    }
    let mut waiting: Vec<usize> = vec![0; code.len()];
    let mut users: Vec<Vec<usize>> = vec![Vec::new(); code.len()];
    for (k, p) in code.iter().enumerate() {
        let mut from: Vec<usize> = p.reads().map(|t| producer[t as usize]).collect();
        from.sort_unstable();
        from.dedup();
        waiting[k] = from.len();
        for f in from {
            users[f].push(k);
        }
    }
    let mut ready: HashMap<Instruction, Vec<usize>> = HashMap::new();
    for (k, p) in code.iter().enumerate() {
        if waiting[k] == 0 {
            ready.entry(p.op).or_default().push(k);
        }
    }
    let mut order = Vec::with_capacity(code.len());
    while let Some(op) = ready
        .iter()
        .filter(|(_, ks)| !ks.is_empty())
        .max_by_key(|(_, ks)| (ks.len(), std::cmp::Reverse(ks.iter().min())))
        .map(|(op, _)| *op)
    {
        let mut run = std::mem::take(ready.get_mut(&op).expect("a ready operation"));
        run.sort_unstable();
        let mut next = 0;
        while let Some(&k) = run.get(next) {
            next += 1;
            for &u in &users[k] {
                waiting[u] -= 1;
                if waiting[u] == 0 {
                    if code[u].op == op && op != Instruction::SinCos {
                        run.push(u);
                    } else {
                        ready.entry(code[u].op).or_default().push(u);
                    }
                }
            }
        }
        order.extend(run);
    }
    debug_assert_eq!(order.len(), code.len(), "the program has no cycle");
    order
}
