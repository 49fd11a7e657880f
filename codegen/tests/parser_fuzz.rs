//! Hostile input never panics the scene reader: random bytes and random token
//! soup fed to the expression parser, and random mutations of valid scene
//! files fed to the model builder. Every error carries a message and a
//! position that exists in its text.
//!
//! The seed is fixed, so a run is reproducible. `FLEXDYN_FUZZ_CASES` sets the
//! number of cases per property (default 2000); `FLEXDYN_FUZZ_SEED` (a number)
//! picks another fixed seed.

use std::collections::BTreeMap;
use std::path::Path;

use flexdyn_codegen::error::{Error, Source};
use flexdyn_codegen::expr::{Graph, Symbol};
use flexdyn_codegen::model::Model;
use flexdyn_codegen::parse::{parse_expr, Binding, ParseError, Scope};
use flexdyn_codegen::scene::parse_scene;
use proptest::prelude::*;
use proptest::test_runner::{Config, RngAlgorithm, TestCaseError, TestRng, TestRunner};

fn cases() -> u32 {
    match std::env::var("FLEXDYN_FUZZ_CASES") {
        Ok(v) => v
            .trim()
            .parse()
            .unwrap_or_else(|_| panic!("FLEXDYN_FUZZ_CASES must be a number, not `{v}`")),
        Err(_) => 2000,
    }
}

/// A runner with a fixed seed (varied by `FLEXDYN_FUZZ_SEED`, a number) and
/// no failure files.
fn runner(property: u8) -> TestRunner {
    let mut seed = [property; 32];
    if let Ok(v) = std::env::var("FLEXDYN_FUZZ_SEED") {
        let extra: u64 = v
            .trim()
            .parse()
            .unwrap_or_else(|_| panic!("FLEXDYN_FUZZ_SEED must be a number, not `{v}`"));
        for (s, e) in seed.iter_mut().zip(extra.to_le_bytes()) {
            *s ^= e;
        }
    }
    let config = Config {
        cases: cases(),
        failure_persistence: None,
        rng_algorithm: RngAlgorithm::ChaCha,
        max_shrink_iters: 2000,
        ..Config::default()
    };
    TestRunner::new_with_rng(config, TestRng::from_seed(RngAlgorithm::ChaCha, &seed))
}

fn scope(allow_velocity: bool) -> Scope {
    let mut parameters = BTreeMap::new();
    parameters.insert("m".to_string(), Binding::Value(2.0));
    parameters.insert("zero".to_string(), Binding::Value(0.0));
    parameters.insert("k".to_string(), Binding::Runtime(0));
    Scope {
        coordinates: vec!["x".into(), "theta".into()],
        parameters,
        allow_velocity,
    }
}

/// Parse an expression; on success evaluate it, on failure check the error.
fn check_expr(text: &str, allow_velocity: bool) -> Result<(), TestCaseError> {
    let mut graph = Graph::new();
    match parse_expr(&mut graph, text, &scope(allow_velocity)) {
        Ok(id) => {
            let _ = graph.eval(&[id], &|s| match s {
                Symbol::Q(i) => 0.3 + f64::from(i),
                Symbol::Qd(i) => -0.7 + f64::from(i),
                Symbol::Time => 0.25,
                Symbol::Param(_) => 1.5,
            });
        }
        Err(ParseError { offset, message }) => {
            prop_assert!(!message.trim().is_empty(), "empty message for {text:?}");
            prop_assert!(
                offset <= text.len() && text.is_char_boundary(offset),
                "offset {offset} outside {text:?}: {message}"
            );
        }
    }
    Ok(())
}

#[test]
fn random_bytes_never_panic_the_expression_parser() {
    // Half arbitrary bytes, half printable ASCII, which gets past the lexer.
    let byte = prop_oneof![any::<u8>(), 0x20u8..0x7f];
    let input = (proptest::collection::vec(byte, 0..160), any::<bool>());
    runner(7)
        .run(&input, |(bytes, velocity)| {
            check_expr(&String::from_utf8_lossy(&bytes), velocity)
        })
        .unwrap();
}

const VOCABULARY: &[&str] = &[
    "q",
    "qd",
    "[",
    "]",
    "(",
    ")",
    "0",
    "1",
    "2",
    "5",
    "0.5",
    "1e-3",
    "1e999",
    "2pi",
    "64",
    "65",
    "-64",
    "+",
    "-",
    "*",
    "/",
    "^",
    ",",
    ".",
    "sin",
    "cos",
    "tan",
    "exp",
    "ln",
    "sqrt",
    "powi",
    "pow",
    "atan2",
    "dot",
    "x",
    "theta",
    "m",
    "k",
    "zero",
    "t",
    "pi",
    "PI",
    "undefined",
    "{",
    "}",
    "fn",
    "\"",
    "'",
    "!",
    "&&",
    "|",
    "%",
    "<",
    "==",
    "=",
    ";",
    ":",
    "::",
    "#",
    "$",
    "\\",
    "é",
    "r#x",
    "as",
    "f64",
    "x.sin()",
    "x.powi(2)",
    "theta.atan2(x)",
    "dot(x)",
    "qd[0]",
    "q[1]",
    "q[2]",
    "..",
    "?",
    "@",
    "'a",
    "\n",
    "\t",
];

#[test]
fn token_soup_never_panics_the_expression_parser() {
    let token = proptest::sample::select(VOCABULARY);
    let separator = prop_oneof![Just(""), Just(" ")];
    let soup = proptest::collection::vec((token, separator), 0..40);
    runner(8)
        .run(&(soup, any::<bool>()), |(tokens, velocity)| {
            let text: String = tokens.iter().flat_map(|(t, s)| [*t, *s]).collect();
            check_expr(&text, velocity)
        })
        .unwrap();
}

#[test]
fn expressions_at_the_limits_do_not_overflow_the_stack() {
    let ops = "x+".repeat(499) + "x";
    let methods = "x".to_string() + &".sin()".repeat(249);
    let nested = "sin(".repeat(47) + "x" + &")".repeat(47);
    let negs = "-".repeat(47) + "x";
    let mixed = "(x*".repeat(40) + "x" + &")".repeat(40) + &"/m".repeat(200);
    for text in [ops, methods, nested, negs, mixed] {
        let mut graph = Graph::new();
        parse_expr(&mut graph, &text, &scope(false))
            .unwrap_or_else(|e| panic!("{e:?} for {text:?}"));
    }
}

/// A scene using every feature of the format, including escapes and
/// multi-line strings, so that mutations reach every check.
const KITCHEN_SINK: &str = r#"# every feature
name = "sink"
description = "kitchen sink"
gravity = [0, "-g", 0]
outputs = ["forces", "coriolis_matrix"]

[parameters]
g = 9.81
m = { value = 1.5, runtime = true }
l = 0.5
c = { value = 0.1 }

[[coordinates]]
name = "x"
range = [-1.0, 1.0]
velocity_range = [-2, 2]

[[coordinates]]
name = "theta"

[[frames]]
name = "cart"
translation = ["x", 0, 0]

[[frames]]
name = "arm"
parent = "cart"
rotation = [{ axis = "z", angle = "theta" }, { axis = [1, 0, 1], angle = 0.1 }]

[[components]]
name = "body"
type = "rigid_body"
mass = "m"
frame = "arm"
position = ["l/2", 0]
inertia = [[0.1, 0, 0], [0, "0.1*m", 0], [0, 0, 0.2]]

[[components]]
name = "tip"
type = "point_mass"
mass = 0.2
frame = "arm"
position = ["l", 0, 0]

[[components]]
name = "link"
type = "rod"
mass = "m/3"
from = [0, 0, 0]
to = ["x + l*cos(theta)", "l*sin(theta)", 0]

[[components]]
name = "extra"
type = "energy"
kinetic = """
0.5*c*qd[0]*qd[0] + \
  0.25*c*dot(theta).powi(2)"""
potential = "c * (x\t- 0.1).powi(2) + 0.01*atan2(theta, 1 + x*x)"
dissipation = '0.5*c*qd[1]*qd[1]'

[[components]]
name = "torsion"
type = "spring"
stiffness = "2*c"
expression = "theta"
rest = 0.2

[[components]]
name = "friction"
type = "damper"
damping = "c"
expression = "x - l*sin(theta)"

[[constraints]]
name = "slot"
expression = "sqrt(1 + x*x) - 1 - 0.01*theta + 0*t"

[[actuators]]
name = "push"
coordinate = "x"
gain = 2.0
"#;

const SCENES: &[&str] = &[
    KITCHEN_SINK,
    include_str!("../../scenes/pendulum.toml"),
    include_str!("../../scenes/cart_pole.toml"),
    include_str!("../../scenes/double_pendulum.toml"),
    include_str!("../../scenes/five_bar.toml"),
    include_str!("../../scenes/slider_crank.toml"),
    include_str!("../../scenes/parallel_robot_rigid.toml"),
];

fn load(text: &str) -> (Source, Result<Model, Error>) {
    let source = Source::new(Path::new("fuzz.toml"), text.to_owned());
    let result = Model::from_source(&source);
    (source, result)
}

#[test]
fn the_seed_scenes_are_valid() {
    for text in SCENES {
        let (_, result) = load(text);
        let model = result.unwrap_or_else(|e| panic!("{e}"));
        assert!(model.nq() > 0);
    }
}

#[derive(Debug, Clone)]
enum Mutation {
    Insert(usize, u8),
    Delete(usize),
    Replace(usize, u8),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    // Bytes that matter to TOML and to the expression grammar, then any.
    let byte = prop_oneof![
        proptest::sample::select(b"\"'\\[]{}()=,.#\n\t -+*/^0123456789eqdxtn_".to_vec()),
        0x20u8..0x7f,
        any::<u8>(),
    ];
    prop_oneof![
        (any::<usize>(), byte.clone()).prop_map(|(at, b)| Mutation::Insert(at, b)),
        any::<usize>().prop_map(Mutation::Delete),
        (any::<usize>(), byte).prop_map(|(at, b)| Mutation::Replace(at, b)),
    ]
}

fn mutate(text: &str, mutations: &[Mutation]) -> String {
    let mut bytes = text.as_bytes().to_vec();
    for m in mutations {
        let n = bytes.len();
        match *m {
            Mutation::Insert(at, b) => bytes.insert(at % (n + 1), b),
            Mutation::Delete(at) if n > 0 => {
                bytes.remove(at % n);
            }
            Mutation::Replace(at, b) if n > 0 => bytes[at % n] = b,
            _ => {}
        }
    }
    String::from_utf8_lossy(&bytes).into_owned()
}

/// The error is well formed and its position exists in `text`.
fn check_scene_error(text: &str, e: &Error) -> Result<(), TestCaseError> {
    prop_assert!(!e.message.trim().is_empty(), "empty message: {e:?}");
    prop_assert_eq!(e.file.as_path(), Path::new("fuzz.toml"));
    if e.line == 0 {
        // Only a scene-wide problem may lack a position.
        prop_assert!(
            e.message.contains("declares no coordinates"),
            "unlocated error: {e}"
        );
        return Ok(());
    }
    let lines: Vec<&str> = text.split('\n').collect();
    prop_assert!(e.line <= lines.len(), "line past the end: {e}");
    let line = lines[e.line - 1];
    let width = line.chars().count();
    prop_assert!(
        e.column >= 1 && e.column <= width + 1,
        "column outside line {:?}: {}",
        line,
        e
    );
    // An undefined symbol is reported where its name is written, unless a
    // `\u` escape spelled it.
    if let Some(name) = e
        .message
        .strip_prefix("undefined symbol `")
        .and_then(|r| r.strip_suffix('`'))
    {
        if !text.contains("\\u") && !text.contains("\\U") {
            let rest: String = line.chars().skip(e.column - 1).collect();
            prop_assert!(
                rest.starts_with(name),
                "`{}` is not at the reported position: {} (line {:?})",
                name,
                e,
                line
            );
        }
    }
    Ok(())
}

#[test]
fn mutated_scenes_never_panic_and_errors_are_located() {
    let input = (
        proptest::sample::select(SCENES),
        proptest::collection::vec(mutation(), 1..4),
    );
    runner(9)
        .run(&input, |(scene, mutations)| {
            let text = mutate(scene, &mutations);
            let (source, result) = load(&text);
            if let Err(e) = result {
                check_scene_error(&text, &e)?;
                // An error from reading the TOML is the model's error too,
                // and is always located.
                if let Err(toml_error) = parse_scene(&source) {
                    prop_assert_eq!(&toml_error, &e);
                    prop_assert!(toml_error.line >= 1, "{}", toml_error);
                }
            }
            Ok(())
        })
        .unwrap();
}
