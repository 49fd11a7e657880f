#!/usr/bin/env python3
"""How the generated equations grow with the length of a serial chain.

Two families of scenes, written by this script into a temporary directory:

* ``spatial``: a spatial serial chain of ``n`` rigid bodies, revolute joints
  whose axes alternate z, y, x, each joint offset from the previous one
  (``[0.05, 0.02, 0.3]``), each body with its centre of mass off the joint and
  a full (non-diagonal, positive definite) inertia tensor;
* ``planar``: the classic planar ``n``-link pendulum, point masses on massless
  rods, relative joint angles about y.

For each ``n`` it records the operation counts of ``bias``,
``mass_matrix``, ``dynamics_terms`` and ``inverse_dynamics`` (from the
``@generated`` header), the generation time (as ``flexdyn generate``
reports it, median of three runs) and, with ``--compile``, the release-mode
compile time of the generated module (``benches/scaling.py``'s crate, whose
library calls every generated function; its dependencies are built once
beforehand and not counted). It then fits the growth exponent ``k`` of
``ops ~ n^k`` by least squares on ``log ops`` against ``log n`` over
``n >= 8``, and again over ``n >= 16``: the counts are close to ``a n - b``
(the first links cost less than the others), and a power law fitted from
``n = 8`` on reads that offset as growth, the longer chains much less.

Usage (from the repository root, after ``cargo build --release``):

    python3 benches/chain_scaling.py [--family spatial|planar|both]
        [--n 2,4,8,16,32] [--compile] [--csv out.csv] [--plot out.png]
        [--before earlier.csv] [--flexdyn target/release/flexdyn]
"""

from __future__ import annotations

import argparse
import math
import re
import statistics
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import scaling  # noqa: E402 (generation and compile timing shared with it)

REPO = scaling.REPO
FUNCTIONS = ["bias", "mass_matrix", "dynamics_terms", "inverse_dynamics"]
AXES = ["z", "y", "x"]


def serial_chain(name: str, description: str, n: int, offset: str, axis, bodies) -> str:
    """A serial chain of n revolute joints: coordinates, frames (link k on
    link k-1, translated by ``offset`` except the first, rotated about
    ``axis(k)``), the bodies ``bodies(k)`` (TOML lines) and one actuator per
    joint."""
    out = [f'name = "{name}"', f'description = "{description}"',
           'gravity = [0, 0, -9.81]', ""]
    for k in range(n):
        out += ["[[coordinates]]", f'name = "q{k}"', "range = [-3.1, 3.1]",
                "velocity_range = [-3.0, 3.0]", ""]
    for k in range(n):
        parent = "world" if k == 0 else f"link{k - 1}"
        translation = "[0, 0, 0]" if k == 0 else offset
        out += ["[[frames]]", f'name = "link{k}"', f'parent = "{parent}"',
                f"translation = {translation}",
                f'rotation = [{{ axis = "{axis(k)}", angle = "q{k}" }}]', ""]
    for k in range(n):
        out += ["[[components]]", *bodies(k), ""]
    for k in range(n):
        out += ["[[actuators]]", f'name = "tau{k}"', f'coordinate = "q{k}"', ""]
    return "\n".join(out)


def spatial_chain(n: int) -> str:
    """A spatial serial chain of n rigid bodies with full inertia tensors."""
    def body(k: int) -> list[str]:
        m = 1.0 + 0.1 * (k % 4)
        # The moments cycle every 30 links: beyond 34 links a steady growth
        # would break the triangle inequality, which the generator refuses.
        j = k % 30
        ixx, iyy, izz = 0.02 + 0.001 * j, 0.025, 0.012 + 0.0005 * j
        ixy, ixz, iyz = 0.001, -0.0007, 0.0004
        return [f'name = "body{k}"', 'type = "rigid_body"', f"mass = {m}",
                f'frame = "link{k}"', "position = [0.01, -0.015, 0.15]",
                f"inertia = [[{ixx}, {ixy}, {ixz}], [{ixy}, {iyy}, {iyz}], [{ixz}, {iyz}, {izz}]]"]
    return serial_chain(f"chain{n}", f"Spatial serial chain of {n} rigid bodies", n,
                        "[0.05, 0.02, 0.3]", lambda k: AXES[k % 3], body)


def planar_pendulum(n: int) -> str:
    """The planar n-link pendulum: point masses, relative angles about y."""
    def body(k: int) -> list[str]:
        return [f'name = "mass{k}"', 'type = "point_mass"', f"mass = {1.0 + 0.05 * k}",
                f'frame = "link{k}"', "position = [0, 0, -0.5]"]
    return serial_chain(f"pendulum{n}", f"Planar {n}-link pendulum", n, "[0, 0, -0.5]",
                        lambda k: "y", body)


FAMILIES = {"spatial": spatial_chain, "planar": planar_pendulum}


def op_counts(module: str) -> dict[str, int]:
    """Total operations per function from the module's header."""
    ops = {}
    for line in module.splitlines():
        if not line.startswith("//"):
            break
        m = re.match(r"//\s+(\w+)\s+(\d+)\s+(\d+)\s+(\d+)\s+(\d+)\s*$", line)
        if m:
            ops[m.group(1)] = sum(int(x) for x in m.groups()[1:])
    return ops


def fit_exponent(ns: list[int], ys: list[float], from_n: int = 8) -> float:
    pts = [(math.log(n), math.log(y)) for n, y in zip(ns, ys) if n >= from_n and y > 0]
    if len(pts) < 2:
        return float("nan")
    mx = statistics.mean(p[0] for p in pts)
    my = statistics.mean(p[1] for p in pts)
    return sum((x - mx) * (y - my) for x, y in pts) / sum((x - mx) ** 2 for x, _ in pts)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--family", choices=["spatial", "planar", "both"], default="both")
    ap.add_argument("--n", default="2,4,6,8,12,16,20,24,32")
    ap.add_argument("--compile", action="store_true")
    ap.add_argument("--csv")
    ap.add_argument("--plot")
    ap.add_argument("--before", help="a CSV of an earlier run (--csv), drawn dashed in the plot")
    ap.add_argument("--flexdyn", default=str(REPO / "target/release/flexdyn"))
    args = ap.parse_args()
    ns = [int(x) for x in args.n.split(",")]
    families = ["spatial", "planar"] if args.family == "both" else [args.family]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        crate = scaling.make_crate(tmp) if args.compile else None
        for fam in families:
            for n in ns:
                scene = tmp / f"{fam}{n}.toml"
                scene.write_text(FAMILIES[fam](n))
                ms, _, _, module = scaling.generate(Path(args.flexdyn), scene, tmp)
                ops = op_counts(module.read_text())
                row = {"family": fam, "n": n, "generate_s": ms / 1e3}
                row.update({f: ops.get(f, 0) for f in FUNCTIONS})
                if crate is not None:
                    row["compile_s"] = scaling.compile_time(crate, module)
                module.unlink()
                rows.append(row)
                print(row, flush=True)
    cols = ["family", "n"] + FUNCTIONS + ["generate_s"] + (["compile_s"] if args.compile else [])
    print("| " + " | ".join(cols) + " |")
    print("|" + "---|" * len(cols))
    for r in rows:
        print("| " + " | ".join(f"{r[c]:.3f}" if isinstance(r[c], float) else str(r[c]) for c in cols) + " |")
    for fam in families:
        sub = [r for r in rows if r["family"] == fam]
        fits = {f: fit_exponent([r["n"] for r in sub], [r[f] for r in sub]) for f in FUNCTIONS}
        print(f"{fam}: fitted exponents (n >= 8): "
              + ", ".join(f"{f} {k:.2f}" for f, k in fits.items()))
        long = {f: fit_exponent([r["n"] for r in sub], [r[f] for r in sub], 16) for f in FUNCTIONS}
        print(f"{fam}: fitted exponents (n >= 16): "
              + ", ".join(f"{f} {k:.2f}" for f, k in long.items()))
    if args.csv:
        with open(args.csv, "w") as f:
            f.write(",".join(cols) + "\n")
            for r in rows:
                f.write(",".join(str(r[c]) for c in cols) + "\n")
    if args.plot:
        import matplotlib
        import matplotlib.ticker
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        before = []
        if args.before:
            with open(args.before) as f:
                head = f.readline().strip().split(",")
                before = [dict(zip(head, line.strip().split(","))) for line in f if line.strip()]
        fig, axes = plt.subplots(1, len(families), figsize=(6 * len(families), 4.5), squeeze=False)
        for ax, fam in zip(axes[0], families):
            sub = [r for r in rows if r["family"] == fam]
            old = [r for r in before if r["family"] == fam]
            for k, f in enumerate(FUNCTIONS):
                ns, ys = [r["n"] for r in sub], [r[f] for r in sub]
                if any(ys):
                    ax.loglog(ns, ys, "o-", color=f"C{k}",
                              label=f"{f} (n^{fit_exponent(ns, ys):.2f}; "
                              f"from 16: n^{fit_exponent(ns, ys, 16):.2f})")
                old_ns = [int(r["n"]) for r in old if int(r[f])]
                old_ys = [int(r[f]) for r in old if int(r[f])]
                if old_ys:
                    ax.loglog(old_ns, old_ys, "x--", color=f"C{k}", alpha=0.6,
                              label=f"{f} before (n^{fit_exponent(old_ns, old_ys):.2f})")
            ax.set_xlabel("links n")
            ax.set_ylabel("operations (emitted program)")
            ax.set_title(fam)
            ax.grid(True, which="both", alpha=0.3)
            ax.set_xticks(sorted({r["n"] for r in sub}))
            ax.xaxis.set_major_formatter(matplotlib.ticker.ScalarFormatter())
            ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
            ax.legend(loc="upper left", fontsize=7)
        fig.tight_layout()
        fig.savefig(args.plot, dpi=120)
    return 0


if __name__ == "__main__":
    sys.exit(main())
