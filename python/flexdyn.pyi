"""flexdyn: exact, generated equations of motion for rigid and flexible
multibody systems (scene files and URDF robots), from Python."""

from os import PathLike
from typing import Mapping, Optional, Sequence, Union

import numpy as np
import numpy.typing as npt

ArrayLike = npt.ArrayLike
Time = Union[float, Sequence[float], npt.NDArray[np.float64]]
Path = Union[str, PathLike]

class Model:
    """A scene's equations of motion, generated in memory, each function
    compiled to machine code on its first call (interpreted where that is
    not possible): bitwise the numbers of its compiled module. Every array argument is
    one state (`(nq,)`) or a batch (`(N, nq)`, evaluated in Rust, in
    parallel for large N); `t` a number or one per state."""

    @property
    def name(self) -> str: ...
    @property
    def nq(self) -> int: ...
    @property
    def nc(self) -> int: ...
    @property
    def nu(self) -> int: ...
    @property
    def coordinates(self) -> list[str]: ...
    @property
    def actuators(self) -> list[str]: ...
    @property
    def markers(self) -> list[str]: ...
    @property
    def scene(self) -> str: ...
    def mass_matrix(self, q: ArrayLike, t: Optional[Time] = None) -> npt.NDArray[np.float64]: ...
    def bias(self, q: ArrayLike, qd: ArrayLike, t: Optional[Time] = None) -> npt.NDArray[np.float64]: ...
    def inverse_dynamics(self, q: ArrayLike, qd: ArrayLike, qdd: ArrayLike, t: Optional[Time] = None) -> npt.NDArray[np.float64]: ...
    def forward_dynamics(self, q: ArrayLike, qd: ArrayLike, tau: ArrayLike, t: Optional[Time] = None) -> npt.NDArray[np.float64]: ...
    def constraints(self, q: ArrayLike, t: Optional[Time] = None) -> npt.NDArray[np.float64]: ...
    def constraint_jacobian(self, q: ArrayLike, t: Optional[Time] = None) -> npt.NDArray[np.float64]: ...
    def constraint_rhs(self, q: ArrayLike, qd: ArrayLike, t: Optional[Time] = None) -> npt.NDArray[np.float64]: ...
    def kinetic_energy(self, q: ArrayLike, qd: ArrayLike, t: Optional[Time] = None) -> npt.NDArray[np.float64]: ...
    def potential_energy(self, q: ArrayLike, t: Optional[Time] = None) -> npt.NDArray[np.float64]: ...
    def marker_pose(self, marker: Union[str, int], q: ArrayLike, t: Optional[Time] = None) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """`(position (3,), rotation (3, 3))` in world axes."""
    def marker_jacobian(self, marker: Union[str, int], q: ArrayLike, t: Optional[Time] = None) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """`(position, rotation, jacobian (6, nq))`: rows 0-2 the point's velocity, 3-5 the angular velocity, world axes."""
    def marker_motion(self, marker: Union[str, int], q: ArrayLike, qd: ArrayLike, t: Optional[Time] = None) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """`(velocity (6,), acceleration_bias (6,))`: `J qd` and the acceleration at `qdd = 0`."""
    def inverse_dynamics_derivatives(self, q: ArrayLike, qd: ArrayLike, qdd: ArrayLike, t: Optional[Time] = None) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """`(tau, d tau/d q, d tau/d qd)`; scenes with `outputs = ["dynamics_derivatives"]`."""
    def forward_dynamics_derivatives(self, q: ArrayLike, qd: ArrayLike, tau: ArrayLike, t: Optional[Time] = None) -> dict[str, npt.NDArray[np.float64]]:
        """`qdd`, `lambda` and their derivatives `qdd_q`, `qdd_qd`, `qdd_tau`, `lambda_q`, `lambda_qd`, `lambda_tau`."""

def load(path: Path) -> Model:
    """A scene file; `ValueError` with file and line for a bad one."""

def from_urdf(path: Path, fix: Sequence[str] = ..., outputs: Sequence[str] = ..., keep_angles: bool = False) -> Model:
    """A URDF robot, as `flexdyn import urdf`."""

def simulate(
    model: Model,
    duration: float,
    initial: Optional[Mapping[str, ArrayLike]] = None,
    inputs: Optional[Mapping[str, str]] = None,
    integrator: Optional[str] = None,
    dt: Optional[float] = None,
    quiet: bool = False,
    options: Optional[Mapping[str, object]] = None,
) -> dict[str, npt.NDArray[np.float64]]:
    """`flexdyn simulate`: the CSV's columns, and `q`, `qd` as `(N, nq)`."""

def inverse(
    model: Model,
    duration: float,
    dt: float,
    prescribe: Mapping[str, str],
    quiet: bool = False,
    options: Optional[Mapping[str, object]] = None,
) -> dict[str, npt.NDArray[np.float64]]:
    """`flexdyn inverse`: the CSV's columns, `tau` `(N, nu)`, `q` `(N, nq)`."""

def linearize(
    model: Model,
    q: Sequence[float],
    qd: Sequence[float],
    t: float = 0.0,
    inputs: Optional[Mapping[str, float]] = None,
    independent: Optional[Sequence[str]] = None,
) -> dict[str, object]:
    """`flexdyn linearize`: `A`, `B`, `x0`, `u0`, `f0` (numpy), `eigenvalues_A` (complex), `states`, `inputs`, `reduction`."""

def generate(scene: Path, out: Path, precision: str = "f64", c_header: bool = False) -> None:
    """`flexdyn generate` of one scene into `out`."""
