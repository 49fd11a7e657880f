//! Hostile input never panics the scene reader: random bytes and random token
//! soup fed to the expression parser; random mutations of valid scene files
//! and randomly generated scene documents (every section, field and component
//! type, with right and wrong value types and names) fed to the whole loader
//! (`Model::load`: file reading, TOML, every semantic check, the finite-element
//! model of flexible links), and the scenes it accepts on through the
//! Lagrange derivation and the emitter. Every error carries a message and a
//! position that exists in its text.
//!
//! The seed is fixed, so a run is reproducible. `FLEXDYN_FUZZ_CASES` sets the
//! number of cases per property (default 1000, which CI runs in a few
//! seconds); the nightly-size run is
//!
//! ```text
//! FLEXDYN_FUZZ_CASES=100000 cargo test --release -p flexdyn-codegen --lib tests::parser_fuzz
//! ```
//!
//! (100000 cases for each property). `FLEXDYN_FUZZ_SEED` (a
//! number) picks another fixed seed; `FLEXDYN_FUZZ_SEED=fresh` a new one
//! from the clock, printed first (`fuzzing with FLEXDYN_FUZZ_SEED=N`) so
//! that setting it replays the run. CI sets neither: a landing never depends
//! on luck. A failure, a panic included, prints the offending input: the
//! scene or URDF text itself, of the smallest failing case proptest's
//! shrinking finds.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use proptest::prelude::*;
use proptest::test_runner::{Config, RngAlgorithm, TestCaseError, TestRng, TestRunner};

use crate::emit::emit;
use crate::error::{Error, Source};
use crate::expr::{Graph, Symbol};
use crate::load::parse::{parse_expr, Binding, ParseError, Scope};
use crate::load::scene::parse_scene_file;
use crate::model::Model;

fn cases() -> u32 {
    match std::env::var("FLEXDYN_FUZZ_CASES") {
        Ok(v) => v
            .trim()
            .parse()
            .unwrap_or_else(|_| panic!("FLEXDYN_FUZZ_CASES must be a number, not `{v}`")),
        Err(_) => 1000,
    }
}

/// The seed variation `FLEXDYN_FUZZ_SEED` asks for: a number, or `fresh`
/// for a new one from the clock, printed first so that the run can be
/// replayed with it (CI sets nothing: the fixed seed).
fn seed_variation() -> Option<u64> {
    let v = std::env::var("FLEXDYN_FUZZ_SEED").ok()?;
    if v.trim() == "fresh" {
        let clock = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as u64);
        let fresh = clock ^ u64::from(std::process::id()).rotate_left(32);
        eprintln!("fuzzing with FLEXDYN_FUZZ_SEED={fresh} (set it to replay this run)");
        return Some(fresh);
    }
    Some(
        v.trim()
            .parse()
            .unwrap_or_else(|_| panic!("FLEXDYN_FUZZ_SEED must be a number or `fresh`, not `{v}`")),
    )
}

/// Runs `property` on the input `text` (a scene or URDF), turning a panic
/// into a failure that prints the text, so that proptest's report (after
/// shrinking, of the minimal failing case) shows the input itself, not
/// only the value it was generated from.
pub(super) fn showing(
    text: &str,
    property: impl FnOnce() -> Result<(), TestCaseError>,
) -> Result<(), TestCaseError> {
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(property)) {
        Ok(Err(TestCaseError::Fail(why))) => Err(TestCaseError::fail(format!(
            "{why}\n--- failing input ---\n{text}\n---"
        ))),
        Ok(result) => result,
        Err(panic) => {
            let why = panic
                .downcast_ref::<String>()
                .map(String::as_str)
                .or_else(|| panic.downcast_ref::<&str>().copied())
                .unwrap_or("a panic");
            Err(TestCaseError::fail(format!(
                "panicked: {why}\n--- failing input ---\n{text}\n---"
            )))
        }
    }
}

/// A runner with a fixed seed (varied by `FLEXDYN_FUZZ_SEED`: a number, or
/// `fresh`) and no failure files.
pub(super) fn runner(property: u8) -> TestRunner {
    let mut seed = [property; 32];
    if let Some(extra) = seed_variation() {
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
        points: BTreeMap::new(),
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
                Symbol::Param(_) | Symbol::Qdd(_) => 1.5,
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
    "abs",
    "sign",
    "step",
    "min",
    "max",
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
    "x.min(theta)",
    "step(t - 1)",
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
    let power = "powi(powi(x, 16), 16) * powi(theta, -64)".to_string();
    for text in [ops, methods, nested, negs, mixed, power] {
        let mut graph = Graph::new();
        parse_expr(&mut graph, &text, &scope(false))
            .unwrap_or_else(|e| panic!("{e:?} for {text:?}"));
    }
}

#[test]
fn powers_that_would_multiply_out_to_huge_code_are_rejected() {
    // Each would be accepted operator by operator, but multiplied out in the
    // generated code (x^4096: 53000 multiplications and a stack overflow in
    // the emitter, found by the generated-scene fuzzing).
    for (text, at) in [
        ("powi(powi(x, 64), 64)", 0),
        ("1 + 2*powi(powi(x, 16), -17)", 6),
        (
            "powi(x, 64) * powi(x, 64) * powi(x, 64) * powi(x, 64) * powi(x, 64)",
            54,
        ),
    ] {
        let mut graph = Graph::new();
        let e = parse_expr(&mut graph, text, &scope(false)).unwrap_err();
        assert!(e.message.contains("at most 256"), "{text}: {}", e.message);
        assert_eq!(e.offset, at, "{text}: {}", e.message);
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
    include_str!("../../../scenes/pendulum.toml"),
    include_str!("../../../scenes/cart_pole.toml"),
    include_str!("../../../scenes/double_pendulum.toml"),
    include_str!("../../../scenes/five_bar.toml"),
    include_str!("../../../scenes/slider_crank.toml"),
    include_str!("../../../examples/parallel-robot/scenes/parallel_robot_rigid.toml"),
    include_str!("../../../scenes/four_bar.toml"),
    include_str!("../../../scenes/flyball_governor.toml"),
    include_str!("../../../scenes/extreme_ratios.toml"),
    SMALL_FLEXIBLE,
];

/// A flexible link small enough (4 elements, 2 modes) that its
/// finite-element model is cheap to rebuild for every mutation, with a
/// station frame, a vector constraint and geometric stiffening.
const SMALL_FLEXIBLE: &str = r#"name = "small_flexible"
gravity = [0, 0, -9.81]

[parameters]
l = 0.5

[[coordinates]]
name = "theta"
range = [-1, 1]

[[frames]]
name = "hub"
rotation = [{ axis = "z", angle = "theta" }]

[[frames]]
name = "tip"
parent = "hub"
station = "end"

[[components]]
name = "beam"
type = "flexible_link"
frame = "hub"
length = "l"
material = { youngs_modulus = 7e10, poisson = 0.3, density = 2700 }
section = { radius = 0.005 }
elements = 4
modes = 2
boundary = "clamped_free"
damping_ratio = 0.01
geometric_stiffening = true

[[components]]
name = "payload"
type = "point_mass"
mass = 0.1
frame = "tip"
position = [0, 0, 0]

[[constraints]]
name = "level"
type = "perpendicular"
a = { frame = "tip", axis = "z" }
b = { axis = [1, 0, 0] }

[[actuators]]
name = "tau"
coordinate = "theta"
"#;

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
pub(super) enum Mutation {
    Insert(usize, u8),
    Delete(usize),
    Replace(usize, u8),
}

pub(super) fn mutation() -> impl Strategy<Value = Mutation> {
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

pub(super) fn mutate(text: &str, mutations: &[Mutation]) -> String {
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
            showing(&text, || {
                let (source, result) = load(&text);
                if let Err(e) = result {
                    check_scene_error(&text, &e)?;
                    // An error from reading the TOML is the model's error too,
                    // and is always located.
                    if let Err(toml_error) = parse_scene_file(&source) {
                        prop_assert_eq!(&toml_error, &e);
                        prop_assert!(toml_error.line >= 1, "{}", toml_error);
                    }
                }
                Ok(())
            })
        })
        .unwrap();
}

/// A small deterministic generator (SplitMix64) for building scene documents
/// from one proptest-drawn seed. `noise` is the percentage of decisions that
/// go wrong on purpose (bad names, wrong types, odd numbers, junk tokens):
/// some documents are careful (little noise) so that many get past every
/// check and on to the generator, others are noisy.
struct Gen {
    state: u64,
    noise: u64,
}

impl Gen {
    fn new(seed: u64) -> Gen {
        let mut g = Gen {
            state: seed,
            noise: 0,
        };
        g.noise = [1, 3, 30, 60][g.below(4)];
        g
    }
    fn next(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
    fn chance(&mut self, percent: u64) -> bool {
        self.next() % 100 < percent
    }
    /// Whether to go wrong on purpose here.
    fn junk(&mut self) -> bool {
        let noise = self.noise;
        self.chance(noise)
    }
    fn pick<'a>(&mut self, items: &[&'a str]) -> &'a str {
        items[self.below(items.len())]
    }
}

/// A positive number of ordinary size.
fn positive(g: &mut Gen) -> String {
    format!("{}", (1 + g.next() % 3000) as f64 / 1000.0)
}

/// Numbers a scene may contain: ordinary ones, and (noise) the edge cases.
fn number(g: &mut Gen) -> String {
    if !g.junk() {
        let v = (g.next() % 4000) as f64 / 1000.0 - 0.5;
        format!("{v}")
    } else {
        g.pick(&[
            "0", "-1", "1e-300", "1e300", "1e999", "-0.0", "nan", "inf", "-inf", "2", "200", "201",
            "0.5", "1e9", "1e-6", "3", "-2",
        ])
        .to_owned()
    }
}

/// An expression over the document's names: well formed, or (noise) not.
fn expression(g: &mut Gen, names: &[String], depth: u32) -> String {
    if depth == 0 || g.chance(30) {
        if g.junk() {
            return g
                .pick(&[
                    "q[0]",
                    "q[7]",
                    "qd[0]",
                    "dot(a)",
                    "undefined",
                    "",
                    "(",
                    "x^2",
                    "1/0",
                    "ln(0)",
                ])
                .to_owned();
        }
        return match g.below(5) {
            0 | 1 if !names.is_empty() => names[g.below(names.len())].clone(),
            2 => number(g),
            3 => g.pick(&["t", "pi", "2"]).to_owned(),
            _ => format!("{}", 1 + g.below(5)),
        };
    }
    let a = expression(g, names, depth - 1);
    let b = expression(g, names, depth - 1);
    if g.junk() && g.chance(30) {
        return (0..g.below(6))
            .map(|_| g.pick(VOCABULARY))
            .collect::<Vec<_>>()
            .join(" ");
    }
    match g.below(11) {
        0 => format!("{a} + {b}"),
        1 => format!("{a} - {b}"),
        2 => format!("({a})*({b})"),
        3 => format!("({a})/(2 + ({b})*({b}))"),
        4 => format!("-({a})"),
        5 => format!(
            "{}({a})",
            g.pick(&["sin", "cos", "tan", "exp", "ln", "sqrt", "abs", "sign", "step"])
        ),
        6 => format!("{}({a}, {b})", g.pick(&["atan2", "min", "max"])),
        7 => {
            let n = if g.junk() {
                g.pick(&["65", "x", "0.5", "-65"])
            } else {
                g.pick(&["2", "3", "-1", "64"])
            };
            format!("powi({a}, {n})")
        }
        8 => format!("({a}).{}()", g.pick(&["sin", "cos", "sqrt", "abs"])),
        9 => format!("({a}).{}({b})", g.pick(&["min", "max"])),
        _ => format!("{a} * {b}"),
    }
}

/// A TOML value for a scalar field: an expression string or a number, or
/// (noise) a value of the wrong type.
fn scalar(g: &mut Gen, names: &[String]) -> String {
    if g.junk() && g.chance(30) {
        return wrong_value(g);
    }
    if g.chance(70) {
        toml_string(&expression(g, names, 3))
    } else {
        number(g)
    }
}

fn wrong_value(g: &mut Gen) -> String {
    g.pick(&[
        "true",
        "[]",
        "{}",
        "[1, 2]",
        "{ value = 1 }",
        "\"\"",
        "1979-05-27",
        "[[1, 2], [3]]",
        "'''\nmulti\nline'''",
    ])
    .to_owned()
}

/// A TOML basic string holding `s`.
fn toml_string(s: &str) -> String {
    let mut out = String::from("\"");
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\t' => out.push_str("\\t"),
            c if c.is_control() => {
                let _ = write!(out, "\\u{:04x}", c as u32);
            }
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

fn vector(g: &mut Gen, names: &[String]) -> String {
    let n = if g.junk() {
        [2, 1, 4, 0][g.below(4)]
    } else {
        3
    };
    let items: Vec<String> = (0..n).map(|_| scalar(g, names)).collect();
    format!("[{}]", items.join(", "))
}

fn name_value(g: &mut Gen, names: &[String]) -> String {
    if !g.junk() && !names.is_empty() {
        toml_string(&names[g.below(names.len())])
    } else {
        toml_string(g.pick(&["", "world", "9lives", "x y", "é", "missing", "q", "t", "pi"]))
    }
}

const COMPONENT_TYPES: &[&str] = &[
    "energy",
    "point_mass",
    "rod",
    "rigid_body",
    "spring",
    "damper",
    "flexible_link",
    "flexible_joint",
];

const COMPONENT_FIELDS: &[&str] = &[
    "kinetic",
    "potential",
    "dissipation",
    "mass",
    "frame",
    "position",
    "from",
    "to",
    "inertia",
    "stiffness",
    "damping",
    "expression",
    "rest",
    "axis",
    "length",
    "material",
    "section",
    "elements",
    "modes",
    "max_frequency",
    "boundary",
    "end_stiffness",
    "damping_ratio",
    "geometric_stiffening",
    "allow_unphysical_inertia",
    "colour",
];

/// The value of one component field.
fn component_field(g: &mut Gen, field: &str, names: &[String], frames: &[String]) -> String {
    let junk = g.junk();
    match field {
        "mass" | "stiffness" | "damping" | "length" | "rest" | "max_frequency" if !junk => {
            positive(g)
        }
        "frame" => name_value(g, frames),
        "position" | "from" | "to" => vector(g, names),
        "inertia" if !junk => {
            let (a, b, c) = (positive(g), positive(g), positive(g));
            format!("[[{a}, 0, 0], [0, {b}, 0], [0, 0, {c}]]")
        }
        "inertia" => {
            let rows: Vec<String> = (0..[3, 3, 2][g.below(3)])
                .map(|_| vector(g, names))
                .collect();
            format!("[{}]", rows.join(", "))
        }
        "material" => {
            let value = |g: &mut Gen, big: f64| {
                if g.junk() {
                    scalar(g, names)
                } else {
                    format!("{:e}", big * (1.0 + g.below(9) as f64))
                }
            };
            let mut parts = vec![format!("youngs_modulus = {}", value(g, 1e10))];
            if !junk || g.chance(70) {
                parts.push(format!(
                    "poisson = {}",
                    g.pick(&["0.3", "0.33", "-1", "0.5"])
                ));
            }
            if junk && g.chance(20) {
                parts.push(format!("shear_modulus = {}", scalar(g, names)));
            }
            if !junk || g.chance(90) {
                parts.push(format!("density = {}", value(g, 1e3)));
            }
            format!("{{ {} }}", parts.join(", "))
        }
        "section" => {
            let key = if junk {
                g.pick(&["area", "outer_radius", "inner_radius", "width"])
            } else {
                "radius"
            };
            let mut s = format!("{{ {key} = {}", g.pick(&["0.005", "0.01", "0.02"]));
            if key == "outer_radius" && g.chance(70) {
                let _ = write!(s, ", inner_radius = {}", scalar(g, names));
            }
            s.push_str(" }");
            s
        }
        "axis" => toml_string(if junk {
            g.pick(&["w", "X", "", "z y"])
        } else {
            g.pick(&["x", "y", "z"])
        }),
        "boundary" => {
            let b = if junk {
                g.pick(&["hinged", "pinned_pinned_elastic", "free_free"])
            } else {
                g.pick(&["pinned_pinned", "clamped_free", "clamped_clamped"])
            };
            toml_string(b)
        }
        "end_stiffness" => match g.below(3) {
            0 => vector(g, names),
            1 => format!("{{ start = {} }}", vector(g, names)),
            _ => format!(
                "{{ start = {}, end = {} }}",
                vector(g, names),
                vector(g, names)
            ),
        },
        "damping_ratio" => {
            if junk {
                vector(g, names)
            } else {
                g.pick(&["0.01", "0.02", "[0.01, 0.02]"]).to_owned()
            }
        }
        "geometric_stiffening" | "allow_unphysical_inertia" => if junk {
            g.pick(&["1", "\"yes\""])
        } else {
            g.pick(&["true", "false"])
        }
        .to_owned(),
        "elements" => if junk {
            g.pick(&["0", "-1", "201", "2.5", "\"two\""])
        } else {
            g.pick(&["1", "2", "3", "4"])
        }
        .to_owned(),
        "modes" => if junk {
            g.pick(&["-1", "2.5", "100", "\"two\""])
        } else {
            g.pick(&["0", "1", "2"])
        }
        .to_owned(),
        _ => scalar(g, names),
    }
}

/// A random scene document. Names declared early are used by later
/// expressions, so that many documents get past the syntax checks and reach
/// the semantic ones (and many reach the generator).
fn scene_document(g: &mut Gen) -> String {
    let mut doc = String::new();
    let mut names: Vec<String> = Vec::new();
    let mut frames: Vec<String> = vec!["world".into()];
    if !g.junk() {
        doc.push_str("name = \"fuzz\"\n");
    } else if g.chance(50) {
        let name = g.pick(&["Fuzz", "9x", "", "a-b", "self", "fn"]);
        let _ = writeln!(doc, "name = {}", toml_string(name));
    }
    if g.chance(20) {
        let _ = writeln!(doc, "description = {}", scalar(g, &names));
    }
    if g.chance(30) {
        let _ = writeln!(doc, "gravity = {}", vector(g, &names));
    }
    if g.chance(20) {
        let outs: Vec<String> = (0..g.below(3))
            .map(|_| {
                let o = if g.junk() {
                    "jerk"
                } else {
                    g.pick(&["forces", "coriolis_matrix"])
                };
                toml_string(o)
            })
            .collect();
        let _ = writeln!(doc, "outputs = [{}]", outs.join(", "));
    }
    if g.junk() && g.chance(10) {
        let _ = writeln!(doc, "unknown_key = 1");
    }
    if g.chance(70) {
        doc.push_str("\n[parameters]\n");
        for k in 0..g.below(4) {
            let p = format!("p{k}");
            let value = match g.below(5) {
                0 => format!("{{ value = {}, runtime = true }}", number(g)),
                1 => format!("{{ value = {} }}", number(g)),
                2 if g.junk() => wrong_value(g),
                _ => number(g),
            };
            let _ = writeln!(doc, "{p} = {value}");
            names.push(p);
        }
    }
    let coordinates = if g.junk() && g.chance(20) {
        0
    } else {
        1 + g.below(4)
    };
    for k in 0..coordinates {
        let c = format!("c{k}");
        let _ = writeln!(doc, "\n[[coordinates]]\nname = {}", toml_string(&c));
        for (key, percent) in [("range", 40), ("velocity_range", 20)] {
            if g.chance(percent) {
                let (a, b) = if g.junk() {
                    (number(g), number(g))
                } else {
                    let a = (g.next() % 2000) as f64 / 1000.0 - 1.0;
                    (format!("{a}"), format!("{}", a + 0.001 + g.below(3) as f64))
                };
                let _ = writeln!(doc, "{key} = [{a}, {b}]");
            }
        }
        names.push(c);
    }
    for k in 0..g.below(4) {
        let f = format!("f{k}");
        let _ = writeln!(doc, "\n[[frames]]\nname = {}", toml_string(&f));
        if g.chance(50) {
            let _ = writeln!(doc, "parent = {}", name_value(g, &frames));
        }
        if g.chance(60) {
            let _ = writeln!(doc, "translation = {}", vector(g, &names));
        }
        if g.chance(50) {
            let axis = if g.junk() {
                if g.chance(50) {
                    toml_string(g.pick(&["w", "", "xy"]))
                } else {
                    vector(g, &[])
                }
            } else {
                toml_string(g.pick(&["x", "y", "z"]))
            };
            let _ = writeln!(
                doc,
                "rotation = [{{ axis = {axis}, angle = {} }}]",
                scalar(g, &names)
            );
        }
        if g.junk() && g.chance(30) {
            let station = if g.chance(50) {
                toml_string(g.pick(&["start", "end", "middle"]))
            } else {
                number(g)
            };
            let _ = writeln!(doc, "station = {station}");
        }
        frames.push(f);
    }
    // Velocities may appear in energies and dissipation functions.
    let mut with_velocities = names.clone();
    for k in 0..coordinates {
        with_velocities.push(format!("dot(c{k})"));
        with_velocities.push(format!("qd[{k}]"));
    }
    for k in 0..g.below(5) {
        let kind = if g.junk() && g.chance(10) {
            "wheel"
        } else {
            g.pick(COMPONENT_TYPES)
        };
        let _ = writeln!(doc, "\n[[components]]\nname = \"k{k}\"\ntype = \"{kind}\"");
        let wanted: &[&str] = match kind {
            "energy" => &["kinetic", "potential", "dissipation"],
            "point_mass" => &["mass", "position", "frame"],
            "rod" => &["mass", "from", "to", "frame"],
            "rigid_body" => &[
                "mass",
                "frame",
                "position",
                "inertia",
                "allow_unphysical_inertia",
            ],
            "spring" => &["stiffness", "expression", "rest"],
            "damper" => &["damping", "expression"],
            "flexible_link" => &[
                "frame",
                "length",
                "material",
                "section",
                "boundary",
                "elements",
                "modes",
                "damping_ratio",
                "geometric_stiffening",
            ],
            "flexible_joint" => &[
                "frame",
                "axis",
                "mass",
                "length",
                "material",
                "expression",
                "stiffness",
            ],
            _ => &["mass"],
        };
        for field in wanted {
            if !g.junk() || g.chance(50) {
                let pool = if kind == "energy" {
                    &with_velocities
                } else {
                    &names
                };
                let value = component_field(g, field, pool, &frames);
                let _ = writeln!(doc, "{field} = {value}");
            }
        }
        if g.junk() && g.chance(20) {
            let field = g.pick(COMPONENT_FIELDS);
            let value = component_field(g, field, &names, &frames);
            let _ = writeln!(doc, "{field} = {value}");
        }
    }
    for k in 0..g.below(3) {
        let _ = writeln!(doc, "\n[[constraints]]\nname = \"g{k}\"");
        match g.below(4) {
            0 => {
                let end = |g: &mut Gen, names: &[String], frames: &[String]| {
                    format!(
                        "{{ frame = {}, position = {} }}",
                        name_value(g, frames),
                        vector(g, names)
                    )
                };
                let a = end(g, &names, &frames);
                let b = end(g, &names, &frames);
                let _ = writeln!(doc, "type = \"coincident\"\na = {a}\nb = {b}");
            }
            1 => {
                let axis = |g: &mut Gen| {
                    if g.junk() {
                        vector(g, &[])
                    } else {
                        toml_string(g.pick(&["x", "y", "z"]))
                    }
                };
                let a = format!(
                    "{{ frame = {}, axis = {} }}",
                    name_value(g, &frames),
                    axis(g)
                );
                let b = format!(
                    "{{ frame = {}, axis = {} }}",
                    name_value(g, &frames),
                    axis(g)
                );
                let _ = writeln!(doc, "type = \"perpendicular\"\na = {a}\nb = {b}");
            }
            _ => {
                let _ = writeln!(doc, "expression = {}", scalar(g, &names));
            }
        }
    }
    for k in 0..g.below(3) {
        let coordinate = name_value(g, &names);
        let _ = writeln!(
            doc,
            "\n[[actuators]]\nname = \"u{k}\"\ncoordinate = {coordinate}"
        );
        if g.chance(30) {
            let _ = writeln!(doc, "gain = {}", scalar(g, &names));
        }
    }
    doc
}

#[test]
fn generated_scenes_never_panic_the_loader_or_the_generator() {
    let accepted = std::cell::Cell::new(0u32);
    runner(10)
        .run(&any::<u64>(), |seed| {
            let text = scene_document(&mut Gen::new(seed));
            showing(&text, || {
                let (_, result) = load(&text);
                match result {
                    Err(e) => check_scene_error(&text, &e)?,
                    Ok(mut model) => {
                        accepted.set(accepted.get() + 1);
                        // A scene the loader accepts is derived and emitted,
                        // or refused with a message; never a panic.
                        match model.equations() {
                            Ok(eq) => {
                                let runtime = syn::parse_str("flexdyn_runtime").expect("a path");
                                let functions = crate::schedule::functions(&model, &eq);
                                let (emitted, _) = emit(&model, functions, &runtime, None);
                                prop_assert!(!emitted.source.is_empty());
                            }
                            Err(e) => prop_assert!(!e.message.trim().is_empty()),
                        }
                    }
                }
                Ok(())
            })
        })
        .unwrap();
    // The generator must reach the derivation, not only the error paths.
    let n = cases();
    println!("{} of {n} generated scenes accepted", accepted.get());
    assert!(
        n < 100 || accepted.get() > 0,
        "no generated scene was accepted: the generator only exercises errors"
    );
}

#[test]
fn unreadable_scene_files_are_errors_without_a_position() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("missing.toml");
    let binary = dir.path().join("binary.toml");
    std::fs::write(&binary, [0xff, 0xfe, 0x00, b'n', 0x80, b'\n']).unwrap();
    for path in [missing.as_path(), binary.as_path(), dir.path()] {
        let e = Model::load(path).unwrap_err();
        assert_eq!(e.file, path);
        assert_eq!((e.line, e.column), (0, 0), "{e}");
        assert!(e.message.starts_with("cannot read scene file"), "{e}");
    }
}

#[test]
fn a_failing_case_prints_its_input() {
    let text = "name = \"boom\"";
    for e in [
        showing(text, || panic!("non-finite constant")).unwrap_err(),
        showing(text, || Err(TestCaseError::fail("refused"))).unwrap_err(),
    ] {
        let e = e.to_string();
        assert!(e.contains("--- failing input ---\nname = \"boom\""), "{e}");
    }
    assert!(showing(text, || Ok(())).is_ok());
}
