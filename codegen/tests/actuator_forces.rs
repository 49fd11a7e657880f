//! The actuators' generalized forces `B tau` as derived and emitted: a
//! scene with gains other than 1 and two actuators on one coordinate (no
//! shipped scene has either; the compiled scenes' identity maps are checked
//! against `actuator_map` in the root crate's tests).

use std::path::Path;

use flexdyn_codegen::{generate_scene, Model, Symbol};

/// A point mass moving in a plane, pushed along `a` by two actuators (gains
/// 2.5 and -0.5) and along `b` by one (gain 1, the default).
const SCENE: &str = r#"
name = "pushed"
gravity = [0, 0, -9.81]

[[coordinates]]
name = "a"

[[coordinates]]
name = "b"

[[components]]
name = "mass"
type = "point_mass"
mass = 2.0
position = ["a", 0, "b"]

[[actuators]]
name = "push"
coordinate = "a"
gain = 2.5

[[actuators]]
name = "lift"
coordinate = "b"

[[actuators]]
name = "brake"
coordinate = "a"
gain = -0.5
"#;

fn write(dir: &Path) -> std::path::PathBuf {
    let path = dir.join("pushed.toml");
    std::fs::write(&path, SCENE).expect("write scene");
    path
}

#[test]
fn derived_actuator_forces_are_the_actuator_map_times_the_inputs() {
    let dir = tempfile::tempdir().expect("temporary folder");
    let mut model = Model::load(&write(dir.path())).unwrap();
    let eq = model.equations().unwrap();
    assert_eq!(
        eq.actuator_map,
        vec![vec![2.5, 0.0, -0.5], vec![0.0, 1.0, 0.0]]
    );
    for tau in [[1.0, 0.0, 0.0], [0.3, -1.7, 4.1], [-2.0, 0.5, 1e3]] {
        let env = |s: Symbol| match s {
            Symbol::Qdd(j) => tau[j as usize],
            _ => f64::NAN,
        };
        let got = model.graph.eval(&eq.actuator_forces, &env);
        let want: Vec<f64> = eq
            .actuator_map
            .iter()
            .map(|row| row.iter().zip(&tau).map(|(b, t)| b * t).sum())
            .collect();
        for (g, w) in got.iter().zip(&want) {
            assert!((g - w).abs() <= 1e-15 * w.abs().max(1.0), "{g} vs {w}");
        }
    }
}

/// The emitted function reads the inputs `tau` (not `qdd`), each into its
/// own coordinate's force, and costs the map's non-zero entries: `2.5 tau[0] - 0.5 tau[2]` and
/// `tau[1]`, two multiplications and one addition.
#[test]
fn emitted_actuator_forces_read_the_inputs_and_cost_the_non_zero_entries() {
    let dir = tempfile::tempdir().expect("temporary folder");
    let generated = generate_scene(&write(dir.path())).unwrap_or_else(|e| panic!("{e}"));
    let ops = generated
        .functions
        .iter()
        .find(|f| f.name == "actuator_forces")
        .expect("actuator_forces emitted")
        .ops;
    assert!(ops.total() <= 3, "{ops:?}");
    let source = &generated.source;
    let start = source.find("fn actuator_forces").expect("in the module");
    let body = &source[start..start + source[start..].find("\n    }").unwrap()];
    assert!(body.contains("tau: &SVector<f64, 3>"), "{body}");
    assert!(body.contains("f: &mut SVector<f64, 2>"), "{body}");
    // Actuator j's input on its own coordinate's force.
    let line = |i: usize| {
        let at = body
            .find(&format!("f[{i}] = "))
            .expect("each force written");
        &body[at..at + body[at..].find(';').unwrap()]
    };
    let (a, b) = (line(0), line(1));
    assert!(
        a.contains("tau[0]") && a.contains("tau[2]") && !a.contains("tau[1]"),
        "{a}"
    );
    assert_eq!(b, "f[1] = tau[1]");
    assert!(!body.contains("qdd") && !body.contains(" t:"), "{body}");
}
