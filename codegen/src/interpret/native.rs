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

use super::tape::{Instr, Instruction, Tape};
use crate::expr::Func;

/// Tapes longer than this are interpreted: compiling one function grows
/// faster than linearly with its length (register allocation), and a tape
/// this long spends its time in memory either way.
pub(super) const MAX_INSTRUCTIONS: usize = 100_000;

/// Longer tapes get Cranelift's single-pass register allocator: its
/// default (backtracking) allocates better but takes time that grows much
/// faster than the length on one long block (3 s for Baxter's 12,398
/// instructions of `inverse_dynamics_derivatives`, against 0.09 s single
/// pass; 76 ms against 15 ms for its 2,329 of `dynamics_terms`).
const BACKTRACKING_INSTRUCTIONS: usize = 3_000;

/// `fn(q, qd, qdd, t, params, out)`: the caller's slices, checked against
/// the tape's dimensions before the call.
type Entry = unsafe extern "C" fn(*const f64, *const f64, *const f64, f64, *const f64, *mut f64);

/// A tape's machine code and the memory that holds it.
#[derive(Clone)]
pub(super) struct Native {
    entry: Entry,
    /// Owns the code; freed when the last clone of the tape goes.
    _module: Arc<Owner>,
}

impl std::fmt::Debug for Native {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Native")
    }
}

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
            // `Native` entry that holds this owner, which is being dropped.
            unsafe { module.free_memory() };
        }
    }
}

impl Native {
    /// Runs the code. The caller has checked the slices' lengths against
    /// the tape (`q`, `out` always; `qd`, `qdd` where the tape reads them;
    /// `params`).
    pub(super) fn call(
        &self,
        q: &[f64],
        qd: &[f64],
        qdd: &[f64],
        t: f64,
        params: &[f64],
        out: &mut [f64],
    ) {
        // SAFETY: the code reads `q`, `qd`, `qdd` and `params` within the
        // lengths the tape was compiled for, which the caller checked,
        // `qd`/`qdd` only where the tape uses them, and writes each
        // position of `out` below the tape's output length once.
        unsafe {
            (self.entry)(
                q.as_ptr(),
                qd.as_ptr(),
                qdd.as_ptr(),
                t,
                params.as_ptr(),
                out.as_mut_ptr(),
            )
        }
    }
}

extern "C" fn native_sin(x: f64) -> f64 {
    math::sin(x)
}
extern "C" fn native_cos(x: f64) -> f64 {
    math::cos(x)
}
extern "C" fn native_tan(x: f64) -> f64 {
    math::tan(x)
}
extern "C" fn native_exp(x: f64) -> f64 {
    math::exp(x)
}
extern "C" fn native_ln(x: f64) -> f64 {
    math::ln(x)
}
extern "C" fn native_sqrt(x: f64) -> f64 {
    math::sqrt(x)
}
extern "C" fn native_abs(x: f64) -> f64 {
    math::abs(x)
}
extern "C" fn native_sign(x: f64) -> f64 {
    math::sign(x)
}
extern "C" fn native_step(x: f64) -> f64 {
    math::step(x)
}
extern "C" fn native_atan2(y: f64, x: f64) -> f64 {
    math::atan2(y, x)
}

/// Sines and cosines of the four values at `p`, written to `p[0..4]` and
/// `p[4..8]`.
///
/// # Safety
///
/// `p` points to 8 `f64`.
unsafe extern "C" fn native_sin_cos4(p: *mut f64) {
    // SAFETY: the compiled code passes a stack slot of 8 values.
    let p = unsafe { &mut *(p as *mut [f64; 8]) };
    let sc = math::sin_cos_array([p[0], p[1], p[2], p[3]]);
    for (k, (s, c)) in sc.into_iter().enumerate() {
        p[k] = s;
        p[4 + k] = c;
    }
}

/// The runtime functions the code calls, by symbol.
fn unary(f: Func) -> (&'static str, *const u8) {
    match f {
        Func::Sin => ("flexdyn_sin", native_sin as *const u8),
        Func::Cos => ("flexdyn_cos", native_cos as *const u8),
        Func::Tan => ("flexdyn_tan", native_tan as *const u8),
        Func::Exp => ("flexdyn_exp", native_exp as *const u8),
        Func::Ln => ("flexdyn_ln", native_ln as *const u8),
        Func::Sqrt => ("flexdyn_sqrt", native_sqrt as *const u8),
        Func::Abs => ("flexdyn_abs", native_abs as *const u8),
        Func::Sign => ("flexdyn_sign", native_sign as *const u8),
        Func::Step => ("flexdyn_step", native_step as *const u8),
    }
}

const FUNCS: [Func; 9] = [
    Func::Sin,
    Func::Cos,
    Func::Tan,
    Func::Exp,
    Func::Ln,
    Func::Sqrt,
    Func::Abs,
    Func::Sign,
    Func::Step,
];

/// The tape as machine code; `None` where the tape is too long or the
/// backend fails (the tape is then interpreted).
pub(super) fn compile(tape: &Tape) -> Option<Native> {
    if tape.code.len() > MAX_INSTRUCTIONS {
        return None;
    }
    compile_with(tape, tape.code.len() <= BACKTRACKING_INSTRUCTIONS)
}

/// [`compile`] with the backtracking or the single-pass register allocator.
fn compile_with(tape: &Tape, backtracking: bool) -> Option<Native> {
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
    for f in FUNCS {
        let (name, p) = unary(f);
        jb.symbol(name, p);
    }
    jb.symbol("flexdyn_atan2", native_atan2 as *const u8);
    jb.symbol("flexdyn_sin_cos4", native_sin_cos4 as *const u8);
    let mut module = JITModule::new(jb);
    let id = translate(tape, &mut module)?;
    module.finalize_definitions().ok()?;
    let code = module.get_finalized_function(id);
    // SAFETY: `translate` defined this function with `Entry`'s signature
    // (five pointers and one `f64`, the platform's C convention).
    let entry: Entry = unsafe { std::mem::transmute::<*const u8, Entry>(code) };
    Some(Native {
        entry,
        _module: Arc::new(Owner(Mutex::new(Some(module)))),
    })
}

/// The functions the code imports, declared in `module`.
struct Imports {
    unary: Vec<(Func, FuncId)>,
    atan2: FuncId,
    sin_cos4: FuncId,
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
    for f in FUNCS {
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
        sin_cos4: module
            .declare_function("flexdyn_sin_cos4", Linkage::Import, &pointer)
            .ok()?,
    })
}

/// Defines the tape's function in `module`.
fn translate(tape: &Tape, module: &mut JITModule) -> Option<FuncId> {
    let imports = declare(module)?;
    let ptr = module.target_config().pointer_type();
    let mut ctx = module.make_context();
    let params = &mut ctx.func.signature.params;
    params.extend([ptr, ptr, ptr].map(AbiParam::new));
    params.push(AbiParam::new(types::F64));
    params.extend([ptr, ptr].map(AbiParam::new));
    let id = module
        .declare_function("tape", Linkage::Local, &ctx.func.signature)
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
    let sin_cos4 = module.declare_func_in_func(imports.sin_cos4, b.func);
    let pair = b.create_sized_stack_slot(StackSlotData::new(StackSlotKind::ExplicitSlot, 64, 3));

    let nq = tape.nq;
    let literal0 = 3 * nq + 1 + tape.params;
    let temps0 = literal0 + tape.literals.len();
    let flags = MemFlagsData::trusted();
    let mut values: Vec<Option<Value>> = vec![None; tape.slots];
    // The current value of slot `s`: inputs loaded where first read
    // (velocities and accelerations only where the tape says it reads
    // them), literals as constants.
    let read = |s: u32, b: &mut FunctionBuilder, values: &mut Vec<Option<Value>>| {
        let s = s as usize;
        if let Some(v) = *values.get(s)? {
            return Some(v);
        }
        let v = if s >= temps0 {
            return None; // read before written: not a tape the assembler makes
        } else if s >= literal0 {
            b.ins().f64const(tape.literals[s - literal0])
        } else {
            let (base, k) = match s {
                s if s < nq => (q, s),
                s if s < 2 * nq && tape.uses_qd => (qd, s - nq),
                s if s < 2 * nq => return None,
                s if s < 3 * nq && tape.uses_qdd => (qdd, s - 2 * nq),
                s if s < 3 * nq => return None,
                s if s == 3 * nq => {
                    values[s] = Some(t);
                    return Some(t);
                }
                s => (params, s - 3 * nq - 1),
            };
            b.ins()
                .load(types::F64, flags, base, i32::try_from(8 * k).ok()?)
        };
        values[s] = Some(v);
        Some(v)
    };
    let start = std::iter::once(0).chain(tape.runs.iter().map(|&(_, end)| end as usize));
    for (&(op, end), start) in tape.runs.iter().zip(start) {
        let run: &[Instr] = tape.code.get(start..end as usize)?;
        if op == Instruction::SinCos {
            for group in run.chunks(4) {
                // A group of fewer than four repeats its first argument.
                let first = group.first()?.a;
                let p = b.ins().stack_addr(ptr, pair, 0);
                for k in 0..4 {
                    let x = read(group.get(k).map_or(first, |i| i.a), &mut b, &mut values)?;
                    b.ins().store(flags, x, p, 8 * k as i32);
                }
                b.ins().call(sin_cos4, &[p]);
                for (k, i) in group.iter().enumerate() {
                    let sin = b.ins().load(types::F64, flags, p, 8 * k as i32);
                    let cos = b.ins().load(types::F64, flags, p, 32 + 8 * k as i32);
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
                    let call = b.ins().call(*r, &[x]);
                    b.inst_results(call)[0]
                }
                _ => {
                    let y = read(i.b, &mut b, &mut values)?;
                    match op {
                        Instruction::Add => b.ins().fadd(x, y),
                        Instruction::Sub => b.ins().fsub(x, y),
                        Instruction::Mul => b.ins().fmul(x, y),
                        Instruction::Div => b.ins().fdiv(x, y),
                        Instruction::Atan2 => {
                            let call = b.ins().call(atan2, &[x, y]);
                            b.inst_results(call)[0]
                        }
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
        b.ins()
            .store(flags, v, out, i32::try_from(8 * pos as usize).ok()?);
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
    /// compiled (with either register allocator) and interpreted at states
    /// that include values far from zero (the sines' long reduction):
    /// bitwise equal, and compiled.
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
                let native = super::compile_with(tape, backtracking).expect("compiles");
                compiled += 1;
                for k in 0..6 {
                    let x = |i: usize, s: f64| {
                        let v = ((k * 13 + i * 5) as f64 * s).sin() * 1.7;
                        if (i + k) % 5 == 0 {
                            v * 1e7
                        } else {
                            v
                        }
                    };
                    let q: Vec<f64> = (0..nq).map(|i| x(i, 0.37)).collect();
                    let qd: Vec<f64> = (0..nq).map(|i| x(i, 0.91)).collect();
                    let qdd: Vec<f64> = (0..nq).map(|i| x(i, 1.73)).collect();
                    let t = 0.3 * k as f64;
                    let len = tape.output_len();
                    let (mut want, mut got) = (vec![f64::NAN; len], vec![f64::NAN; len]);
                    tape.interpret(&q, &qd, &qdd, t, &params, &mut scratch, &mut want);
                    native.call(&q, &qd, &qdd, t, &params, &mut got);
                    assert!(
                        got.iter()
                            .zip(&want)
                            .all(|(a, b)| a.to_bits() == b.to_bits()),
                        "{name} {} state {k}: {got:?} vs {want:?}",
                        f.name()
                    );
                }
            }
        }
        assert!(compiled > 120, "{compiled} tapes");
    }
}
