#!/usr/bin/env python3
"""How generation time, operation count, compile time and evaluation time
grow with the number of modes per flexible link and with the number of
finite elements.

Takes ``examples/parallel-robot/scenes/parallel_robot_flexible_links.toml`` (three flexible links),
rewrites its ``modes`` / ``elements`` lines in a temporary copy, and for each
variant records:

* generation time (as ``flexdyn generate`` reports it, median of three runs)
  and operation counts (total, and the fused ``dynamics_terms`` that solvers
  call);
* compile time of the generated module in a small release-mode crate whose
  library calls every generated function (the functions are ``#[inline]``,
  so they are compiled where they are used; the crate's dependencies are
  built once beforehand and not counted);
* evaluation time of ``dynamics_terms`` (M, h, Phi_q and gamma together) at
  a fixed state (``q_k = 0.1 sin(k + 1)``, ``qd_k = 0.1 cos(k + 1)``): a
  release binary of the same crate calls it in batches of about 2 ms and
  prints the median over 15 batches of the time per call. The time is the
  thread's CPU time (``CLOCK_THREAD_CPUTIME_ID``), so that other processes
  on the machine (a parallel build) do not count. Building that binary
  compiles ``dynamics_terms`` once more; that build is not counted in the
  compile column.

``--plot PATH`` draws the table as a PNG (needs matplotlib: see
``benches/requirements.txt``). ``--every-scene`` measures the same columns
for every shipped scene instead (one row per file in ``scenes/`` and
``examples/parallel-robot/scenes/``).

Usage (from the repository root, after ``cargo build --release``):

    python3 benches/scaling.py [--csv scaling.csv] [--plot scaling.png]
"""

from __future__ import annotations

import argparse
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
ROBOT_SCENES = REPO / "examples/parallel-robot/scenes"
SCENE = ROBOT_SCENES / "parallel_robot_flexible_links.toml"
MODES = [0, 1, 2, 3, 4, 6, 8, 10, 12]
ELEMENTS = [5, 10, 20, 40, 80]
MODES_AT = 6  # modes per link of the elements sweep
ELEMENTS_AT = 20  # elements per link of the modes sweep
COLUMNS = ["modes", "elements", "coordinates", "generate_ms", "ops_total", "ops_dynamics_terms",
           "compile_s", "eval_ns"]

USER = """
#![allow(dead_code)]
pub mod scene {{ include!("{path}"); }}
use flexdyn_runtime::nalgebra::{{SMatrix, SVector}};
use flexdyn_runtime::Model;
#[inline(never)]
pub fn every_term(m: &scene::{model}, q: &SVector<f64, {{scene::NQ}}>, qd: &SVector<f64, {{scene::NQ}}>) -> f64 {{
    let mut mm = SMatrix::<f64, {{scene::NQ}}, {{scene::NQ}}>::zeros();
    let mut h = SVector::<f64, {{scene::NQ}}>::zeros();
    let mut pq = SMatrix::<f64, {{scene::NC}}, {{scene::NQ}}>::zeros();
    let mut g = SVector::<f64, {{scene::NC}}>::zeros();
    let mut p = SVector::<f64, {{scene::NC}}>::zeros();
    m.mass_matrix(q, 0.0, &mut mm);
    m.bias(q, qd, 0.0, &mut h);
    m.constraints(q, 0.0, &mut p);
    m.constraint_jacobian(q, 0.0, &mut pq);
    m.constraint_time_derivative(q, 0.0, &mut p);
    m.constraint_rhs(q, qd, 0.0, &mut g);
    m.dynamics_terms(q, qd, 0.0, &mut mm, &mut h, &mut pq, &mut g);
    let mut tau = SVector::<f64, {{scene::NQ}}>::zeros();
    m.inverse_dynamics(q, qd, qd, 0.0, &mut tau);
    mm[(0, 0)] + h[0] + tau[0] + pq[(0, 0)] + g[0] + p[0] + m.kinetic_energy(q, qd, 0.0) + m.potential_energy(q, 0.0)
}}
"""

TIMER = """
use std::hint::black_box;
use flexdyn_runtime::nalgebra::{{SMatrix, SVector}};
use flexdyn_runtime::Model;
use scaling_check::scene::{{self, NC, NQ}};

/// CPU time of this thread in nanoseconds.
fn thread_ns() -> f64 {{
    let mut t = libc::timespec {{ tv_sec: 0, tv_nsec: 0 }};
    // SAFETY: `t` is a valid timespec for the call to fill.
    unsafe {{ libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut t) }};
    t.tv_sec as f64 * 1e9 + t.tv_nsec as f64
}}

fn main() {{
    let model = scene::{model}::default();
    let q = SVector::<f64, NQ>::from_fn(|k, _| 0.1 * ((k + 1) as f64).sin());
    let qd = SVector::<f64, NQ>::from_fn(|k, _| 0.1 * ((k + 1) as f64).cos());
    let mut m = SMatrix::<f64, NQ, NQ>::zeros();
    let mut h = SVector::<f64, NQ>::zeros();
    let mut pq = SMatrix::<f64, NC, NQ>::zeros();
    let mut g = SVector::<f64, NC>::zeros();
    let mut batch = |calls: u32| {{
        let t0 = thread_ns();
        for _ in 0..calls {{
            black_box(&model)
                .dynamics_terms(black_box(&q), black_box(&qd), 0.0, &mut m, &mut h, &mut pq, &mut g);
            black_box((&m, &h, &pq, &g));
        }}
        (thread_ns() - t0) / f64::from(calls)
    }};
    // Warm up and size the batches to about 2 ms each.
    let mut calls = 1;
    while batch(calls) * f64::from(calls) < 2e6 {{
        calls *= 2;
    }}
    let mut ns: Vec<f64> = (0..15).map(|_| batch(calls)).collect();
    ns.sort_by(f64::total_cmp);
    println!("{{}}", ns[ns.len() / 2]);
}}
"""


def generate(binary: Path, scene: Path, work: Path) -> tuple[float, int, int, Path]:
    """Generate `scene` into `work/gen` three times: median time (ms), total
    ops, ops of dynamics_terms, and the module written."""
    out = work / "gen"
    out.mkdir(exist_ok=True)
    times = []
    for _ in range(3):
        run = subprocess.run([str(binary), "generate", "--scene", str(scene), "--out", str(out)],
                             capture_output=True, text=True)
        if run.returncode != 0:
            raise SystemExit(f"flexdyn generate failed:\n{run.stderr}")
        found = re.search(r"^(\w+): .* in ([0-9.]+) ms", run.stdout + run.stderr, re.M)
        name, ms = found.group(1), float(found.group(2))
        times.append(ms)
    module = out / f"{name}.rs"
    header = module.read_text()

    def ops(function: str) -> int:
        m = re.search(rf"^//\s+{function}\s+(\d+)\s+(\d+)\s+(\d+)\s+(\d+)", header, re.M)
        return sum(int(x) for x in m.groups())

    return statistics.median(times), ops("total"), ops("dynamics_terms"), module


def every_scene(binary: Path, crate: Path, tmp: Path) -> None:
    """Generation, ops, compile and evaluation time of every shipped scene."""
    print("| scene | coordinates | generate | ops (all) | ops (dynamics_terms) | compile "
          "| dynamics_terms call |")
    print("|---|---|---|---|---|---|---|")
    shipped = [*(REPO / "scenes").glob("*.toml"), *ROBOT_SCENES.glob("*.toml")]
    for scene in sorted(shipped, key=lambda p: p.name):
        ms, total, fused, module = generate(binary, scene, tmp)
        nq = int(re.search(r"pub const NQ: usize = (\d+);", module.read_text()).group(1))
        secs = compile_time(crate, module)
        ns = eval_time(crate)
        print(f"| {module.stem} | {nq} | {ms:.1f} ms | {total} | {fused} | {secs:.1f} s "
              f"| {ns / 1e3:.3f} us |", flush=True)
        module.unlink()


def make_crate(tmp: Path) -> Path:
    """The crate that compiles and times a generated module, its
    dependencies built (not counted in the compile times)."""
    crate = tmp / "crate"
    (crate / "src").mkdir(parents=True)
    (crate / "Cargo.toml").write_text(
        '[package]\nname = "scaling-check"\nversion = "0.0.0"\nedition = "2021"\n'
        f'[dependencies]\nflexdyn-runtime = {{ path = "{REPO / "runtime"}" }}\nlibc = "0.2"\n'
        '[workspace]\n')
    (crate / "Cargo.lock").write_text((REPO / "Cargo.lock").read_text())
    (crate / "src/lib.rs").write_text("")
    cargo(crate, "--lib")
    return crate


def cargo(crate: Path, *what: str) -> None:
    run = subprocess.run(["cargo", "build", "--release", "--quiet", "--manifest-path",
                          str(crate / "Cargo.toml"), *what], capture_output=True, text=True)
    if run.returncode != 0:
        raise SystemExit(f"compiling the generated module failed:\n{run.stderr}")


def compile_time(crate: Path, module: Path) -> float:
    model = re.search(r"^pub struct (\w+)", module.read_text(), re.M).group(1)
    (crate / "src/lib.rs").write_text(USER.format(path=str(module), model=model))
    (crate / "src/main.rs").write_text(TIMER.format(model=model))
    t0 = time.perf_counter()
    cargo(crate, "--lib")
    return time.perf_counter() - t0


def eval_time(crate: Path) -> float:
    cargo(crate, "--bins")
    run = subprocess.run([str(crate / "target/release/scaling-check")], capture_output=True,
                         text=True, check=True)
    return float(run.stdout)


def plot(rows: list[dict], path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    quantities = [("ops_dynamics_terms", "ops of dynamics_terms", 1.0),
                  ("eval_ns", "dynamics_terms call (µs)", 1e-3),
                  ("compile_s", "compile time (s)", 1.0),
                  ("generate_ms", "generation time (ms)", 1.0)]
    sweeps = [([r for r in rows if r["elements"] == ELEMENTS_AT], "modes",
               f"modes per link, {ELEMENTS_AT} elements (coordinates in parentheses)"),
              ([r for r in rows if r["modes"] == MODES_AT], "elements",
               f"finite elements per link, {MODES_AT} modes")]
    fig, axes = plt.subplots(len(quantities), 2, figsize=(10, 11), sharex="col", sharey="row")
    for col, (sweep, x, xlabel) in enumerate(sweeps):
        sweep = sorted(sweep, key=lambda r: r[x])
        xs = [r[x] for r in sweep]
        for row, (key, label, scale) in enumerate(quantities):
            ax = axes[row][col]
            ax.plot(xs, [r[key] * scale for r in sweep], "o-", color=f"C{row}")
            ax.grid(True, alpha=0.3)
            if col == 0:
                ax.set_ylabel(label)
        ax = axes[-1][col]
        ax.set_xlabel(xlabel)
        if x == "elements":
            ax.set_xscale("log", base=2)
        ax.set_xticks(xs)
        ax.set_xticklabels([f"{r[x]}\n({r['coordinates']})" if x == "modes" else str(r[x])
                            for r in sweep])
    for row, (key, _, scale) in enumerate(quantities):
        axes[row][0].set_ylim(0, 1.08 * max(r[key] * scale for r in rows))
    fig.suptitle("parallel_robot_flexible_links: scaling with modes and elements")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--flexdyn", default=str(REPO / "target/release/flexdyn"))
    ap.add_argument("--csv", help="also write the table as CSV")
    ap.add_argument("--plot", help="also draw the table as a PNG (needs matplotlib)")
    ap.add_argument("--every-scene", action="store_true",
                    help="instead, one row per shipped scene (scenes/*.toml and the robot's): generation, ops, "
                         "compile and evaluation time")
    args = ap.parse_args()
    binary = Path(args.flexdyn)
    if not binary.exists():
        print(f"error: no flexdyn binary at {binary}: run `cargo build --release`", file=sys.stderr)
        return 2
    if args.plot:
        try:
            import matplotlib  # noqa: F401 (checked before the long run)
        except ImportError:
            print("error: --plot needs matplotlib (benches/requirements.txt)", file=sys.stderr)
            return 2
    base = SCENE.read_text()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        crate = make_crate(tmp)
        if args.every_scene:
            every_scene(binary, crate, tmp)
            return 0
        variants = [(m, ELEMENTS_AT) for m in MODES] + \
                   [(MODES_AT, e) for e in ELEMENTS if e != ELEMENTS_AT]
        print("| modes/link | elements/link | coordinates | generate | ops (all) "
              "| ops (dynamics_terms) | compile | dynamics_terms call |")
        print("|---|---|---|---|---|---|---|---|")
        for modes, elements in variants:
            text = re.sub(r"^modes = \d+", f"modes = {modes}", base, flags=re.M)
            text = re.sub(r"^elements = \d+", f"elements = {elements}", text, flags=re.M)
            variant = tmp / SCENE.name
            variant.write_text(text)
            ms, total, fused, module = generate(binary, variant, tmp)
            nq = int(re.search(r"pub const NQ: usize = (\d+);", module.read_text()).group(1))
            secs = compile_time(crate, module)
            ns = eval_time(crate)
            rows.append(dict(zip(COLUMNS, (modes, elements, nq, ms, total, fused, secs, ns))))
            print(f"| {modes} | {elements} | {nq} | {ms:.1f} ms | {total} | {fused} | {secs:.1f} s "
                  f"| {ns / 1e3:.2f} us |", flush=True)
    if args.csv:
        with open(args.csv, "w") as f:
            f.write(",".join(COLUMNS) + "\n")
            for r in rows:
                f.write(",".join(f"{r[c]:.4g}" if isinstance(r[c], float) else str(r[c])
                                 for c in COLUMNS) + "\n")
    if args.plot:
        plot(rows, args.plot)
    return 0


if __name__ == "__main__":
    sys.exit(main())
