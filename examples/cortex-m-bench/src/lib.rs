//! Host side of the Cortex-M4F firmware in `firmware/`: finds the
//! cross toolchain, builds the firmware for `thumbv7em-none-eabihf` (no
//! `std`, no allocator, `core` built from source), runs it on QEMU's
//! `mps2-an386` board with `-icount` so that its counts are instructions, and
//! reads its symbols and sizes with the `arm-none-eabi` binutils.
//!
//! The firmware's programs: `bench` (instructions and stack per call, see
//! `firmware/src/lib.rs` for how they are counted), `terms` (every generated
//! function of the rigid robot and of the spin-up beam, nothing else: the
//! panic check) and `panic_control` (a program that can panic: the control
//! of that check).

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

/// What to install when the toolchain is missing.
pub const INSTALL: &str = "install it with `apt-get install rustc-web cargo-web rust-web-src \
     binutils-arm-none-eabi qemu-system-arm` (Debian 12; what .ci/run does), or point \
     FLEXDYN_THUMB_CARGO and FLEXDYN_THUMB_RUSTC at a cargo and rustc whose sysroot has the \
     standard library's sources (rustup: `rustup component add rust-src`) with the \
     arm-none-eabi binutils and qemu-system-arm on PATH; to run the rest of the test suite \
     without it: `cargo test --workspace --release --exclude flexdyn-cortex-m-bench`";

/// QEMU's options before the program: the Cortex-M4F board, semihosting
/// output on stdout (by default it goes to stderr when stdout is not a
/// terminal), no other devices on the terminal, and the virtual clock
/// advancing `2^10` ns per instruction (the firmware's `ICOUNT_SHIFT`). The
/// firmware's .cargo/config.toml runs it the same way (`cargo run`).
const QEMU_ARGS: [&str; 15] = [
    "-M",
    "mps2-an386",
    "-display",
    "none",
    "-serial",
    "none",
    "-monitor",
    "none",
    "-chardev",
    "stdio,id=out,signal=off",
    "-semihosting-config",
    "enable=on,target=native,chardev=out",
    "-icount",
    "shift=10",
    "-kernel",
];

/// Longest accepted run of one firmware program on QEMU.
const QEMU_LIMIT: Duration = Duration::from_secs(120);

/// The cross toolchain.
#[derive(Debug, Clone)]
pub struct Toolchain {
    /// cargo.
    pub cargo: PathBuf,
    /// rustc (its sysroot holds the standard library's sources).
    pub rustc: PathBuf,
}

fn run_tool(cmd: &mut Command) -> Result<Output, String> {
    cmd.output()
        .map_err(|e| format!("cannot run {:?}: {e}", cmd.get_program()))
}

impl Toolchain {
    /// `FLEXDYN_THUMB_CARGO` / `FLEXDYN_THUMB_RUSTC`, by default Debian's
    /// `cargo-web` and `rustc-web` (`/usr/bin/cargo`, `/usr/bin/rustc`); an
    /// error that says what is missing and how to install it.
    pub fn find() -> Result<Toolchain, String> {
        let pick = |var: &str, default: &str| {
            std::env::var_os(var).map_or_else(|| PathBuf::from(default), PathBuf::from)
        };
        let tc = Toolchain {
            cargo: pick("FLEXDYN_THUMB_CARGO", "/usr/bin/cargo"),
            rustc: pick("FLEXDYN_THUMB_RUSTC", "/usr/bin/rustc"),
        };
        let missing =
            |what: String| format!("the Cortex-M toolchain is missing: {what}; {INSTALL}");
        for tool in [&tc.cargo, &tc.rustc] {
            if !run_tool(Command::new(tool).arg("--version")).is_ok_and(|o| o.status.success()) {
                return Err(missing(format!("{} does not run", tool.display())));
            }
        }
        let sysroot = run_tool(Command::new(&tc.rustc).args(["--print", "sysroot"]))?;
        let sysroot = PathBuf::from(String::from_utf8_lossy(&sysroot.stdout).trim());
        let core = sysroot.join("lib/rustlib/src/rust/library/core");
        if !core.is_dir() {
            return Err(missing(format!(
                "{} has no standard library sources ({} does not exist)",
                tc.rustc.display(),
                core.display()
            )));
        }
        for tool in [
            "arm-none-eabi-ld",
            "arm-none-eabi-nm",
            "arm-none-eabi-size",
            "qemu-system-arm",
        ] {
            if !run_tool(Command::new(tool).arg("--version")).is_ok_and(|o| o.status.success()) {
                return Err(missing(format!("`{tool}` is not on PATH")));
            }
        }
        Ok(tc)
    }

    /// `rustc --version` of the cross compiler (what the recorded counts
    /// are compared against: see [`Allowance`]).
    pub fn version(&self) -> Result<String, String> {
        let out = run_tool(Command::new(&self.rustc).arg("--version"))?;
        if !out.status.success() {
            return Err(format!("{} --version failed", self.rustc.display()));
        }
        Ok(String::from_utf8_lossy(&out.stdout).trim().to_owned())
    }
}

/// The workspace root.
pub fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .nth(2)
        .expect("the crate lies two levels below the workspace root")
        .to_path_buf()
}

/// Builds the firmware's programs (release profile) into
/// `target/cortex-m-firmware` of the workspace; the folder that holds them.
pub fn build(tc: &Toolchain) -> Result<PathBuf, String> {
    let firmware = Path::new(env!("CARGO_MANIFEST_DIR")).join("firmware");
    let target = workspace().join("target").join("cortex-m-firmware");
    let out = run_tool(
        Command::new(&tc.cargo)
            .args(["build", "--release", "--bins"])
            // The firmware's .cargo/config.toml (target, linker, build-std)
            // is found from the working directory.
            .current_dir(&firmware)
            .env("RUSTC_BOOTSTRAP", "1")
            .env("RUSTC", &tc.rustc)
            .env("CARGO_TARGET_DIR", &target)
            .env_remove("RUSTFLAGS")
            .env_remove("CARGO_ENCODED_RUSTFLAGS")
            .env_remove("CARGO_BUILD_TARGET")
            .env_remove("RUSTUP_TOOLCHAIN"),
    )?;
    if !out.status.success() {
        return Err(format!(
            "the firmware ({}) does not build for thumbv7em-none-eabihf:\n{}",
            firmware.display(),
            String::from_utf8_lossy(&out.stderr)
        ));
    }
    Ok(target.join("thumbv7em-none-eabihf").join("release"))
}

/// One symbol of a linked program.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Symbol {
    /// Demangled name.
    pub name: String,
    /// Size, bytes (0 when unknown).
    pub size: u64,
}

/// The symbols of `elf` (`arm-none-eabi-nm --demangle --print-size`).
pub fn symbols(elf: &Path) -> Result<Vec<Symbol>, String> {
    let out = run_tool(Command::new("arm-none-eabi-nm").args(["-C", "-S"]).arg(elf))?;
    if !out.status.success() {
        return Err(format!(
            "arm-none-eabi-nm {}: {}",
            elf.display(),
            String::from_utf8_lossy(&out.stderr)
        ));
    }
    Ok(String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| {
            // `ADDR [SIZE] TYPE NAME`; the name may contain spaces.
            let mut f = l.splitn(4, ' ');
            let _addr = f.next()?;
            let second = f.next()?;
            let third = f.next()?;
            match f.next() {
                Some(name) if third.len() == 1 => Some(Symbol {
                    name: name.to_owned(),
                    size: u64::from_str_radix(second, 16).ok()?,
                }),
                _ => {
                    let name = l.splitn(3, ' ').nth(2)?;
                    Some(Symbol {
                        name: name.to_owned(),
                        size: 0,
                    })
                }
            }
        })
        .collect())
}

/// The symbols of `elf` that belong to Rust's panic machinery.
pub fn panic_symbols(elf: &Path) -> Result<Vec<String>, String> {
    const PANIC: [&str; 7] = [
        "core::panicking",
        "panic_bounds_check",
        "rust_begin_unwind",
        "panic_fmt",
        "slice_index",
        "unwrap_failed",
        "expect_failed",
    ];
    Ok(symbols(elf)?
        .into_iter()
        .map(|s| s.name)
        .filter(|n| PANIC.iter().any(|p| n.contains(p)))
        .collect())
}

/// Flash (`.text` + `.rodata` + `.data` initialisers) and RAM (`.data` +
/// `.bss`) bytes of `elf`, from `arm-none-eabi-size`.
pub fn flash_and_ram(elf: &Path) -> Result<(u64, u64), String> {
    let out = run_tool(Command::new("arm-none-eabi-size").arg(elf))?;
    let text = String::from_utf8_lossy(&out.stdout);
    let numbers: Vec<u64> = text
        .lines()
        .nth(1)
        .unwrap_or("")
        .split_whitespace()
        .take(3)
        .filter_map(|n| n.parse().ok())
        .collect();
    match numbers[..] {
        [text, data, bss] => Ok((text + data, data + bss)),
        _ => Err(format!("unexpected arm-none-eabi-size output:\n{text}")),
    }
}

/// Instructions and stack of one measured call.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Measurement {
    /// What was measured (`rigid.mass_matrix`, `inverse_dynamics.mean`, ...).
    pub name: String,
    /// Instructions executed.
    pub instructions: u64,
    /// Stack high-water mark, bytes.
    pub stack: u64,
}

/// What the `bench` program reports.
#[derive(Debug, Clone, PartialEq)]
pub struct Bench {
    /// The measurements, in the firmware's order (the `nop1000` check first).
    pub counts: Vec<Measurement>,
    /// Time of the last inverse-dynamics call.
    pub t: f64,
    /// Its actuator torques.
    pub tau: Vec<f64>,
    /// The actuator torques of the last f32 inverse-dynamics call.
    pub tau_f32: Vec<f32>,
}

/// Runs `elf` on QEMU's mps2-an386 (Cortex-M4F) with semihosting and
/// instruction counting; its standard output, or an error when it fails,
/// exits with an error status or runs too long.
pub fn qemu(elf: &Path) -> Result<String, String> {
    let mut child = Command::new("qemu-system-arm")
        .args(QEMU_ARGS)
        .arg(elf)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| format!("cannot run qemu-system-arm: {e}"))?;
    let start = Instant::now();
    loop {
        match child.try_wait().map_err(|e| e.to_string())? {
            Some(_) => break,
            None if start.elapsed() > QEMU_LIMIT => {
                let _ = child.kill();
                return Err(format!(
                    "{} ran for more than {QEMU_LIMIT:?} on QEMU",
                    elf.display()
                ));
            }
            None => std::thread::sleep(Duration::from_millis(20)),
        }
    }
    let out = child.wait_with_output().map_err(|e| e.to_string())?;
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    if !out.status.success() {
        return Err(format!(
            "{} failed on QEMU ({}):\n{stdout}\n{}",
            elf.display(),
            out.status,
            String::from_utf8_lossy(&out.stderr)
        ));
    }
    Ok(stdout)
}

fn hex_f64(s: &str) -> Option<f64> {
    u64::from_str_radix(s, 16).ok().map(f64::from_bits)
}

/// Parses the output of the `bench` program.
pub fn parse_bench(stdout: &str) -> Result<Bench, String> {
    let bad = |l: &str| format!("unexpected line `{l}` in the firmware's output:\n{stdout}");
    let mut bench = Bench {
        counts: Vec::new(),
        t: f64::NAN,
        tau: Vec::new(),
        tau_f32: Vec::new(),
    };
    let mut done = false;
    for l in stdout.lines().map(str::trim).filter(|l| !l.is_empty()) {
        let f: Vec<&str> = l.split_whitespace().collect();
        match f[..] {
            ["count", name, ins, stack] => bench.counts.push(Measurement {
                name: name.to_owned(),
                instructions: ins.parse().map_err(|_| bad(l))?,
                stack: stack.parse().map_err(|_| bad(l))?,
            }),
            ["t", bits] => bench.t = hex_f64(bits).ok_or_else(|| bad(l))?,
            ["tau", _, bits] => bench.tau.push(hex_f64(bits).ok_or_else(|| bad(l))?),
            ["tau_f32", _, bits] => bench.tau_f32.push(
                u32::from_str_radix(bits, 16)
                    .map(f32::from_bits)
                    .map_err(|_| bad(l))?,
            ),
            ["done"] => done = true,
            _ => return Err(bad(l)),
        }
    }
    if !done {
        return Err(format!("the firmware did not finish:\n{stdout}"));
    }
    Ok(bench)
}

/// The header of the table of recorded counts in docs/benchmarks.md.
pub const RECORDED_HEADER: &str = "| firmware measurement | instructions | stack (bytes) |";

/// The line of docs/benchmarks.md that names the compiler of the recorded
/// counts: this prefix, then `rustc --version` in backquotes.
pub const RECORDED_COMPILER: &str = "Compiler of the recorded counts: ";

/// The compiler named in `markdown` (docs/benchmarks.md) under
/// [`RECORDED_COMPILER`].
pub fn recorded_compiler(markdown: &str) -> Result<String, String> {
    markdown
        .lines()
        .find_map(|l| l.trim().strip_prefix(RECORDED_COMPILER))
        .map(|rest| {
            rest.trim()
                .trim_end_matches('.')
                .trim_matches('`')
                .to_owned()
        })
        .filter(|v| !v.is_empty())
        .ok_or_else(|| format!("no line starting `{RECORDED_COMPILER}` names the compiler"))
}

/// How far a measured count may exceed its recorded figure.
///
/// Instruction counts are deterministic for one compiler build, so with the
/// compiler that recorded the table the bound is tight (10 %). Another
/// compiler build (a newer Debian `rustc-web`, which a machine set up later
/// gets: the archive serves only the newest) inlines and allocates stack
/// slots differently; with it the bound is 25 %. Small stacks move by whole
/// spill slots (84 to 96 bytes between Rust 1.85 and 1.96), so a stack
/// depth may also grow by a fixed number of bytes. Either way a change that
/// doubles a function's instructions or stack fails (tested for every
/// recorded row).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Allowance {
    /// Largest ratio of measured to recorded instructions and stack.
    pub growth: f64,
    /// Stack bytes a depth may grow by whatever its ratio.
    pub stack_bytes: u64,
}

impl Allowance {
    /// The allowance with the recording compiler (`same`) or another one.
    pub fn for_compiler(same: bool) -> Allowance {
        if same {
            Allowance {
                growth: 1.10,
                stack_bytes: 32,
            }
        } else {
            Allowance {
                growth: 1.25,
                stack_bytes: 64,
            }
        }
    }

    /// The largest instruction count and stack depth accepted for `r`.
    pub fn limits(&self, r: &Measurement) -> (u64, u64) {
        let grown = |x: u64| (self.growth * x as f64).floor() as u64;
        (
            grown(r.instructions),
            grown(r.stack).max(r.stack + self.stack_bytes),
        )
    }

    /// What of `m` exceeds its recorded figure `r`, one line each.
    pub fn exceeded(&self, m: &Measurement, r: &Measurement) -> Vec<String> {
        let (ins, stack) = self.limits(r);
        let mut out = Vec::new();
        if m.instructions > ins {
            out.push(format!(
                "{} instructions: {}, recorded {}, limit {ins}",
                m.name, m.instructions, r.instructions
            ));
        }
        if m.stack > stack {
            out.push(format!(
                "{} stack: {} bytes, recorded {}, limit {stack}",
                m.name, m.stack, r.stack
            ));
        }
        out
    }
}

/// The counts recorded in `markdown` (docs/benchmarks.md): the rows of the
/// table under [`RECORDED_HEADER`], `` | `name` | 45,730 | 1,388 | ``.
pub fn recorded(markdown: &str) -> Result<Vec<Measurement>, String> {
    let mut lines = markdown.lines().skip_while(|l| l.trim() != RECORDED_HEADER);
    if lines.next().is_none() {
        return Err(format!("no table headed `{RECORDED_HEADER}`"));
    }
    let number = |cell: &str, line: &str| {
        let digits: String = cell.chars().filter(char::is_ascii_digit).collect();
        digits
            .parse::<u64>()
            .map_err(|_| format!("not a number in `{line}`"))
    };
    lines
        .skip(1) // |---|---|---|
        .take_while(|l| l.trim_start().starts_with('|'))
        .map(|l| {
            let cells: Vec<&str> = l.split('|').map(str::trim).collect();
            match cells[..] {
                ["", name, ins, stack, ""] => Ok(Measurement {
                    name: name.trim_matches('`').to_owned(),
                    instructions: number(ins, l)?,
                    stack: number(stack, l)?,
                }),
                _ => Err(format!("a row of three cells expected, got `{l}`")),
            }
        })
        .collect()
}
