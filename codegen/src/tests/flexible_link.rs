//! Issue 5: the `flexible_link` component, stations and vector constraints.
//!
//! References are independent of the symbolic path: the kinetic energy is
//! compared with `fem::kinetic_energy` fed with frame velocities computed
//! here by hand, the rigid limit with the `rod` component, the static
//! deflection with the Euler-Bernoulli closed form, the closure with a
//! configuration assembled here from the nodal mode shapes, and Jacobians
//! with finite differences.

use std::path::Path;

use crate::derive::{derive, Equations};
use crate::error::{Error, Source};
use crate::expr::{Graph, Id, Node, Symbol};
use crate::fem::modal::ModeKind;
use crate::fem::{
    self, Beam, BoundaryConditions, FeModel, Invariants, Material, ModeSelection, Section,
    NODE_DOFS, RX, RY, RZ, UX, UY, UZ,
};
use crate::model::Model;
use nalgebra::{DMatrix, DVector, Matrix3, Rotation3, Vector3};

const FILE: &str = "scene.toml";

fn load(text: &str) -> Result<Model, Error> {
    Model::from_source(&Source::new(Path::new(FILE), text.to_owned()))
}

#[track_caller]
fn model(text: &str) -> Model {
    load(text).unwrap_or_else(|e| panic!("{e}\n{text}"))
}

#[track_caller]
fn fail(text: &str) -> Error {
    match load(text) {
        Ok(_) => panic!("scene was accepted:\n{text}"),
        Err(e) => e,
    }
}

/// Deterministic pseudo-random numbers in `[-1, 1)` (xorshift).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }

    /// A state inside the declared ranges of the model's coordinates.
    fn state(&mut self, m: &Model) -> (Vec<f64>, Vec<f64>) {
        let mut pick = |r: Option<[f64; 2]>| {
            let [a, b] = r.unwrap_or([-2.0, 2.0]);
            a + (b - a) * (self.next() + 1.0) / 2.0
        };
        let q = m.coordinates.iter().map(|c| pick(c.range)).collect();
        let qd = m
            .coordinates
            .iter()
            .map(|c| pick(c.velocity_range))
            .collect();
        (q, qd)
    }
}

fn eval(g: &Graph, ids: &[Id], q: &[f64], qd: &[f64], t: f64) -> Vec<f64> {
    g.eval(ids, &|s| match s {
        Symbol::Q(i) => q[i as usize],
        Symbol::Qd(i) => qd[i as usize],
        Symbol::Time => t,
        Symbol::Param(_) | Symbol::Qdd(_) => {
            panic!("no runtime parameters in these scenes, no accelerations in these terms")
        }
    })
}

fn eval_matrix(g: &Graph, m: &[Vec<Id>], q: &[f64], qd: &[f64]) -> DMatrix<f64> {
    let flat: Vec<Id> = m.iter().flatten().copied().collect();
    let v = eval(g, &flat, q, qd, 0.0);
    let cols = m.first().map_or(0, Vec::len);
    DMatrix::from_row_slice(m.len(), cols, &v)
}

fn coordinate(m: &Model, name: &str) -> usize {
    m.coordinates
        .iter()
        .position(|c| c.name == name)
        .unwrap_or_else(|| panic!("no coordinate `{name}`"))
}

// ---------------------------------------------------------------------------
// A link on a rotating hub: T against the invariants' numeric assembly.

const L: f64 = 0.9;
const R_HUB: f64 = 0.25;
const BETA: f64 = 0.4;

/// A hub spinning about world z by `theta`; the link frame sits at radius
/// `R_HUB` on it, pitched by the constant `BETA` about its y axis, and the
/// link is clamped there. Every frame-axis component of `V` and `w` is
/// nonzero, so every invariant enters `T`.
fn rotating_scene(extra: &str) -> String {
    format!(
        r#"name = "rotor"
gravity = [0, 0, 0]

[parameters]
L = {L}
r = {R_HUB}
beta = {BETA}

[[coordinates]]
name = "theta"
range = [-3.0, 3.0]
velocity_range = [-20.0, 20.0]

[[frames]]
name = "hub"
rotation = [{{ axis = "z", angle = "theta" }}]

[[frames]]
name = "arm"
parent = "hub"
translation = ["r", 0, 0]
rotation = [{{ axis = "y", angle = "beta" }}]

[[components]]
name = "blade"
type = "flexible_link"
frame = "arm"
length = "L"
material = {{ youngs_modulus = 7.0e10, poisson = 0.33, density = 2700 }}
section = {{ outer_radius = 0.02, inner_radius = 0.015 }}
elements = 8
boundary = "clamped_free"
{extra}
"#
    )
}

fn rotating_invariants(modes: usize) -> Invariants {
    let material = Material::new(7.0e10, 0.33, 2700.0).unwrap();
    let beam = Beam::new(L, material, Section::tube(0.02, 0.015).unwrap(), 8).unwrap();
    let fe = FeModel::new(&beam, &BoundaryConditions::clamped_free()).unwrap();
    let basis = fe.modes_selected(ModeSelection::First(modes)).unwrap();
    Invariants::new(&fe, &basis)
}

/// Origin velocity and angular velocity of the link frame, in its axes.
fn hub_kinematics(theta: f64, theta_dot: f64) -> ([f64; 3], [f64; 3]) {
    let a = Rotation3::from_axis_angle(&Vector3::z_axis(), theta)
        * Rotation3::from_axis_angle(&Vector3::y_axis(), BETA);
    let w_world = Vector3::new(0.0, 0.0, theta_dot);
    let origin =
        Rotation3::from_axis_angle(&Vector3::z_axis(), theta) * Vector3::new(R_HUB, 0.0, 0.0);
    let v_world = w_world.cross(&origin);
    let v = a.inverse() * v_world;
    let w = a.inverse() * w_world;
    ([v.x, v.y, v.z], [w.x, w.y, w.z])
}

#[test]
fn kinetic_energy_matches_the_invariants_and_strain_energy_the_frequencies() {
    // Ten modes: bending in both planes, torsion and, with this tube, the
    // first axial mode, so that S1, I1 and I2 all have entries.
    let m = model(&rotating_scene("modes = 10"));
    let link = &m.flexible_links[0];
    assert_eq!(link.modes(), 10);
    assert_eq!(m.nq(), 11);
    for j in 0..10 {
        assert_eq!(m.coordinates[1 + j].name, format!("blade_eta{}", j + 1));
    }
    let inv = rotating_invariants(10);
    let kinds = &link.basis.kinds;
    for kind in [ModeKind::BendingXY, ModeKind::BendingXZ, ModeKind::Torsion] {
        assert!(kinds.contains(&kind), "{kinds:?}");
    }
    let c = &m.components[0];
    // The strain energy keeps only the squares: the off-diagonal entries of
    // Kff are round-off and dropped. (The half in front stays outside the
    // sum of ten terms, one multiplication instead of ten.)
    let potential = match m.graph.node(c.potential) {
        Node::Sum(terms, constant) if terms.len() == 1 && constant.get() == 0.0 => terms[0].0,
        _ => c.potential,
    };
    match m.graph.node(potential) {
        Node::Sum(terms, constant) => {
            assert_eq!(terms.len(), 10, "{}", m.graph.display(c.potential));
            assert_eq!(constant.get(), 0.0);
        }
        other => panic!("{other:?}"),
    }
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    for _ in 0..30 {
        let (mut q, mut qd) = rng.state(&m);
        // Deflections well beyond the declared range, so that the terms
        // quadratic in eta weigh in.
        for j in 1..11 {
            q[j] *= 1e3;
            qd[j] *= 1e2;
        }
        let got = eval(&m.graph, &[c.kinetic, c.potential], &q, &qd, 0.0);
        let (v, w) = hub_kinematics(q[0], qd[0]);
        let reference = fem::kinetic_energy(&inv, v, w, &q[1..], &qd[1..]);
        assert!(
            (got[0] - reference).abs() < 1e-11 * reference.abs().max(1e-300),
            "T = {} vs {reference}",
            got[0]
        );
        let strain: f64 = (0..10)
            .map(|j| 0.5 * (inv.omega[j] * q[1 + j]).powi(2))
            .sum();
        assert!(
            (got[1] - strain).abs() < 1e-9 * strain,
            "V = {} vs {strain}",
            got[1]
        );
    }
}

#[test]
fn damping_is_modal() {
    let m = model(&rotating_scene(
        "modes = 3\ndamping_ratio = [0.01, 0.02, 0.0]",
    ));
    let omega = &m.flexible_links[0].basis.omega;
    let d = m.components[0].dissipation;
    let qd = [0.0, 0.3, -0.7, 1.1];
    let got = eval(&m.graph, &[d], &[0.0; 4], &qd, 0.0)[0];
    let reference = 0.01 * omega[0] * 0.09 + 0.02 * omega[1] * 0.49;
    assert!(
        (got - reference).abs() < 1e-12 * reference,
        "{got} vs {reference}"
    );
    let one = model(&rotating_scene("modes = 2\ndamping_ratio = 0.05"));
    assert_eq!(one.flexible_links[0].damping_ratio, vec![0.05, 0.05]);
}

#[test]
fn geometric_stiffening_adds_the_centrifugal_potential() {
    let plain = model(&rotating_scene("modes = 4"));
    let stiff = model(&rotating_scene("modes = 4\ngeometric_stiffening = true"));
    let kg = stiff.flexible_links[0]
        .geometric_stiffness
        .clone()
        .expect("projected geometric stiffness");
    // Independent projection: N(x) = rho A (L^2 - x^2) / 2 per unit spin^2.
    let material = Material::new(7.0e10, 0.33, 2700.0).unwrap();
    let beam = Beam::new(L, material, Section::tube(0.02, 0.015).unwrap(), 8).unwrap();
    let fe = FeModel::new(&beam, &BoundaryConditions::clamped_free()).unwrap();
    let basis = fe.modes_selected(ModeSelection::First(4)).unwrap();
    let rho_a = beam.mass_per_length();
    let reference = basis.project(&fe.geometric_stiffness(|x| 0.5 * rho_a * (L * L - x * x)));
    assert!((&kg - &reference).amax() < 1e-12 * reference.amax());
    // A bending mode stiffens (positive diagonal).
    assert!(kg[(0, 0)] > 0.0);
    let q = [0.3, 1e-3, -2e-3, 5e-4, 1e-3];
    let qd = [4.0, 0.0, 0.0, 0.0, 0.0];
    let t_plain = eval(&plain.graph, &[plain.components[0].kinetic], &q, &qd, 0.0)[0];
    let t_stiff = eval(&stiff.graph, &[stiff.components[0].kinetic], &q, &qd, 0.0)[0];
    let (_, w) = hub_kinematics(q[0], qd[0]);
    let eta = DVector::from_column_slice(&q[1..]);
    let u = 0.5 * (w[1] * w[1] + w[2] * w[2]) * (eta.transpose() * &reference * &eta)[0];
    assert!(
        (t_plain - t_stiff - u).abs() < 1e-9 * u.abs(),
        "{t_plain} - {t_stiff} vs {u}"
    );
}

// ---------------------------------------------------------------------------
// modes = 0 is the rigid rod.

fn double_pendulum(second: &str) -> String {
    format!(
        r#"name = "dp"

[parameters]
l1 = 0.7
m2 = 1.3
l2 = 0.9
rho = 2700

[[coordinates]]
name = "a"
range = [-3.0, 3.0]

[[coordinates]]
name = "b"
range = [-3.0, 3.0]

[[coordinates]]
name = "c"
range = [-1.5, 1.5]

[[frames]]
name = "upper"
rotation = [{{ axis = "z", angle = "a" }}, {{ axis = "y", angle = "b" }}]

[[frames]]
name = "lower"
parent = "upper"
translation = ["l1", "0.1*sin(c)", 0]
rotation = [{{ axis = [0.3, 0.4, 0.5], angle = "c" }}]

[[components]]
name = "upper_rod"
type = "rod"
mass = 0.8
frame = "upper"
from = [0, 0, 0]
to = ["l1", 0, 0]

{second}
"#
    )
}

#[test]
fn zero_modes_is_the_rigid_rod() {
    let flexible = double_pendulum(
        r#"[[components]]
name = "lower_link"
type = "flexible_link"
frame = "lower"
length = "l2"
material = { youngs_modulus = 7.0e10, poisson = 0.33, density = "rho" }
section = { area = "m2/(rho*l2)" }
boundary = "pinned_pinned"
modes = 0"#,
    );
    let rigid = double_pendulum(
        r#"[[components]]
name = "lower_rod"
type = "rod"
mass = "m2"
frame = "lower"
from = [0, 0, 0]
to = ["l2", 0, 0]"#,
    );
    let mut mf = model(&flexible);
    let mut mr = model(&rigid);
    assert_eq!(mf.nq(), 3);
    assert_eq!(mf.flexible_links[0].modes(), 0);
    assert!((mf.flexible_links[0].invariants.mass - 1.3).abs() < 1e-12);
    let ef = derive(&mut mf).unwrap();
    let er = derive(&mut mr).unwrap();
    let mut rng = Rng(7);
    for _ in 0..40 {
        let (q, qd) = rng.state(&mf);
        let (mass_f, mass_r) = (
            eval_matrix(&mf.graph, &ef.mass, &q, &qd),
            eval_matrix(&mr.graph, &er.mass, &q, &qd),
        );
        assert!(
            (&mass_f - &mass_r).amax() < 1e-12 * mass_r.amax(),
            "M: {mass_f} vs {mass_r}"
        );
        let bf = DVector::from_vec(eval(&mf.graph, &ef.bias, &q, &qd, 0.0));
        let br = DVector::from_vec(eval(&mr.graph, &er.bias, &q, &qd, 0.0));
        assert!((&bf - &br).amax() < 1e-12 * br.amax(), "bias: {bf} vs {br}");
        let energies = |m: &Model, e: &Equations| {
            eval(
                &m.graph,
                &[e.kinetic_energy, e.potential_energy],
                &q,
                &qd,
                0.0,
            )
        };
        let (tf, tr) = (energies(&mf, &ef), energies(&mr, &er));
        assert!((tf[0] - tr[0]).abs() < 1e-12 * tr[0].abs().max(1.0));
        assert!((tf[1] - tr[1]).abs() < 1e-12 * tr[1].abs().max(1.0));
    }
}

// ---------------------------------------------------------------------------
// Cantilever under its own weight.

const CANTILEVER: &str = r#"name = "cantilever"
gravity = [0, 0, "-g"]

[parameters]
g = 9.81
L = 1.2
r = 0.01
E = 2.1e11
rho = 7850

[[coordinates]]
name = "dummy"

[[components]]
name = "dummy_mass"
type = "point_mass"
mass = 1
position = ["dummy", 0, 0]

[[frames]]
name = "root"

[[frames]]
name = "tip"
parent = "root"
station = "end"

[[components]]
name = "beam"
type = "flexible_link"
frame = "root"
length = "L"
material = { youngs_modulus = "E", poisson = 0.3, density = "rho" }
section = { radius = "r" }
elements = 16
modes = 6
boundary = "clamped_free"

[[markers]]
name = "tip"
frame = "tip"
"#;

/// Six modes are kept, three per bending plane (the round section gives
/// equal pairs). The 16 cubic elements with consistent loads are nodally
/// exact for a uniform load, so the error is the modal truncation: with the
/// three modes of the loaded plane the tip deflection is 0.016 % off the
/// closed form (the tolerance is 0.1 %); with the first mode alone, 1.3 %.
#[test]
fn cantilever_sags_by_the_closed_form() {
    let mut m = model(CANTILEVER);
    let k = m.flexible_links[0].modes();
    assert_eq!(k, 6);
    let kinds = m.flexible_links[0].basis.kinds.clone();
    let eq = derive(&mut m).unwrap();
    let n = m.nq();
    let first = coordinate(&m, "beam_eta1");
    // Potential forces: dV/deta = Kff eta + dV_g/deta (V_g linear in eta).
    let forces = |q: &[f64]| -> DVector<f64> {
        let f = eval(&m.graph, &eq.potential_forces, q, &vec![0.0; n], 0.0);
        DVector::from_iterator(k, (0..k).map(|j| f[first + j]))
    };
    let zero = vec![0.0; n];
    let f0 = forces(&zero);
    let kff = DMatrix::from_fn(k, k, |i, j| {
        let mut q = zero.clone();
        q[first + j] = 1.0;
        forces(&q)[i] - f0[i]
    });
    let eta = kff.clone().lu().solve(&(-&f0)).expect("Kff invertible");
    let mut q = zero.clone();
    for j in 0..k {
        q[first + j] = eta[j];
    }
    let tip = eval(&m.graph, &eq.markers[0].position, &q, &zero, 0.0);
    let (g, l, r, e, rho): (f64, f64, f64, f64, f64) = (9.81, 1.2, 0.01, 2.1e11, 7850.0);
    let pi = std::f64::consts::PI;
    let (area, inertia) = (pi * r * r, pi * r.powi(4) / 4.0);
    let exact = rho * area * g * l.powi(4) / (8.0 * e * inertia);
    assert!(
        (tip[2] + exact).abs() < 1e-3 * exact,
        "tip sag {} vs {exact}",
        -tip[2]
    );
    // Only the x-z plane modes respond; no sideways or axial motion.
    for j in 0..k {
        if kinds[j] != ModeKind::BendingXZ {
            assert!(eta[j].abs() < 1e-12 * eta.amax(), "{kinds:?} {eta}");
        }
    }
    assert!(tip[1].abs() < 1e-12 * exact);
    assert!((tip[0] - l).abs() < 1e-12);
    // One mode is not enough: the truncation error is visible.
    let q1 = {
        let mut q1 = zero.clone();
        let j = kinds
            .iter()
            .position(|&k| k == ModeKind::BendingXZ)
            .unwrap();
        q1[first + j] = -f0[j] / kff[(j, j)];
        q1
    };
    let tip1 = eval(&m.graph, &[eq.markers[0].position[2]], &q1, &zero, 0.0)[0];
    assert!((tip1 + exact).abs() > 1e-2 * exact, "{tip1} {exact}");
}

// ---------------------------------------------------------------------------
// Loop closure through a deformed tip.

const CLOSURE: &str = r#"name = "closure"

[parameters]
L = 0.8

[[coordinates]]
name = "psi"
range = [-3.0, 3.0]

[[coordinates]]
name = "bx"
range = [-1.0, 1.0]

[[coordinates]]
name = "by"
range = [-1.0, 1.0]

[[coordinates]]
name = "bz"
range = [-1.0, 1.0]

[[coordinates]]
name = "gam"
range = [-1.0, 1.0]

[[frames]]
name = "crank"
rotation = [{ axis = "z", angle = "psi" }, { axis = "x", angle = "0.3" }]

[[frames]]
name = "end"
parent = "crank"
station = "end"

[[frames]]
name = "mid"
parent = "crank"
station = 0.3
translation = [0, 0.05, 0]

[[frames]]
name = "block"
translation = ["bx", "by", "bz"]
rotation = [{ axis = "x", angle = "gam" }]

[[components]]
name = "link"
type = "flexible_link"
frame = "crank"
length = "L"
material = { youngs_modulus = 2.0e11, shear_modulus = 8.0e10, density = 7800 }
section = { radius = 0.01 }
elements = 6
modes = 8
boundary = "pinned_pinned_elastic"
end_stiffness = { start = [100.0, 0.0] }

[[components]]
name = "block_mass"
type = "point_mass"
mass = 1
frame = "block"
position = [0, 0, 0]

[[constraints]]
name = "pin"
type = "coincident"
a = { frame = "end", position = [0, 0, 0.1] }
b = { frame = "block", position = [0, 0, 0.1] }

[[constraints]]
name = "axes"
type = "perpendicular"
a = { frame = "end", axis = "y" }
b = { frame = "block", axis = "z" }

[[constraints]]
name = "plain"
expression = "link_eta1 - 2*link_eta2"
"#;

/// Rotation by the small rotation vector `t` as in the station frames:
/// elementary rotations about x, y, z in turn.
fn small_rotation(t: Vector3<f64>) -> Matrix3<f64> {
    (Rotation3::from_axis_angle(&Vector3::x_axis(), t.x)
        * Rotation3::from_axis_angle(&Vector3::y_axis(), t.y)
        * Rotation3::from_axis_angle(&Vector3::z_axis(), t.z))
    .into_inner()
}

#[test]
fn coincident_and_perpendicular_close_through_the_deformed_tip() {
    let mut m = model(CLOSURE);
    let names: Vec<&str> = m.constraints.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names, ["pin_x", "pin_y", "pin_z", "axes", "plain"]);
    let link = m.flexible_links[0].clone();
    let k = link.modes();
    assert_eq!(k, 8);
    // Independent placement of the tip from the nodal rows of the shapes.
    let shapes = &link.basis.shapes;
    let end = NODE_DOFS * link.fe.beam.elements;
    let eq = derive(&mut m).unwrap();
    let n = m.nq();
    let mut rng = Rng(99);
    for _ in 0..10 {
        let (mut q, qd) = rng.state(&m);
        for j in 0..k {
            q[5 + j] *= 50.0;
        }
        let eta = DVector::from_column_slice(&q[5..5 + k]);
        let u = Vector3::new(
            L_CLOSURE + (shapes.row(end + UX) * &eta)[0],
            (shapes.row(end + UY) * &eta)[0],
            (shapes.row(end + UZ) * &eta)[0],
        );
        let theta = Vector3::new(
            (shapes.row(end + RX) * &eta)[0],
            (shapes.row(end + RY) * &eta)[0],
            (shapes.row(end + RZ) * &eta)[0],
        );
        let crank = (Rotation3::from_axis_angle(&Vector3::z_axis(), q[0])
            * Rotation3::from_axis_angle(&Vector3::x_axis(), 0.3))
        .into_inner();
        let tip_axes = crank * small_rotation(theta);
        let pin_world = crank * u + tip_axes * Vector3::new(0.0, 0.0, 0.1);
        // Choose the block to close the loop: its point (0, 0, 0.1) in its
        // own axes, rotated by gam about x, lands on the pin.
        let gam = q[4];
        let block_axes = Rotation3::from_axis_angle(&Vector3::x_axis(), gam).into_inner();
        let b = pin_world - block_axes * Vector3::new(0.0, 0.0, 0.1);
        q[1] = b.x;
        q[2] = b.y;
        q[3] = b.z;
        let phi = eval(&m.graph, &eq.phi, &q, &qd, 0.0);
        for r in &phi[..3] {
            assert!(r.abs() < 1e-14, "{phi:?}");
        }
        // The perpendicularity residual is the dot product of the axes.
        let dot = (tip_axes * Vector3::y()).dot(&(block_axes * Vector3::z()));
        assert!((phi[3] - dot).abs() < 1e-14, "{} vs {dot}", phi[3]);
        assert!((phi[4] - (q[5] - 2.0 * q[6])).abs() < 1e-15);
        // Phi_q against central differences.
        let jac = eval_matrix(&m.graph, &eq.phi_q, &q, &qd);
        for j in 0..n {
            let h = if j >= 5 { 1e-7 } else { 1e-6 };
            let mut qp = q.clone();
            let mut qm = q.clone();
            qp[j] += h;
            qm[j] -= h;
            let fp = eval(&m.graph, &eq.phi, &qp, &qd, 0.0);
            let fm = eval(&m.graph, &eq.phi, &qm, &qd, 0.0);
            for i in 0..phi.len() {
                let fd = (fp[i] - fm[i]) / (2.0 * h);
                assert!(
                    (jac[(i, j)] - fd).abs() < 1e-7 * fd.abs().max(1.0),
                    "Phi_q[{i}][{j}] = {} vs {fd}",
                    jac[(i, j)]
                );
            }
        }
    }
    // The mid station: 0.3 m along, offset 0.05 m along its own y.
    let basis = &link.basis;
    let st = basis.station(0.3).unwrap();
    assert!(st.translation.amax() > 0.0);
}

const L_CLOSURE: f64 = 0.8;

// ---------------------------------------------------------------------------
// Errors, with their positions.

/// 1-based line and column of the first `needle` on the only line of `text`
/// containing `marker`.
#[track_caller]
fn locate(text: &str, marker: &str, needle: &str) -> (usize, usize) {
    let lines: Vec<(usize, &str)> = text
        .split('\n')
        .enumerate()
        .filter(|(_, l)| l.contains(marker))
        .collect();
    assert_eq!(lines.len(), 1, "`{marker}` must mark exactly one line");
    let (i, line) = lines[0];
    let byte = line.find(needle).expect("needle on the line");
    (i + 1, line[..byte].chars().count() + 1)
}

#[track_caller]
fn check(e: &Error, at: (usize, usize), context: &str, words: &[&str]) {
    assert_eq!(e.file, Path::new(FILE), "{e}");
    assert_eq!((e.line, e.column), at, "wrong position: {e}");
    assert_eq!(e.context.as_deref(), Some(context), "{e}");
    for w in words {
        assert!(e.message.contains(w), "message lacks `{w}`: {e}");
    }
}

/// The rotating scene with its component's lines replaced.
fn with(fields: &str) -> String {
    rotating_scene("").replace(
        "section = { outer_radius = 0.02, inner_radius = 0.015 }\nelements = 8\nboundary = \"clamped_free\"\n",
        fields,
    )
}

#[test]
fn bad_sections_are_located() {
    let cases: &[(&str, &str, &str, &[&str])] = &[
        (
            "section = { outer_radius = 0.02, inner_radius = 0.03 }\nboundary = \"clamped_free\"\n",
            "0.03",
            "0.03",
            &["inner radius", "smaller"],
        ),
        (
            "section = { radius = -0.01 }\nboundary = \"clamped_free\"\n",
            "-0.01",
            "-0.01",
            &["radius must be positive"],
        ),
        (
            "section = { radius = 0.01, area = 1e-4 }\nboundary = \"clamped_free\"\n",
            "area = 1e-4",
            "{",
            &["one of"],
        ),
        (
            "section = { outer_radius = 0.02 }\nboundary = \"clamped_free\"\n",
            "outer_radius = 0.02 }",
            "{",
            &["both `outer_radius` and `inner_radius`"],
        ),
        (
            "section = {}\nboundary = \"clamped_free\"\n",
            "section = {}",
            "{",
            &["needs `radius`"],
        ),
    ];
    for (fields, marker, needle, words) in cases {
        let text = with(fields);
        let e = fail(&text);
        check(
            &e,
            locate(&text, marker, needle),
            "component `blade`",
            words,
        );
    }
    // Unknown key inside the section table: a TOML-level error, located.
    let text = with("section = { diameter = 0.02 }\nboundary = \"clamped_free\"\n");
    let e = fail(&text);
    assert_eq!(e.line, locate(&text, "diameter", "diameter").0, "{e}");
    assert!(e.message.contains("diameter"), "{e}");
}

#[test]
fn bad_boundaries_and_mode_selections_are_located() {
    let section = "section = { radius = 0.01 }\n";
    let cases: Vec<(String, &str, &str, Vec<&str>)> = vec![
        (
            format!("{section}boundary = \"hinged\"\n"),
            "hinged",
            "\"hinged",
            vec!["unknown boundary `hinged`", "pinned_pinned_elastic"],
        ),
        (
            format!("{section}boundary = \"clamped_free\"\nmodes = 0\nmax_frequency = 100\n"),
            "max_frequency",
            "100",
            vec!["either `modes` or `max_frequency`"],
        ),
        (
            format!("{section}boundary = \"clamped_free\"\nmodes = 2.5\n"),
            "modes",
            "2.5",
            vec!["whole number"],
        ),
        (
            format!("{section}boundary = \"clamped_free\"\nelements = 2\nmodes = 40\n"),
            "modes",
            "40",
            vec!["only", "elastic modes"],
        ),
        (
            format!("{section}boundary = \"pinned_pinned_elastic\"\n"),
            "boundary",
            "\"pinned",
            vec!["needs `end_stiffness"],
        ),
        (
            format!("{section}boundary = \"clamped_free\"\nend_stiffness = [1, 2]\n"),
            "end_stiffness",
            "[",
            vec!["applies only to"],
        ),
        (
            format!("{section}boundary = \"pinned_pinned_elastic\"\nend_stiffness = [1, -2]\n"),
            "end_stiffness",
            "-2",
            vec!["non-negative"],
        ),
        (
            format!("{section}boundary = \"pinned_pinned_elastic\"\nend_stiffness = [1, 2, 3]\n"),
            "end_stiffness",
            "[",
            vec!["two numbers"],
        ),
        (
            format!(
                "{section}boundary = \"clamped_free\"\nmodes = 3\ndamping_ratio = [0.1, 0.2]\n"
            ),
            "damping_ratio",
            "[",
            vec!["2 values but 3 modes"],
        ),
        (
            format!("{section}boundary = \"clamped_free\"\ndamping_ratio = -0.1\n"),
            "damping_ratio",
            "-0.1",
            vec!["non-negative"],
        ),
        (
            format!("{section}boundary = \"clamped_clamped\"\ngeometric_stiffening = true\n"),
            "geometric_stiffening",
            "true",
            vec!["geometric_stiffening is supported only"],
        ),
        (
            format!("{section}boundary = \"clamped_free\"\nelements = \"theta\"\n"),
            "elements",
            "\"theta",
            vec!["must be a constant"],
        ),
        (
            format!("{section}boundary = \"clamped_free\"\nmass = 2\n"),
            "mass = 2",
            "2",
            vec!["field `mass` does not apply", "flexible_link"],
        ),
    ];
    for (fields, marker, needle, words) in &cases {
        let text = with(fields);
        let e = fail(&text);
        check(
            &e,
            locate(&text, marker, needle),
            "component `blade`",
            words,
        );
    }
    // Missing boundary: at the type.
    let text = with(&format!("{section}\n"));
    let e = fail(&text);
    check(
        &e,
        locate(&text, "type = \"flexible_link\"", "\"flexible_link"),
        "component `blade`",
        &["needs `boundary`"],
    );
    // Poisson's ratio out of range, and both Poisson and G.
    let text = rotating_scene("").replace("poisson = 0.33", "poisson = 0.7");
    let e = fail(&text);
    check(
        &e,
        locate(&text, "poisson", "0.7"),
        "component `blade`",
        &["Poisson"],
    );
    let text = rotating_scene("").replace("poisson = 0.33", "poisson = 0.3, shear_modulus = 1e10");
    let e = fail(&text);
    check(
        &e,
        locate(&text, "poisson", "1e10"),
        "component `blade`",
        &["either `poisson` or `shear_modulus`"],
    );
}

#[test]
fn station_and_constraint_errors_are_located() {
    // A station on a frame that no flexible link uses.
    let text = CLOSURE.replace(
        "name = \"mid\"\nparent = \"crank\"\nstation = 0.3",
        "name = \"mid\"\nparent = \"block\"\nstation = 0.3",
    );
    let text = text.replace(
        "[[frames]]\nname = \"block\"\ntranslation = [\"bx\", \"by\", \"bz\"]\nrotation = [{ axis = \"x\", angle = \"gam\" }]\n",
        "",
    );
    let text = text.replacen(
        "[[frames]]\nname = \"crank\"",
        "[[frames]]\nname = \"block\"\ntranslation = [\"bx\", \"by\", \"bz\"]\nrotation = [{ axis = \"x\", angle = \"gam\" }]\n\n[[frames]]\nname = \"crank\"",
        1,
    );
    let e = fail(&text);
    check(
        &e,
        locate(&text, "station = 0.3", "0.3"),
        "frame `mid`",
        &["not the reference frame of a flexible link"],
    );
    // A station beyond the end.
    let text = CLOSURE.replace("station = 0.3", "station = 0.9");
    let e = fail(&text);
    check(
        &e,
        locate(&text, "station = 0.9", "0.9"),
        "frame `mid`",
        &["outside"],
    );
    // A station without parent.
    let text = CLOSURE.replace("parent = \"crank\"\nstation = 0.3", "station = 0.3");
    let e = fail(&text);
    check(
        &e,
        locate(&text, "station = 0.3", "0.3"),
        "frame `mid`",
        &["needs `parent`"],
    );
    // Unknown constraint type, expression with type, axis in coincident,
    // frame not defined, missing end.
    let cases: &[(&str, &str, &str, &str, &[&str])] = &[
        (
            "type = \"coincident\"",
            "type = \"welded\"",
            "welded",
            "\"welded",
            &["unknown constraint type `welded`"],
        ),
        (
            "a = { frame = \"end\", position = [0, 0, 0.1] }",
            "a = { frame = \"end\", axis = \"x\" }",
            "axis = \"x\" }",
            "\"x\"",
            &["give `position`, not `axis`"],
        ),
        (
            "b = { frame = \"block\", position = [0, 0, 0.1] }",
            "b = { frame = \"nowhere\", position = [0, 0, 0.1] }",
            "nowhere",
            "\"nowhere",
            &["frame `nowhere` is not defined"],
        ),
        (
            "b = { frame = \"block\", position = [0, 0, 0.1] }",
            "expression = \"psi\"",
            "expression = \"psi\"",
            "\"psi",
            &["not `expression`"],
        ),
    ];
    for (from, to, marker, needle, words) in cases {
        let text = CLOSURE.replacen(from, to, 1);
        let e = fail(&text);
        check(&e, locate(&text, marker, needle), "constraint `pin`", words);
    }
    let text = CLOSURE.replace(
        "b = { frame = \"block\", axis = \"z\" }",
        "b = { frame = \"block\", position = [1, 0, 0] }",
    );
    let e = fail(&text);
    check(
        &e,
        locate(
            &text,
            "b = { frame = \"block\", position = [1, 0, 0] }",
            "[",
        ),
        "constraint `axes`",
        &["give `axis`, not `position`"],
    );
    let text = CLOSURE.replace("b = { frame = \"block\", axis = \"z\" }\n", "");
    let e = fail(&text);
    check(
        &e,
        locate(&text, "type = \"perpendicular\"", "\"perp"),
        "constraint `axes`",
        &["needs `b`"],
    );
    // Neither `expression` nor `type`.
    let text = format!("{CLOSURE}\n[[constraints]]\nname = \"empty\"\n");
    let e = fail(&text);
    check(
        &e,
        locate(&text, "name = \"empty\"", "\"empty"),
        "constraint `empty`",
        &["needs `expression`, or `type`"],
    );
    // Modal coordinates clash with a declared coordinate.
    let text = CLOSURE
        .replace("name = \"gam\"", "name = \"link_eta3\"")
        .replace("\"gam\"", "\"link_eta3\"");
    let e = fail(&text);
    check(
        &e,
        locate(&text, "name = \"link\"", "\"link\""),
        "component `link`",
        &["`link_eta3`", "already"],
    );
}

#[test]
fn modal_coordinates_are_ranged_and_max_frequency_selects() {
    let m = model(&rotating_scene("max_frequency = 200"));
    let link = &m.flexible_links[0];
    assert!(link.basis.frequencies_hz().iter().all(|&f| f < 200.0));
    let all = rotating_scene("modes = 20");
    let all = model(&all);
    let n_below = all.flexible_links[0]
        .basis
        .frequencies_hz()
        .iter()
        .filter(|&&f| f < 200.0)
        .count();
    assert_eq!(link.modes(), n_below);
    assert!(n_below >= 2);
    // Range: ten times g sqrt(m) / w^2, velocity range w times that.
    let mass = link.invariants.mass;
    for j in 0..link.modes() {
        let c = &m.coordinates[1 + j];
        let w = link.basis.omega[j];
        let a = 10.0 * 9.81 * mass.sqrt() / (w * w);
        assert_eq!(c.range, Some([-a, a]));
        assert_eq!(c.velocity_range, Some([-w * a, w * a]));
    }
    // Default: six modes, twenty elements.
    let d = model(&rotating_scene("").replace("elements = 8\n", ""));
    assert_eq!(d.flexible_links[0].modes(), 6);
    assert_eq!(d.flexible_links[0].fe.beam.elements, 20);
    let _ = (RY, RZ);
}

// ---------------------------------------------------------------------------
// The flexible robot scenes close at the rigid pose.

/// Closed-form inverse kinematics of chain `i` (docs/model.md).
fn chain_ik(phi: f64, p: [f64; 3]) -> [f64; 3] {
    let (ra, rp, l1, l2, l3) = (0.4, 0.1, 0.4, 0.1, 0.8);
    let x = phi.cos() * p[0] + phi.sin() * p[1] + rp;
    let y = -phi.sin() * p[0] + phi.cos() * p[1];
    let z = p[2];
    let th3 = (y / l3).asin();
    let l = l2 + l3 * th3.cos();
    let d2 = (x - ra).powi(2) + z * z;
    let b = ((d2 - l1 * l1 - l * l) / (2.0 * l1 * l)).acos();
    let th1 = z.atan2(x - ra) - (l * b.sin()).atan2(l1 + l * b.cos());
    [th1, th1 + b, th3]
}

fn robot(name: &str) -> Model {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../examples/parallel-robot/scenes")
        .join(format!("{name}.toml"));
    Model::load(&path).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn flexible_robot_scenes_close_at_the_rigid_pose_with_full_rank() {
    for (name, nq, links) in [
        ("parallel_robot_flexible", 39, 3),
        ("parallel_robot_flexible_links", 33, 3),
        ("parallel_robot_flexible_joints", 21, 0),
        ("parallel_robot_soft", 33, 3),
    ] {
        let mut m = robot(name);
        assert_eq!(m.nq(), nq, "{name}");
        assert_eq!(m.constraints.len(), 12, "{name}");
        assert_eq!(m.flexible_links.len(), links, "{name}");
        let eq = derive(&mut m).unwrap();
        let mut rng = Rng(5);
        for trial in 0..4 {
            let p = if trial == 0 {
                [0.1, 0.0, 0.7]
            } else {
                [0.1 * rng.next(), 0.1 * rng.next(), 0.7 + 0.08 * rng.next()]
            };
            let mut q = vec![0.0; m.nq()];
            for i in 0..3 {
                let th = chain_ik(2.0 * std::f64::consts::PI * i as f64 / 3.0, p);
                q[3 * i..3 * i + 3].copy_from_slice(&th);
            }
            q[9..12].copy_from_slice(&p);
            let qd = vec![0.0; m.nq()];
            let phi = eval(&m.graph, &eq.phi, &q, &qd, 0.0);
            assert!(
                phi.iter().all(|r| r.abs() < 1e-12),
                "{name} at {p:?}: {phi:?}"
            );
            let jac = eval_matrix(&m.graph, &eq.phi_q, &q, &qd);
            let sv = jac.singular_values();
            assert!(
                sv.min() > 1e-3 * sv.max(),
                "{name}: rank-deficient Phi_q, {sv}"
            );
        }
    }
    // Spec paper check: P = (0.1, 0, 0.7) gives th11 ~ 4.06 deg, th12 ~ 131.7 deg.
    let th = chain_ik(0.0, [0.1, 0.0, 0.7]);
    assert!((th[0].to_degrees() - 4.06).abs() < 0.01 && (th[1].to_degrees() - 131.7).abs() < 0.05);
}

#[test]
fn robot_link_modes_with_the_elastic_start() {
    let m = robot("parallel_robot_flexible");
    let link = &m.flexible_links[0];
    let f = link.basis.frequencies_hz();
    // Pinned in the x-y plane (R3 turns about n = z): pi^2 / (2 pi L^2) sqrt(EI / rho A).
    let area: f64 = 1.5 / (2740.0 * 0.8);
    let ei = 2.07e11 * area * area / (4.0 * std::f64::consts::PI);
    let pinned = std::f64::consts::PI / (2.0 * 0.64) * (ei / (2740.0 * area)).sqrt();
    assert_eq!(link.basis.kinds[0], ModeKind::BendingXY);
    assert!((f[0] - pinned).abs() < 1e-3 * pinned, "{f:?} vs {pinned}");
    // The x-z plane is held at the start by the joint's bending stiffness:
    // between pinned-pinned and clamped-pinned (15.418 / (2 pi L^2) sqrt(EI / rho A)).
    let clamped_pinned =
        15.418 / (2.0 * std::f64::consts::PI * 0.64) * (ei / (2740.0 * area)).sqrt();
    assert_eq!(link.basis.kinds[1], ModeKind::BendingXZ);
    assert!(f[1] > 1.2 * pinned && f[1] < clamped_pinned, "{f:?}");
    eprintln!("driven link modes (Hz): {f:?} {:?}", link.basis.kinds);
}
