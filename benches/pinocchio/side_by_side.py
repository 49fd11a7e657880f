#!/usr/bin/env python3
"""Runs the Pinocchio comparison (``benches/compare.rs``) in its two builds,
one after the other, and prints their criterion medians as one Markdown
table, a row per robot and build:

* ``default``: release build for the baseline target on both sides;
* ``native``: ``RUSTFLAGS="-C target-cpu=native"`` for flexdyn and
  ``FLEXDYN_NATIVE=1`` (``-march=native``) for the Pinocchio shim.

Each build has its own target directory (``target/pinbench``,
``target/pinbench-native``), so neither replaces the other; the first run
of each compiles Pinocchio's templates (minutes, about 3 GB). The load
average before and after each run is printed with it. Stdlib only.

Usage (from the repository root):

    python3 benches/pinocchio/side_by_side.py
"""

from __future__ import annotations

import json
import os
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
ROBOTS = [("ur5", "UR5 (6 joints)"), ("panda", "Panda (7 joints, arm)")]
PAIRS = [("flexdyn dynamics_terms", "pinocchio crba + nonLinearEffects"),
         ("flexdyn inverse_dynamics", "pinocchio rnea"),
         ("flexdyn forward dynamics", "pinocchio aba")]


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


def main() -> int:
    results = {}
    for build, target, env in BUILDS:
        print(f"{build}: load average before {load()}", flush=True)
        run = subprocess.run(
            ["cargo", "bench", "--manifest-path", str(MANIFEST)],
            env={**os.environ, **env, "CARGO_TARGET_DIR": str(target)},
            capture_output=True, text=True)
        for line in run.stdout.splitlines():
            if "largest relative difference" in line:
                print(f"{build}: {line}")
        if run.returncode != 0:
            print(f"error: the {build} run failed:\n{run.stderr[-4000:]}", file=sys.stderr)
            return 1
        print(f"{build}: load average after {load()}", flush=True)
        results[build] = medians(target / "criterion")
    print("| robot | build | flexdyn `dynamics_terms` | Pinocchio `crba` + `nonLinearEffects` "
          "| ratio | flexdyn `inverse_dynamics` | Pinocchio `rnea` | ratio "
          "| flexdyn forward dynamics | Pinocchio `aba` | ratio |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for robot, label in ROBOTS:
        for build, _, _ in BUILDS:
            cells = []
            for ours, theirs in PAIRS:
                try:
                    a, b = results[build][(robot, ours)], results[build][(robot, theirs)]
                except KeyError as missing:
                    print(f"error: no criterion result for {missing} in the {build} run",
                          file=sys.stderr)
                    return 1
                ratio = b / a
                cells += [duration(a), duration(b),
                          f"{ratio:.2f}x" if ratio < 3 else f"{ratio:.1f}x"]
            print(f"| {label} | {build} | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
