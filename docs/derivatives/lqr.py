"""An LQR gain for a linearization written by `flexdyn linearize`.

Reads the linearization (JSON with `A`, `B`, `states`, `inputs`, `x0`, `u0`),
solves the continuous-time algebraic Riccati equation
`A^T P + P A - P B R^-1 B^T P + Q = 0` from the stable invariant subspace of
its Hamiltonian matrix (numpy only), and writes the same JSON with the gain
`K = R^-1 B^T P` added: the file `flexdyn simulate --feedback` reads
(`u = u0 - K (x - x0)`). Also prints the closed-loop eigenvalues.

Usage: lqr.py LINEARIZATION.json K.json [--q W1,W2,...] [--r R1,...]
(the diagonals of Q and R, default ones).
"""

import argparse
import json

import numpy as np


def lqr(a, b, q, r):
    n = a.shape[0]
    r_inv = np.linalg.inv(r)
    hamiltonian = np.block([[a, -b @ r_inv @ b.T], [-q, -a.T]])
    values, vectors = np.linalg.eig(hamiltonian)
    stable = vectors[:, values.real < 0]
    if stable.shape[1] != n:
        raise SystemExit("no stabilising solution: is (A, B) stabilisable?")
    p = np.real(stable[n:] @ np.linalg.inv(stable[:n]))
    return r_inv @ b.T @ p


def diagonal(text, n, what):
    if text is None:
        return np.eye(n)
    values = [float(v) for v in text.split(",")]
    if len(values) != n:
        raise SystemExit(f"{what}: {len(values)} weights for {n} entries")
    return np.diag(values)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("linearization")
    ap.add_argument("out")
    ap.add_argument("--q")
    ap.add_argument("--r")
    args = ap.parse_args()
    with open(args.linearization) as f:
        lin = json.load(f)
    a, b = np.array(lin["A"]), np.array(lin["B"])
    k = lqr(a, b, diagonal(args.q, a.shape[0], "--q"), diagonal(args.r, b.shape[1], "--r"))
    closed = np.linalg.eigvals(a - b @ k)
    print("closed-loop eigenvalues:", " ".join(f"{z:.4g}" for z in sorted(closed, key=lambda z: z.real)))
    lin["K"] = k.tolist()
    with open(args.out, "w") as f:
        json.dump(lin, f, indent=1)


if __name__ == "__main__":
    main()
