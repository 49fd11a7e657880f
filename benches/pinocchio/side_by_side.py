#!/usr/bin/env python3
"""Runs the Pinocchio comparison (``benches/compare.rs``) in its two builds,
one after the other, and prints their criterion medians as one Markdown
table, a row per robot and build: flexdyn, Pinocchio's templated library
and Pinocchio's algorithms generated to C by CasADi, with flexdyn's speed-up
over each (above 1: flexdyn is faster).

* ``default``: release build for the baseline target on every side;
* ``native``: ``RUSTFLAGS="-C target-cpu=native"`` for flexdyn and
  ``FLEXDYN_NATIVE=1`` (``-march=native``) for the Pinocchio shim and the
  generated C.

Each build has its own target directory (``target/pinbench``,
``target/pinbench-native``), so neither replaces the other; the first run
of each compiles Pinocchio's templates twice (over double for the shim,
over ``casadi::SX`` for the generator of C: minutes, about 3 GB). The load
average before and after each run is printed with it, and the lines of the
run that give agreement and operation counts. A robot without forward
dynamics (a singular mass matrix: Romeo as published) has ``-`` in those
cells. The robots are those of the
run (``FLEXDYN_BENCH_ROBOTS``, see ``build.rs``; the default five when it
is unset). Stdlib only.

Usage (from any directory; cargo runs in the repository root):

    python3 benches/pinocchio/side_by_side.py [default|native|both] [--interleaved] [CRITERION ARGS...]

e.g. ``side_by_side.py default --warm-up-time 1 --measurement-time 3``.

``--interleaved`` times without criterion (``FLEXDYN_BENCH_INTERLEAVED``):
each term's functions (flexdyn's, Pinocchio's templated, Pinocchio's C) in
turn, a batch of about 2 ms each per round, 201 rounds, and each ratio is
the median over the rounds of the two batches' ratio, so that a shared
machine whose speed drifts over minutes slows both sides of a ratio alike
(criterion times one function after the other, several seconds each).
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
MANIFEST = REPO / "benches/pinocchio/Cargo.toml"
BUILDS = [
    ("default", REPO / "target/pinbench", {}),
    ("native", REPO / "target/pinbench-native",
     {"FLEXDYN_NATIVE": "1", "RUSTFLAGS": "-C target-cpu=native"}),
]
# Labels of the default robots; others (`FLEXDYN_BENCH_ROBOTS`, see
# `build.rs`) are labelled by their module name, after these.
LABELS = {"ur5": "UR5 (6)", "panda": "Panda (7, arm)",
          "tiago": "TIAGo (10, torso, arm, head; as published)",
          "solo": "Solo12 (12, fixed base)", "talos": "TALOS (30, fixed base)"}
# flexdyn's function, Pinocchio's templated one, Pinocchio's generated C.
TERMS = [("flexdyn inverse_dynamics", "pinocchio rnea", "pinocchio C rnea"),
         ("flexdyn dynamics_terms", "pinocchio crba + nonLinearEffects",
          "pinocchio C crba + nle"),
         ("flexdyn forward dynamics", "pinocchio aba", "pinocchio C aba")]


def load() -> str:
    return " ".join(Path("/proc/loadavg").read_text().split()[:3])


def medians(criterion: Path) -> dict[tuple[str, str], float]:
    """Median (ns) of every benchmark criterion recorded under `criterion`,
    by (group, function)."""
    found = {}
    for estimates in criterion.glob("*/*/new/estimates.json"):
        function = json.loads((estimates.parent / "benchmark.json").read_text())["function_id"]
        median = json.loads(estimates.read_text())["median"]["point_estimate"]
        found[(estimates.parents[2].name, function)] = median
    return found


def duration(ns: float) -> str:
    return f"{ns:.0f} ns" if ns < 1000 else f"{ns / 1000:.2f} us"


def ratio(x: float) -> str:
    return f"{x:.2f}x" if x < 3 else f"{x:.1f}x"


def main() -> int:
    wanted = sys.argv[1] if len(sys.argv) > 1 else "both"
    builds = [b for b in BUILDS if wanted in ("both", b[0])]
    if not builds:
        print(f"error: no build named {wanted!r} (default, native, both)", file=sys.stderr)
        return 2
    extra = sys.argv[2:]
    interleaved = "--interleaved" in extra
    extra = [a for a in extra if a != "--interleaved"]
    # (group, function) -> median ns, and that function's time relative to
    # flexdyn's in the same round (median over rounds), per build.
    timed: dict[str, dict[tuple[str, str], tuple[float, float]]] = {}
    results = {}
    compared = set()
    # Robots whose mass matrix is singular (no forward dynamics to time).
    no_forward = set()
    for build, target, env in builds:
        print(f"{build}: load average before {load()}", flush=True)
        run = subprocess.run(
            ["cargo", "bench", "--manifest-path", str(MANIFEST), "--", *extra],
            env={**os.environ, **env, "CARGO_TARGET_DIR": str(target),
                 **({"FLEXDYN_BENCH_INTERLEAVED": "1"} if interleaved else {})},
            cwd=REPO, capture_output=True, text=True)
        timed[build] = {}
        for line in run.stdout.splitlines():
            found = re.match(r"interleaved (.+) / (.+): median ([\d.]+) ns; per round ([\d.]+) times",
                             line)
            if found:
                print(f"{build}: {line}")
                timed[build][(found.group(1), found.group(2))] = (float(found.group(3)),
                                                                  float(found.group(4)))
            if "largest relative difference" in line or "operations" in line:
                print(f"{build}: {line}")
            robot = re.match(r"(\w+): \d+ joints;", line)
            if robot:
                compared.add(robot.group(1))
            singular = re.match(r"(\w+): no forward dynamics", line)
            if singular:
                print(f"{build}: {line}")
                no_forward.add(singular.group(1))
        if run.returncode != 0:
            print(f"error: the {build} run failed:\n{run.stderr[-4000:]}", file=sys.stderr)
            return 1
        print(f"{build}: load average after {load()}", flush=True)
        results[build] = ({key: t for key, (t, _) in timed[build].items()} if interleaved
                          else medians(target / "criterion"))
    header = ["robot", "build"]
    for term in ("inverse dynamics", "M + h", "forward dynamics"):
        header += [f"{term}: flexdyn", "Pinocchio templated", "Pinocchio C", "vs templated",
                   "vs C"]
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    robots = [r for r in LABELS if r in compared] + sorted(compared - set(LABELS))
    for robot in robots:
        label = LABELS.get(robot, robot)
        for build, _, _ in builds:
            cells = []
            for names in TERMS:
                if robot in no_forward and names == TERMS[2]:
                    cells += ["-"] * 5
                    continue
                try:
                    ours, templated, generated = (results[build][(robot, n)] for n in names)
                except KeyError as missing:
                    print(f"error: no timing for {missing} in the {build} run",
                          file=sys.stderr)
                    return 1
                # Interleaved: the medians of the per-round ratios, not the
                # ratios of the medians.
                vs_templated, vs_c = ((timed[build][(robot, n)][1] for n in names[1:])
                                      if interleaved else (templated / ours, generated / ours))
                cells += [duration(ours), duration(templated), duration(generated),
                          ratio(vs_templated), f"**{ratio(vs_c)}**"]
            print(f"| {label} | {build} | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
