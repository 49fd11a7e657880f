//! The interpreter (`flexdyn::interpreted`, any scene file at run time)
//! against the compiled module of every shipped scene: every term, bit for
//! bit, at the scene's validation states (`scenes/<scene>.states.json`, else
//! seeded states in its declared ranges), with the runtime parameters at the
//! states' values and then all moved off their nominal values.

mod common;

use std::collections::BTreeMap;

use flexdyn::dynamic::DynModel;
use flexdyn::eval::{check_state, evaluate, State, States};
use flexdyn::interpreted::InterpretedModel;
use serde_json::Value;

/// Seeded states per scene without a states file.
const STATES: usize = 8;

/// The validation states of a scene.
fn states(path: &std::path::Path, model: &flexdyn::codegen::model::Model) -> Vec<State> {
    let file = path.with_extension("states.json");
    if let Ok(text) = std::fs::read_to_string(&file) {
        let s: States = serde_json::from_str(&text).unwrap_or_else(|e| panic!("{file:?}: {e}"));
        return s.states;
    }
    let mut rng = common::rng(5);
    (0..STATES)
        .map(|_| {
            let (q, qd, t) = common::random_state(model, &mut rng);
            State {
                q,
                qd,
                t,
                params: BTreeMap::new(),
            }
        })
        .collect()
}

/// Where two JSON trees of numbers differ in any bit (`None`: identical).
fn first_difference(a: &Value, b: &Value, at: &str) -> Option<String> {
    match (a, b) {
        (Value::Number(x), Value::Number(y)) => {
            let (x, y) = (x.as_f64()?, y.as_f64()?);
            (x.to_bits() != y.to_bits()).then(|| format!("{at}: {x:e} vs {y:e}"))
        }
        (Value::Array(x), Value::Array(y)) if x.len() == y.len() => x
            .iter()
            .zip(y)
            .enumerate()
            .find_map(|(i, (x, y))| first_difference(x, y, &format!("{at}[{i}]"))),
        (Value::Object(x), Value::Object(y)) if x.len() == y.len() => {
            x.iter().find_map(|(k, v)| {
                first_difference(v, y.get(k).unwrap_or(&Value::Null), &format!("{at}.{k}"))
            })
        }
        _ => (a != b).then(|| format!("{at}: {a} vs {b}")),
    }
}

#[test]
fn every_term_of_every_scene_is_bitwise_the_compiled_one() {
    let scenes = common::scenes();
    assert!(scenes.len() >= 20, "{} scenes", scenes.len());
    let mut compared = 0;
    for (path, scene) in &scenes {
        let name = &scene.name;
        let mut compiled = flexdyn::scenes::model(name).expect("compiled in");
        let mut interpreted = InterpretedModel::load(path).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(interpreted.name(), compiled.name());
        assert_eq!(interpreted.coordinates(), compiled.coordinates());
        assert_eq!(interpreted.actuators(), compiled.actuators());
        assert_eq!(interpreted.nc(), compiled.nc());
        assert_eq!(interpreted.parameters(), compiled.parameters());
        // Every parameter off its nominal value.
        let moved: BTreeMap<String, f64> = scene
            .runtime_parameters
            .iter()
            .enumerate()
            .map(|(i, p)| (p.name.clone(), p.value * 1.25 + 0.1 * (i + 1) as f64))
            .collect();
        for (k, state) in states(path, scene).into_iter().enumerate() {
            let off_nominal = State {
                params: moved.clone(),
                ..state.clone()
            };
            for s in [state, off_nominal] {
                check_state(compiled.as_ref(), &s, k).unwrap();
                let want = serde_json::to_value(evaluate(compiled.as_mut(), &s).unwrap()).unwrap();
                let got = serde_json::to_value(evaluate(&mut interpreted, &s).unwrap()).unwrap();
                if let Some(d) = first_difference(&got, &want, "") {
                    panic!("{name}, state {k}, params {:?}: {d}", s.params);
                }
                compared += 1;
            }
        }
    }
    assert!(compared >= 200, "{compared} evaluations compared");
}

#[test]
fn a_state_of_the_wrong_length_is_a_clear_error() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/four_bar.toml");
    let model = InterpretedModel::load(&path).unwrap();
    let s = State {
        q: vec![0.1, 0.2],
        qd: vec![0.0; 3],
        t: 0.0,
        params: BTreeMap::new(),
    };
    let e = check_state(&model, &s, 4).unwrap_err();
    assert_eq!(
        e,
        "state 4: scene `four_bar` has 3 coordinates, got 2 positions and 3 velocities"
    );
}

#[test]
fn a_scene_file_with_errors_gives_the_generators_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("broken.toml");
    std::fs::write(
        &path,
        "name = \"broken\"\n[[coordinates]]\nname = \"a\"\n\
         [[components]]\nname = \"m\"\ntype = \"point_mass\"\nmass = 1\n\
         position = [\"a + nope\", 0, 0]\n",
    )
    .unwrap();
    let e = InterpretedModel::load(&path).unwrap_err();
    let generator = flexdyn::codegen::generate_scene(&path).unwrap_err();
    assert_eq!(e, generator.to_string());
    assert!(e.contains("broken.toml") && e.contains("nope"), "{e}");
}

/// `flexdyn eval` on a scene that is not compiled in (a renamed copy of
/// `pendulum`) interprets it: the results are the compiled pendulum's.
#[test]
fn eval_interprets_a_scene_that_is_not_compiled_in() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(root.join("scenes/pendulum.toml")).unwrap();
    let copy = dir.path().join("my_pendulum.toml");
    std::fs::write(
        &copy,
        text.replace("name = \"pendulum\"", "name = \"my_pendulum\""),
    )
    .unwrap();
    let states = root.join("scenes/pendulum.states.json");
    let run = |scene: &std::path::Path| -> Value {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_flexdyn"))
            .args(["eval", "--scene"])
            .arg(scene)
            .arg("--states")
            .arg(&states)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        serde_json::from_slice(&out.stdout).unwrap()
    };
    let mine = run(&copy);
    let shipped = run(&root.join("scenes/pendulum.toml"));
    assert_eq!(mine["scene"], "my_pendulum");
    assert_eq!(
        first_difference(&mine["results"], &shipped["results"], ""),
        None
    );
    assert!(mine["results"].as_array().unwrap().len() >= 3);
}
