//! Issue 5: the `flexible_joint` component (the paper's flexible joint: a
//! joint member with its own inertia and a torsion spring on its twist).
//!
//! The reference is the same joint written out by hand as a `rigid_body`
//! (solid-cylinder inertia from the member's mass, length and density) plus
//! a `spring` whose stiffness `G Ip / l` is computed here from the textbook
//! formulas, not by the generator.

use std::path::Path;

#[path = "common/energies.rs"]
mod common;

use common::energies;
use flexdyn_codegen::{Error, Model, Source};

fn load(text: &str) -> Result<Model, Error> {
    Model::from_source(&Source::new(Path::new("scene.toml"), text.to_owned()))
}

/// A link turning about the world y axis by `a`, carrying at its tip a joint
/// member that turns about the link's z axis by `b + tw` (`tw` the twist).
fn scene(joint: &str) -> String {
    format!(
        r#"name = "joint_test"
[parameters]
E = 2.07e11
nu = 0.33
rho = 2740
mj = 0.07
lj = 0.04
kj = {{ value = 5.0e4, runtime = true }}
[[coordinates]]
name = "a"
[[coordinates]]
name = "b"
[[coordinates]]
name = "tw"
range = [-0.01, 0.01]
[[frames]]
name = "link"
rotation = [{{ axis = "y", angle = "a" }}]
[[frames]]
name = "rotor"
parent = "link"
translation = [0.3, 0.1, -0.2]
rotation = [{{ axis = "x", angle = "0.4" }}, {{ axis = "z", angle = "b + tw" }}]
{joint}"#
    )
}

const COMPONENT: &str = r#"[[components]]
name = "joint"
type = "flexible_joint"
frame = "rotor"
axis = "z"
mass = "mj"
length = "lj"
material = { youngs_modulus = "E", poisson = "nu", density = "rho" }
expression = "tw"
"#;

/// The same joint by hand, with stiffness `k` (an expression).
fn by_hand(k: &str) -> String {
    let (m, l, rho) = (0.07f64, 0.04f64, 2740.0f64);
    let r2 = m / (rho * l * std::f64::consts::PI);
    let (axial, transverse) = (m * r2 / 2.0, m * (3.0 * r2 + l * l) / 12.0);
    format!(
        r#"[[components]]
name = "member"
type = "rigid_body"
frame = "rotor"
mass = "mj"
inertia = [[{transverse:e}, 0, 0], [0, {transverse:e}, 0], [0, 0, {axial:e}]]
[[components]]
name = "spring"
type = "spring"
stiffness = "{k}"
expression = "tw"
"#
    )
}

/// Torsional stiffness of a solid circular shaft of mass m, length l.
fn shaft_stiffness() -> f64 {
    let (e, nu, rho, m, l) = (2.07e11f64, 0.33f64, 2740.0f64, 0.07f64, 0.04f64);
    let g = e / (2.0 * (1.0 + nu));
    let area = m / (rho * l);
    let radius = (area / std::f64::consts::PI).sqrt();
    let polar = std::f64::consts::PI * radius.powi(4) / 2.0;
    g * polar / l
}

fn compare(component: &str, reference: &str, params: &[f64]) {
    let a = load(&scene(component)).unwrap_or_else(|e| panic!("{e}"));
    let b = load(&scene(reference)).unwrap_or_else(|e| panic!("{e}"));
    for k in 0..20 {
        let x = k as f64;
        let q = [(0.7 * x).sin(), (1.3 * x).cos(), 0.01 * (0.9 * x).sin()];
        let qd = [(0.4 * x).cos(), -(1.1 * x).sin(), 3.0 * (2.1 * x).cos()];
        let (ta, va) = energies(&a, &q, &qd, params);
        let (tb, vb) = energies(&b, &q, &qd, params);
        assert!(
            (ta - tb).abs() <= 1e-12 * tb.abs().max(1e-9),
            "T {ta} vs {tb}"
        );
        assert!(
            (va - vb).abs() <= 1e-12 * vb.abs().max(1e-9),
            "V {va} vs {vb}"
        );
    }
}

#[test]
fn flexible_joint_is_the_member_body_plus_the_shaft_torsion_spring() {
    let k = shaft_stiffness();
    // 1.263e5 N m/rad for the paper's joint member (docs/model.md).
    assert!((k / 126305.95 - 1.0).abs() < 1e-6, "{k}");
    compare(COMPONENT, &by_hand(&format!("{k:e}")), &[5.0e4]);
}

#[test]
fn flexible_joint_stiffness_can_be_overridden_by_a_runtime_parameter() {
    let with_override = COMPONENT.replace(
        "expression = \"tw\"",
        "expression = \"tw\"\nstiffness = \"kj\"",
    );
    compare(&with_override, &by_hand("kj"), &[5.0e4]);
    compare(&with_override, &by_hand("kj"), &[8.0e5]);
}

#[test]
fn flexible_joint_errors_are_located() {
    for (change, needle, what) in [
        (
            "axis = \"z\"",
            "axis = \"w\"",
            "axis must be `x`, `y` or `z`",
        ),
        ("axis = \"z\"\n", "", "needs `axis`"),
        ("mass = \"mj\"", "mass = \"-mj\"", "mass must be positive"),
        ("expression = \"tw\"\n", "", "needs `expression`"),
        (
            "length = \"lj\"",
            "length = \"lj\"\ninertia = [[1,0,0],[0,1,0],[0,0,1]]",
            "field `inertia` does not apply",
        ),
    ] {
        let text = scene(&COMPONENT.replace(change, needle));
        let e = load(&text).expect_err(what);
        let msg = e.to_string();
        assert!(
            msg.contains(what) && msg.contains("component `joint`"),
            "{msg}"
        );
        assert!(e.line > 0, "{msg}");
    }
}

/// The robot scenes pass the joint stiffness as runtime parameters `kj1`,
/// `kj2` (so that it can be overridden at run time): their nominal values
/// must be the `G Ip / l` that the component derives from the same scene's
/// joint-member parameters, computed here by the textbook formula.
#[test]
fn robot_joint_stiffness_parameters_equal_the_derived_shaft_stiffness() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    for scene in ["parallel_robot_flexible", "parallel_robot_flexible_joints"] {
        let model = Model::load(&root.join(format!("examples/parallel-robot/scenes/{scene}.toml")))
            .unwrap();
        let p = |k: &str| model.parameters[k];
        let g = p("Ej") / (2.0 * (1.0 + p("nuj")));
        let area = p("mj") / (p("rhoj") * p("lj"));
        let derived = g * area * area / (2.0 * std::f64::consts::PI) / p("lj");
        for k in ["kj1", "kj2"] {
            let nominal = model
                .runtime_parameters
                .iter()
                .find(|r| r.name == k)
                .unwrap_or_else(|| panic!("{scene}: no runtime parameter {k}"))
                .value;
            assert!(
                (nominal / derived - 1.0).abs() < 1e-7,
                "{scene}: {k} = {nominal}, derived {derived}"
            );
        }
    }
}
