#!/usr/bin/env python3
"""CasADi's generated C for the terms a solver needs, for side-by-side timing.

From a scene export (``flexdyn export``, format ``flexdyn-scene-export/1``)
this rebuilds the energies and constraints as CasADi SX exactly as
``validate.py`` does, derives ``M``, ``h``, ``Phi_q`` and ``gamma`` with
CasADi's AD, and writes one C function ``<name>_terms(q, qd, t, p) ->
(M, h, Phi_q, gamma)`` generated with CasADi's common-subexpression
elimination on (``cse``). All four outputs are dense, column-major.

It also prints a JSON line with operation counts: CasADi's arithmetic
instructions (every instruction except inputs, outputs, constants and
copies), so that they compare with flexdyn's `@generated` op counts.

Usage: codegen_c.py EXPORT.json OUT_DIR NAME
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import validate  # noqa: E402  (the SX reconstruction and derivation)

ca = validate.ca

# Instructions that move data rather than compute.
NOT_ARITHMETIC = {ca.OP_INPUT, ca.OP_OUTPUT, ca.OP_CONST, ca.OP_PARAMETER, ca.OP_ASSIGN}


def arithmetic_ops(f) -> dict:
    counts: dict[str, int] = {}
    for k in range(f.n_instructions()):
        op = f.instruction_id(k)
        if op in NOT_ARITHMETIC:
            continue
        name = {ca.OP_ADD: "add", ca.OP_SUB: "add", ca.OP_MUL: "mul", ca.OP_DIV: "div",
                ca.OP_NEG: "neg", ca.OP_SQ: "mul"}.get(op, "call")
        counts[name] = counts.get(name, 0) + 1
    counts["total"] = sum(counts.values())
    return counts


def main(argv: list[str]) -> int:
    if len(argv) != 4:
        print(__doc__, file=sys.stderr)
        return 2
    export = validate.load_export(Path(argv[1]))
    out_dir, name = Path(argv[2]), argv[3]
    nq = len(export["coordinates"])
    npar = len(export["runtime_parameters"])
    func, shapes = validate.derive(export, False, False, False)
    q, qd, qdd = ca.SX.sym("q", nq), ca.SX.sym("qd", nq), ca.SX.sym("qdd", nq)
    tau = ca.SX.sym("tau", len(export["actuators"]))
    t, p = ca.SX.sym("t"), ca.SX.sym("p", npar)
    terms = dict(zip([n for n, _ in shapes], func(q, qd, qdd, tau, t, p)))
    wanted = ["mass_matrix", "bias", "constraint_jacobian", "constraint_rhs"]
    f = ca.Function(f"{name}_terms", [q, qd, t, p], [ca.densify(terms[w]) for w in wanted],
                    ["q", "qd", "t", "p"], ["M", "h", "phi_q", "gamma"], {"cse": True})
    out_dir.mkdir(parents=True, exist_ok=True)
    cg = ca.CodeGenerator(f"{name}.c", {"with_header": True, "casadi_real": "double",
                                          "casadi_int": "long long int"})
    cg.add(f)
    cg.generate(str(out_dir) + "/")
    print(json.dumps({"scene": export["name"], "ops": arithmetic_ops(f),
                      "n_instructions": f.n_instructions()}))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
