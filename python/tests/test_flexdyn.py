"""The flexdyn Python package against the command line (bitwise), Pinocchio
(UR5, Panda), closed forms, itself (batch against loop) and bad input.

Needs the package installed (`pip install ./python`) and, for the
comparison with `flexdyn eval`, the command line's binary in FLEXDYN_BIN
(tests/python_package.rs sets both up); Pinocchio's comparison is skipped
where `pinocchio` is not installed.
"""

import json
import math
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

import flexdyn

ROOT = Path(__file__).resolve().parents[2]
SCENES = ROOT / "scenes"
RNG = np.random.default_rng(20261126)


def states(model, n):
    return (RNG.uniform(-2, 2, (n, model.nq)), RNG.uniform(-2, 2, (n, model.nq)),
            RNG.uniform(-2, 2, (n, model.nq)))


@pytest.mark.parametrize("scene", ["double_pendulum", "five_bar", "spin_up_beam", "four_bar"])
def test_terms_equal_flexdyn_eval_bitwise(scene, tmp_path):
    binary = os.environ.get("FLEXDYN_BIN")
    if not binary:
        pytest.skip("FLEXDYN_BIN is not set")
    m = flexdyn.load(SCENES / f"{scene}.toml")
    q, qd, qdd = states(m, 5)
    t = RNG.uniform(0, 1, 5)
    path = tmp_path / "states.json"
    path.write_text(json.dumps({"states": [
        {"q": q[k].tolist(), "qd": qd[k].tolist(), "qdd": qdd[k].tolist(), "t": float(t[k])}
        for k in range(5)]}))
    out = subprocess.run([binary, "eval", "--scene", str(SCENES / f"{scene}.toml"), "--states", str(path)],
                         check=True, capture_output=True, text=True).stdout
    results = json.loads(out)["results"]
    ours = {
        "mass_matrix": m.mass_matrix(q, t),
        "bias": m.bias(q, qd, t),
        "inverse_dynamics": m.inverse_dynamics(q, qd, qdd, t),
        "constraints": m.constraints(q, t),
        "constraint_jacobian": m.constraint_jacobian(q, t),
        "constraint_rhs": m.constraint_rhs(q, qd, t),
        "kinetic_energy": m.kinetic_energy(q, qd, t),
        "potential_energy": m.potential_energy(q, t),
    }
    for name, value in ours.items():
        theirs = np.array([r[name] for r in results], dtype=float).reshape(value.shape)
        assert np.array_equal(value, theirs), f"{scene} {name}: {value} vs {theirs}"


def test_a_batch_equals_a_loop_of_single_states():
    m = flexdyn.load(SCENES / "five_bar.toml")
    # A few states (one at a time), some (side by side on the tapes, a
    # partial group last) and many (also split over the cores).
    for n in (3, 13, 700):
        q, qd, qdd = states(m, n)
        tau = RNG.uniform(-1, 1, (n, m.nu))
        batch = [m.mass_matrix(q), m.bias(q, qd), m.inverse_dynamics(q, qd, qdd),
                 m.constraint_jacobian(q), m.forward_dynamics(q, qd, tau),
                 m.kinetic_energy(q, qd)]
        loop = [np.array([f(k) for k in range(n)]) for f in (
            lambda k: m.mass_matrix(q[k]), lambda k: m.bias(q[k], qd[k]),
            lambda k: m.inverse_dynamics(q[k], qd[k], qdd[k]),
            lambda k: m.constraint_jacobian(q[k]),
            lambda k: m.forward_dynamics(q[k], qd[k], tau[k]),
            lambda k: m.kinetic_energy(q[k], qd[k]))]
        for b, l in zip(batch, loop):
            assert b.shape == l.shape and np.array_equal(b, l), n
    # Arrays in other layouts and plain lists read as the same numbers.
    assert np.array_equal(m.bias(np.asfortranarray(q), qd[:, ::-1][:, ::-1]), batch[1])
    assert np.array_equal(m.bias(q[5].tolist(), list(qd[5])), batch[1][5])


def test_forward_dynamics_solve_the_equations_of_motion():
    m = flexdyn.load(SCENES / "double_pendulum.toml")
    q, qd, _ = states(m, 20)
    tau = RNG.uniform(-1, 1, (20, m.nu))
    qdd = m.forward_dynamics(q, qd, tau)
    # M qdd + h = B tau (B is the identity for this scene's actuators).
    assert np.allclose(m.inverse_dynamics(q, qd, qdd), tau, rtol=0, atol=1e-12)


def robots_dir():
    import site

    for root in site.getsitepackages():
        p = Path(root) / "cmeel.prefix" / "share" / "example-robot-data" / "robots"
        if p.is_dir():
            return p
    pytest.skip("example-robot-data is not installed")


@pytest.mark.parametrize("robot,urdf,fix", [
    ("ur5", "ur_description/urdf/ur5_robot.urdf", []),
    ("panda", "panda_description/urdf/panda.urdf", ["panda_finger_joint1", "panda_finger_joint2"]),
])
def test_urdf_robots_match_pinocchio(robot, urdf, fix):
    pin = pytest.importorskip("pinocchio")
    path = robots_dir() / urdf
    m = flexdyn.from_urdf(path, fix=fix, keep_angles=True)
    model = pin.buildModelFromUrdf(str(path))
    if fix:
        model = pin.buildReducedModel(model, [model.getJointId(j) for j in fix], pin.neutral(model))
    data = model.createData()
    index = {model.names[j]: model.joints[j].idx_v for j in range(1, model.njoints)}
    order = [index[c] for c in m.coordinates]
    q, qd, qdd = states(m, 50)
    ours_m, ours_tau = m.mass_matrix(q), m.inverse_dynamics(q, qd, qdd)
    for k in range(50):
        qp, vp, ap = (np.zeros(model.nv) for _ in range(3))
        qp[order], vp[order], ap[order] = q[k], qd[k], qdd[k]
        mm = pin.crba(model, data, qp)
        mm = np.triu(mm) + np.triu(mm, 1).T
        tau = pin.rnea(model, data, qp, vp, ap) + model.damping * vp
        assert np.abs(ours_m[k] - mm[np.ix_(order, order)]).max() <= 1e-12 * np.abs(mm).max()
        assert np.abs(ours_tau[k] - tau[order]).max() <= 1e-12 * np.abs(tau).max()


SPRING = """
name = "oscillator"
[parameters]
m = 2.0
k = 50.0
[[coordinates]]
name = "x"
[[components]]
name = "mass"
type = "point_mass"
mass = "m"
position = ["x", 0, 0]
[[components]]
name = "spring"
type = "spring"
stiffness = "k"
expression = "x"
"""


def test_simulate_reproduces_the_closed_form_oscillation(tmp_path):
    scene = tmp_path / "oscillator.toml"
    scene.write_text(SPRING)
    m = flexdyn.load(scene)
    r = flexdyn.simulate(m, duration=2.0, initial={"q": [0.1], "qd": [0.0]}, dt=0.01, quiet=True)
    w = math.sqrt(50.0 / 2.0)
    assert r["t"].shape == (201,) and r["q"].shape == (201, 1) and r["qd"].shape == (201, 1)
    assert np.abs(r["q"][:, 0] - 0.1 * np.cos(w * r["t"])).max() < 1e-7
    assert np.abs(r["qd"][:, 0] + 0.1 * w * np.sin(w * r["t"])).max() < 1e-6


def test_simulate_takes_inputs_and_options(tmp_path):
    m = flexdyn.load(SCENES / "pendulum.toml")
    r = flexdyn.simulate(m, duration=1.0, initial={"q": [0.0], "qd": [0.0]},
                         inputs={"tau": "0.5*sin(2*t)"}, dt=0.001, quiet=True,
                         options={"integrator": "rk4", "output_dt": 0.01})
    assert r["t"].shape == (101,)
    # Driven from rest: it moved, in the direction of the first push.
    assert r["theta"][10] > 0


def test_inverse_dynamics_along_a_prescribed_motion_match_the_closed_form():
    m = flexdyn.load(SCENES / "pendulum.toml")
    r = flexdyn.inverse(m, duration=1.0, dt=0.01, prescribe={"theta": "0.3*sin(t)"}, quiet=True)
    t = r["t"]
    theta, acc = 0.3 * np.sin(t), -0.3 * np.sin(t)
    # m l^2 theta'' + m g l sin(theta), m = 1, l = 0.5, g = 9.81.
    want = 0.25 * acc + 9.81 * 0.5 * np.sin(theta)
    assert r["tau"].shape == (101, 1)
    assert np.abs(r["tau"][:, 0] - want).max() < 1e-9


def test_generate_writes_a_module(tmp_path):
    flexdyn.generate(SCENES / "pendulum.toml", tmp_path / "f64", c_header=True)
    assert (tmp_path / "f64" / "pendulum.rs").is_file() and (tmp_path / "f64" / "pendulum.h").is_file()
    flexdyn.generate(SCENES / "pendulum.toml", tmp_path / "f32", precision="f32")
    assert "f32" in (tmp_path / "f32" / "pendulum.rs").read_text()
    with pytest.raises(ValueError, match="f64 models only"):
        flexdyn.generate(SCENES / "pendulum.toml", tmp_path / "x", precision="f32", c_header=True)


def test_bad_input_raises_with_the_command_lines_message(tmp_path):
    with pytest.raises(ValueError, match="nope.toml"):
        flexdyn.load(tmp_path / "nope.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "bad"\n[[coordinates]]\nname = "x"\n[[components]]\ntype = "warp"\n')
    with pytest.raises(ValueError, match=r"bad.toml:5"):
        flexdyn.load(bad)
    m = flexdyn.load(SCENES / "double_pendulum.toml")
    with pytest.raises(ValueError, match=r"needs \(2,\)"):
        m.mass_matrix([0.1, 0.2, 0.3])
    with pytest.raises(ValueError, match="t: 3 times for 2 states"):
        m.mass_matrix(np.zeros((2, 2)), t=[0.0, 1.0, 2.0])
    with pytest.raises(ValueError, match="warp-drive"):
        flexdyn.simulate(m, duration=1.0, integrator="warp-drive")
    with pytest.raises(ValueError, match="unknown actuator `push`"):
        flexdyn.simulate(m, duration=1.0, inputs={"push": "1"})
    with pytest.raises(RuntimeError, match="step"):
        flexdyn.simulate(m, duration=1.0, dt=0.5, options={"integrator": "rk4"}, quiet=True,
                         initial={"q": [3.0, -3.0], "qd": [40.0, -40.0]})
    with pytest.raises(ValueError, match="robot.urdf"):
        (tmp_path / "robot.urdf").write_text("<robot name='r'><link name='a'/>")
        flexdyn.from_urdf(tmp_path / "robot.urdf")


def test_markers_and_derivatives_equal_flexdyn_eval_bitwise(tmp_path):
    binary = os.environ.get("FLEXDYN_BIN")
    if not binary:
        pytest.skip("FLEXDYN_BIN is not set")
    for scene in ["four_bar", "cart_pole"]:
        m = flexdyn.load(SCENES / f"{scene}.toml")
        q, qd, qdd = states(m, 4)
        tau = RNG.uniform(-1, 1, (4, m.nu))
        t = RNG.uniform(0, 1, 4)
        path = tmp_path / "states.json"
        path.write_text(json.dumps({"states": [
            {"q": q[k].tolist(), "qd": qd[k].tolist(), "qdd": qdd[k].tolist(),
             "tau": tau[k].tolist(), "t": float(t[k])} for k in range(4)]}))
        out = subprocess.run([binary, "eval", "--scene", str(SCENES / f"{scene}.toml"),
                              "--states", str(path)], check=True, capture_output=True, text=True).stdout
        results = json.loads(out)["results"]
        for name in m.markers:
            position, rotation, jacobian = m.marker_jacobian(name, q, t)
            velocity, bias = m.marker_motion(name, q, qd, t)
            for key, ours in [("position", position), ("rotation", rotation), ("jacobian", jacobian),
                              ("velocity", velocity), ("acceleration_bias", bias)]:
                theirs = np.array([r["markers"][name][key] for r in results], dtype=float)
                assert np.array_equal(ours, theirs.reshape(ours.shape)), f"{scene} {name} {key}"
        if scene == "cart_pole":
            tau_id, tau_q, tau_qd = m.inverse_dynamics_derivatives(q, qd, qdd, t)
            fd = m.forward_dynamics_derivatives(q, qd, tau, t)
            for key, ours in [("inverse_dynamics", tau_id), ("inverse_dynamics_q", tau_q),
                              ("inverse_dynamics_qd", tau_qd), ("forward_dynamics", fd["qdd"]),
                              ("forward_dynamics_q", fd["qdd_q"]), ("forward_dynamics_qd", fd["qdd_qd"]),
                              ("forward_dynamics_tau", fd["qdd_tau"])]:
                theirs = np.array([r[key] for r in results], dtype=float)
                assert np.array_equal(ours, theirs.reshape(ours.shape)), f"{scene} {key}"


def test_marker_jacobian_is_the_derivative_of_the_marker_position():
    m = flexdyn.load(SCENES / "ur5.toml")
    q, qd, _ = states(m, 3)
    h = 1e-6
    for name in m.markers:
        _, _, jacobian = m.marker_jacobian(name, q)
        velocity, _ = m.marker_motion(name, q, qd)
        ahead, _ = m.marker_pose(name, q + h * qd)
        behind, _ = m.marker_pose(name, q - h * qd)
        central = (ahead - behind) / (2 * h)
        linear = np.einsum("kij,kj->ki", jacobian, qd)[:, :3]
        scale = max(1.0, np.abs(linear).max())
        assert np.abs(central - linear).max() <= 1e-7 * scale, name
        assert np.array_equal(velocity, np.einsum("kij,kj->ki", jacobian, qd)) or \
            np.abs(velocity - np.einsum("kij,kj->ki", jacobian, qd)).max() <= 1e-13 * scale


def test_forward_dynamics_derivatives_match_central_differences():
    m = flexdyn.load(SCENES / "cart_pole.toml")
    q, qd, _ = states(m, 1)
    q, qd = q[0], qd[0]
    tau = np.array([0.3] * m.nu)
    d = m.forward_dynamics_derivatives(q, qd, tau)
    assert np.array_equal(d["qdd"], m.forward_dynamics(q, qd, tau))
    h = 1e-6
    for j in range(m.nq):
        e = np.zeros(m.nq)
        e[j] = h
        dq = (m.forward_dynamics(q + e, qd, tau) - m.forward_dynamics(q - e, qd, tau)) / (2 * h)
        dqd = (m.forward_dynamics(q, qd + e, tau) - m.forward_dynamics(q, qd - e, tau)) / (2 * h)
        scale = max(1.0, np.abs(d["qdd_q"]).max(), np.abs(d["qdd_qd"]).max())
        assert np.abs(d["qdd_q"][:, j] - dq).max() <= 1e-6 * scale
        assert np.abs(d["qdd_qd"][:, j] - dqd).max() <= 1e-6 * scale


def test_a_batch_of_marker_poses_equals_a_loop():
    m = flexdyn.load(SCENES / "ur5.toml")
    q, _, _ = states(m, 600)
    position, rotation = m.marker_pose("wrist_1_link", q)
    for k in range(600):
        p, r = m.marker_pose("wrist_1_link", q[k])
        assert np.array_equal(p, position[k]) and np.array_equal(r, rotation[k])


def test_unknown_markers_and_missing_derivatives_raise():
    m = flexdyn.load(SCENES / "ur5.toml")
    q = np.zeros(m.nq)
    with pytest.raises(ValueError, match="no marker tcp; its markers: \\[base_link"):
        m.marker_pose("tcp", q)
    with pytest.raises(ValueError, match="no marker 99"):
        m.marker_pose(99, q)
    with pytest.raises(ValueError, match="does not generate `inverse_dynamics_derivatives`"):
        m.inverse_dynamics_derivatives(q, q, q)
    with pytest.raises(ValueError, match="does not generate `inverse_dynamics_derivatives`"):
        m.forward_dynamics_derivatives(q, q, np.zeros(m.nu))


def test_linearize_is_the_forward_dynamics_derivatives_in_state_space():
    m = flexdyn.load(SCENES / "cart_pole.toml")
    q, qd = np.array([0.1, 2.9]), np.array([0.2, -0.3])
    lin = flexdyn.linearize(m, q, qd, t=0.0, inputs={m.actuators[0]: 0.4})
    d = m.forward_dynamics_derivatives(q, qd, np.array([0.4]))
    n = m.nq
    assert lin["states"] == m.coordinates + [f"{c}_dot" for c in m.coordinates]
    assert np.array_equal(lin["A"][:n], np.hstack([np.zeros((n, n)), np.eye(n)]))
    assert np.array_equal(lin["A"][n:], np.hstack([d["qdd_q"], d["qdd_qd"]]))
    assert np.array_equal(lin["B"][n:], d["qdd_tau"]) and not lin["B"][:n].any()
    assert np.array_equal(lin["f0"], np.concatenate([qd, d["qdd"]]))
    ours = np.sort_complex(lin["eigenvalues_A"])
    theirs = np.sort_complex(np.linalg.eigvals(lin["A"]))
    assert np.abs(ours - theirs).max() <= 1e-9 * np.abs(theirs).max()
    with pytest.raises(ValueError, match="does not generate the derivatives"):
        flexdyn.linearize(flexdyn.load(SCENES / "pendulum.toml"), [0.1], [0.0])
