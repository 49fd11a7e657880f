#!/usr/bin/env python3
"""The Panda's inverse dynamics from Python: flexdyn's package against
Pinocchio's ``pin.rnea``, side by side in one process (docs/python.md).

* per call: one state, ``m.inverse_dynamics(q, qd, qdd)`` against
  ``pin.rnea(model, data, q, v, a)``;
* a batch of ``N`` states: one call with ``(N, 7)`` arrays against a Python
  loop over ``pin.rnea``.

Each figure is the best of ``--repeat`` timings (the machine is shared).
Both sides are checked to agree first. Needs the package (``pip install
./python``), ``pin`` and ``example-robot-data``.

    python python/benchmarks/panda_inverse_dynamics.py [--batch 10000] [--repeat 20]
"""

from __future__ import annotations

import argparse
import site
import time
from pathlib import Path

import numpy as np
import pinocchio as pin

import flexdyn

FINGERS = ["panda_finger_joint1", "panda_finger_joint2"]


def urdf() -> Path:
    for root in site.getsitepackages():
        p = Path(root) / "cmeel.prefix/share/example-robot-data/robots/panda_description/urdf/panda.urdf"
        if p.is_file():
            return p
    raise SystemExit("example-robot-data is not installed")


def best(f, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        f()
        times.append(time.perf_counter() - t)
    return min(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--batch", type=int, default=10000)
    ap.add_argument("--repeat", type=int, default=20)
    args = ap.parse_args()

    path = urdf()
    m = flexdyn.from_urdf(path, fix=FINGERS, keep_angles=True)
    model = pin.buildModelFromUrdf(str(path))
    model = pin.buildReducedModel(model, [model.getJointId(j) for j in FINGERS], pin.neutral(model))
    data = model.createData()
    index = {model.names[j]: model.joints[j].idx_v for j in range(1, model.njoints)}
    order = [index[c] for c in m.coordinates]
    assert order == list(range(model.nv)), "coordinates in Pinocchio's order"

    rng = np.random.default_rng(1)
    n = args.batch
    q, qd, qdd = (rng.uniform(-1, 1, (n, model.nv)) for _ in range(3))
    ours = m.inverse_dynamics(q, qd, qdd)
    theirs = np.array([pin.rnea(model, data, q[k], qd[k], qdd[k]) + model.damping * qd[k]
                       for k in range(n)])
    err = np.abs(ours - theirs).max() / np.abs(theirs).max()
    assert err <= 1e-12, err

    calls = 2000
    one = best(lambda: [m.inverse_dynamics(q[k], qd[k], qdd[k]) for k in range(calls)],
               args.repeat) / calls
    pin_one = best(lambda: [pin.rnea(model, data, q[k], qd[k], qdd[k]) for k in range(calls)],
                   args.repeat) / calls
    batch = best(lambda: m.inverse_dynamics(q, qd, qdd), args.repeat) / n
    loop = best(lambda: [pin.rnea(model, data, q[k], qd[k], qdd[k]) for k in range(n)],
                args.repeat) / n
    print(f"agreement: {err:.1e} of scale over {n} states")
    print("| | flexdyn | Pinocchio | ratio (Pinocchio / flexdyn) |")
    print("|---|---|---|---|")
    print(f"| per call, one state | {one * 1e6:.2f} us | `pin.rnea` {pin_one * 1e6:.2f} us "
          f"| {pin_one / one:.2f} |")
    print(f"| {n} states | {batch * 1e6:.3f} us per state (one batched call) "
          f"| Python loop over `pin.rnea`: {loop * 1e6:.2f} us per state | {loop / batch:.1f} |")


if __name__ == "__main__":
    main()
