"""Tip (tool flange) deviation of scenes/ur5_flexible.toml from the rigid
robot along a joint-space trajectory, and a check of the joint deflection
against statics.

Runs `flexdyn inverse` on the flexible UR5 with the motor-side joint angles
prescribed (the elastic coordinates, the gear twists and the tube's modes,
integrated by the servo path), then evaluates the scene's `tool0` marker
with `flexdyn eval` (the generated marker kinematics, on the frames that
hang from the tube's deformed end) at three states per time:
* rigid robot: the prescribed angles, twists and tube modes zero;
* gears only: the twists as integrated, the tube straight (modes zero);
* flexible robot: every coordinate as integrated (twists and bending).
The deviation is flexible - rigid; the tube's share is flexible - gears
only.

Check (fails loudly): at t = 0 the inverse starts at rest in static
equilibrium, so each gear's spring balances gravity on the link side:
k e = -dV/de, with V = -sum m g.c over the scene's bodies placed by the same
forward kinematics (tube as a uniform straight tube). Agreement to 1e-3
relative (the tube's bending is the only thing left out).

Usage: python3 docs/flexible-ur5/tip_deviation.py [--flexdyn target/release/flexdyn]
writes docs/flexible-ur5/tip_deviation.png and prints the numbers; needs
numpy and matplotlib.
"""

import argparse
import csv
import json
import math
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
SCENE = ROOT / "scenes" / "ur5_flexible.toml"
PRESCRIBE = {
    "shoulder_pan_joint": "0.5*powi(sin(t),3)",
    "shoulder_lift_joint": "-1.2+0.4*powi(sin(t),3)",
    "elbow_joint": "1.0-0.5*powi(sin(t),3)",
    "wrist_1_joint": "-1.4",
    "wrist_2_joint": "-1.57",
    "wrist_3_joint": "0",
}
TWISTS = {"shoulder_lift_twist": "shoulder_lift_gear", "elbow_twist": "elbow_gear"}
# The tube's modal coordinates are named `<component>_eta<k>`.
MODE_PREFIX = "forearm_tube_eta"


def rot(axis, a):
    c, s = math.cos(a), math.sin(a)
    return {
        "x": np.array([[1, 0, 0], [0, c, -s], [0, s, c]]),
        "y": np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]),
        "z": np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]),
    }[axis]


def value(x, q):
    if isinstance(x, (int, float)):
        return float(x)
    return float(eval(x, {"__builtins__": {}, "pi": math.pi}, dict(q)))


def frames(scene, q):
    """World position and rotation of every frame, in file order."""
    tube = next(c for c in scene["components"] if c["type"] == "flexible_link")
    out = {"world": (np.zeros(3), np.eye(3))}
    for f in scene["frames"]:
        p, r = out[f.get("parent", "world")]
        t = np.array([value(v, q) for v in f.get("translation", [0, 0, 0])])
        if f.get("station") == "end":
            t = t + np.array([tube["length"], 0.0, 0.0])  # straight tube
        p = p + r @ t
        for rr in f.get("rotation", []):
            r = r @ rot(rr["axis"], value(rr["angle"], q))
        out[f["name"]] = (p, r)
    return out


def potential(scene, q):
    g = np.array(scene["gravity"], dtype=float)
    fr = frames(scene, q)
    v = 0.0
    for c in scene["components"]:
        if c["type"] in ("rigid_body", "point_mass"):
            p, r = fr[c["frame"]]
            com = p + r @ np.array(c.get("position", [0, 0, 0]), dtype=float)
            v -= c["mass"] * g @ com
        elif c["type"] == "flexible_link":
            ro, ri = c["section"]["outer_radius"], c["section"]["inner_radius"]
            m = c["material"]["density"] * math.pi * (ro**2 - ri**2) * c["length"]
            p, r = fr[c["frame"]]
            v -= m * g @ (p + r @ np.array([c["length"] / 2, 0, 0]))
    return v


def marker_positions(flexdyn, names, states):
    """`tool0`'s world position at each state (coordinates by name, rates
    zero), from `flexdyn eval` of the scene's generated marker."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "states.json"
        path.write_text(json.dumps({"states": [
            {"q": [s[n] for n in names], "qd": [0.0] * len(names), "t": 0.0} for s in states
        ]}))
        out = subprocess.run([flexdyn, "eval", "--scene", str(SCENE), "--states", str(path)],
                             capture_output=True, text=True)
    if out.returncode != 0:
        sys.exit(f"flexdyn eval failed: {out.stderr}")
    out = out.stdout
    return np.array([r["markers"]["tool0"]["position"] for r in json.loads(out)["results"]])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--flexdyn", default=str(ROOT / "target" / "release" / "flexdyn"))
    ap.add_argument("--png", default=str(Path(__file__).with_name("tip_deviation.png")))
    args = ap.parse_args()
    scene = tomllib.loads(SCENE.read_text())
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "inverse.csv"
        cmd = [args.flexdyn, "inverse", "--scene", str(SCENE), "--duration", "3", "--dt", "0.005"]
        for k, e in PRESCRIBE.items():
            cmd += ["--prescribe", f"{k}={e}"]
        subprocess.run(cmd + ["--csv", str(out)], check=True)
        rows = list(csv.reader(out.open()))
    head, data = rows[0], np.array(rows[1:], dtype=float)
    # Columns: t, the actuators, then the coordinates (named like them).
    na = len(scene["actuators"])
    coord = {n: data[:, 1 + na + i] for i, n in enumerate(head[1 + na :])}
    names = [c["name"] for c in scene["coordinates"]]

    # Statics at t = 0.
    q0 = {n: coord[n][0] for n in names}
    worst = 0.0
    for tw, gear in TWISTS.items():
        k = next(c["stiffness"] for c in scene["components"] if c["name"] == gear)
        h = 1e-6
        qp, qm = dict(q0), dict(q0)
        qp[tw] += h
        qm[tw] -= h
        dv = (potential(scene, qp) - potential(scene, qm)) / (2 * h)
        spring = k * q0[tw]
        rel = abs(spring + dv) / abs(dv)
        worst = max(worst, rel)
        print(f"{tw}: k e = {spring:.4f} N m, -dV/de = {-dv:.4f} N m, relative difference {rel:.2e}")

    # Tip deviation along the trajectory: the generated marker at the
    # flexible state, with the tube straight, and at the rigid state.
    every = list(coord)  # the model's coordinates, the tube's modes included
    elastic = [n for n in every if n in TWISTS or n.startswith(MODE_PREFIX)]
    variants = {"flexible": [], "gears": [], "rigid": []}
    for i in range(len(data)):
        qf = {n: coord[n][i] for n in every}
        variants["flexible"].append(qf)
        variants["gears"].append({n: 0.0 if n.startswith(MODE_PREFIX) else v for n, v in qf.items()})
        variants["rigid"].append({n: 0.0 if n in elastic else v for n, v in qf.items()})
    tool = {k: marker_positions(args.flexdyn, every, v) for k, v in variants.items()}
    dev = (tool["flexible"] - tool["rigid"]) * 1e3
    tube = (tool["flexible"] - tool["gears"]) * 1e3
    t = data[:, 0]
    norm = np.linalg.norm(dev, axis=1)
    tube_norm = np.linalg.norm(tube, axis=1)
    print(f"tool0 deviation: max {norm.max():.4f} mm at t = {t[norm.argmax()]:.3f} s, "
          f"{norm[0]:.4f} mm at t = 0, {norm[-1]:.4f} mm at t = {t[-1]:.3f} s")
    print(f"of which the tube's bending: {tube_norm[0] * 1e3:.2f} um at t = 0, "
          f"max {tube_norm.max() * 1e3:.2f} um at t = {t[tube_norm.argmax()]:.3f} s")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4))
    for j, lab in enumerate("xyz"):
        ax.plot(t, dev[:, j], label=f"{lab}")
    ax.plot(t, norm, "k", label="|deviation|")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("tool0 flexible - rigid (mm)")
    ax2 = ax.twinx()
    ax2.plot(t, tube_norm * 1e3, "k--", label="|tube bending's share| (um, right)")
    ax2.set_ylabel("tube bending's share (um)")
    ax2.set_ylim(0, 1.2 * tube_norm.max() * 1e3)
    ax2.legend(loc="lower right")
    ax.set_title("ur5_flexible: tool flange deviation along the inverse-dynamics trajectory")
    ax.legend(loc="center left", ncol=4)
    ax.grid(True)
    fig.tight_layout()
    fig.savefig(args.png, dpi=100)
    print(f"wrote {args.png}")
    if worst > 1e-3:
        sys.exit(f"statics check failed: relative difference {worst:.2e} > 1e-3")


if __name__ == "__main__":
    main()
