//! Frames turned by constant angles beside their joints (a URDF joint's
//! `rpy`): the same motion as the turns written one frame apart, and what
//! they cost the generated code.
//!
//! The arm: a base turning about z, a waist about y, a shoulder about y
//! mounted with a tilt (three constant turns about z, y and x: the Unitree
//! G1's `rpy="0.27931 5.4949E-05 -0.00019159"`), an upper arm about x
//! mounted with a constant turn about x, a forearm about z; one rigid body
//! in each.

use std::path::Path;

use flexdyn_codegen::{generate_scene, Equations, Id, Model, Symbol};

/// The shoulder's tilt, in turn.
const TILT: &[(&str, f64)] = &[("z", -0.00019159), ("y", 5.4949e-5), ("x", 0.27931)];
/// The upper arm's mount, about its joint's axis.
const ROLL: &[(&str, f64)] = &[("x", -0.27925)];

/// The arm's scene; with `apart`, each mount's constant turns are a frame
/// of their own, the joint's turn its child.
fn arm(shoulder: &[(&str, f64)], upper: &[(&str, f64)], apart: bool) -> String {
    let turn = |axis: &str, angle: &str| format!("{{ axis = \"{axis}\", angle = {angle} }}");
    let mut frames: Vec<(String, String, &str, String)> = vec![
        (
            "base".into(),
            "world".into(),
            "[0, 0, 0.1]",
            turn("z", "\"q0\""),
        ),
        (
            "waist".into(),
            "base".into(),
            "[0, 0, 0.2]",
            turn("y", "\"q1\""),
        ),
    ];
    let mut joint = |name: &str, parent: &str, at: &'static str, mount: &[(&str, f64)], axis| {
        let fixed: Vec<String> = mount.iter().map(|(a, x)| turn(a, &x.to_string())).collect();
        let own = turn(axis, &format!("\"{name}_q\""));
        if apart && !mount.is_empty() {
            let m = format!("{name}_mount");
            frames.push((m.clone(), parent.into(), at, fixed.join(", ")));
            frames.push((name.into(), m, "[0, 0, 0]", own));
        } else {
            let all = [fixed, vec![own]].concat().join(", ");
            frames.push((name.into(), parent.into(), at, all));
        }
    };
    joint("shoulder", "waist", "[0.004, 0.1, 0.25]", shoulder, "y");
    joint("upper", "shoulder", "[0, 0.038, -0.014]", upper, "x");
    joint("fore", "upper", "[0, 0.006, -0.1]", &[], "z");
    let mut s = String::from("name = \"arm\"\ngravity = [0, 0, -9.81]\n\n");
    for q in ["q0", "q1", "shoulder_q", "upper_q", "fore_q"] {
        s += &format!(
            "[[coordinates]]\nname = \"{q}\"\nrange = [-2, 2]\nvelocity_range = [-3, 3]\n\n"
        );
    }
    for (name, parent, at, turns) in &frames {
        s += &format!(
            "[[frames]]\nname = \"{name}\"\nparent = \"{parent}\"\ntranslation = {at}\nrotation = [{turns}]\n\n"
        );
    }
    for (k, f) in ["base", "waist", "shoulder", "upper", "fore"]
        .iter()
        .enumerate()
    {
        s += &format!(
            "[[components]]\nname = \"{f}_body\"\ntype = \"rigid_body\"\nframe = \"{f}\"\n\
             mass = {}\nposition = [0.01, -0.02, {}]\n\
             inertia = [[0.004, 1e-5, -2e-5], [1e-5, 0.003, 3e-6], [-2e-5, 3e-6, 0.002]]\n\n",
            1.5 - 0.2 * k as f64,
            -0.05 - 0.01 * k as f64
        );
    }
    s
}

fn write(dir: &Path, name: &str, text: &str) -> std::path::PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).expect("write scene");
    path
}

/// Operations of the emitted function `name`.
fn ops(path: &Path, name: &str) -> usize {
    generate_scene(path)
        .unwrap_or_else(|e| panic!("{e}"))
        .functions
        .iter()
        .find(|f| f.name == name)
        .unwrap_or_else(|| panic!("no {name}"))
        .ops
        .total()
}

#[test]
fn turns_beside_a_joint_move_the_arm_as_turns_one_frame_apart() {
    let dir = tempfile::tempdir().expect("temporary folder");
    let mut beside = Model::load(&write(dir.path(), "a.toml", &arm(TILT, ROLL, false))).unwrap();
    let mut apart = Model::load(&write(dir.path(), "b.toml", &arm(TILT, ROLL, true))).unwrap();
    let (eb, ea) = (beside.equations().unwrap(), apart.equations().unwrap());
    let mut worst = 0.0f64;
    for k in 0..40 {
        // Deterministic states spread over the ranges.
        let x = |i: usize, s: f64| s * (2.0 * ((k * 5 + i) as f64 * 0.754_877_666).fract() - 1.0);
        let state: Vec<f64> = (0..15).map(|i| x(i, 2.0 + i as f64 / 5.0)).collect();
        let values = |m: &Model, e: &Equations| {
            let roots: Vec<Id> = e
                .mass
                .iter()
                .flatten()
                .chain(&e.bias)
                .chain(&e.inverse_dynamics)
                .chain(&[e.kinetic_energy, e.potential_energy])
                .copied()
                .collect();
            m.graph.eval(&roots, &|s| match s {
                Symbol::Q(i) => state[i as usize],
                Symbol::Qd(i) => state[5 + i as usize],
                Symbol::Qdd(i) => state[10 + i as usize],
                _ => 0.0,
            })
        };
        let (a, b) = (values(&beside, &eb), values(&apart, &ea));
        let scale = b.iter().fold(1.0f64, |m, v| m.max(v.abs()));
        for (u, v) in a.iter().zip(&b) {
            worst = worst.max((u - v).abs() / scale);
        }
    }
    assert!(worst < 1e-13, "worst relative difference {worst:e}");
}

#[test]
fn a_constant_turn_about_the_joints_axis_costs_one_addition() {
    // R_x(c) R_x(q) is R_x(c + q): one addition where the constant turn
    // would mix the components of every vector carried across it (56 more
    // operations of inverse dynamics when it was kept apart).
    let dir = tempfile::tempdir().expect("temporary folder");
    let with = write(dir.path(), "with.toml", &arm(TILT, ROLL, false));
    let without = write(dir.path(), "without.toml", &arm(TILT, &[], false));
    for function in ["inverse_dynamics", "mass_matrix", "bias"] {
        let (a, b) = (ops(&with, function), ops(&without, function));
        assert!(a <= b + 1, "{function}: {a} operations against {b}");
    }
}

#[test]
fn a_tilt_costs_about_one_constant_rotation_per_carried_vector() {
    // The tilt turns the waist's twist and its rate into the shoulder's
    // axes (four vectors) and the shoulder's force and moment back (two):
    // six products of a constant 3x3 matrix, 15 operations each. Opening
    // each component's short sums into the three rows cost 138 operations
    // of inverse dynamics here (and 1,148 on the G1) before it kept them.
    let dir = tempfile::tempdir().expect("temporary folder");
    let tilted = write(dir.path(), "tilted.toml", &arm(TILT, &[], false));
    let straight = write(dir.path(), "straight.toml", &arm(&[], &[], false));
    let (a, b) = (
        ops(&tilted, "inverse_dynamics"),
        ops(&straight, "inverse_dynamics"),
    );
    assert!(
        a <= b + 6 * 15 * 11 / 10,
        "the tilt costs {} operations of inverse dynamics ({a} against {b})",
        a - b.min(a)
    );
}
