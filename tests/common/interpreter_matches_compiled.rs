// The interpreter (`flexdyn::interpreted`, any scene file at run time)
// against the compiled module of every scene a crate compiles in: every
// term, bit for bit, at the scene's validation states
// (`<scene>.states.json`, else seeded states in its declared ranges), with
// the runtime parameters at the states' values and then all moved off their
// nominal values. Shared by the crates that compile scenes in: each test
// file declares `mod common;` and `use ... as compiled;` (its index module
// of generated scenes), then `include!`s this file.

use std::collections::BTreeMap;

use flexdyn::dynamic::DynModel;
use flexdyn::eval::{check_state, evaluate, State, States};
use flexdyn::interpreted::InterpretedModel;
use serde_json::Value;

/// Seeded states per scene without a states file.
const STATES: usize = 8;

/// The validation states of a scene.
fn states(path: &std::path::Path, model: &flexdyn::codegen::Model) -> Vec<State> {
    let file = path.with_extension("states.json");
    if let Ok(text) = std::fs::read_to_string(&file) {
        let s: States = serde_json::from_str(&text).unwrap_or_else(|e| panic!("{file:?}: {e}"));
        return s.states;
    }
    let mut rng = common::rng(5);
    (0..STATES)
        .map(|_| {
            let (q, qd, t) = common::random_state(model, &mut rng);
            // Accelerations of the size of the velocities, another order.
            let qdd = qd.iter().rev().map(|v| 1.5 * v - 0.2).collect();
            // Inputs of the same size, for the forward dynamics.
            let tau = (0..model.actuators.len())
                .map(|j| 0.7 * qd[j % qd.len()] + 0.1)
                .collect();
            State {
                q,
                qd,
                qdd,
                tau,
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
    assert!(scenes.len() >= 5, "{} scenes", scenes.len());
    let mut compared = 0;
    for (path, scene) in &scenes {
        let name = &scene.name;
        let mut compiled = compiled::model(name).expect("compiled in");
        let mut interpreted = InterpretedModel::load(path).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(interpreted.name(), compiled.name());
        assert_eq!(interpreted.coordinates(), compiled.coordinates());
        assert_eq!(interpreted.actuators(), compiled.actuators());
        assert_eq!(interpreted.nc(), compiled.nc());
        assert_eq!(interpreted.markers(), compiled.markers());
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
    assert!(
        compared >= 10 * scenes.len(),
        "{compared} evaluations compared"
    );
}

