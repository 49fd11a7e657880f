//! Bare-metal support for the benchmark firmware on QEMU's `mps2-an386`
//! board (Cortex-M4F): start-up (FPU on, `.data` copied, `.bss` zeroed),
//! output and exit through Arm semihosting, and a deterministic cost meter.
//!
//! **Counting instructions.** The Cortex-M4's cycle counter (DWT) is not
//! emulated by QEMU, and semihosting's clocks (`SYS_CLOCK`, `SYS_ELAPSED`)
//! read the host's clock. With `-icount shift=S`, QEMU's virtual clock instead
//! advances exactly `2^S` ns per executed guest instruction, and the board's
//! CMSDK APB timer 0 (a 32-bit down-counter at 25 MHz, i.e. one tick per
//! 40 ns of virtual time) runs on that clock. So `n` instructions are
//! `n 2^S / 40` timer ticks; with `S = 10` (the runner's setting,
//! [`ICOUNT_SHIFT`]) one instruction is 25.6 ticks and the count is exact
//! after rounding. [`measure`] subtracts the cost of the measurement itself
//! (calibrated on an empty call) and the firmware checks the method on a
//! block of exactly 1000 `nop`s.
//!
//! **Stack.** [`measure`] paints the 64 KiB below the current stack pointer
//! with a pattern before the call and afterwards finds the deepest word that
//! was overwritten: the call's stack high-water mark.

#![no_std]

use core::fmt::{self, Write};
use core::ptr::{read_volatile, write_volatile};

/// The `-icount shift` the firmware must run under (see the module docs).
pub const ICOUNT_SHIFT: u32 = 10;
/// Virtual nanoseconds per tick of the 25 MHz timer.
const NS_PER_TICK: u64 = 40;
/// Bytes painted below the stack pointer by [`measure`].
const PAINTED: usize = 64 * 1024;
const PAINT: u32 = 0x5AA5_C33C;

core::arch::global_asm!(
    r#"
    .section .vectors.reset, "a"
    .word reset
    .word fault
    .word fault
    .word fault
    .word fault
    .word fault

    .section .text.reset, "ax"
    .global reset
    .type reset, %function
    .thumb_func
reset:
    ldr r0, =0xE000ED88
    ldr r1, [r0]
    orr r1, r1, #0xF00000
    str r1, [r0]
    dsb
    isb
    ldr r0, =__data_start
    ldr r1, =__data_end
    ldr r2, =__data_load
.Lcopy:
    cmp r0, r1
    bhs .Lzero_start
    ldr r3, [r2], #4
    str r3, [r0], #4
    b .Lcopy
.Lzero_start:
    ldr r0, =__bss_start
    ldr r1, =__bss_end
    movs r2, #0
.Lzero:
    cmp r0, r1
    bhs .Lmain
    str r2, [r0], #4
    b .Lzero
.Lmain:
    bl main
    b .
    .ltorg

    .section .text.fault, "ax"
    .global fault
    .type fault, %function
    .thumb_func
fault:
    ldr r1, =0x20023
    movs r0, #0x18
    bkpt 0xab
    b .
    .ltorg
"#
);

/// One semihosting call: operation `op` with argument `arg`.
fn semihost(op: u32, arg: u32) -> u32 {
    let r;
    // SAFETY: `bkpt 0xab` is the Arm semihosting trap; QEMU (run with
    // `-semihosting`) handles it and returns in r0.
    unsafe {
        core::arch::asm!("bkpt 0xab", inout("r0") op => r, in("r1") arg, options(nostack));
    }
    r
}

/// Ends the emulation: exit status 0 when `ok`, 1 otherwise.
pub fn exit(ok: bool) -> ! {
    // ADP_Stopped_ApplicationExit / ADP_Stopped_RunTimeErrorUnknown.
    semihost(0x18, if ok { 0x20026 } else { 0x20023 });
    loop {}
}

/// Writes text to the host's standard output (semihosting `SYS_WRITE0`,
/// in pieces of a small buffer).
pub struct Host;

impl Write for Host {
    fn write_str(&mut self, s: &str) -> fmt::Result {
        let mut buf = [0u8; 65];
        for chunk in s.as_bytes().chunks(64) {
            buf[..chunk.len()].copy_from_slice(chunk);
            buf[chunk.len()] = 0;
            semihost(0x04, buf.as_ptr() as u32);
        }
        Ok(())
    }
}

/// Prints one line.
pub fn line(args: fmt::Arguments) {
    let _ = Host.write_fmt(args);
    let _ = Host.write_str("\n");
}

const TIMER0: usize = 0x4000_0000;

/// Starts timer 0 free-running from its largest value.
pub fn start_timer() {
    // SAFETY: the CMSDK APB timer 0 registers of mps2-an386 (CTRL, VALUE,
    // RELOAD at offsets 0, 4, 8).
    unsafe {
        write_volatile((TIMER0 + 8) as *mut u32, u32::MAX);
        write_volatile((TIMER0 + 4) as *mut u32, u32::MAX);
        write_volatile(TIMER0 as *mut u32, 1);
    }
}

#[inline(always)]
fn ticks() -> u32 {
    // SAFETY: timer 0's VALUE register.
    unsafe { read_volatile((TIMER0 + 4) as *const u32) }
}

#[inline(always)]
fn stack_pointer() -> usize {
    let sp: usize;
    // SAFETY: reads sp only.
    unsafe { core::arch::asm!("mov {}, sp", out(reg) sp, options(nomem, nostack)) };
    sp
}

/// Instructions and stack bytes of one call.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Cost {
    /// Instructions executed.
    pub instructions: u32,
    /// Stack high-water mark below the caller's stack pointer, bytes.
    pub stack: u32,
}

/// Runs `f` once and measures it (see the module docs), minus the
/// measurement's own cost `overhead` (the measure of an empty call).
#[inline(never)]
pub fn measure(overhead: Cost, f: &mut dyn FnMut()) -> Cost {
    let sp = stack_pointer();
    let bottom = sp - PAINTED;
    let mut a = bottom;
    while a < sp - 16 {
        // SAFETY: RAM below the stack pointer, unused until `f` runs.
        unsafe { write_volatile(a as *mut u32, PAINT) };
        a += 4;
    }
    let t0 = ticks();
    f();
    let t1 = ticks();
    let mut low = bottom;
    // SAFETY: the same painted RAM.
    while low < sp && unsafe { read_volatile(low as *const u32) } == PAINT {
        low += 4;
    }
    let ns = u64::from(t0.wrapping_sub(t1)) * NS_PER_TICK;
    let instructions = ((ns + (1 << (ICOUNT_SHIFT - 1))) >> ICOUNT_SHIFT) as u32;
    Cost {
        instructions: instructions.saturating_sub(overhead.instructions),
        stack: ((sp - low) as u32).saturating_sub(overhead.stack),
    }
}

/// The cost of measuring nothing, to subtract from every measurement.
pub fn overhead() -> Cost {
    measure(Cost::default(), &mut || {})
}

/// Exactly 1000 `nop` instructions: the check of the counting method.
#[inline(always)]
pub fn thousand_nops() {
    // SAFETY: no operands, no effects.
    unsafe { core::arch::asm!(".rept 1000", "nop", ".endr", options(nomem, nostack)) };
}

#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    line(format_args!("panic"));
    exit(false)
}
