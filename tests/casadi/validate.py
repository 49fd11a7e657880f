#!/usr/bin/env python3
"""Validate every term flexdyn generates against CasADi's automatic differentiation.

For each scene (the files given, or every ``scenes/*.toml``):

1. ``flexdyn export`` writes the scene's symbolic inputs (format
   ``flexdyn-scene-export/1``, see ``docs/export-format.md``);
2. the energies ``T``, ``V``, ``D`` and the constraint residuals ``Phi`` are
   rebuilt as CasADi SX expressions, node by node, in one pass;
3. every term is derived from them with CasADi AD only (nothing of flexdyn's
   own differentiation is reused):

   * ``M = hessian(T, qd)``;
   * ``coriolis = d/dt(dT/dqd)|_(qdd=0) - dT/dq``, the time derivative taken
     with ``jtimes`` along ``(q, t) -> (qd, 1)``;
   * ``potential_forces = dV/dq``, ``damping_forces = dD/dqd``,
     ``bias = coriolis + potential_forces + damping_forces``;
   * ``inverse_dynamics = M qdd + bias`` at seeded random accelerations;
   * ``Phi_q = jacobian(Phi, q)``, ``Phi_t = jacobian(Phi, t)``,
     ``gamma = -d/dt(Phi_q qd + Phi_t)|_(qdd=0)`` (``jtimes`` again);
   * the Christoffel Coriolis matrix
     ``C_ij = sum_k (dM_ij/dq_k + dM_ik/dq_j - dM_jk/dq_i) qd_k / 2``;
   * each marker's kinematics from its exported world position ``p`` and
     rotation ``R`` alone: the Jacobian, linear rows ``jacobian(p, q)`` and
     angular columns ``vee(dR/dq_i R^T)``; the velocity ``J qd`` plus the
     explicit time terms ``dp/dt`` and ``vee(dR/dt R^T)``; the acceleration
     bias, the velocity's time derivative at ``qdd = 0`` (``jtimes`` along
     ``(q, t) -> (qd, 1)``);

4. one ``casadi.Function``, mapped over all states, evaluates them at seeded
   random states (plus the scene's "working states" from
   ``<scene dir>/<scene>.states.json`` when that file exists);
5. ``flexdyn eval`` evaluates the generated code once at the same states, and
   every term is compared: a term passes when
   ``max |rust - casadi| <= 1e-10 * max(max |casadi|, 1e-4 * S)`` over all
   states, relative to the term's own scale (``max |casadi|`` of that term,
   however small the scene's numbers), with a floor for terms that cancel
   to (near) zero: ``S`` is the largest ``|casadi|`` of any term of the
   scene (the actuator map, gains, left out), whose rounding such a term
   carries; for a marker's terms (lengths and angles, not forces), the
   largest of any marker's terms.

Exit status: 0 when every term of every scene passes, 1 when a term fails or
is missing from flexdyn's output, 2 on any other error.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
import zlib
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
FORMAT = "flexdyn-scene-export/1"
RTOL = 1e-10
# The floor of a term's scale, as a fraction of the scene's largest term
# (module docs): rounding of 1e-14 of the scene's scale passes in terms that
# cancel to zero.
CANCEL_FLOOR = 1e-4
# Terms whose size says nothing of the scene's (the actuator map: gains),
# left out of its largest term.
UNSCALED_TERMS = {"actuator_map"}
DEFAULT_SEED = 20240611
DEFAULT_RANGE = (-math.pi, math.pi)
DEFAULT_VELOCITY_RANGE = (-2.0, 2.0)
TIME_RANGE = (0.0, 5.0)


class ValidationError(Exception):
    """An error that stops the validation (not a failed comparison)."""


try:
    import numpy as np
    import casadi as ca
except ImportError as e:  # pragma: no cover - environment problem
    print(
        f"error: {e}. Install the pinned packages first:\n"
        f"  python3 -m pip install -r {Path(__file__).resolve().parent / 'requirements.txt'}",
        file=sys.stderr,
    )
    sys.exit(2)


# ---------------------------------------------------------------------------
# Command line and the flexdyn binary
# ---------------------------------------------------------------------------


def find_flexdyn(explicit: str | None) -> Path:
    """The flexdyn binary: --flexdyn, $FLEXDYN, the newest of target/{release,debug}, or PATH."""
    if explicit:
        p = Path(explicit)
        if not p.is_file():
            raise ValidationError(f"flexdyn binary `{explicit}` does not exist (from --flexdyn)")
        if not os.access(p, os.X_OK):
            raise ValidationError(f"flexdyn binary `{explicit}` is not executable")
        return p
    env = os.environ.get("FLEXDYN")
    if env:
        return find_flexdyn(env)
    exe = "flexdyn.exe" if os.name == "nt" else "flexdyn"
    built = [REPO / "target" / prof / exe for prof in ("release", "debug")]
    built = [p for p in built if p.is_file()]
    if built:
        return max(built, key=lambda p: p.stat().st_mtime)
    on_path = shutil.which("flexdyn")
    if on_path:
        return Path(on_path)
    raise ValidationError(
        "flexdyn binary not found: build it (`cargo build --release`) or pass --flexdyn PATH"
    )


def run_flexdyn(binary: Path, args: list[str], what: str) -> None:
    try:
        proc = subprocess.run(
            [str(binary), *args], capture_output=True, text=True, check=False
        )
    except OSError as e:
        raise ValidationError(f"cannot run {binary}: {e}") from e
    if proc.returncode != 0:
        detail = (proc.stderr.strip() or proc.stdout.strip() or "(no output)")
        raise ValidationError(
            f"{what} failed (exit status {proc.returncode}): {' '.join([str(binary), *args])}\n{detail}"
        )


def positive_or_zero(text: str) -> int:
    n = int(text)
    if n < 0:
        raise argparse.ArgumentTypeError("must be >= 0")
    return n


# ---------------------------------------------------------------------------
# Export -> CasADi
# ---------------------------------------------------------------------------


def load_export(path: Path) -> dict:
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as e:
        raise ValidationError(f"cannot read export {path}: {e}") from e
    if data.get("format") != FORMAT:
        raise ValidationError(
            f"{path}: unsupported export format {data.get('format')!r} (expected {FORMAT!r})"
        )
    for key in ("name", "coordinates", "runtime_parameters", "nodes", "components",
                "constraints", "actuators", "outputs"):
        if key not in data:
            raise ValidationError(f"{path}: export has no `{key}`")
    # Exports of flexdyn before markers have none.
    data.setdefault("markers", [])
    return data


# The export's functions of one argument as CasADi functions. CasADi's `sign`
# is 0 at 0, as the export's; `step` is Heaviside's (1 + sign)/2, 1/2 at 0.
# CasADi differentiates `fabs` to `sign` and `sign` to 0, as flexdyn does away
# from the switch.
UNARY = {
    "sin": ca.sin,
    "cos": ca.cos,
    "tan": ca.tan,
    "exp": ca.exp,
    "ln": ca.log,
    "sqrt": ca.sqrt,
    "abs": ca.fabs,
    "sign": ca.sign,
    "step": lambda x: 0.5 * (1 + ca.sign(x)),
}
LEAVES = ("const", "q", "qd", "t", "param")
# Groups of same-op nodes at the same depth smaller than this are built node by
# node; larger ones with one vectorised CasADi call (far less Python overhead).
BATCH_MIN = 8


def node_children(k: int, nd: dict) -> list:
    """The node indices a node refers to, checked to come before it."""
    if not isinstance(nd, dict):
        raise ValidationError(f"node {k} is not an object")
    op = nd.get("op")
    try:
        if op in LEAVES:
            children = []
        elif op == "sum":
            children = [j for j, _ in nd["terms"]]
            float(nd["constant"])
            for _, c in nd["terms"]:
                float(c)
        elif op == "prod":
            children = [j for j, _ in nd["factors"]]
            for _, e in nd["factors"]:
                if not isinstance(e, int) or isinstance(e, bool):
                    raise ValidationError(f"node {k}: non-integer exponent {e!r}")
        elif op in UNARY:
            children = [nd["arg"]]
        elif op == "atan2":
            children = [nd["y"], nd["x"]]
        else:
            raise ValidationError(f"node {k}: unknown op {op!r}")
    except (KeyError, TypeError, ValueError) as e:
        raise ValidationError(f"node {k} ({op}): malformed ({e!r})") from e
    for j in children:
        if not isinstance(j, int) or isinstance(j, bool) or not 0 <= j < k:
            raise ValidationError(f"node {k} refers to node {j!r}, which does not come before it")
    return children


def build_nodes(nodes: list, q, qd, t, p) -> list:
    """Every export node as a CasADi SX scalar.

    One pass over the nodes computes each node's depth; nodes are then built
    depth by depth, all nodes of one op at one depth together with vectorised
    CasADi calls (sums as one sparse matrix-vector product), so that the
    Python overhead stays small for graphs of 10^5 nodes. The expressions are
    exactly those of the export: sum = constant + sum(coeff * node), prod =
    prod(node^exponent) with integer exponents.
    """
    nq, npar = q.shape[0], p.shape[0]
    qs = ca.vertsplit(q) if nq else []
    qds = ca.vertsplit(qd) if nq else []
    ps = ca.vertsplit(p) if npar else []
    vals: list = [None] * len(nodes)
    depth = [0] * len(nodes)
    groups: dict = {}

    def sym(k, table, index, what):
        if not isinstance(index, int) or not 0 <= index < len(table):
            raise ValidationError(f"node {k}: {what} index {index!r} out of range")
        return table[index]

    for k, nd in enumerate(nodes):
        children = node_children(k, nd)
        op = nd["op"]
        if op == "const":
            vals[k] = ca.SX(float(nd["value"]))
        elif op == "q":
            vals[k] = sym(k, qs, nd.get("index"), "coordinate")
        elif op == "qd":
            vals[k] = sym(k, qds, nd.get("index"), "velocity")
        elif op == "t":
            vals[k] = t
        elif op == "param":
            vals[k] = sym(k, ps, nd.get("index"), "runtime parameter")
        else:
            depth[k] = 1 + max((depth[j] for j in children), default=0)
            groups.setdefault((depth[k], op), []).append(k)

    for (_, op), ks in sorted(groups.items()):
        if len(ks) < BATCH_MIN:
            for k in ks:
                vals[k] = build_one(nodes[k], vals)
        elif op == "sum":
            build_sums(ks, nodes, vals)
        elif op == "prod":
            build_prods(ks, nodes, vals)
        elif op == "atan2":
            y = ca.vertcat(*[vals[nodes[k]["y"]] for k in ks])
            x = ca.vertcat(*[vals[nodes[k]["x"]] for k in ks])
            for k, v in zip(ks, ca.vertsplit(ca.atan2(y, x))):
                vals[k] = v
        else:
            f = UNARY[op]
            args = ca.vertcat(*[vals[nodes[k]["arg"]] for k in ks])
            for k, v in zip(ks, ca.vertsplit(f(args))):
                vals[k] = v
    return vals


def build_one(nd: dict, vals: list):
    """One non-leaf node, scalar by scalar."""
    op = nd["op"]
    if op == "sum":
        c0 = float(nd["constant"])
        v = None
        for j, c in nd["terms"]:
            x = vals[j]
            c = float(c)
            if v is None:
                v = x if c == 1.0 else c * x
            else:
                v = v + (x if c == 1.0 else c * x)
        if v is None:
            return ca.SX(c0)
        return v if c0 == 0.0 else c0 + v
    if op == "prod":
        v = None
        for j, e in nd["factors"]:
            f = vals[j] if e == 1 else ca.constpow(vals[j], e)
            v = f if v is None else v * f
        return ca.SX(1.0) if v is None else v
    if op == "atan2":
        return ca.atan2(vals[nd["y"]], vals[nd["x"]])
    return UNARY[op](vals[nd["arg"]])


def build_sums(ks: list, nodes: list, vals: list) -> None:
    """Sums as one sparse product: [s_k] = A x + b."""
    col_of: dict = {}
    rows, cols, coeffs = [], [], []
    for r, k in enumerate(ks):
        seen: dict = {}
        for j, c in nodes[k]["terms"]:
            col = col_of.setdefault(j, len(col_of))
            if col in seen:  # a repeated term: merge the coefficients
                coeffs[seen[col]] += float(c)
            else:
                seen[col] = len(coeffs)
                rows.append(r)
                cols.append(col)
                coeffs.append(float(c))
    m = len(ks)
    x = ca.vertcat(*[vals[j] for j in col_of])
    a = ca.DM.triplet(rows, cols, coeffs, m, len(col_of))
    s = ca.mtimes(a, x) + ca.DM([float(nodes[k]["constant"]) for k in ks])
    for k, v in zip(ks, ca.vertsplit(ca.densify(s))):
        vals[k] = v


def build_prods(ks: list, nodes: list, vals: list) -> None:
    """Products of integer powers, factor position by factor position."""
    ks = sorted(ks, key=lambda k: -len(nodes[k]["factors"]))
    m = len(ks)
    out = None
    for f in range(len(nodes[ks[0]]["factors"])):
        rows = [k for k in ks if len(nodes[k]["factors"]) > f]  # a prefix of ks
        bases = ca.vertcat(*[vals[nodes[k]["factors"][f][0]] for k in rows])
        exps = [nodes[k]["factors"][f][1] for k in rows]
        if all(e == 1 for e in exps):
            powered = bases
        else:
            powered = ca.constpow(bases, ca.DM(exps))
        if len(rows) < m:
            powered = ca.vertcat(powered, ca.SX.ones(m - len(rows)))
        out = powered if out is None else out * powered
    if out is None:
        out = ca.SX.ones(m)
    for k, v in zip(ks, ca.vertsplit(out)):
        vals[k] = v


# A marker's terms, as `flexdyn eval` names them under `markers.<name>`.
MARKER_TERMS = ["position", "rotation", "jacobian", "velocity", "acceleration_bias"]


def marker_term(marker: str, term: str) -> str:
    """The row name of one term of a marker (its path in the eval output)."""
    return f"markers.{marker}.{term}"


def is_marker_term(term: str) -> bool:
    return term.startswith("markers.")


def vee(w):
    """The vector ``w`` of the skew-symmetric part of a 3 x 3 matrix ``W``:
    ``skew(w) = (W - W^T) / 2``."""
    return 0.5 * ca.vertcat(w[2, 1] - w[1, 2], w[0, 2] - w[2, 0], w[1, 0] - w[0, 1])


def marker_kinematics(position, rotation, q, qd, t) -> list:
    """A marker's terms (name, expression, shape) from its world position
    and rotation alone, by CasADi AD.

    The angular velocity in world axes is ``vee(Rdot R^T)`` with
    ``Rdot = sum_i dR/dq_i qd_i + dR/dt``: the Jacobian's angular column
    ``i`` is ``vee(dR/dq_i R^T)``, its explicit time term ``vee(dR/dt R^T)``.
    The acceleration bias is the velocity's time derivative along
    ``(q, t) -> (qd, 1)`` at ``qdd = 0``.
    """
    nq = q.shape[0]
    flat = ca.reshape(rotation, 9, 1)  # column-major, as reshape back below

    def angular(d_flat):
        return vee(ca.mtimes(ca.reshape(d_flat, 3, 3), rotation.T))

    d_dq = ca.jacobian(flat, q)
    angular_jacobian = ca.horzcat(*[angular(d_dq[:, i]) for i in range(nq)]) if nq else ca.SX(3, 0)
    jacobian = ca.vertcat(ca.jacobian(position, q), angular_jacobian)
    explicit = ca.vertcat(ca.jacobian(position, t), angular(ca.jacobian(flat, t)))
    velocity = ca.mtimes(jacobian, qd) + explicit
    acceleration_bias = ca.jtimes(velocity, ca.vertcat(q, t), ca.vertcat(qd, 1))
    return [
        ("position", position, (3,)),
        ("rotation", rotation, (3, 3)),
        ("jacobian", jacobian, (6, nq)),
        ("velocity", velocity, (6,)),
        ("acceleration_bias", acceleration_bias, (6,)),
    ]


def derive(export: dict, with_coriolis_matrix: bool, with_bias_jacobians: bool,
           with_derivatives: bool):
    """The CasADi function of every term, and the names/shapes of its outputs.

    The Christoffel matrix (the costliest term: a full Jacobian of `M qd`) is
    only built when asked for, and so are the derivatives of the inverse
    dynamics and (unconstrained scenes) of the forward dynamics
    `M^-1 (B tau - h)`, each CasADi's `jacobian` of its own expression.
    """
    nq = len(export["coordinates"])
    npar = len(export["runtime_parameters"])
    q = ca.SX.sym("q", nq)
    qd = ca.SX.sym("qd", nq)
    qdd = ca.SX.sym("qdd", nq)
    tau = ca.SX.sym("tau", len(export["actuators"]))
    t = ca.SX.sym("t")
    p = ca.SX.sym("p", npar)
    vals = build_nodes(export["nodes"], q, qd, t, p)

    def node(j, what):
        if not isinstance(j, int) or not 0 <= j < len(vals):
            raise ValidationError(f"{what} refers to node {j}, out of range")
        return vals[j]

    kinetic = ca.SX(0.0)
    potential = ca.SX(0.0)
    dissipation = ca.SX(0.0)
    for c in export["components"]:
        kinetic = kinetic + node(c["kinetic"], f"component `{c['name']}`")
        potential = potential + node(c["potential"], f"component `{c['name']}`")
        dissipation = dissipation + node(c["dissipation"], f"component `{c['name']}`")
    residuals = [node(c["residual"], f"constraint `{c['name']}`") for c in export["constraints"]]
    phi = ca.vertcat(*residuals) if residuals else ca.SX(0, 1)

    qt = ca.vertcat(q, t)            # d/dt at zero acceleration: q -> qd, t -> 1
    qt_rate = ca.vertcat(qd, 1)

    mass, momenta = ca.hessian(kinetic, qd)
    coriolis = ca.jtimes(momenta, qt, qt_rate) - ca.gradient(kinetic, q)
    potential_forces = ca.gradient(potential, q)
    damping_forces = ca.gradient(dissipation, qd)
    bias = coriolis + potential_forces + damping_forces
    inverse_dynamics = ca.mtimes(mass, qdd) + bias

    phi_q = ca.jacobian(phi, q)
    phi_t = ca.jacobian(phi, t)
    # Phi_q qd + Phi_t, by forward AD along (q, t) -> (qd, 1): the same
    # quantity as mtimes(phi_q, qd) + phi_t, without differentiating the whole
    # Jacobian a second time (several times cheaper on big graphs).
    velocity_residual = ca.jtimes(phi, qt, qt_rate)
    gamma = -ca.jtimes(velocity_residual, qt, qt_rate)

    if with_coriolis_matrix:
        # Christoffel form: C = (Mdot + J - J^T) / 2 with
        #   Mdot_ij = sum_k dM_ij/dq_k qd_k   (one forward sweep),
        #   J_ij = d(M w)_i/dq_j at w = qd = sum_k dM_ik/dq_j qd_k.
        mdot = ca.reshape(ca.jtimes(ca.reshape(mass, nq * nq, 1), q, qd), nq, nq)
        jac = ca.jacobian(ca.mtimes(mass, qd), q)
        coriolis_matrix = 0.5 * (mdot + jac - jac.T)

    terms = [
        ("mass_matrix", mass, (nq, nq)),
        ("bias", bias, (nq,)),
        ("inverse_dynamics", inverse_dynamics, (nq,)),
        ("constraints", phi, (len(residuals),)),
        ("constraint_jacobian", phi_q, (len(residuals), nq)),
        ("constraint_time_derivative", phi_t, (len(residuals),)),
        ("constraint_rhs", gamma, (len(residuals),)),
        ("kinetic_energy", kinetic, ()),
        ("potential_energy", potential, ()),
        ("coriolis_forces", coriolis, (nq,)),
        ("potential_forces", potential_forces, (nq,)),
        ("damping_forces", damping_forces, (nq,)),
    ]
    if with_coriolis_matrix:
        terms.append(("coriolis_matrix", coriolis_matrix, (nq, nq)))
    if with_bias_jacobians:
        terms.append(("bias_jacobian_q", ca.jacobian(bias, q), (nq, nq)))
        terms.append(("bias_jacobian_qd", ca.jacobian(bias, qd), (nq, nq)))
    if with_derivatives:
        terms.append(("inverse_dynamics_q", ca.jacobian(inverse_dynamics, q), (nq, nq)))
        terms.append(("inverse_dynamics_qd", ca.jacobian(inverse_dynamics, qd), (nq, nq)))
        forces = ca.mtimes(ca.DM(actuator_map(export)), tau) - bias
        nc = len(residuals)
        if nc:
            # The ideal constrained equations: [M, -Phi_q^T; Phi_q, 0]
            # [qdd; lambda] = [B tau - h; gamma], solved symbolically.
            kkt = ca.vertcat(ca.horzcat(mass, -phi_q.T), ca.horzcat(phi_q, ca.SX(nc, nc)))
            solution = ca.solve(kkt, ca.vertcat(forces, gamma))
            forward, multipliers = solution[:nq], solution[nq:]
            terms.append(("forward_dynamics", forward, (nq,)))
            terms.append(("constraint_forces", multipliers, (nc,)))
            terms.append(("constraint_forces_q", ca.jacobian(multipliers, q), (nc, nq)))
            terms.append(("constraint_forces_qd", ca.jacobian(multipliers, qd), (nc, nq)))
            terms.append(("constraint_forces_tau", ca.jacobian(multipliers, tau), (nc, tau.numel())))
        else:
            forward = ca.solve(mass, forces)
        terms.append(("forward_dynamics_q", ca.jacobian(forward, q), (nq, nq)))
        terms.append(("forward_dynamics_qd", ca.jacobian(forward, qd), (nq, nq)))
        terms.append(("forward_dynamics_tau", ca.jacobian(forward, tau), (nq, tau.numel())))
    for m in export["markers"]:
        what = f"marker `{m.get('name')}`"
        try:
            position = ca.vertcat(*[node(j, what) for j in m["position"]])
            rotation = ca.vertcat(*[ca.horzcat(*[node(j, what) for j in row]) for row in m["rotation"]])
        except (KeyError, TypeError) as e:
            raise ValidationError(f"{what}: malformed ({e!r})") from e
        if position.shape != (3, 1) or rotation.shape != (3, 3):
            raise ValidationError(f"{what}: expected 3 position and 3 x 3 rotation nodes")
        terms += [(marker_term(m["name"], k), e, shape)
                  for k, e, shape in marker_kinematics(position, rotation, q, qd, t)]
    outs = [ca.densify(e) for _, e, _ in terms]
    func = ca.Function(f"{export['name']}_terms", [q, qd, qdd, tau, t, p], outs)
    return func, [(name, shape) for name, _, shape in terms]


def actuator_map(export: dict) -> "np.ndarray":
    nq = len(export["coordinates"])
    acts = export["actuators"]
    b = np.zeros((nq, len(acts)))
    for j, a in enumerate(acts):
        i = a["coordinate"]
        if not isinstance(i, int) or not 0 <= i < nq:
            raise ValidationError(f"actuator `{a['name']}`: coordinate {i} out of range")
        b[i, j] += float(a["gain"])
    return b


def evaluate_casadi(func, shapes, q, qd, qdd, tau, t, p) -> dict:
    """Evaluate the mapped function; every term as an array of shape (N, *shape)."""
    n = q.shape[0]
    mapped = func.map(n)
    outs = mapped(q.T, qd.T, qdd.T, tau.T, t.reshape(1, n), p.T)
    if not isinstance(outs, (list, tuple)):
        outs = [outs]
    result = {}
    for (name, shape), out in zip(shapes, outs):
        a = np.asarray(ca.DM(out).full(), dtype=float)
        rows = shape[0] if len(shape) >= 1 else 1
        cols = shape[1] if len(shape) == 2 else 1
        # A mapped r x c output is [block_0 block_1 ...], each r x c.
        a = a.reshape(rows, n, cols).transpose(1, 0, 2)
        result[name] = a.reshape((n, *shape))
    return result


# ---------------------------------------------------------------------------
# States
# ---------------------------------------------------------------------------


def rng_for(seed: int, name: str):
    # Seeded per scene, so that a scene's states do not depend on which other
    # scenes run or in what order.
    return np.random.default_rng([seed, zlib.crc32(name.encode())])


def bounds(value, default, what: str):
    if value is None:
        return default
    lo, hi = float(value[0]), float(value[1])
    if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
        raise ValidationError(f"{what}: bad range {value!r}")
    return lo, hi


def random_states(export: dict, count: int, seed: int):
    coords = export["coordinates"]
    nq = len(coords)
    rng = rng_for(seed, export["name"])
    qr = [bounds(c["range"], DEFAULT_RANGE, f"coordinate `{c['name']}`") for c in coords]
    vr = [bounds(c["velocity_range"], DEFAULT_VELOCITY_RANGE, f"coordinate `{c['name']}`")
          for c in coords]
    q = rng.uniform([a for a, _ in qr], [b for _, b in qr], size=(count, nq)) if nq else np.zeros((count, 0))
    qd = rng.uniform([a for a, _ in vr], [b for _, b in vr], size=(count, nq)) if nq else np.zeros((count, 0))
    t = rng.uniform(*TIME_RANGE, size=count)
    return q, qd, t


def working_states(path: Path, export: dict):
    """States from `<scene>.states.json` (the `flexdyn eval` input format)."""
    nq = len(export["coordinates"])
    params = [p["name"] for p in export["runtime_parameters"]]
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as e:
        raise ValidationError(f"cannot read working states {path}: {e}") from e
    states = data.get("states") if isinstance(data, dict) else None
    if not isinstance(states, list):
        raise ValidationError(f"{path}: expected {{\"states\": [...]}}")
    out = []
    for k, s in enumerate(states):
        where = f"{path}: state {k}"
        if not isinstance(s, dict):
            raise ValidationError(f"{where}: not an object")
        try:
            q = [float(x) for x in s["q"]]
            qd = [float(x) for x in s["qd"]]
            t = float(s.get("t", 0.0))
        except (KeyError, TypeError, ValueError) as e:
            raise ValidationError(f"{where}: bad or missing q/qd/t ({e})") from e
        if len(q) != nq or len(qd) != nq:
            raise ValidationError(
                f"{where}: the scene has {nq} coordinates, got {len(q)} positions and {len(qd)} velocities"
            )
        extra = s.get("params")
        if extra is not None:
            if not isinstance(extra, dict) or any(k2 not in params for k2 in extra):
                raise ValidationError(f"{where}: `params` must map runtime parameter names ({params}) to values")
        out.append({"q": q, "qd": qd, "t": t, "params": extra})
    return out


# ---------------------------------------------------------------------------
# Comparison
# ---------------------------------------------------------------------------


def flatten_markers(result: dict, k: int) -> dict:
    """One eval result with each marker's terms as keys of their own
    (``markers.<name>.<term>``, see :func:`marker_term`)."""
    flat = {key: v for key, v in result.items() if key != "markers"}
    markers = result.get("markers", {})
    if not isinstance(markers, dict) or not all(isinstance(v, dict) for v in markers.values()):
        raise ValidationError(f"`markers` of result {k} is not an object of objects")
    for name, terms in markers.items():
        for term, value in terms.items():
            flat[marker_term(name, term)] = value
    return flat


def rust_array(results: list, key: str, shape: tuple) -> "np.ndarray":
    """One term of every result as an array (N, *shape), its shape checked."""
    n = len(results)
    out = np.empty((n, *shape))
    for k, r in enumerate(results):
        try:
            a = np.asarray(r[key], dtype=float)
        except (TypeError, ValueError) as e:
            raise ValidationError(f"`{key}` of result {k} is not numeric: {e}") from e
        if a.size == 0 and math.prod(shape) == 0:
            a = a.reshape(shape)
        if a.shape != shape:
            raise ValidationError(
                f"`{key}` of result {k} has shape {a.shape}, expected {shape}"
            )
        out[k] = a
    return out


# Terms a derived scene's `reduce.drop_below` prunes (the mass matrix and the
# bias forces, and the Coriolis matrix derived from M; the bias Jacobians are
# those of the exact forces). The generator bounds the pruned
# summands at its own sample states; here, at other states, they may differ
# from the exact derivatives by PRUNE_FACTOR * drop_below of the term's scale.
PRUNED_TERMS = {"mass_matrix", "bias", "coriolis_forces", "potential_forces",
                "damping_forces", "coriolis_matrix", "fused_mass_matrix", "fused_bias"}
PRUNE_FACTOR = 4.0


def term_rtol(export: dict, term: str) -> float:
    """Relative tolerance of one term of a scene."""
    drop = export.get("drop_below")
    if drop is not None and term in PRUNED_TERMS:
        return max(RTOL, PRUNE_FACTOR * float(drop))
    return RTOL


def finite_max(ref: "np.ndarray") -> float:
    """Largest finite magnitude of an array (0 for none)."""
    finite = np.abs(np.where(np.isfinite(ref), ref, 0.0))
    return float(np.max(finite)) if finite.size else 0.0


def compare(rust: "np.ndarray", ref: "np.ndarray", rtol: float = RTOL,
            floor: float = 0.0) -> dict:
    """Worst absolute error, scale, where, and the verdict for one term: the
    scale is the term's own largest magnitude, at least ``floor`` (and the
    smallest normal number, for a scene that is zero throughout)."""
    shape = ref.shape[1:]
    if ref.size == 0:
        return {"max_abs_error": 0.0, "scale": 1.0, "tolerance": rtol, "state": None,
                "entry": None, "nonfinite": 0, "passed": True}
    finite_ref = np.isfinite(ref)
    finite_rust = np.isfinite(rust)
    # Entries non-finite on both sides in the same way agree; any other
    # non-finite entry is an infinite error.
    same_nonfinite = (~finite_ref) & (~finite_rust) & (
        (np.isnan(ref) & np.isnan(rust)) | (ref == rust)
    )
    both = finite_ref & finite_rust
    with np.errstate(invalid="ignore"):
        err = np.where(both, np.abs(rust - ref), np.inf)
    err = np.where(same_nonfinite, 0.0, err)
    scale = max(finite_max(ref), floor, sys.float_info.min)
    flat = int(np.argmax(err))
    worst = float(err.reshape(-1)[flat])
    state, entry = divmod(flat, max(1, math.prod(shape)))
    return {
        "max_abs_error": worst,
        "scale": scale,
        "tolerance": rtol * scale,
        "state": state,
        "entry": entry if shape else None,
        "nonfinite": int(np.count_nonzero(same_nonfinite)),
        "passed": worst <= rtol * scale,
    }


# ---------------------------------------------------------------------------
# One scene
# ---------------------------------------------------------------------------

BASE_TERMS = [
    "mass_matrix", "bias", "inverse_dynamics", "constraints", "constraint_jacobian",
    "constraint_time_derivative", "constraint_rhs", "actuator_map",
    "kinetic_energy", "potential_energy",
]
FORCE_TERMS = ["coriolis_forces", "potential_forces", "damping_forces"]
JACOBIAN_TERMS = ["bias_jacobian_q", "bias_jacobian_qd"]
# `outputs = ["dynamics_derivatives"]`: the inverse dynamics' derivatives,
# and for unconstrained scenes the forward dynamics' ones.
ID_DERIVATIVE_TERMS = ["fused_inverse_dynamics", "inverse_dynamics_q", "inverse_dynamics_qd"]
FD_DERIVATIVE_TERMS = ["forward_dynamics_q", "forward_dynamics_qd", "forward_dynamics_tau"]
# Constrained scenes: the constraint forces with the forward dynamics.
MULTIPLIER_TERMS = ["constraint_forces", "constraint_forces_q", "constraint_forces_qd",
                    "constraint_forces_tau"]
# The fused programs (what the solvers call) compute terms again, sharing
# subexpressions: `constraints_and_jacobian` Phi and Phi_q, `dynamics_terms`
# M, h, Phi_q and gamma. Each is compared with the same CasADi reference as
# the separate function.
FUSED_TERMS = {"fused_constraints": "constraints",
               "fused_position_constraint_jacobian": "constraint_jacobian",
               "fused_mass_matrix": "mass_matrix", "fused_bias": "bias",
               "fused_constraint_jacobian": "constraint_jacobian",
               "fused_constraint_rhs": "constraint_rhs"}


def validate_scene(scene: Path, binary: Path, args, workdir: Path) -> dict:
    t0 = time.perf_counter()
    export_path = workdir / f"{scene.stem}.export.json"
    run_flexdyn(binary, ["export", "--scene", str(scene), "--out", str(export_path)],
                f"export of {scene}")
    export = load_export(export_path)
    name = export["name"]
    nq = len(export["coordinates"])
    nc = len(export["constraints"])
    outputs = export["outputs"]
    t_export = time.perf_counter() - t0

    # States: random ones, then the working states.
    q, qd, t = random_states(export, args.states, args.seed)
    nominal = {p["name"]: float(p["value"]) for p in export["runtime_parameters"]}
    param_names = [p["name"] for p in export["runtime_parameters"]]
    states = [{"q": q[k].tolist(), "qd": qd[k].tolist(), "t": float(t[k])} for k in range(len(t))]
    params = [dict(nominal) for _ in states]
    extra_file = None
    for candidate in dict.fromkeys([scene.with_name(f"{scene.stem}.states.json"),
                                    scene.with_name(f"{name}.states.json")]):
        if candidate.is_file():
            extra_file = candidate
            break
    n_working = 0
    if extra_file is not None:
        for s in working_states(extra_file, export):
            state = {"q": s["q"], "qd": s["qd"], "t": s["t"]}
            values = dict(nominal)
            if s["params"] is not None:
                # Passed through to flexdyn eval as given.
                state["params"] = s["params"]
                values.update({k: float(v) for k, v in s["params"].items()})
            states.append(state)
            params.append(values)
            n_working += 1
    if not states:
        raise ValidationError(f"scene `{name}`: no states to evaluate (--states 0 and no working states)")
    n = len(states)
    # Accelerations for the inverse dynamics, from their own seeded stream
    # (the states above do not depend on them).
    qdd_all = rng_for(args.seed, f"{name}/qdd").uniform(-2.0, 2.0, size=(n, nq))
    nu = len(export["actuators"])
    tau_all = rng_for(args.seed, f"{name}/tau").uniform(-2.0, 2.0, size=(n, nu))
    for s, a, u in zip(states, qdd_all, tau_all):
        s["qdd"] = a.tolist()
        s["tau"] = u.tolist()
    q_all = np.array([s["q"] for s in states], dtype=float).reshape(n, nq)
    qd_all = np.array([s["qd"] for s in states], dtype=float).reshape(n, nq)
    t_all = np.array([s["t"] for s in states], dtype=float)
    p_all = np.array([[v[k] for k in param_names] for v in params], dtype=float).reshape(n, len(param_names))

    t0 = time.perf_counter()
    states_path = workdir / f"{scene.stem}.states.json"
    results_path = workdir / f"{scene.stem}.results.json"
    states_path.write_text(json.dumps({"states": states}))
    eval_args = ["eval", "--scene", str(scene), "--states", str(states_path), "--out", str(results_path)]
    if args.perturbed:
        eval_args.append("--perturbed")
    run_flexdyn(binary, eval_args, f"eval of {scene}")
    try:
        out = json.loads(results_path.read_text())
    except (OSError, ValueError) as e:
        raise ValidationError(f"cannot read eval output {results_path}: {e}") from e
    results = out.get("results") if isinstance(out, dict) else None
    if not isinstance(results, list) or len(results) != n:
        raise ValidationError(
            f"eval of {scene}: expected {n} results, got "
            f"{len(results) if isinstance(results, list) else 'none'}"
        )
    if out.get("scene") != name:
        raise ValidationError(f"eval of {scene}: results are for scene {out.get('scene')!r}, expected {name!r}")
    if not all(isinstance(r, dict) for r in results):
        raise ValidationError(f"eval of {scene}: a result is not an object")
    results = [flatten_markers(r, k) for k, r in enumerate(results)]
    t_eval = time.perf_counter() - t0

    # Which terms are required, which merely compared when present.
    required = list(BASE_TERMS) + list(FUSED_TERMS)
    if outputs.get("forces"):
        required += FORCE_TERMS
    if outputs.get("coriolis_matrix"):
        required.append("coriolis_matrix")
    if outputs.get("bias_jacobians"):
        required += JACOBIAN_TERMS
    if nc == 0:
        required.append("forward_dynamics")
    if outputs.get("dynamics_derivatives"):
        required += ID_DERIVATIVE_TERMS + FD_DERIVATIVE_TERMS
        if nc:
            required += ["forward_dynamics"] + MULTIPLIER_TERMS
    markers = [marker_term(m["name"], k) for m in export["markers"] for k in MARKER_TERMS]
    required += markers
    optional = [k for k in FORCE_TERMS + ["coriolis_matrix"] + JACOBIAN_TERMS if k not in required]
    present = set(results[0].keys()) if results else set()
    for k, r in enumerate(results):
        if set(r.keys()) != present:
            raise ValidationError(f"eval of {scene}: result {k} has keys {sorted(r)}, result 0 has {sorted(present)}")

    t0 = time.perf_counter()
    func, shapes = derive(
        export,
        "coriolis_matrix" in required or "coriolis_matrix" in present,
        any(k in required or k in present for k in JACOBIAN_TERMS),
        any(k in required or k in present for k in ID_DERIVATIVE_TERMS),
    )
    t_build = time.perf_counter() - t0

    t0 = time.perf_counter()
    ref = evaluate_casadi(func, shapes, q_all, qd_all, qdd_all, tau_all, t_all, p_all)
    ref["actuator_map"] = np.broadcast_to(actuator_map(export), (n, nq, nu))
    if nc == 0:
        # M^-1 (B tau - h) from CasADi's M and h, solved by numpy.
        forces = np.einsum("ij,nj->ni", actuator_map(export), tau_all) - ref["bias"]
        ref["forward_dynamics"] = np.linalg.solve(ref["mass_matrix"], forces[..., None])[..., 0]
    for fused, separate in FUSED_TERMS.items():
        ref[fused] = ref[separate]
    # `tau` as the program of its derivatives computes it.
    ref["fused_inverse_dynamics"] = ref["inverse_dynamics"]
    t_casadi = time.perf_counter() - t0

    t0 = time.perf_counter()
    rows = []
    def floor_of(terms):
        return CANCEL_FLOOR * max((finite_max(ref[t]) for t in terms), default=0.0)

    # Markers' terms (lengths, angles) are scaled among themselves, the
    # forward dynamics and their derivatives (accelerations) among
    # themselves, the constraint forces (whose units depend on the
    # constraint) among themselves, the others (forces, energies) among
    # themselves.
    def group(t):
        if is_marker_term(t):
            return "markers"
        if t.startswith("forward_dynamics"):
            return "accelerations"
        return "multipliers" if t.startswith("constraint_forces") else "forces"

    floors = {g: floor_of(t for t in ref if t not in UNSCALED_TERMS and group(t) == g)
              for g in ("forces", "markers", "accelerations", "multipliers")}
    for term in required + [k for k in optional if k in present]:
        shape = ref[term].shape[1:]
        row = {"term": term, "shape": "x".join(map(str, shape)) or "scalar"}
        if term not in present:
            row.update({"max_abs_error": None, "scale": None, "tolerance": None, "state": None,
                        "entry": None, "nonfinite": 0, "passed": False, "missing": True})
        else:
            row.update(compare(rust_array(results, term, shape), ref[term],
                               term_rtol(export, term),
                               floors[group(term)]))
            row["missing"] = False
        rows.append(row)
    known = set(BASE_TERMS + list(FUSED_TERMS) + FORCE_TERMS + ["coriolis_matrix"] + JACOBIAN_TERMS
                + markers + ["forward_dynamics"] + ID_DERIVATIVE_TERMS + FD_DERIVATIVE_TERMS
                + MULTIPLIER_TERMS)
    unchecked = sorted(present - known)
    t_compare = time.perf_counter() - t0

    return {
        "scene": name,
        "file": str(scene),
        "coordinates": nq,
        "constraints": nc,
        "nodes": len(export["nodes"]),
        "random_states": len(t),
        "working_states": n_working,
        "working_states_file": str(extra_file) if extra_file else None,
        "terms": rows,
        "unchecked_keys": unchecked,
        "passed": all(r["passed"] for r in rows),
        "seconds": {"export": t_export, "build": t_build, "casadi": t_casadi,
                    "eval": t_eval, "compare": t_compare},
    }


def describe_state(report: dict, state) -> str:
    if state is None:
        return "-"
    if state < report["random_states"]:
        return f"random {state}"
    return f"working {state - report['random_states']}"


def print_scene(report: dict) -> None:
    s = report["seconds"]
    extra = (f" + {report['working_states']} working states ({report['working_states_file']})"
             if report["working_states"] else "")
    print(
        f"\nscene {report['scene']} ({report['file']}): {report['coordinates']} coordinates, "
        f"{report['constraints']} constraints, {report['nodes']} export nodes; "
        f"{report['random_states']} random states{extra}"
    )
    w = max([34] + [len(r["term"]) for r in report["terms"]])
    header = f"  {'term':<{w}} {'shape':>7} {'max |err|':>10} {'scale':>10} {'tolerance':>10}  {'worst at':<22} result"
    print(header)
    print("  " + "-" * (len(header) - 2))
    for r in report["terms"]:
        if r["missing"]:
            print(f"  {r['term']:<{w}} {r['shape']:>7} {'-':>10} {'-':>10} {'-':>10}  {'-':<22} "
                  f"FAIL (missing from flexdyn eval output)")
            continue
        if r["state"] is None or r["max_abs_error"] == 0.0:
            where = "-"  # no entries, or exact everywhere
        else:
            where = describe_state(report, r["state"])
            if r["entry"] is not None:
                where += f" [{r['entry']}]"
        verdict = "PASS" if r["passed"] else "FAIL"
        note = f" ({r['nonfinite']} non-finite entries agree)" if r["nonfinite"] else ""
        print(f"  {r['term']:<{w}} {r['shape']:>7} {r['max_abs_error']:>10.3e} {r['scale']:>10.3e} "
              f"{r['tolerance']:>10.3e}  {where:<22} {verdict}{note}")
    if report["unchecked_keys"]:
        print(f"  note: eval keys not validated: {', '.join(report['unchecked_keys'])}")
    print(f"  time: export {s['export']:.2f} s, CasADi build {s['build']:.2f} s, CasADi eval "
          f"{s['casadi']:.2f} s, flexdyn eval {s['eval']:.2f} s, compare {s['compare']:.2f} s")


def finite_json(x):
    """Non-finite floats as strings ("inf", "nan"), so that the report is strict JSON."""
    if isinstance(x, float) and not math.isfinite(x):
        return str(x)
    if isinstance(x, dict):
        return {k: finite_json(v) for k, v in x.items()}
    if isinstance(x, list):
        return [finite_json(v) for v in x]
    return x


def discover_scenes() -> list[Path]:
    return sorted((REPO / "scenes").glob("*.toml"))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        description="Validate flexdyn's generated terms against CasADi AD (see docs/export-format.md).")
    ap.add_argument("scene_files", nargs="*", metavar="SCENE", help="scene files (default: scenes/*.toml)")
    ap.add_argument("--scenes", nargs="+", default=[], metavar="SCENE", help="scene files (as positional)")
    ap.add_argument("--flexdyn", metavar="PATH",
                    help="flexdyn binary (default: $FLEXDYN, else the newest target/{release,debug}/flexdyn, else PATH)")
    ap.add_argument("--states", type=positive_or_zero, default=1000, metavar="N",
                    help="random states per scene (default 1000)")
    ap.add_argument("--seed", type=int, default=DEFAULT_SEED, help=f"random seed (default {DEFAULT_SEED})")
    ap.add_argument("--perturbed", action="store_true",
                    help="evaluate flexdyn's test-only build with one emitted coefficient wrong "
                         "(`flexdyn eval --perturbed`; negative test: that term must then FAIL)")
    ap.add_argument("--json-report", metavar="FILE", help="also write the results as JSON")
    args = ap.parse_args(argv)

    start = time.perf_counter()
    scenes = [Path(s) for s in args.scene_files + args.scenes] or discover_scenes()
    if not scenes:
        raise ValidationError(f"no scenes given and none found in {REPO / 'scenes'}")
    for s in scenes:
        if not s.is_file():
            raise ValidationError(f"scene file {s} does not exist")
    binary = find_flexdyn(args.flexdyn)
    print(f"flexdyn: {binary}")
    print(f"casadi {ca.__version__}, numpy {np.__version__}; seed {args.seed}; "
          f"pass when max |rust - casadi| <= {RTOL:g} * max(max |casadi| of the term, "
          f"{CANCEL_FLOOR:g} * that of the scene's largest term)")
    if args.perturbed:
        print("evaluating the perturbed build (`flexdyn eval --perturbed`)")

    reports = []
    with tempfile.TemporaryDirectory(prefix="flexdyn-casadi-") as tmp:
        for scene in scenes:
            report = validate_scene(scene, binary, args, Path(tmp))
            print_scene(report)
            sys.stdout.flush()
            reports.append(report)

    failed = [f"{r['scene']}/{t['term']}" for r in reports for t in r["terms"] if not t["passed"]]
    total = time.perf_counter() - start
    checked = sum(len(r["terms"]) for r in reports)
    print()
    if failed:
        print(f"FAILED: {len(failed)} of {checked} terms: {', '.join(failed)}")
    else:
        print(f"PASSED: all {checked} terms of {len(reports)} scenes")
    print(f"total time {total:.2f} s")
    if args.json_report:
        report = {"format": "flexdyn-casadi-report/1", "casadi": ca.__version__, "numpy": np.__version__,
                  "seed": args.seed, "rtol": RTOL, "perturbed": args.perturbed, "passed": not failed,
                  "failed": failed, "seconds": total, "scenes": reports}
        try:
            Path(args.json_report).write_text(json.dumps(finite_json(report), indent=2, allow_nan=False))
        except OSError as e:
            raise ValidationError(f"cannot write {args.json_report}: {e}") from e
    return 1 if failed else 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except ValidationError as e:
        sys.stdout.flush()
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2)
    except KeyboardInterrupt:
        sys.exit(130)
    except Exception:  # an unexpected failure is an error, not a failed term
        import traceback

        traceback.print_exc()
        sys.exit(2)
