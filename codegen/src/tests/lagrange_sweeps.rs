//! The derivation by reverse and forward sweeps: the inverse dynamics
//! against the mass matrix and bias forces derived by separate sweeps, the
//! mass matrix against central differences of the momenta, and the growth
//! of the emitted programs along a spatial serial chain and a planar
//! pendulum.

use std::path::Path;

use crate::expr::{Id, Symbol};
use crate::model::Model;
use crate::schedule::functions;
use crate::Source;

fn scene(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../scenes")
        .join(format!("{name}.toml"))
}

/// A serial chain of `n` links, link `k` turning by `q{k}` about
/// `axis(k)`, offset by `translation` from its parent, carrying the
/// component `body(k)` (a TOML table body).
fn serial_chain(
    n: usize,
    translation: &str,
    axis: impl Fn(usize) -> &'static str,
    body: impl Fn(usize) -> String,
) -> Model {
    let mut s = String::from("name = \"chain\"\ngravity = [0, 0, -9.81]\n");
    for k in 0..n {
        s += &format!("[[coordinates]]\nname = \"q{k}\"\n");
    }
    for k in 0..n {
        let parent = if k == 0 {
            "world".into()
        } else {
            format!("link{}", k - 1)
        };
        s += &format!(
            "[[frames]]\nname = \"link{k}\"\nparent = \"{parent}\"\ntranslation = {translation}\nrotation = [{{ axis = \"{}\", angle = \"q{k}\" }}]\n",
            axis(k)
        );
    }
    for k in 0..n {
        s += &format!(
            "[[components]]\nname = \"body{k}\"\nframe = \"link{k}\"\n{}",
            body(k)
        );
    }
    Model::from_source(&Source::new(Path::new("chain.toml"), s)).unwrap()
}

/// A spatial chain of `n` rigid bodies: joint axes alternating z, y, x,
/// offset joints, centres of mass off the joint axes, full inertia tensors.
fn chain(n: usize) -> Model {
    serial_chain(
        n,
        "[0.05, 0.02, 0.3]",
        |k| ["z", "y", "x"][k % 3],
        |k| {
            format!(
                "type = \"rigid_body\"\nmass = {}\nposition = [0.01, -0.015, 0.15]\ninertia = [[0.02, 0.001, -0.0007], [0.001, 0.025, 0.0004], [-0.0007, 0.0004, 0.012]]\n",
                1.0 + 0.1 * k as f64
            )
        },
    )
}

/// The planar `n`-link pendulum: point masses on massless rods, relative
/// joint angles about y.
fn planar_pendulum(n: usize) -> Model {
    serial_chain(
        n,
        "[0, 0, -0.5]",
        |_| "y",
        |k| {
            format!(
                "type = \"point_mass\"\nmass = {}\nposition = [0, 0, -0.5]\n",
                1.0 + 0.05 * k as f64
            )
        },
    )
}

fn state(n: usize, k: usize) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let x = |i: usize, s: f64| ((k * 5 + i * 3 + 1) as f64 * s).sin();
    (
        (0..n).map(|i| 1.2 * x(i, 0.37)).collect(),
        (0..n).map(|i| 2.0 * x(i, 0.91)).collect(),
        (0..n).map(|i| 3.0 * x(i, 1.73)).collect(),
    )
}

fn eval(m: &Model, ids: &[Id], q: &[f64], qd: &[f64], qdd: &[f64], t: f64) -> Vec<f64> {
    m.graph.eval(ids, &|s| match s {
        Symbol::Q(i) => q[i as usize],
        Symbol::Qd(i) => qd[i as usize],
        Symbol::Qdd(i) => qdd[i as usize],
        Symbol::Time => t,
        Symbol::Param(i) => m.runtime_parameters[i as usize].value,
    })
}

#[test]
fn inverse_dynamics_is_mass_times_acceleration_plus_bias() {
    let mut models: Vec<Model> = [
        "double_pendulum",
        "five_bar",
        "spin_up_beam",
        "flyball_governor",
    ]
    .iter()
    .map(|name| Model::load(&scene(name)).unwrap())
    .collect();
    models.push(chain(7));
    models.push(planar_pendulum(12));
    for mut m in models {
        let eq = m.equations().unwrap();
        let n = m.nq();
        for k in 0..4 {
            let (q, qd, qdd) = state(n, k);
            let t = 0.3 * k as f64;
            let tau = eval(&m, &eq.inverse_dynamics, &q, &qd, &qdd, t);
            let h = eval(&m, &eq.bias, &q, &qd, &qdd, t);
            let mass = eval(&m, &eq.mass.concat(), &q, &qd, &qdd, t);
            for i in 0..n {
                let want = h[i] + (0..n).map(|j| mass[i * n + j] * qdd[j]).sum::<f64>();
                let scale = want.abs().max(1.0);
                assert!(
                    (tau[i] - want).abs() <= 1e-12 * scale,
                    "{}: tau[{i}] = {} vs M qdd + h = {want}",
                    m.name,
                    tau[i]
                );
            }
        }
    }
}

/// `M_ij = d p_i / d qd_j` with `p = dT/dqd`: central differences of the
/// kinetic energy's velocity gradient, taken from the energy itself by
/// second differences (`T` is quadratic in `qd`, so they are exact to
/// rounding).
#[test]
fn mass_matrix_is_the_velocity_hessian_of_the_kinetic_energy() {
    let mut m = chain(6);
    let eq = m.equations().unwrap();
    let n = m.nq();
    let (q, qd, qdd) = state(n, 2);
    let energy = |v: &[f64]| eval(&m, &[eq.kinetic_energy], &q, v, &qdd, 0.0)[0];
    let mass = eval(&m, &eq.mass.concat(), &q, &qd, &qdd, 0.0);
    let h = 0.5;
    for i in 0..n {
        for j in 0..n {
            let at = |a: f64, b: f64| {
                let mut v = qd.clone();
                v[i] += a;
                v[j] += b;
                energy(&v)
            };
            let fd = (at(h, h) - at(h, -h) - at(-h, h) + at(-h, -h)) / (4.0 * h * h);
            assert!(
                (fd - mass[i * n + j]).abs() <= 1e-9 * mass[i * n + j].abs().max(1.0),
                "M[{i}][{j}] = {} vs {fd}",
                mass[i * n + j]
            );
        }
    }
}

/// Total operations of the emitted function `name`.
fn ops(m: &Model, eq: &crate::Equations, name: &str) -> usize {
    let f = functions(m, eq)
        .into_iter()
        .find(|f| f.function.name() == name)
        .unwrap();
    f.program.ops.total()
}

/// Bias forces and inverse dynamics grow linearly along a spatial chain,
/// the mass matrix quadratically: doubling the chain from 16 to 32 links at
/// most multiplies them by 2.5 and 5 (quadratic growth would give 4 and
/// cubic 8). The first links cost less than the others (their velocities
/// in the first joints' axes keep zeros), so the counts are `a n - b`, and
/// shorter chains double by more: bias forces 2,338, 6,414 and 14,560
/// operations at 8, 16 and 32 links.
#[test]
fn chain_programs_grow_like_the_recursive_algorithms() {
    let count = |n: usize| {
        let mut m = chain(n);
        let eq = m.equations().unwrap();
        ["bias", "inverse_dynamics", "mass_matrix"].map(|f| ops(&m, &eq, f) as f64)
    };
    let (small, large) = (count(16), count(32));
    let ratio: Vec<f64> = small.iter().zip(&large).map(|(a, b)| b / a).collect();
    assert!(
        ratio[0] < 2.5 && ratio[1] < 2.5 && ratio[2] < 5.0,
        "{small:?} -> {large:?}"
    );
}

/// On the planar pendulum every joint turns about the same axis, so the
/// angular velocity of link `k` is `qd_0 + ... + qd_k`: kept as partial
/// sums, the kinetic energy takes a bounded number of operands per link,
/// and the programs grow like the recursive algorithms' (doubling from 16
/// to 32 links: at most 2.3x for the energy, 2.5x for bias forces and
/// inverse dynamics, 5x for the mass matrix; flat sums gave 3.4x for the
/// bias forces and 12x for the mass matrix).
#[test]
fn planar_pendulum_programs_grow_like_the_recursive_algorithms() {
    let count = |n: usize| {
        let mut m = planar_pendulum(n);
        let eq = m.equations().unwrap();
        let energy: usize = m
            .graph
            .reachable(&[eq.kinetic_energy])
            .iter()
            .map(|&id| m.graph.children(id).len())
            .sum();
        [
            energy as f64,
            ops(&m, &eq, "bias") as f64,
            ops(&m, &eq, "inverse_dynamics") as f64,
            ops(&m, &eq, "mass_matrix") as f64,
        ]
    };
    let (small, large) = (count(16), count(32));
    let ratio: Vec<f64> = small.iter().zip(&large).map(|(a, b)| b / a).collect();
    assert!(
        ratio[0] < 2.3 && ratio[1] < 2.5 && ratio[2] < 2.5 && ratio[3] < 5.0,
        "{small:?} -> {large:?}"
    );
}

/// A scene with every case the Newton-Euler form of a body must cover: a
/// frame turned by time and a coordinate, a frame translated by a
/// coordinate and by time, two elementary rotations in one frame, a
/// rotated full inertia tensor, a centre of mass off the frame's origin, a
/// point mass moving within a turning frame and one in the world, a rod
/// whose end moves within a turning frame and one in the world, and
/// gravity off the axes.
fn mixed_bodies() -> Model {
    let s = r#"
name = "mixed"
gravity = [0.3, -0.2, -9.81]
[[coordinates]]
name = "a"
[[coordinates]]
name = "b"
[[coordinates]]
name = "s"
[[coordinates]]
name = "c"
[[frames]]
name = "hub"
rotation = [{ axis = "z", angle = "0.7*t + a" }]
[[frames]]
name = "arm"
parent = "hub"
translation = ["0.2 + s", "0.05", "0.1*sin(t)"]
rotation = [{ axis = "x", angle = "b" }, { axis = "y", angle = "0.3*b + c" }]
[[frames]]
name = "bracket"
parent = "hub"
translation = [0.0, 0.1, 0.2]
rotation = [{ axis = "x", angle = 0.4 }]
[[frames]]
name = "finger"
parent = "bracket"
translation = [0.05, 0.0, 0.0]
rotation = [{ axis = "z", angle = "b" }]
[[frames]]
name = "spinner"
rotation = [{ axis = "z", angle = "0.9*t" }]
[[frames]]
name = "tip"
parent = "spinner"
translation = [0.1, 0.0, 0.0]
rotation = [{ axis = "y", angle = "c" }]
[[components]]
type = "rigid_body"
frame = "bracket"
mass = 0.25
position = [0.01, 0.02, 0.03]
inertia = [0.002, 0.003, 0.004]
[[components]]
type = "rigid_body"
frame = "finger"
mass = 0.15
position = [0.04, 0.0, 0.01]
inertia = [0.001, 0.002, 0.0015]
[[components]]
type = "rigid_body"
frame = "tip"
mass = 0.35
position = [0.0, 0.03, 0.05]
inertia = [0.003, 0.002, 0.001]
[[components]]
type = "rigid_body"
frame = "arm"
mass = 1.3
position = [0.01, -0.02, 0.15]
inertia = [[0.02, 0.001, -0.0007], [0.001, 0.025, 0.0004], [-0.0007, 0.0004, 0.012]]
inertia_rpy = [0.1, 0.2, 0.3]
[[components]]
type = "rigid_body"
frame = "hub"
mass = 0.5
inertia = [0.01, 0.02, 0.03]
[[components]]
type = "point_mass"
frame = "hub"
mass = 0.4
position = ["0.1*s", "0.2", "0.3*c"]
[[components]]
type = "point_mass"
mass = 0.2
position = ["s", "c*c", "0.1"]
[[components]]
type = "rod"
frame = "arm"
mass = 0.7
from = [0, 0, 0]
to = ["0.3*cos(c)", "0.1", "0.3*sin(c) + 0.2*s"]
[[components]]
type = "rod"
mass = 0.3
from = ["s", 0, 0]
to = ["s + 0.4*cos(a)", "0.4*sin(a)", "0.1*b"]
"#;
    Model::from_source(&Source::new(Path::new("mixed.toml"), s.into())).unwrap()
}

/// The bias forces and inverse dynamics that the derivation writes for
/// rigid bodies and point masses as Newton-Euler forces equal those of
/// Lagrange's equations differentiated from the same kinetic energies
/// (the bodies' rigid-body form removed, so that their energies go through
/// the reverse and forward sweeps like any other component).
#[test]
fn newton_euler_forces_equal_the_lagrange_terms_of_the_bodies() {
    let mut models: Vec<Model> = ["double_pendulum", "five_bar", "flyball_governor", "ur5"]
        .iter()
        .map(|name| Model::load(&scene(name)).unwrap())
        .collect();
    models.push(
        Model::load(
            &Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../examples/parallel-robot/scenes/parallel_robot_rigid.toml"),
        )
        .unwrap(),
    );
    models.push(chain(5));
    models.push(planar_pendulum(4));
    models.push(mixed_bodies());
    for mut m in models {
        assert!(
            m.components.iter().any(|c| !c.bodies.is_empty()),
            "{}",
            m.name
        );
        let mut lagrange = m.clone();
        for c in &mut lagrange.components {
            c.bodies.clear();
        }
        let (eq, eq_l) = (m.equations().unwrap(), lagrange.equations().unwrap());
        let n = m.nq();
        for k in 0..4 {
            let (q, qd, qdd) = state(n, k);
            let t = 0.3 * k as f64;
            for (what, a, b) in [
                ("bias", &eq.bias, &eq_l.bias),
                (
                    "inverse dynamics",
                    &eq.inverse_dynamics,
                    &eq_l.inverse_dynamics,
                ),
                ("mass matrix", &eq.mass.concat(), &eq_l.mass.concat()),
            ] {
                let x = eval(&m, a, &q, &qd, &qdd, t);
                let y = eval(&lagrange, b, &q, &qd, &qdd, t);
                let scale = y.iter().fold(1.0f64, |s, v| s.max(v.abs()));
                for i in 0..x.len() {
                    assert!(
                        (x[i] - y[i]).abs() <= 1e-12 * scale,
                        "{} {what}[{i}]: Newton-Euler {} vs Lagrange {}",
                        m.name,
                        x[i],
                        y[i]
                    );
                }
            }
        }
    }
}
