//! Issue 7, "model only what a scene needs": derived scenes (`base` +
//! `[reduce]`) against independent constructions of the same model.
//!
//! * `modes = k` against the base scene rewritten with `modes = k` (the
//!   finite-element mode selection, not the substitution);
//! * `freeze` against the base scene rewritten with the frozen coordinates
//!   deleted and replaced by `0` in its expressions (the parser's folding);
//! * `drop_below` against the exact model at states other than the ones the
//!   generator pruned at, with the bound its documentation states;
//! * every way of writing a reduction wrong is a located error.

use std::path::{Path, PathBuf};

use flexdyn_codegen::{generate_scene, Equations, Error, Id, Model, Symbol};

const ROBOT: &str =
    include_str!("../../examples/parallel-robot/scenes/parallel_robot_flexible.toml");
const TWISTS: [&str; 6] = ["th11j", "th12j", "th21j", "th22j", "th31j", "th32j"];

/// A folder with the flexible robot as `base.toml` and `files`.
fn folder(files: &[(&str, &str)]) -> tempfile::TempDir {
    let dir = tempfile::tempdir().expect("temporary folder");
    std::fs::write(dir.path().join("base.toml"), ROBOT).expect("write base");
    for (name, text) in files {
        std::fs::write(dir.path().join(name), text).expect("write scene");
    }
    dir
}

fn derived(reduce: &str) -> String {
    format!("name = \"variant\"\nbase = \"base.toml\"\n\n[reduce]\n{reduce}\n")
}

#[track_caller]
fn load(dir: &Path, name: &str) -> Model {
    Model::load(&dir.join(name)).unwrap_or_else(|e| panic!("{e}"))
}

#[track_caller]
fn fail(dir: &Path, name: &str) -> Error {
    match Model::load(&dir.join(name)) {
        Ok(_) => panic!("{name} was accepted"),
        Err(e) => e,
    }
}

/// Deterministic states in the declared ranges (a different generator and
/// seed from the one the pruning samples with).
struct Rng(u64);

impl Rng {
    fn unit(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }

    fn state(&mut self, m: &Model) -> (Vec<f64>, Vec<f64>) {
        let mut pick = |r: Option<[f64; 2]>| {
            let [a, b] = r.unwrap_or([-1.0, 1.0]);
            a + (b - a) * self.unit()
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

/// M (row-major), h, Phi, T and V of a model at a state.
fn terms(m: &Model, eq: &Equations, q: &[f64], qd: &[f64]) -> Vec<Vec<f64>> {
    let eval = |roots: &[Id]| {
        m.graph.eval(roots, &|s| match s {
            Symbol::Q(i) => q[i as usize],
            Symbol::Qd(i) => qd[i as usize],
            Symbol::Time => 0.3,
            Symbol::Param(i) => m.runtime_parameters[i as usize].value,
            Symbol::Qdd(_) => f64::NAN, // not read by these terms
        })
    };
    let mass: Vec<Id> = eq.mass.iter().flatten().copied().collect();
    vec![
        eval(&mass),
        eval(&eq.bias),
        eval(&eq.phi),
        eval(&[eq.kinetic_energy, eq.potential_energy]),
    ]
}

/// Largest difference of every term of two models at `states` random states,
/// relative to max(1, the term's size).
fn compare(a: &mut Model, b: &mut Model, states: usize) -> f64 {
    assert_eq!(
        a.coordinates.iter().map(|c| &c.name).collect::<Vec<_>>(),
        b.coordinates.iter().map(|c| &c.name).collect::<Vec<_>>()
    );
    let (ea, eb) = (
        a.equations().expect("derive"),
        b.equations().expect("derive"),
    );
    let mut rng = Rng(0x1234_5678_9abc_def1);
    let mut worst = 0.0f64;
    for _ in 0..states {
        let (q, qd) = rng.state(a);
        let (ta, tb) = (terms(a, &ea, &q, &qd), terms(b, &eb, &q, &qd));
        for (x, y) in ta.iter().zip(&tb) {
            let scale = y.iter().fold(1.0f64, |m, v| m.max(v.abs()));
            let d = x
                .iter()
                .zip(y)
                .fold(0.0f64, |m, (u, v)| m.max((u - v).abs()));
            worst = worst.max(d / scale);
        }
    }
    worst
}

#[test]
fn fewer_modes_equal_a_scene_built_with_fewer_modes() {
    for k in [0, 1, 3] {
        let dir = folder(&[
            ("variant.toml", &derived(&format!("modes = {k}"))),
            (
                "direct.toml",
                &ROBOT.replace("modes = 6", &format!("modes = {k}")),
            ),
        ]);
        let mut reduced = load(dir.path(), "variant.toml");
        let mut direct = load(dir.path(), "direct.toml");
        assert_eq!(reduced.nq(), 21 + 3 * k);
        assert_eq!(reduced.name, "variant");
        for (a, b) in reduced.flexible_links.iter().zip(&direct.flexible_links) {
            assert_eq!(a.modes(), k);
            assert_eq!(a.first_coordinate, b.first_coordinate);
            assert_eq!(a.basis.omega, b.basis.omega);
        }
        let worst = compare(&mut reduced, &mut direct, 20);
        assert!(
            worst < 1e-12,
            "modes = {k}: worst relative difference {worst:e}"
        );
    }
}

#[test]
fn max_frequency_keeps_the_modes_below_it() {
    // The links' modes: 157.4, 224.5, 629.7, 736.5, 1416.9, 1551.8 Hz.
    let dir = folder(&[("variant.toml", &derived("max_frequency = 700.0"))]);
    let m = load(dir.path(), "variant.toml");
    for link in &m.flexible_links {
        assert_eq!(link.modes(), 3);
        assert!(link
            .basis
            .omega
            .iter()
            .all(|w| w / std::f64::consts::TAU < 700.0));
    }
}

/// The base scene with coordinates `names` deleted and replaced by `0`.
fn without_coordinates(names: &[&str]) -> String {
    let mut text = ROBOT.to_owned();
    for name in names {
        let block = text
            .split("[[coordinates]]")
            .find(|b| b.contains(&format!("name = \"{name}\"")))
            .map(|b| &b[..b.find("\n\n").map_or(b.len(), |e| e + 1)])
            .expect("coordinate block")
            .to_owned();
        text = text.replacen(&format!("[[coordinates]]{block}"), "", 1);
        text = text.replace(&format!("expression = \"{name}\""), "expression = \"0\"");
        text = text.replace(&format!("+ {name}\""), "+ 0\"");
    }
    assert!(
        names.iter().all(|n| !text.contains(n)),
        "every use replaced"
    );
    text
}

#[test]
fn frozen_joints_equal_a_scene_written_without_them() {
    let list = TWISTS.map(|t| format!("\"{t}\"")).join(", ");
    let dir = folder(&[
        ("variant.toml", &derived(&format!("freeze = [{list}]"))),
        ("direct.toml", &without_coordinates(&TWISTS)),
    ]);
    let mut frozen = load(dir.path(), "variant.toml");
    let mut direct = load(dir.path(), "direct.toml");
    assert_eq!(frozen.nq(), 33);
    let worst = compare(&mut frozen, &mut direct, 20);
    assert!(worst < 1e-12, "worst relative difference {worst:e}");
}

#[test]
fn pruned_terms_stay_within_the_stated_bound_elsewhere() {
    let tol = 1e-6;
    let dir = folder(&[("variant.toml", &derived(&format!("drop_below = {tol:e}")))]);
    let mut pruned = load(dir.path(), "variant.toml");
    let mut exact = load(dir.path(), "base.toml");
    assert_eq!(pruned.drop_below, Some(tol));
    let (ep, ee) = (pruned.equations().unwrap(), exact.equations().unwrap());
    let mut rng = Rng(0x0bad_5eed_1357_9bdf);
    let (mut err_m, mut err_h, mut scale_m, mut scale_h) = (0.0f64, 0.0f64, 1.0f64, 1.0f64);
    let mut changed = false;
    for _ in 0..50 {
        let (q, qd) = rng.state(&exact);
        let (tp, te) = (terms(&pruned, &ep, &q, &qd), terms(&exact, &ee, &q, &qd));
        for (k, (err, scale)) in [
            (0, (&mut err_m, &mut scale_m)),
            (1, (&mut err_h, &mut scale_h)),
        ] {
            for (a, b) in tp[k].iter().zip(&te[k]) {
                *err = err.max((a - b).abs());
                *scale = scale.max(b.abs());
                changed |= a != b;
            }
        }
        // Constraints, T and V are never pruned.
        assert_eq!(tp[2], te[2]);
        assert_eq!(tp[3], te[3]);
    }
    assert!(changed, "nothing was pruned");
    // The documented bound at the generator's samples is tol * scale; here,
    // at other states, the validation allows 4 tol * scale.
    assert!(
        err_m <= 4.0 * tol * scale_m,
        "M: {err_m:e} against scale {scale_m:e}"
    );
    assert!(
        err_h <= 4.0 * tol * scale_h,
        "h: {err_h:e} against scale {scale_h:e}"
    );
    let ops = |name: &str| {
        generate_scene(&dir.path().join(name))
            .unwrap()
            .functions
            .iter()
            .find(|f| f.name == "dynamics_terms")
            .unwrap()
            .ops
            .total()
    };
    let (p, e) = (ops("variant.toml"), ops("base.toml"));
    assert!(p < e, "pruning saved nothing: {p} against {e} operations");
}

#[track_caller]
fn check(e: &Error, dir: &Path, line: usize, words: &[&str]) {
    assert_eq!(e.file, dir.join("variant.toml"), "{e}");
    assert_eq!(e.line, line, "{e}");
    for w in words {
        assert!(e.message.contains(w), "`{w}` not in: {e}");
    }
}

#[test]
fn reduction_errors_are_located() {
    let cases: [(&str, usize, &[&str]); 8] = [
        ("freeze = [\"nope\"]", 5, &["`nope`", "not declared"]),
        (
            "freeze = [\"driven1_eta1\"]",
            5,
            &["modal coordinate", "`modes`"],
        ),
        ("freeze = [\"th11\"]", 4, &["actuator `tau_1`", "freezes"]),
        (
            "modes = 2\nmax_frequency = 500.0",
            6,
            &["either `modes` or `max_frequency`"],
        ),
        ("modes = -1", 5, &["0 or more"]),
        ("drop_below = 2.0", 5, &["between 0 and 1"]),
        ("max_frequency = -3.0", 5, &["positive"]),
        ("bogus = 1", 5, &["bogus"]),
    ];
    for (reduce, line, words) in cases {
        let dir = folder(&[("variant.toml", &derived(reduce))]);
        let e = fail(dir.path(), "variant.toml");
        check(&e, dir.path(), line, words);
    }
}

#[test]
fn base_errors_are_located() {
    let text =
        |base: &str| format!("name = \"variant\"\nbase = \"{base}\"\n\n[reduce]\nmodes = 1\n");
    let dir = folder(&[
        ("variant.toml", &text("../base.toml")),
        ("missing.toml", &text("nowhere.toml")),
        ("chain.toml", &text("variant.toml")),
    ]);
    check(
        &fail(dir.path(), "variant.toml"),
        dir.path(),
        2,
        &["file name of a scene"],
    );
    let e = fail(dir.path(), "missing.toml");
    assert_eq!(
        (e.file.clone(), e.line),
        (dir.path().join("missing.toml"), 2),
        "{e}"
    );
    assert!(e.message.contains("cannot read base scene"), "{e}");
    let e = fail(dir.path(), "chain.toml");
    assert!(e.message.contains("itself a derived scene"), "{e}");
    // A base without flexible links has no modes to drop.
    let rigid = include_str!("../../examples/parallel-robot/scenes/parallel_robot_rigid.toml");
    let dir = folder(&[
        ("rigid.toml", rigid),
        (
            "variant.toml",
            "name = \"variant\"\nbase = \"rigid.toml\"\n[reduce]\nmodes = 1\n",
        ),
    ]);
    check(
        &fail(dir.path(), "variant.toml"),
        dir.path(),
        4,
        &["no flexible link"],
    );
}

#[test]
fn generated_variants_name_both_files_as_inputs() {
    let dir = folder(&[("variant.toml", &derived("modes = 1"))]);
    let g = generate_scene(&dir.path().join("variant.toml")).unwrap();
    let want: Vec<PathBuf> = vec![
        dir.path().join("variant.toml"),
        dir.path().join("base.toml"),
    ];
    assert_eq!(g.sources, want);
    assert_eq!(g.dims.0, 24);
}
