#!/usr/bin/env python3
"""How generation time, operation count and compile time grow with the
number of modes per flexible link and with the number of finite elements.

Takes ``scenes/parallel_robot_flexible_links.toml`` (three flexible links),
rewrites its ``modes`` / ``elements`` lines in a temporary copy, and for each
variant records:

* generation time (as ``flexdyn generate`` reports it) and operation counts
  (total, and the fused ``dynamics_terms`` that solvers call);
* compile time of the generated module in a small release-mode crate that
  calls every generated function (the functions are ``#[inline]``, so they
  are compiled where they are used; the crate's dependencies are built once
  beforehand and not counted).

Usage (from the repository root, after ``cargo build --release``):

    python3 benches/scaling.py [--csv scaling.csv]
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SCENE = REPO / "scenes/parallel_robot_flexible_links.toml"
MODES = [0, 1, 2, 3, 4, 6, 8, 10, 12]
ELEMENTS = [5, 10, 20, 40, 80]

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
    mm[(0, 0)] + h[0] + pq[(0, 0)] + g[0] + p[0] + m.kinetic_energy(q, qd, 0.0) + m.potential_energy(q, 0.0)
}}
"""


def generate(binary: Path, text: str, work: Path) -> tuple[float, int, int, Path]:
    scene = work / "parallel_robot_flexible_links.toml"
    scene.write_text(text)
    out = work / "gen"
    out.mkdir(exist_ok=True)
    run = subprocess.run([str(binary), "generate", "--scene", str(scene), "--out", str(out)],
                         capture_output=True, text=True)
    if run.returncode != 0:
        raise SystemExit(f"flexdyn generate failed:\n{run.stderr}")
    ms = float(re.search(r"in ([0-9.]+) ms", run.stdout + run.stderr).group(1))
    module = out / "parallel_robot_flexible_links.rs"
    header = module.read_text()

    def ops(name: str) -> int:
        m = re.search(rf"^//\s+{name}\s+(\d+)\s+(\d+)\s+(\d+)\s+(\d+)", header, re.M)
        return sum(int(x) for x in m.groups())

    return ms, ops("total"), ops("dynamics_terms"), module


def compile_time(crate: Path, module: Path) -> float:
    model = re.search(r"^pub struct (\w+)", module.read_text(), re.M).group(1)
    (crate / "src/lib.rs").write_text(USER.format(path=str(module), model=model))
    t0 = time.perf_counter()
    run = subprocess.run(["cargo", "build", "--release", "--quiet", "--manifest-path",
                          str(crate / "Cargo.toml")], capture_output=True, text=True)
    if run.returncode != 0:
        raise SystemExit(f"compiling the generated module failed:\n{run.stderr}")
    return time.perf_counter() - t0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--flexdyn", default=str(REPO / "target/release/flexdyn"))
    ap.add_argument("--csv", help="also write the table as CSV")
    args = ap.parse_args()
    binary = Path(args.flexdyn)
    if not binary.exists():
        print(f"error: no flexdyn binary at {binary}: run `cargo build --release`", file=sys.stderr)
        return 2
    base = SCENE.read_text()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        crate = tmp / "crate"
        (crate / "src").mkdir(parents=True)
        (crate / "Cargo.toml").write_text(
            '[package]\nname = "scaling-check"\nversion = "0.0.0"\nedition = "2021"\n'
            f'[dependencies]\nflexdyn-runtime = {{ path = "{REPO / "runtime"}" }}\n[workspace]\n')
        (crate / "Cargo.lock").write_text((REPO / "Cargo.lock").read_text())
        (crate / "src/lib.rs").write_text("")
        subprocess.run(["cargo", "build", "--release", "--quiet", "--manifest-path",
                        str(crate / "Cargo.toml")], check=True)
        variants = [(m, 20) for m in MODES] + [(6, e) for e in ELEMENTS if e != 20]
        print("| modes/link | elements/link | coordinates | generate | ops (all) | ops (dynamics_terms) | compile |")
        print("|---|---|---|---|---|---|---|")
        for modes, elements in variants:
            text = re.sub(r"^modes = \d+", f"modes = {modes}", base, flags=re.M)
            text = re.sub(r"^elements = \d+", f"elements = {elements}", text, flags=re.M)
            ms, total, fused, module = generate(binary, text, tmp)
            nq = int(re.search(r"pub const NQ: usize = (\d+);", module.read_text()).group(1))
            secs = compile_time(crate, module)
            rows.append((modes, elements, nq, ms, total, fused, secs))
            print(f"| {modes} | {elements} | {nq} | {ms:.1f} ms | {total} | {fused} | {secs:.1f} s |",
                  flush=True)
    if args.csv:
        with open(args.csv, "w") as f:
            f.write("modes,elements,coordinates,generate_ms,ops_total,ops_dynamics_terms,compile_s\n")
            for r in rows:
                f.write(",".join(str(x) for x in r) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
