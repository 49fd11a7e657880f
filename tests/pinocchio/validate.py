"""Validate `flexdyn import urdf` + `flexdyn eval` against Pinocchio.

For each robot: import its URDF (from example-robot-data in this Python
environment) with `flexdyn import urdf`, evaluate the mass matrix M and the
bias forces h of the imported scene with `flexdyn eval --scene` (the
interpreter) at seeded random states, and compare with Pinocchio's
`crba` (symmetrized), `nonLinearEffects` and `rnea` (against M qdd + h).
Joints are matched by name. Pinocchio leaves joint damping out of both;
the damping forces `d qd` of the URDF's `<dynamics damping>` are added to
its values. The UR5 is validated a second time with rotor inertias
(`armature` on its actuators, Pinocchio's `model.armature`). Errors are relative to the scale of each term: the largest
magnitude of the reference over all states.

For UR5 and Panda the imported scene's generated Rust module
(`flexdyn generate`) is also scanned: no numeric literal in it may be
nonzero and below 1e-14 in magnitude (a round-off of zero; with exact
constant folding, rotations by multiples of pi/2 leave none).

Exit status 0 when every term of every robot is within the tolerance, 1
otherwise. Every link's marker (`import urdf` puts one at the origin of every link)
is compared with Pinocchio's frame of that link: position and rotation
(`framesForwardKinematics`), the Jacobian in LOCAL_WORLD_ALIGNED
(`computeFrameJacobian`), the velocity and, at zero joint accelerations, the
classical acceleration (`getFrameVelocity`, `getFrameClassicalAcceleration`).

The comparisons import with `--keep-angles` (Pinocchio builds the URDF as
written); the default import (angles within their written precision of a
multiple of pi/12 snapped) is the one compared with the shipped scene and
scanned for round-off literals. TIAGo as published (torso, arm and head)
must import, and its generated code must have the operation count of the
same URDF with its angles written exactly (within 5 %).

UR5, Panda and Baxter are imported once more with `--output
dynamics_derivatives`: their `d tau/dq`, `d tau/dqd` (at random
accelerations) against `computeRNEADerivatives`, and their forward dynamics
with `d qdd/dq`, `d qdd/dqd`, `d qdd/dtau` (at random inputs) against
Pinocchio's `crba`, `nonLinearEffects` and RNEA derivatives solved by LAPACK
(to `eps cond(M)`) and against `aba` and `computeABADerivatives`.

`--perturb` changes one inertia entry of each imported scene
(the first entry of the last rigid body's inertia, times 1 + 1e-6) and
moves its last marker by 1e-6 m before evaluating it: the comparison must
then fail.

`--shipped DIR` checks that the scenes shipped in DIR for these robots
(`ur5.toml` in `scenes/`) are the import of today, below their header
comment.

`--every` checks every URDF file of example-robot-data instead, as
published (no joint held): terms, markers and derivatives (Pinocchio's ABA
derivatives reported, not required), and the default import's terms and
markers within ten times its largest snapped angle, or the refusal
`REFUSED` expects.

Usage: validate.py --flexdyn BIN --work DIR [--states N] [--perturb] [--shipped DIR] [--every]
"""

import argparse
import json
import os
import re
import subprocess
import sys
import tomllib

import numpy as np
import pinocchio as pin

TOLERANCE = 1e-12

# (name, URDF path under example-robot-data's robots/, joints held fixed at 0,
# whether to scan the generated code for round-off of zeros)
ROBOTS = [
    ("ur5", "ur_description/urdf/ur5_robot.urdf", [], True),
    # The Panda's two finger joints (prismatic, the second a mimic of the
    # first) are held fixed at 0: the hand and fingers become part of the
    # last arm link, on both sides (Pinocchio: buildReducedModel at 0).
    (
        "panda",
        "panda_description/urdf/panda.urdf",
        ["panda_finger_joint1", "panda_finger_joint2"],
        True,
    ),
    # A tree with prismatic joints (grippers), 19 moving joints.
    ("baxter", "baxter_description/urdf/baxter.urdf", [], False),
    # Two more arms the derivation was not tuned on (7 and 6 joints).
    ("xarm7", "xarm_description/urdf/xarm7.urdf", [], False),
    ("z1", "z1_description/urdf/z1.urdf", [], False),
    # Two humanoids with inertias as published: Romeo's arm links break the
    # triangle inequality (imported with `allow_unphysical_inertia`), iCub's
    # tensors include rounding noise (`ixz = 2.4e-35`, all else zero) that
    # the body's own scale absorbs.
    ("romeo_small", "romeo_description/urdf/romeo_small.urdf", [], False),
    ("icub", "icub_description/robots/icub.urdf", [], False),
]

# Robots whose generated derivatives (`--output dynamics_derivatives`) are
# compared with Pinocchio's RNEA and ABA derivatives.
DERIVATIVES = ("ur5", "panda", "baxter")

# Robots validated again with rotor inertias: `armature = ARMATURE[k]` added
# to the k-th actuator of the imported scene, `model.armature` set alike.
ARMATURE = {"ur5": [0.3, 0.25, 0.2, 0.05, 0.04, 0.03]}


def add_armature(text, values):
    """`armature = v` after the `coordinate = ...` line of each actuator."""
    parts = text.split("[[actuators]]\n")
    out = [parts[0]]
    for part, v in zip(parts[1:], values, strict=True):
        lines = part.split("\n")
        k = next(i for i, l in enumerate(lines) if l.startswith("coordinate = "))
        lines.insert(k + 1, f"armature = {v!r}")
        out.append("\n".join(lines))
    return "[[actuators]]\n".join(out)


def robots_dir():
    prefix = os.path.join(sys.prefix, "lib")
    for root, dirs, _ in os.walk(prefix):
        if root.endswith(os.path.join("cmeel.prefix", "share", "example-robot-data")):
            return os.path.join(root, "robots")
    sys.exit("example-robot-data's robots/ folder not found under " + prefix)


def identifier(name, prefix="j"):
    """The scene identifier `flexdyn import urdf` gives a URDF joint name
    (prefix `l` for a link)."""
    s = re.sub(r"[^A-Za-z0-9_]", "_", name)
    if not s[:1].isalpha():
        s = prefix + "_" + s
    return s


MARKER_TERMS = ("position", "rotation", "jacobian", "velocity", "acceleration_bias")


def marker_errors(model, data, order, results, pin_states):
    """Worst error and scale of each marker term over all states and every
    marker (one per link), against Pinocchio's frame of the link:
    `framesForwardKinematics` (position, rotation), `computeFrameJacobian`
    in LOCAL_WORLD_ALIGNED, `getFrameVelocity` and, at zero joint
    accelerations, `getFrameClassicalAcceleration` (both LOCAL_WORLD_ALIGNED).
    Also the number of markers compared; an unknown marker name is an error."""
    frames = {}
    for fid, f in enumerate(model.frames):
        if f.type == pin.FrameType.BODY:
            frames[identifier(f.name, "l")] = fid
    worst = dict.fromkeys(MARKER_TERMS, 0.0)
    scale = dict.fromkeys(MARKER_TERMS, 0.0)
    lwa = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
    count = 0
    for r, (qp, vp) in zip(results, pin_states):
        markers = r.get("markers", {})
        count = max(count, len(markers))
        pin.forwardKinematics(model, data, qp, vp, np.zeros(model.nv))
        pin.updateFramePlacements(model, data)
        for name, got in markers.items():
            if name not in frames:
                sys.exit(f"marker `{name}` is no link frame of Pinocchio's model")
            fid = frames[name]
            placement = data.oMf[fid]
            v = pin.getFrameVelocity(model, data, fid, lwa)
            a = pin.getFrameClassicalAcceleration(model, data, fid, lwa)
            jac = pin.computeFrameJacobian(model, data, qp, fid, lwa)[:, order]
            want = {
                "position": placement.translation,
                "rotation": placement.rotation,
                "jacobian": jac,
                "velocity": np.concatenate([v.linear, v.angular]),
                "acceleration_bias": np.concatenate([a.linear, a.angular]),
            }
            for term in MARKER_TERMS:
                w = np.asarray(want[term])
                worst[term] = max(worst[term], float(np.abs(np.array(got[term]) - w).max()))
                scale[term] = max(scale[term], float(np.abs(w).max()))
    return worst, scale, count


def run(cmd):
    out = subprocess.run(cmd, capture_output=True, text=True)
    if out.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed:\n{out.stdout}\n{out.stderr}")


def perturb(text):
    """The first entry of the last `inertia = ...` line times 1 + 1e-6, and
    the last marker moved by 1e-6 m along z from its link's origin."""
    lines = text.splitlines(keepends=True)
    k = max(i for i, l in enumerate(lines) if l.startswith("inertia = "))
    m = re.match(r"(inertia = \[+)([-0-9.eE+]+)", lines[k])
    value = float(m.group(2)) * (1 + 1e-6)
    lines[k] = m.group(1) + repr(value) + lines[k][m.end():]
    text = "".join(lines)
    if "[[markers]]" in text:
        text = text.rstrip("\n") + "\nposition = [0, 0, 1e-6]\n"
    return text


def perturb_file(scene, args):
    """With `--perturb`, the scene file perturbed in place ([`perturb`])."""
    if args.perturb:
        with open(scene) as f:
            text = perturb(f.read())
        with open(scene, "w") as f:
            f.write(text)


LITERAL = re.compile(r"(?<![A-Za-z0-9_.])(\d+\.\d*(?:e[-+]?\d+)?|\d+e[-+]?\d+)")


def round_off_literals(name, scene, args):
    """The nonzero numeric literals below 1e-14 of the scene's generated module."""
    out = os.path.join(args.work, "generated")
    run([args.flexdyn, "generate", "--scene", scene, "--out", out, "--quiet"])
    with open(os.path.join(out, f"{name}.rs")) as f:
        values = [float(x) for x in LITERAL.findall(f.read())]
    return len(values), [x for x in values if x != 0.0 and abs(x) < 1e-14]


def reference_model(path, fixed):
    model = pin.buildModelFromUrdf(path)
    if fixed:
        ids = [model.getJointId(n) for n in fixed]
        model = pin.buildReducedModel(model, ids, pin.neutral(model))
    return model


def pin_state(model, joints, coordinates, q, qd, qdd):
    """Pinocchio's configuration, velocity and acceleration of the scene's
    coordinates `q`, rates `qd` and accelerations `qdd` (joints matched by
    name; a continuous joint's configuration is (cos, sin))."""
    qp, vp, ap = pin.neutral(model), np.zeros(model.nv), np.zeros(model.nv)
    for i, c in enumerate(coordinates):
        j = joints[c]
        if j.nq == 2:  # continuous: (cos, sin)
            qp[j.idx_q : j.idx_q + 2] = [np.cos(q[i]), np.sin(q[i])]
        else:
            qp[j.idx_q] = q[i]
        vp[j.idx_v] = qd[i]
        ap[j.idx_v] = qdd[i]
    return qp, vp, ap


def imported_joints(model, scene):
    """The scene's coordinate names, and Pinocchio's joints by those names."""
    with open(scene) as f:
        coordinates = re.findall(r'^\[\[coordinates\]\]\n(?:#.*\n)*name = "([^"]*)"', f.read(), re.M)
    joints = {identifier(model.names[jid]): model.joints[jid] for jid in range(1, model.njoints)}
    if any(c not in joints for c in coordinates) or model.nv != len(coordinates):
        sys.exit(f"{scene}: coordinates {coordinates} do not match Pinocchio's joints {list(joints)}")
    return coordinates, joints


DERIVATIVE_TERMS = ("d tau/dq", "d tau/dqd", "qdd", "d qdd/dq", "d qdd/dqd", "d qdd/dtau")



def derivatives_check(name, path, fixed, args, against_aba=True):
    """The robot imported with `--output dynamics_derivatives`: `flexdyn
    eval`'s `inverse_dynamics_q`, `inverse_dynamics_qd` against Pinocchio's
    `computeRNEADerivatives`, and `forward_dynamics` with its derivatives
    (joint damping `d qd` added: `d tau/dqd + diag(d)`, and the forward
    dynamics at `B tau - d qd`, so `d qdd/dqd - M^-1 diag(d)`), at
    `args.states` random states, each relative to the scale of the term.

    The forward dynamics' terms are compared with a reference independent of
    any articulated-body algorithm: Pinocchio's own `crba`,
    `nonLinearEffects` and `computeRNEADerivatives` (at the solved
    accelerations) solved by LAPACK, `qdd = M^-1 (tau - h)`, `d qdd/dx = -M^-1
    d ID/dx`, `d qdd/dtau = M^-1`. Any solve loses up to `eps cond(M)` of
    its scale, so the tolerance is `TOLERANCE` or `10 eps cond(M)` at the
    state, whichever is larger (TIAGo's and iCub's mass matrices reach
    `cond(M)` 1e5 to 1e10, the UR5's 3e2). With `against_aba`,
    `computeABADerivatives` must also agree to `TOLERANCE`; otherwise its
    distance from the reference is reported."""
    scene = import_robot(f"{name}_derivatives", path, fixed, args, "--output", "dynamics_derivatives",
                         "--keep-angles")
    perturb_file(scene, args)
    model = reference_model(path, fixed)
    coordinates, joints = imported_joints(model, scene)
    data = model.createData()
    n = len(coordinates)
    order = [joints[c].idx_v for c in coordinates]
    ix = np.ix_(order, order)
    rng = np.random.default_rng(20261126)
    states, refs, abas, allowed, ms = [], [], [], [], []
    massless = False
    for _ in range(args.states):
        q = rng.uniform(-np.pi, np.pi, n)
        qd = rng.uniform(-3.0, 3.0, n)
        qdd = rng.uniform(-5.0, 5.0, n)
        tau = rng.uniform(-20.0, 20.0, n)
        qp, vp, ap = pin_state(model, joints, coordinates, q, qd, qdd)
        damping = np.diag(model.damping)
        # Copies: the returned arrays are views of `data`, which later calls
        # overwrite.
        dq, dv = (d.copy() for d in pin.computeRNEADerivatives(model, data, qp, vp, ap)[:2])
        # The scene's actuator j drives coordinate j with gain 1.
        tau_p = np.zeros(model.nv)
        tau_p[order] = tau
        tau_p -= model.damping * vp
        m = pin.crba(model, data, qp)
        m = np.triu(m) + np.triu(m, 1).T
        ms.append(m[ix])
        refs.append({"d tau/dq": dq[ix], "d tau/dqd": (dv + damping)[ix]})
        states.append({"q": q.tolist(), "qd": qd.tolist(), "qdd": qdd.tolist(), "tau": tau.tolist(), "t": 0.0})
        massless = not np.diag(m).all()
        if massless:
            continue
        solved = np.linalg.solve(m, tau_p - pin.nonLinearEffects(model, data, qp, vp))
        sq, sv = (d.copy() for d in pin.computeRNEADerivatives(model, data, qp, vp, solved)[:2])
        fq, fv, minv = (d.copy() for d in pin.computeABADerivatives(model, data, qp, vp, tau_p))
        minv = np.triu(minv) + np.triu(minv, 1).T
        allowed.append(max(TOLERANCE, 10 * np.finfo(float).eps * np.linalg.cond(m[ix])))
        refs[-1].update({
            "qdd": solved[order],
            "d qdd/dq": -np.linalg.solve(m, sq)[ix], "d qdd/dqd": -np.linalg.solve(m, sv + damping)[ix],
            "d qdd/dtau": np.linalg.inv(m)[ix],
        })
        abas.append({
            "qdd": pin.aba(model, data, qp, vp, tau_p)[order], "d qdd/dq": fq[ix],
            "d qdd/dqd": (fv - minv @ damping)[ix], "d qdd/dtau": minv[ix],
        })
    states_file = os.path.join(args.work, f"{name}_derivatives.states.json")
    with open(states_file, "w") as f:
        json.dump({"states": states}, f)
    out_file = os.path.join(args.work, f"{name}_derivatives.eval.json")
    run([args.flexdyn, "eval", "--interpret", "--scene", scene, "--states", states_file, "--out", out_file])
    with open(out_file) as f:
        results = json.load(f)["results"]
    if massless:
        # No forward dynamics where a joint moves no mass (Pinocchio's `aba`
        # is not finite there either): `eval` must leave them out, naming it.
        left_out = all("moves with it" in r.get("forward_dynamics_error", "") for r in results)
        print(f"{name}: derivatives: M singular (joints moving no mass): forward dynamics left out "
              f"at every state {'ok' if left_out else 'FAILED'}")
        ok = left_out
        terms = DERIVATIVE_TERMS[:2]
    else:
        ok = True
        terms = DERIVATIVE_TERMS
    keys = {"d tau/dq": "inverse_dynamics_q", "d tau/dqd": "inverse_dynamics_qd", "qdd": "forward_dynamics",
            "d qdd/dq": "forward_dynamics_q", "d qdd/dqd": "forward_dynamics_qd", "d qdd/dtau": "forward_dynamics_tau"}
    # Where a term vanishes (below 1e-6 of that size: a quadrotor's rotors,
    # whose `d tau/dqd` is 1e-19 of round-off in Pinocchio and exactly 0
    # here), its errors are relative to the
    # size its products of inertias and rates would have: `|M| |qd|` for
    # `d tau/dqd`, `|M| (|qd|^2 + |qdd|)` for `d tau/dq`, and `|M^-1|` times
    # those, or times `|tau|`, for the forward dynamics.
    m_scale = max(float(np.abs(m).max()) for m in ms)
    inv_scale = max((float(np.abs(ref["d qdd/dtau"]).max()) for ref in refs if "d qdd/dtau" in ref), default=0.0)
    floors = {"d tau/dq": m_scale * (3.0**2 + 5.0), "d tau/dqd": m_scale * 3.0}
    floors |= {"qdd": inv_scale * 20.0, "d qdd/dq": inv_scale * floors["d tau/dq"],
               "d qdd/dqd": inv_scale * floors["d tau/dqd"], "d qdd/dtau": inv_scale}
    for term in terms:
        scale = max(float(np.abs(ref[term]).max()) for ref in refs)
        scale = scale if scale >= 1e-6 * floors[term] else floors[term]
        errors = [float(np.abs(np.array(r[keys[term]]) - ref[term]).max()) / scale for r, ref in zip(results, refs)]
        forward = bool(abas) and term in abas[0]
        tolerances = allowed if forward else [TOLERANCE] * len(errors)
        good = all(e <= t for e, t in zip(errors, tolerances))
        line = f"{name}: derivatives: {term}: relative error {max(errors):.3e}"
        if forward:
            aba = max(float(np.abs(a[term] - ref[term]).max()) for a, ref in zip(abas, refs)) / scale
            line += (f" (allowed {min(tolerances):.1e} to {max(tolerances):.1e} by cond(M)); "
                     f"Pinocchio's ABA {aba:.3e} from the LAPACK reference")
            if against_aba:
                mine = max(float(np.abs(np.array(r[keys[term]]) - a[term]).max()) for r, a in zip(results, abas))
                good &= mine / scale <= TOLERANCE
                line += f", flexdyn {mine / scale:.3e} from it"
        ok &= good
        print(f"{line} {'ok' if good else 'FAILED'}")
    return ok


def import_robot(stem, path, fixed, args, *extra):
    """`flexdyn import urdf` of `path` into `args.work/stem.toml`."""
    scene = os.path.join(args.work, f"{stem}.toml")
    cmd = [args.flexdyn, "import", "urdf", path, "--out", scene, *extra]
    for j in fixed:
        cmd += ["--fix", j]
    run(cmd)
    return scene


# TIAGo's torso, arm and head (every other moving joint held fixed).
TIAGO = ("tiago_description/robots/tiago.urdf",
         ["torso_lift_joint", "head_1_joint", "head_2_joint"] + [f"arm_{k}_joint" for k in range(1, 8)])


def operation_counts(scene, args):
    """Operations (add + mul + div + call) of each function of the scene's
    generated module, from its header."""
    out = os.path.join(args.work, "generated")
    run([args.flexdyn, "generate", "--scene", scene, "--out", out, "--quiet"])
    name = re.search(r'^name = "([^"]*)"', open(scene).read(), re.M).group(1)
    counts = {}
    for line in open(os.path.join(out, f"{name}.rs")):
        m = re.match(r"//   (\w+)\s+(\d+)\s+(\d+)\s+(\d+)\s+(\d+)$", line)
        if m:
            counts[m.group(1)] = sum(int(g) for g in m.groups()[1:])
    return counts


def tiago_check(base, args):
    """TIAGo as published (1e-6 kg antennas with tensors that are not
    positive semi-definite, fixed to the base; quarter turns written as
    `1.57079632679`) imports, and its generated code has the operation
    count of the same URDF with its angles written exactly (within 5 %)."""
    rel, moving = TIAGO
    path = os.path.join(base, rel)
    text = open(path).read()
    joints = re.findall(r'<joint name="([^"]+)" type="(?:revolute|continuous|prismatic)"', text)
    fixed = [j for j in joints if j not in moving]

    def exact(m):
        words = []
        for w in m.group(1).split():
            try:
                x = float(w)
            except ValueError:
                words.append(w)
                continue
            n = round(x * 12 / np.pi)
            words.append(repr(n * np.pi / 12) if abs(x - n * np.pi / 12) < 1e-9 else w)
        return 'rpy="' + " ".join(words) + '"'

    exact_path = os.path.join(args.work, "tiago_exact_angles.urdf")
    with open(exact_path, "w") as f:
        f.write(re.sub(r'rpy="([^"]*)"', exact, text))
    published = operation_counts(import_robot("tiago", path, fixed, args), args)
    written = operation_counts(import_robot("tiago_exact", exact_path, fixed, args, "--keep-angles"), args)
    ok = True
    for f in ("inverse_dynamics", "dynamics_terms", "mass_matrix", "bias"):
        ratio = published[f] / written[f]
        good = ratio <= 1.05
        ok &= good
        print(f"tiago: {f}: {published[f]} operations as published, {written[f]} with exact angles "
              f"({ratio:.3f}) {'ok' if good else 'FAILED'}")
    return ok


def snapping(scene):
    """The largest change the import's snapping made to an angle of
    `scene` (its header), 0 where none."""
    with open(scene) as f:
        found = re.search(r"largest change ([0-9.e+-]+) rad", f.read())
    return float(found.group(1)) if found else 0.0


def validate(name, path, fixed, scan, args, armature=None, snapped=False):
    # What users get (angles within their written precision of a multiple
    # of pi/12 snapped): the shipped scene and the literal scan. The
    # comparisons with Pinocchio, which builds the URDF as written, use
    # `--keep-angles`; with `snapped`, the default import is compared
    # instead, within ten times its largest snapped angle (the round-off of
    # zero it also drops changes the model by 1e-12 of a vector at most).
    default = import_robot(name, path, fixed, args)
    scene = default if snapped else import_robot(f"{name}_as_written", path, fixed, args, "--keep-angles")
    tolerance = max(TOLERANCE, 10 * snapping(default)) if snapped else TOLERANCE
    if snapped:
        name += " (default import)"
    ok = True
    shipped = args.shipped and os.path.join(args.shipped, f"{name}.toml")
    if shipped and not armature and os.path.exists(shipped):
        with open(shipped) as f:
            text = f.read()
        with open(default) as f:
            fresh = f.read()
        same = text[text.index("# Imported by") :] == fresh
        ok &= same
        print(f"{name}: shipped {shipped} {'is the import' if same else 'FAILED: differs from a fresh import'}")
    if armature:
        with open(scene) as f:
            text = add_armature(f.read(), armature)
        scene = os.path.join(args.work, f"{name}_armature.toml")
        with open(scene, "w") as f:
            f.write(text)
        name += " with armature"
    perturb_file(scene, args)
    model = reference_model(path, fixed)
    coordinates, joints = imported_joints(model, scene)
    n = len(coordinates)
    for c, v in zip(coordinates, armature or []):
        model.armature[joints[c].idx_v] = v
    data = model.createData()

    rng = np.random.default_rng(20261123)
    states, refs, pin_states = [], [], []
    for _ in range(args.states):
        q = rng.uniform(-np.pi, np.pi, n)
        qd = rng.uniform(-3.0, 3.0, n)
        qdd = rng.uniform(-5.0, 5.0, n)
        qp, vp, ap = pin_state(model, joints, coordinates, q, qd, qdd)
        order = [joints[c].idx_v for c in coordinates]
        m = pin.crba(model, data, qp)
        m = np.triu(m) + np.triu(m, 1).T
        damping = model.damping * vp
        h = pin.nonLinearEffects(model, data, qp, vp) + damping
        tau = pin.rnea(model, data, qp, vp, ap) + damping
        refs.append((m[np.ix_(order, order)], h[order], tau[order], qdd))
        pin_states.append((qp.copy(), vp.copy()))
        states.append({"q": q.tolist(), "qd": qd.tolist(), "t": 0.0})
    stem = os.path.splitext(os.path.basename(scene))[0]
    states_file = os.path.join(args.work, f"{stem}.states.json")
    with open(states_file, "w") as f:
        json.dump({"states": states}, f)
    out_file = os.path.join(args.work, f"{stem}.eval.json")
    run([args.flexdyn, "eval", "--interpret", "--scene", scene, "--states", states_file, "--out", out_file])
    with open(out_file) as f:
        results = json.load(f)["results"]

    worst = {"M": 0.0, "h": 0.0, "M qdd + h": 0.0}
    scale = {"M": 0.0, "h": 0.0, "M qdd + h": 0.0}
    for r, (m_ref, h_ref, tau_ref, qdd) in zip(results, refs):
        m = np.array(r["mass_matrix"])
        h = np.array(r["bias"])
        for term, got, want in (
            ("M", m, m_ref),
            ("h", h, h_ref),
            ("M qdd + h", m @ qdd + h, tau_ref),
        ):
            worst[term] = max(worst[term], float(np.abs(got - want).max()))
            scale[term] = max(scale[term], float(np.abs(want).max()))
    if not armature:
        m_worst, m_scale, count = marker_errors(model, data, order, results, pin_states)
        links = len(re.findall(r"^\[\[markers\]\]", open(scene).read(), re.M))
        good = count == links and count > 0
        ok &= good
        print(f"{name}: markers: {count} of {links} links {'ok' if good else 'FAILED'}")
        for term in MARKER_TERMS:
            worst[f"marker {term}"] = m_worst[term]
            scale[f"marker {term}"] = m_scale[term]
    if scan:
        count, small = round_off_literals(name, default, args)
        ok &= not small
        print(
            f"{name}: generated code: {count} literals, {len(small)} nonzero below 1e-14 "
            f"{'ok' if not small else 'FAILED: ' + str(sorted(set(small))[:5])}"
        )
    for term in worst:
        rel = worst[term] / max(scale[term], 1e-300)
        good = rel <= tolerance
        ok &= good
        print(
            f"{name}: {term}: max error {worst[term]:.3e}, scale {scale[term]:.3e}, "
            f"relative {rel:.3e} {'ok' if good else 'FAILED'}"
        )
    return ok


# Robots whose every joint is prescribed in `flexdyn inverse` (interpreted,
# at the scene's own size) and the torques compared with Pinocchio's `rnea`
# along the prescribed motion: Baxter (19 joints) and a fixed-base TALOS
# (32 joints), both beyond the 8 actuators the command once took.
INVERSE = [
    ("baxter", "baxter_description/urdf/baxter.urdf"),
    ("talos", "talos_data/robots/talos_reduced.urdf"),
]


def inverse_check(name, path, args):
    """`flexdyn inverse` with q_i = a_i sin(w_i t + p_i) on every joint
    against `rnea` at every output time, to TOLERANCE of the torques' scale."""
    scene = os.path.join(args.work, f"{name}_inverse.toml")
    run([args.flexdyn, "import", "urdf", path, "--out", scene, "--keep-angles"])
    if args.perturb:
        with open(scene) as f:
            text = perturb(f.read())
        with open(scene, "w") as f:
            f.write(text)
    with open(scene, "rb") as f:
        parsed = tomllib.load(f)
    coordinates = [c["name"] for c in parsed["coordinates"]]
    actuators = parsed["actuators"]
    n = len(coordinates)
    motion = {}
    for i, c in enumerate(coordinates):
        amp, w, ph = 0.2 + 0.01 * i, 1.0 + 0.1 * i, 0.37 * i
        motion[c] = (amp, w, ph)
    motion_file = os.path.join(args.work, f"{name}_motion.toml")
    with open(motion_file, "w") as f:
        f.write("[prescribe]\n")
        for c, (amp, w, ph) in motion.items():
            f.write(f'{c} = "{amp!r}*sin({w!r}*t + {ph!r})"\n')
    csv_file = os.path.join(args.work, f"{name}_inverse.csv")
    run([args.flexdyn, "inverse", "--scene", scene, "--interpret", "--duration", "1",
         "--dt", "0.05", "--motion", motion_file, "--csv", csv_file, "--quiet"])
    with open(csv_file) as f:
        header = f.readline().strip().split(",")
        rows = [[float(x) for x in line.split(",")] for line in f if line.strip()]
    taken = {"t", *coordinates}
    column = {}
    for a in actuators:
        col = a["name"]
        while col in taken or col.startswith("lambda_"):
            col = "tau_" + col
        taken.add(col)
        column[a["coordinate"]] = header.index(col)
    model = reference_model(path, [])
    joints = {identifier(model.names[j]): model.joints[j] for j in range(1, model.njoints)}
    if model.nv != n or any(c not in joints for c in coordinates):
        sys.exit(f"{name}: coordinates {coordinates} do not match Pinocchio's joints {list(joints)}")
    data = model.createData()
    worst, scale = 0.0, 0.0
    for row in rows:
        t = row[0]
        qp, vp, ap = pin.neutral(model), np.zeros(model.nv), np.zeros(model.nv)
        for c in coordinates:
            amp, w, ph = motion[c]
            x = amp * np.sin(w * t + ph)
            j = joints[c]
            if j.nq == 2:
                qp[j.idx_q : j.idx_q + 2] = [np.cos(x), np.sin(x)]
            else:
                qp[j.idx_q] = x
            vp[j.idx_v] = amp * w * np.cos(w * t + ph)
            ap[j.idx_v] = -amp * w * w * np.sin(w * t + ph)
        tau = pin.rnea(model, data, qp, vp, ap) + model.damping * vp
        for c in coordinates:
            want = tau[joints[c].idx_v]
            worst = max(worst, abs(row[column[c]] - want))
            scale = max(scale, abs(want))
    rel = worst / scale
    good = rel <= TOLERANCE and len(rows) == 21
    print(
        f"{name}: inverse ({n} joints prescribed, {len(rows)} samples): max torque error "
        f"{worst:.3e}, scale {scale:.3e}, relative {rel:.3e} {'ok' if good else 'FAILED'}"
    )
    return good


# The files of example-robot-data that `--every` expects `flexdyn import
# urdf` to refuse, with a piece of the error.
REFUSED = {
    "ur_description/urdf/ur3.urdf": "the robot has no <link>",
    "hector_description/robots/quadrotor_base.urdf": "no moving joint",
    "iris_description/robots/iris_simple.urdf": "no moving joint",
    "romeo_description/urdf/romeo_laas_small.urdf": "`LHipPitch_link`: the inertia tensor is not positive semi-definite",
}


def every_urdf(args):
    """Every URDF file of example-robot-data, as published (no joint held):
    terms, markers and derivatives against Pinocchio, or the refusal that
    `REFUSED` expects. Pinocchio's ABA derivatives are reported, not
    required (see `derivatives_check`)."""
    base = robots_dir()
    files = sorted(os.path.relpath(os.path.join(root, f), base)
                   for root, _, names in os.walk(base) for f in names if f.endswith(".urdf"))
    ok, passed = True, 0
    for rel in files:
        path = os.path.join(base, rel)
        name = re.sub(r"\W", "_", os.path.splitext(os.path.basename(rel))[0])
        if rel in REFUSED:
            out = subprocess.run([args.flexdyn, "import", "urdf", path, "--out",
                                  os.path.join(args.work, f"{name}.toml")], capture_output=True, text=True)
            good = out.returncode == 1 and REFUSED[rel] in out.stderr and "panicked" not in out.stderr
            print(f"{rel}: refused {'as expected' if good else 'FAILED: ' + out.stderr.strip()}")
        else:
            good = (validate(name, path, [], False, args) & validate(name, path, [], False, args, snapped=True)
                    & derivatives_check(name, path, [], args, False))
            print(f"{rel}: {'ok' if good else 'FAILED'}")
        ok &= good
        passed += good
    print(f"{passed} of {len(files)} URDF files as expected")
    return ok


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--flexdyn", required=True)
    p.add_argument("--work", required=True)
    p.add_argument("--states", type=int, default=1000)
    p.add_argument("--perturb", action="store_true")
    p.add_argument("--shipped")
    p.add_argument("--every", action="store_true",
                   help="every URDF of example-robot-data instead of the named robots")
    args = p.parse_args()
    if args.every:
        ok = every_urdf(args)
        print("pinocchio validation:", "passed" if ok else "FAILED")
        sys.exit(0 if ok else 1)
    base = robots_dir()
    ok = True
    for name, rel, fixed, scan in ROBOTS:
        ok &= validate(name, os.path.join(base, rel), fixed, scan, args)
        if name in ARMATURE:
            ok &= validate(name, os.path.join(base, rel), fixed, False, args, ARMATURE[name])
        if name in DERIVATIVES:
            ok &= derivatives_check(name, os.path.join(base, rel), fixed, args)
    for name, rel in INVERSE:
        ok &= inverse_check(name, os.path.join(base, rel), args)
    if not args.perturb:
        ok &= tiago_check(base, args)
    print("pinocchio validation:", "passed" if ok else "FAILED")
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
