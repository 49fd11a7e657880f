#!/usr/bin/env python3
"""Generation time and operation counts: flexdyn against SymPy.

For each scene, from the same export (``flexdyn export``), SymPy derives the
mass matrix (upper triangle of ``hessian(T, qd)``) and the bias forces
``h = d/dt(dT/dqd)|_(qdd=0) - dT/dq + dV/dq + dD/dqd`` and runs ``cse`` on
them; the script times the derivation and the CSE separately and counts the
operations of the result (``count_ops`` over the CSE replacements and the
reduced expressions). flexdyn's side is the wall time of ``flexdyn generate``
for the whole scene (every term, emission and formatting included: an upper
bound for the same job) and the operation counts of ``mass_matrix`` and
``bias`` from the ``@generated`` header.

Each SymPy run has a time limit (``--timeout``, default 300 s); a scene that
exceeds it is reported as such.

Usage (from the repository root, after ``cargo build --release``, with SymPy
installed, for example in ``target/casadi-venv`` which the CasADi test
creates):

    target/casadi-venv/bin/python benches/sympy_generation.py [SCENE.toml ...]
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DEFAULT_SCENES = ["pendulum", "double_pendulum", "cart_pole", "slider_crank", "five_bar",
                  "parallel_robot_rigid", "parallel_robot_flexible_joints"]


def scene_file(name: str) -> Path:
    """A shipped scene by name: in scenes/, or the parallel-robot example's."""
    generic = REPO / f"scenes/{name}.toml"
    return generic if generic.is_file() else REPO / f"examples/parallel-robot/scenes/{name}.toml"


def build(export: dict):
    import sympy as sp

    nq = len(export["coordinates"])
    q = sp.symbols(f"q0:{nq}")
    qd = sp.symbols(f"qd0:{nq}")
    t = sp.Symbol("t")
    p = sp.symbols(f"p0:{len(export['runtime_parameters'])}")
    # `step` is 1/2 at 0, as the export's; SymPy keeps the DiracDelta terms
    # of its derivative that flexdyn drops (zero away from the switch).
    unary = {"sin": sp.sin, "cos": sp.cos, "tan": sp.tan, "exp": sp.exp, "ln": sp.log,
             "sqrt": sp.sqrt, "abs": sp.Abs, "sign": sp.sign,
             "step": lambda x: sp.Heaviside(x, sp.Rational(1, 2))}
    vals = []
    for nd in export["nodes"]:
        op = nd["op"]
        if op == "const":
            v = sp.Float(nd["value"])
        elif op == "q":
            v = q[nd["index"]]
        elif op == "qd":
            v = qd[nd["index"]]
        elif op == "t":
            v = t
        elif op == "param":
            v = p[nd["index"]]
        elif op == "sum":
            v = sp.Add(sp.Float(nd["constant"]), *[sp.Float(c) * vals[j] for j, c in nd["terms"]])
        elif op == "prod":
            v = sp.Mul(*[vals[j] ** e for j, e in nd["factors"]])
        elif op == "atan2":
            v = sp.atan2(vals[nd["y"]], vals[nd["x"]])
        else:
            v = unary[op](vals[nd["arg"]])
        vals.append(v)
    total = lambda key: sp.Add(*[vals[c[key]] for c in export["components"]])  # noqa: E731
    return q, qd, t, total("kinetic"), total("potential"), total("dissipation")


def sympy_job(export: dict, queue) -> None:
    import sympy as sp

    q, qd, t, kinetic, potential, dissipation = build(export)
    n = len(q)
    t0 = time.perf_counter()
    momenta = [sp.diff(kinetic, v) for v in qd]
    mass = [sp.diff(momenta[i], qd[j]) for i in range(n) for j in range(i, n)]
    bias = []
    for i in range(n):
        rate = sum(sp.diff(momenta[i], q[k]) * qd[k] for k in range(n)) + sp.diff(momenta[i], t)
        bias.append(rate - sp.diff(kinetic, q[i]) + sp.diff(potential, q[i])
                    + sp.diff(dissipation, qd[i]))
    t_derive = time.perf_counter() - t0
    t0 = time.perf_counter()
    replacements, reduced = sp.cse(mass + bias)
    t_cse = time.perf_counter() - t0
    ops = sum(sp.count_ops(e) for _, e in replacements) + sum(sp.count_ops(e) for e in reduced)
    queue.put({"derive": t_derive, "cse": t_cse, "ops": int(ops)})


def flexdyn_side(binary: Path, scene: Path, work: Path) -> dict:
    t0 = time.perf_counter()
    run = subprocess.run([str(binary), "generate", "--scene", str(scene), "--out", str(work)],
                         capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if run.returncode != 0:
        raise SystemExit(f"flexdyn generate failed for {scene}:\n{run.stderr}")
    reported = re.search(r"in ([0-9.]+) ms", run.stdout + run.stderr)
    header = next(work.glob("*.rs")).read_text()
    ops = 0
    for name in ("mass_matrix", "bias"):
        m = re.search(rf"^//\s+{name}\s+(\d+)\s+(\d+)\s+(\d+)\s+(\d+)", header, re.M)
        ops += sum(int(x) for x in m.groups())
    return {"generate_ms": float(reported.group(1)) if reported else wall * 1e3, "ops": ops}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scenes", nargs="*", help="scene files (default: a representative set)")
    ap.add_argument("--flexdyn", default=str(REPO / "target/release/flexdyn"))
    ap.add_argument("--timeout", type=float, default=300.0, help="seconds per SymPy run")
    args = ap.parse_args()
    try:
        import sympy
    except ImportError:
        print("error: SymPy is not installed (pip install sympy)", file=sys.stderr)
        return 2
    binary = Path(args.flexdyn)
    if not binary.exists():
        print(f"error: no flexdyn binary at {binary}: run `cargo build --release`", file=sys.stderr)
        return 2
    scenes = [Path(s) for s in args.scenes] or [scene_file(s) for s in DEFAULT_SCENES]
    print(f"SymPy {sympy.__version__}; M (upper triangle) and h, then cse\n")
    print("| scene | nq | flexdyn generate (all terms) | flexdyn ops M+h | SymPy derive | SymPy cse | SymPy ops M+h |")
    print("|---|---|---|---|---|---|---|")
    for scene in scenes:
        with tempfile.TemporaryDirectory() as tmp:
            tmp = Path(tmp)
            export_path = tmp / "export.json"
            subprocess.run([str(binary), "export", "--scene", str(scene), "--out", str(export_path)],
                           check=True, capture_output=True)
            export = json.loads(export_path.read_text())
            (tmp / "gen").mkdir()
            ours = flexdyn_side(binary, scene, tmp / "gen")
        queue = mp.Queue()
        job = mp.Process(target=sympy_job, args=(export, queue))
        job.start()
        job.join(args.timeout)
        if job.is_alive():
            job.terminate()
            theirs = None
        else:
            theirs = queue.get() if not queue.empty() else None
        nq = len(export["coordinates"])
        if theirs is None:
            sym = f"> {args.timeout:.0f} s | - | -"
        else:
            sym = f"{theirs['derive']:.3f} s | {theirs['cse']:.3f} s | {theirs['ops']}"
        print(f"| {export['name']} | {nq} | {ours['generate_ms']:.1f} ms | {ours['ops']} | {sym} |",
              flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
