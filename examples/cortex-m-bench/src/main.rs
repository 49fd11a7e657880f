//! Builds the firmware, runs it on QEMU and prints its counts as the rows of
//! the table in docs/benchmarks.md (after the line naming the compiler), with
//! the flash and RAM of each program.

use flexdyn_cortex_m_bench::{
    build, flash_and_ram, parse_bench, qemu, Toolchain, RECORDED_COMPILER, RECORDED_HEADER,
};

fn main() -> Result<(), String> {
    let tc = Toolchain::find()?;
    let dir = build(&tc)?;
    let bench = parse_bench(&qemu(&dir.join("bench"))?)?;
    println!("{RECORDED_COMPILER}`{}`.\n", tc.version()?);
    println!("{RECORDED_HEADER}\n|---|---:|---:|");
    for m in &bench.counts {
        println!("| `{}` | {} | {} |", m.name, m.instructions, m.stack);
    }
    println!();
    for program in ["bench", "terms", "panic_control"] {
        let (flash, ram) = flash_and_ram(&dir.join(program))?;
        println!("{program}: flash {flash} bytes, static RAM {ram} bytes");
    }
    Ok(())
}
