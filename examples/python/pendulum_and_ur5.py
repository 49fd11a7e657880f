"""flexdyn from Python, notebook style: a pendulum simulated and checked
against energy conservation, the UR5's inverse dynamics on a batch of
states against a loop, and a plot.

    pip install ./python numpy matplotlib   # from the repository root
    python examples/python/pendulum_and_ur5.py

writes examples/python/pendulum.png.
"""

# %% A scene file, generated in memory and interpreted.
from pathlib import Path

import numpy as np

import flexdyn

root = Path(__file__).resolve().parents[2]
pendulum = flexdyn.load(root / "scenes" / "pendulum.toml")
print(pendulum, pendulum.coordinates, pendulum.actuators)

# %% Its terms at a state, or at many at once.
print("M(0.3) =", pendulum.mass_matrix([0.3]))
q = np.linspace(-1, 1, 5)[:, None]
print("V(q) =", pendulum.potential_energy(q))

# %% A simulation from 1 rad: the command line's `simulate`, same code.
run = flexdyn.simulate(pendulum, duration=5.0, initial={"q": [1.0], "qd": [0.0]}, dt=0.01, quiet=True)
energy = run["T"] + run["V"]
print(f"{len(run['t'])} rows; energy drift {np.ptp(energy):.2e} J (no damping, no input)")

# %% The UR5 (scenes/ur5.toml, imported from its URDF): 10,000 states in one call.
ur5 = root / "scenes" / "ur5.toml"
robot = flexdyn.load(ur5)
rng = np.random.default_rng(0)
qs, qds, qdds = (rng.uniform(-2, 2, (10_000, robot.nq)) for _ in range(3))
tau = robot.inverse_dynamics(qs, qds, qdds)
assert np.array_equal(tau[17], robot.inverse_dynamics(qs[17], qds[17], qdds[17]))
print("UR5 torques:", tau.shape)

# %% A plot.
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

fig, ax = plt.subplots(figsize=(7, 3))
ax.plot(run["t"], run["theta"], label="theta (rad)")
ax.plot(run["t"], run["theta_dot"], label="theta_dot (rad/s)")
ax.set_xlabel("t (s)")
ax.legend()
ax.grid(True)
fig.tight_layout()
out = Path(__file__).with_name("pendulum.png")
fig.savefig(out, dpi=100)
print("wrote", out)
