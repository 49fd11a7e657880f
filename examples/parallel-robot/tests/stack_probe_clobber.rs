//! Guards against an LLVM x86-64 miscompile that once corrupted the padded
//! flexible robot's inverse dynamics (see `project_finite` in the runtime's
//! projection module): when shrink-wrapping moves a prologue with an inline
//! stack-probe loop (`mov r11, rsp; sub r11, SIZE; ...`) after code that
//! already holds a live value in `r11`, the probe loop overwrites it.
//!
//! The test disassembles its own executable (which holds the flexible
//! robot's fixed-size instances of the runtime's solvers, through the
//! example's study, and the command line's run-time-size ones) with
//! `objdump` and fails on any function where such a probe loop follows a
//! write of `r11` and `r11` is read after the loop before being written
//! again. `FLEXDYN_SCAN_BINARY` scans another executable instead (e.g. a
//! build from before the workaround, where it finds the projection's
//! instances).

use std::process::Command;

/// Destination and source operands of an Intel-syntax instruction.
fn operands(ins: &str) -> (&str, &str, &str) {
    let (op, args) = ins.split_once(char::is_whitespace).unwrap_or((ins, ""));
    let (dst, src) = args.split_once(',').unwrap_or((args, ""));
    (op, dst.trim(), src.trim())
}

fn is_r11(operand: &str) -> bool {
    operand == "r11" || operand == "r11d"
}

/// Whether a probe loop in `body` follows a write of `r11` that is read
/// after the loop.
fn clobbers_r11(body: &[&str]) -> bool {
    for (k, w) in body.windows(2).enumerate() {
        if w[0] != "mov    r11,rsp" || !w[1].starts_with("sub    r11,") {
            continue;
        }
        let written_before = body[..k].iter().any(|ins| {
            let (op, dst, _) = operands(ins);
            is_r11(dst) && op != "cmp" && op != "test"
        });
        if !written_before {
            continue;
        }
        let after = &body[k + 2..];
        let loop_end = after
            .iter()
            .position(|i| i.starts_with("jne"))
            .map_or(0, |p| p + 1);
        for ins in &after[loop_end..] {
            let (op, dst, src) = operands(ins);
            if src.contains("r11")
                || (dst.contains("r11")
                    && (dst.contains('[') || !op.starts_with("mov") && op != "lea"))
            {
                return true;
            }
            if is_r11(dst) {
                break;
            }
        }
    }
    false
}

#[test]
fn no_stack_probe_overwrites_a_live_r11() {
    if !cfg!(target_arch = "x86_64") {
        return;
    }
    let binary = std::env::var_os("FLEXDYN_SCAN_BINARY")
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| std::env::current_exe().unwrap());
    // Keep the robot's fixed-size solvers (the flexible robot's 39
    // coordinates: frames of tens of KiB, with inline stack probes) and the
    // generic inverse command in this executable.
    type Study = fn(
        &flexdyn_parallel_robot::report::Study,
        &mut dyn FnMut(&str),
    ) -> Result<flexdyn_parallel_robot::report::Results, String>;
    std::hint::black_box(flexdyn_parallel_robot::report::run as Study);
    type Run = fn(&flexdyn::cli::inverse::Args, &flexdyn::compiled::Compiled) -> Result<(), String>;
    std::hint::black_box(flexdyn::cli::inverse::run as Run);
    let out = Command::new("objdump")
        .args(["-d", "-M", "intel", "--no-show-raw-insn"])
        .arg(&binary)
        .output()
        .expect("objdump (binutils) is needed to disassemble the test executable");
    assert!(
        out.status.success(),
        "objdump failed on {}",
        binary.display()
    );
    let text = String::from_utf8_lossy(&out.stdout);
    let (mut functions, mut probes, mut bad) = (0, 0, Vec::new());
    let mut name = "";
    let mut body: Vec<&str> = Vec::new();
    let mut finish = |name: &str, body: &[&str]| {
        functions += 1;
        probes += body.iter().filter(|i| **i == "mov    r11,rsp").count();
        if clobbers_r11(body) {
            bad.push(name.to_owned());
        }
    };
    for line in text.lines() {
        if let Some(header) = line.strip_suffix(">:") {
            finish(name, &body);
            name = header.split_once('<').map_or(header, |(_, n)| n);
            body.clear();
        } else if let Some((_, ins)) = line.split_once(":\t") {
            body.push(ins.trim());
        }
    }
    finish(name, &body);
    println!(
        "{}: {functions} functions, {probes} inline stack probes",
        binary.display()
    );
    assert!(
        probes > 0,
        "no inline stack probe found: the scan sees nothing"
    );
    assert!(
        bad.is_empty(),
        "inline stack probes overwrite a live r11 in {} functions: {:#?}",
        bad.len(),
        bad
    );
}
