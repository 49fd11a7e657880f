//! A tape compiled to machine code for the processor it runs on (with
//! Cranelift), which [`Tape::eval`] calls in place of running the tape.
//!
//! The tape already fixes every operation and its operands, so compiling it
//! is a translation, one instruction at a time, in the tape's order: each
//! slot's current value is an SSA value of one basic block (a slot written
//! again simply names a new value), inputs are loaded from the caller's
//! slices where they are first read, literals are constants, the outputs are
//! stored to the caller's buffer, and the register allocator keeps values
//! in registers where the interpreter went through memory. Fused
//! instructions stay two operations (product, then sum: the same two
//! roundings), nothing is reassociated, and the calls go to the same
//! `flexdyn_runtime::math` functions (sines and cosines four at a time
//! through `sin_cos_array`, as the interpreter and generated code batch
//! them), so the results are bitwise the interpreter's
//! (`native_code_equals_the_interpreter_bitwise`).
//!
//! Compiling costs 5 to 30 microseconds per instruction, paid on a tape's
//! first evaluation; tapes above [`MAX_INSTRUCTIONS`], and any that the
//! backend refuses (a processor it does not support), are interpreted.

use std::sync::{Arc, Mutex};

use cranelift_codegen::ir::{
    types, AbiParam, InstBuilder, MemFlagsData, Signature, StackSlotData, StackSlotKind,
    UserFuncName, Value,
};
use cranelift_codegen::settings::{self, Configurable};
use cranelift_frontend::{FunctionBuilder, FunctionBuilderContext};
use cranelift_jit::{JITBuilder, JITModule};
use cranelift_module::{FuncId, Linkage, Module};
use flexdyn_runtime::math;

use super::machine::{Entry, Machine, Shape};
use super::tape::{Instr, Instruction, Tape};
use crate::expr::Func;

/// Tapes longer than this are interpreted: compiling one would take more
/// than half a second (about 7 us per instruction with the single-pass
/// register allocator), and a tape this long spends much of its time in
/// memory either way.
const MAX_INSTRUCTIONS: usize = 100_000;

/// Longer tapes get Cranelift's single-pass register allocator: its
/// default (backtracking) allocates better but takes time that grows much
/// faster than the length on one long block (3 s for Baxter's 12,398
/// instructions of `inverse_dynamics_derivatives`, against 0.09 s single
/// pass; 76 ms against 15 ms for its 2,329 of `dynamics_terms`).
const BACKTRACKING_INSTRUCTIONS: usize = 3_000;

/// The JIT module, kept only to free its memory.
struct Owner(Mutex<Option<JITModule>>);

impl Drop for Owner {
    fn drop(&mut self) {
        let module = match self.0.get_mut() {
            Ok(m) => m.take(),
            Err(poisoned) => poisoned.into_inner().take(),
        };
        if let Some(module) = module {
            // SAFETY: the only pointer into this module's code is the
            // `Machine` entry that holds this owner, which is being dropped
            // (none where the code could not be made).
            unsafe { module.free_memory() };
        }
    }
}

extern "C" fn native_atan2(y: f64, x: f64) -> f64 {
    math::atan2(y, x)
}

/// Sines and cosines of the first `N` (at most 4) values at `p`, written
/// to `p[0..N]` and `p[4..4 + N]`.
///
/// # Safety
///
/// `p` points to 8 `f64`, the first `N` initialised.
unsafe extern "C" fn native_sin_cos<const N: usize>(p: *mut f64) {
    // SAFETY: the compiled code passes a stack slot of 8 values, the first
    // `N` stored.
    let p = unsafe { &mut *(p as *mut [f64; 8]) };
    let sc = math::sin_cos_array::<N>(core::array::from_fn(|k| p[k]));
    for (k, (s, c)) in sc.into_iter().enumerate() {
        p[k] = s;
        p[4 + k] = c;
    }
}

/// `unary(f)`: the symbol and the C entry of the runtime function `f`
/// that generated code calls.
macro_rules! unary_entries {
    ($($func:ident => $f:path,)*) => {
        fn unary(f: Func) -> (&'static str, *const u8) {
            match f {
                $(Func::$func => {
                    extern "C" fn entry(x: f64) -> f64 {
                        $f(x)
                    }
                    (concat!("flexdyn_", stringify!($func)), entry as *const u8)
                })*
            }
        }
    };
}

unary_entries! {
    Sin => math::sin,
    Cos => math::cos,
    Tan => math::tan,
    Exp => math::exp,
    Ln => math::ln,
    Sqrt => math::sqrt,
    Abs => math::abs,
    Sign => math::sign,
    Step => math::step,
}

/// The tape as machine code for `lanes` states a call (1 or 2); `None`
/// where the tape is too long or the backend fails (the tape is then
/// interpreted).
pub(super) fn compile(tape: &Tape, lanes: usize) -> Option<Machine> {
    if tape.code.len() > MAX_INSTRUCTIONS {
        return None;
    }
    let backtracking = tape.code.len() <= BACKTRACKING_INSTRUCTIONS;
    // Cranelift reports what it cannot do as errors (an unsupported
    // processor, memory that may not be made executable); a panic inside
    // it would be a bug of its own, and the tape is interpreted then too.
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        compile_with(tape, lanes, backtracking)
    }))
    .ok()
    .flatten()
}

/// [`compile`] with the backtracking or the single-pass register allocator.
fn compile_with(tape: &Tape, lanes: usize, backtracking: bool) -> Option<Machine> {
    let mut flags = settings::builder();
    flags.set("opt_level", "speed").ok()?;
    flags.set("enable_verifier", "false").ok()?;
    if !backtracking {
        flags.set("regalloc_algorithm", "single_pass").ok()?;
    }
    let isa = cranelift_native::builder()
        .ok()?
        .finish(settings::Flags::new(flags))
        .ok()?;
    let mut jb = JITBuilder::with_isa(isa, cranelift_module::default_libcall_names());
    for f in Func::ALL {
        let (name, p) = unary(f);
        jb.symbol(name, p);
    }
    jb.symbol("flexdyn_atan2", native_atan2 as *const u8);
    jb.symbol("flexdyn_sin_cos1", native_sin_cos::<1> as *const u8);
    jb.symbol("flexdyn_sin_cos4", native_sin_cos::<4> as *const u8);
    let mut module = JITModule::new(jb);
    let code = translate(tape, &mut module, lanes).and_then(|id| {
        module.finalize_definitions().ok()?;
        Some(module.get_finalized_function(id))
    });
    // The owner frees the module's memory when it goes: at once if the
    // code could not be made.
    let owner = Arc::new(Owner(Mutex::new(Some(module))));
    let code = code?;
    // SAFETY: `translate` defined this function with `Entry`'s signature
    // (six pointers, the platform's C convention).
    let entry: Entry = unsafe { std::mem::transmute::<*const u8, Entry>(code) };
    let shape = Shape {
        nq: tape.nq,
        uses_qd: tape.uses_qd,
        uses_qdd: tape.uses_qdd,
        params: tape.params,
        outputs: tape.output_len(),
    };
    // SAFETY: the code reads and writes within `shape` for `lanes` states.
    Some(unsafe { Machine::new(entry, lanes, shape, owner) })
}

/// The functions the code imports, declared in `module`.
struct Imports {
    unary: Vec<(Func, FuncId)>,
    atan2: FuncId,
    /// Sines and cosines of one value, and of four.
    sin_cos: [FuncId; 2],
}

fn declare(module: &mut JITModule) -> Option<Imports> {
    let ptr = module.target_config().pointer_type();
    let sig = |params: &[types::Type], returns: &[types::Type], module: &JITModule| {
        let mut s: Signature = module.make_signature();
        s.params.extend(params.iter().map(|&t| AbiParam::new(t)));
        s.returns.extend(returns.iter().map(|&t| AbiParam::new(t)));
        s
    };
    let f64x1 = sig(&[types::F64], &[types::F64], module);
    let f64x2 = sig(&[types::F64, types::F64], &[types::F64], module);
    let pointer = sig(&[ptr], &[], module);
    let mut unary_ids = Vec::new();
    for f in Func::ALL {
        let id = module
            .declare_function(unary(f).0, Linkage::Import, &f64x1)
            .ok()?;
        unary_ids.push((f, id));
    }
    Some(Imports {
        unary: unary_ids,
        atan2: module
            .declare_function("flexdyn_atan2", Linkage::Import, &f64x2)
            .ok()?,
        sin_cos: [
            module
                .declare_function("flexdyn_sin_cos1", Linkage::Import, &pointer)
                .ok()?,
            module
                .declare_function("flexdyn_sin_cos4", Linkage::Import, &pointer)
                .ok()?,
        ],
    })
}

/// Defines the tape's function in `module` over `lanes` states side by
/// side (1, or 2 in `f64x2` vectors: the same IEEE operations lane by
/// lane): the slices hold `lanes` states one after the other, `t` one
/// time per state.
fn translate(tape: &Tape, module: &mut JITModule, lanes: usize) -> Option<FuncId> {
    let imports = declare(module)?;
    let ptr = module.target_config().pointer_type();
    let mut ctx = module.make_context();
    ctx.func
        .signature
        .params
        .extend([ptr; 6].map(AbiParam::new));
    let id = module
        .declare_anonymous_function(&ctx.func.signature)
        .ok()?;
    ctx.func.name = UserFuncName::user(0, id.as_u32());
    let mut fbc = FunctionBuilderContext::new();
    let mut b = FunctionBuilder::new(&mut ctx.func, &mut fbc);
    let block = b.create_block();
    b.append_block_params_for_function_params(block);
    b.switch_to_block(block);
    b.seal_block(block);
    let args = b.block_params(block).to_vec();
    let [q, qd, qdd, t, params, out] = args[..] else {
        return None;
    };
    let unary_refs: Vec<(Func, _)> = imports
        .unary
        .iter()
        .map(|&(f, id)| (f, module.declare_func_in_func(id, b.func)))
        .collect();
    let atan2 = module.declare_func_in_func(imports.atan2, b.func);
    let sin_cos = imports
        .sin_cos
        .map(|id| module.declare_func_in_func(id, b.func));
    let buffer = b.create_sized_stack_slot(StackSlotData::new(StackSlotKind::ExplicitSlot, 64, 3));

    let nq = tape.nq;
    let len = tape.output_len();
    let literal0 = 3 * nq + 1 + tape.params;
    let temps0 = literal0 + tape.literals.len();
    let flags = MemFlagsData::trusted();
    let vector = match lanes {
        1 => types::F64,
        2 => types::F64X2,
        _ => return None,
    };
    let offset = |k: usize| i32::try_from(8 * k).ok();
    // A value's lanes, and lanes as a value.
    let split = |v: Value, b: &mut FunctionBuilder| -> Vec<Value> {
        if lanes == 1 {
            return vec![v];
        }
        (0..lanes as u8)
            .map(|l| b.ins().extractlane(v, l))
            .collect()
    };
    // (The same value in every lane is a splat.)
    let join = |x: &[Value], b: &mut FunctionBuilder| -> Value {
        if lanes == 1 {
            return x[0];
        }
        if x.iter().all(|&v| v == x[0]) {
            return b.ins().splat(vector, x[0]);
        }
        let mut v = b.ins().scalar_to_vector(vector, x[0]);
        for (l, &x) in x.iter().enumerate().skip(1) {
            v = b.ins().insertlane(v, x, l as u8);
        }
        v
    };
    let mut values: Vec<Option<Value>> = vec![None; tape.slots];
    // The current value of slot `s`: inputs loaded where first read
    // (velocities and accelerations only where the tape says it reads
    // them; each lane's state `stride` values after the last), runtime
    // parameters and literals the same in every lane.
    let read = |s: u32, b: &mut FunctionBuilder, values: &mut Vec<Option<Value>>| {
        let s = s as usize;
        if let Some(v) = *values.get(s)? {
            return Some(v);
        }
        let v = if s >= temps0 {
            return None; // read before written: not a tape the assembler makes
        } else if s >= literal0 {
            let c = b.ins().f64const(tape.literals[s - literal0]);
            join(&[c; 2][..lanes], b)
        } else if s > 3 * nq {
            let p = b
                .ins()
                .load(types::F64, flags, params, offset(s - 3 * nq - 1)?);
            join(&[p; 2][..lanes], b)
        } else {
            let (base, k, stride) = match s {
                s if s < nq => (q, s, nq),
                s if s < 2 * nq && tape.uses_qd => (qd, s - nq, nq),
                s if s < 2 * nq => return None,
                s if s < 3 * nq && tape.uses_qdd => (qdd, s - 2 * nq, nq),
                s if s < 3 * nq => return None,
                _ => (t, 0, 1),
            };
            let x = (0..lanes)
                .map(|l| {
                    Some(
                        b.ins()
                            .load(types::F64, flags, base, offset(k + l * stride)?),
                    )
                })
                .collect::<Option<Vec<Value>>>()?;
            join(&x, b)
        };
        values[s] = Some(v);
        Some(v)
    };
    // `f` of each lane of `x` (and `y`), by calls.
    let call = |f: cranelift_codegen::ir::FuncRef, x: &[Value], b: &mut FunctionBuilder| {
        let x: Vec<Vec<Value>> = x.iter().map(|&v| split(v, b)).collect();
        let r: Vec<Value> = (0..lanes)
            .map(|l| {
                let args: Vec<Value> = x.iter().map(|v| v[l]).collect();
                let c = b.ins().call(f, &args);
                b.inst_results(c)[0]
            })
            .collect();
        join(&r, b)
    };
    let start = std::iter::once(0).chain(tape.runs.iter().map(|&(_, end)| end as usize));
    for (&(op, end), start) in tape.runs.iter().zip(start) {
        let run: &[Instr] = tape.code.get(start..end as usize)?;
        if op == Instruction::SinCos {
            for group in run.chunks(4 / lanes) {
                // Their arguments' lanes: one value alone, two or three as
                // four (the last repeated).
                let mut x = Vec::new();
                for i in group {
                    let v = read(i.a, &mut b, &mut values)?;
                    x.extend(split(v, &mut b));
                }
                let width = if x.len() == 1 { 1 } else { 4 };
                let p = b.ins().stack_addr(ptr, buffer, 0);
                for k in 0..width {
                    let v = *x.get(k).or(x.last())?;
                    b.ins().store(flags, v, p, offset(k)?);
                }
                b.ins().call(sin_cos[width / 4], &[p]);
                for (k, i) in group.iter().enumerate() {
                    let result = |at: usize, b: &mut FunctionBuilder| {
                        let x = (0..lanes)
                            .map(|l| {
                                Some(b.ins().load(
                                    types::F64,
                                    flags,
                                    p,
                                    offset(at + k * lanes + l)?,
                                ))
                            })
                            .collect::<Option<Vec<Value>>>()?;
                        Some(join(&x, b))
                    };
                    let (sin, cos) = (result(0, &mut b)?, result(4, &mut b)?);
                    *values.get_mut(i.dst as usize)? = Some(sin);
                    *values.get_mut(i.b as usize)? = Some(cos);
                }
            }
            continue;
        }
        for i in run {
            let x = read(i.a, &mut b, &mut values)?;
            let v = match op {
                Instruction::Neg => b.ins().fneg(x),
                Instruction::Call(f) => {
                    let (_, r) = unary_refs.iter().find(|(g, _)| *g == f)?;
                    call(*r, &[x], &mut b)
                }
                _ => {
                    let y = read(i.b, &mut b, &mut values)?;
                    match op {
                        Instruction::Add => b.ins().fadd(x, y),
                        Instruction::Sub => b.ins().fsub(x, y),
                        Instruction::Mul => b.ins().fmul(x, y),
                        Instruction::Div => b.ins().fdiv(x, y),
                        Instruction::Atan2 => call(atan2, &[x, y], &mut b),
                        Instruction::MulAdd | Instruction::SubMul | Instruction::MulSub => {
                            let z = read(i.c, &mut b, &mut values)?;
                            let p = b.ins().fmul(x, y);
                            match op {
                                Instruction::MulAdd => b.ins().fadd(z, p),
                                Instruction::SubMul => b.ins().fsub(z, p),
                                _ => b.ins().fsub(p, z),
                            }
                        }
                        _ => return None,
                    }
                }
            };
            *values.get_mut(i.dst as usize)? = Some(v);
        }
    }
    for &(slot, pos) in &tape.writes {
        let v = read(slot, &mut b, &mut values)?;
        for (l, x) in split(v, &mut b).into_iter().enumerate() {
            b.ins()
                .store(flags, x, out, offset(l * len + pos as usize)?);
        }
    }
    b.ins().return_(&[]);
    b.finalize(module.target_config());
    module.define_function(id, &mut ctx).ok()?;
    module.clear_context(&mut ctx);
    Some(id)
}

#[cfg(test)]
mod tests {
    use super::super::{Interpreted, Scratch};
    use std::path::Path;

    /// Every tape of scenes with constraints, time, markers, runtime
    /// parameters, flexible links, derivatives and every math function,
    /// compiled (with either register allocator, for one state and for
    /// two side by side) and interpreted at states that include values far
    /// from zero (the sines' long reduction): bitwise equal, and compiled.
    #[test]
    fn native_code_equals_the_interpreter_bitwise() {
        let scenes = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
        let mut compiled = 0;
        for name in [
            "four_bar",
            "spin_up_beam",
            "cart_pole",
            "ur5",
            "slider_crank",
            "pendulum",
        ] {
            let it = Interpreted::load(&scenes.join(format!("{name}.toml"))).unwrap();
            let nq = it.nq();
            let params: Vec<f64> = it.parameters().iter().map(|(_, v)| v * 1.3).collect();
            let mut scratch = Scratch::default();
            for ((f, _, tape), backtracking) in
                it.tapes.iter().flat_map(|t| [(t, true), (t, false)])
            {
                let one = super::compile_with(tape, 1, backtracking).expect("compiles");
                let two = super::compile_with(tape, 2, backtracking).expect("compiles");
                compiled += 1;
                let len = tape.output_len();
                let mut pair = vec![f64::NAN; 2 * len];
                let mut previous: Option<(Vec<f64>, [Vec<f64>; 3], f64)> = None;
                for k in 0..6 {
                    let x = |i: usize, s: f64| {
                        let v = ((k * 13 + i * 5) as f64 * s).sin() * 1.7;
                        if (i + k).is_multiple_of(5) {
                            v * 1e7
                        } else {
                            v
                        }
                    };
                    let q: Vec<f64> = (0..nq).map(|i| x(i, 0.37)).collect();
                    let qd: Vec<f64> = (0..nq).map(|i| x(i, 0.91)).collect();
                    let qdd: Vec<f64> = (0..nq).map(|i| x(i, 1.73)).collect();
                    let t = 0.3 * k as f64;
                    let (mut want, mut got) = (vec![f64::NAN; len], vec![f64::NAN; len]);
                    tape.interpret(&q, &qd, &qdd, t, &params, &mut scratch, &mut want);
                    one.call(&q, &qd, &qdd, &[t], &params, &mut got);
                    let same = |a: &[f64], b: &[f64]| {
                        a.iter().zip(b).all(|(a, b)| a.to_bits() == b.to_bits())
                    };
                    assert!(
                        same(&got, &want),
                        "{name} {} state {k}: {got:?} vs {want:?}",
                        f.name()
                    );
                    // This state and the previous one side by side.
                    if let Some((before, [q0, qd0, qdd0], t0)) = previous.take() {
                        let both = |a: &[f64], b: &[f64]| [a, b].concat();
                        two.call(
                            &both(&q0, &q),
                            &both(&qd0, &qd),
                            &both(&qdd0, &qdd),
                            &[t0, t],
                            &params,
                            &mut pair,
                        );
                        assert!(
                            same(&pair, &both(&before, &want)),
                            "{name} {} states {k} and before, two at a time",
                            f.name()
                        );
                    }
                    previous = Some((want, [q, qd, qdd], t));
                }
            }
        }
        assert!(compiled > 120, "{compiled} tapes");
    }
}
