//! Every class of scene error names the right place: the file, the exact line
//! and column (computed here independently of the crate, from the scene text),
//! the component or constraint concerned, and a message that says what is
//! wrong.

use std::fs;
use std::path::{Path, PathBuf};

use flexdyn_codegen::{generate_scene, Builder, Error, Model, Source};

const FILE: &str = "scene.toml";

fn load(text: &str) -> Result<Model, Error> {
    Model::from_source(&Source::new(Path::new(FILE), text.to_owned()))
}

#[track_caller]
fn fail(text: &str) -> Error {
    match load(text) {
        Ok(_) => panic!("scene was accepted:\n{text}"),
        Err(e) => e,
    }
}

/// 1-based line and column (in characters) of the first `needle` on the only
/// line of `text` that contains `line_marker`.
#[track_caller]
fn locate(text: &str, line_marker: &str, needle: &str) -> (usize, usize) {
    let lines: Vec<(usize, &str)> = text
        .split('\n')
        .enumerate()
        .filter(|(_, l)| l.contains(line_marker))
        .collect();
    assert_eq!(lines.len(), 1, "`{line_marker}` must mark exactly one line");
    let (index, line) = lines[0];
    let byte = line
        .find(needle)
        .unwrap_or_else(|| panic!("`{needle}` is not on line `{line}`"));
    (index + 1, line[..byte].chars().count() + 1)
}

/// Assert an error's file, position, context and message words.
#[track_caller]
fn check(e: &Error, at: (usize, usize), context: Option<&str>, words: &[&str]) {
    assert_eq!(e.file, Path::new(FILE), "{e}");
    assert_eq!((e.line, e.column), at, "wrong position: {e}");
    assert_eq!(e.context.as_deref(), context, "wrong context: {e}");
    for w in words {
        assert!(e.message.contains(w), "message lacks `{w}`: {e}");
    }
    let shown = e.to_string();
    assert!(
        shown.starts_with(&format!("{FILE}:{}:{}: ", at.0, at.1)),
        "{shown}"
    );
}

/// A valid scene head: parameters and two coordinates, `x` and `y`.
const HEAD: &str = r#"name = "s"

[parameters]
m = 1.0
l = 0.5
k = { value = 2.0, runtime = true }

[[coordinates]]
name = "x"

[[coordinates]]
name = "y"
"#;

fn scene(rest: &str) -> String {
    format!("{HEAD}\n{rest}")
}

#[test]
fn the_head_alone_is_valid() {
    let m = load(HEAD).unwrap();
    assert_eq!(m.nq(), 2);
    let m = load(&scene(
        "[[components]]\ntype = \"point_mass\"\nmass = \"m\"\nposition = [\"x\", \"y\", 0]\n",
    ))
    .unwrap();
    assert_eq!(m.components.len(), 1);
}

// 1. Unknown fields.

#[test]
fn unknown_field_at_top_level() {
    let text = "name = \"s\"\ngravity = [0, 0, -9.81]\nbogus = 1\n[[coordinates]]\nname = \"x\"\n";
    let e = fail(text);
    check(&e, (3, 1), None, &["unknown field `bogus`", "coordinates"]);
}

#[test]
fn unknown_field_in_a_component() {
    let text =
        scene("[[components]]\ntype = \"point_mass\"\nmasss = \"m\"\nposition = [0, 0, 0]\n");
    let e = fail(&text);
    let at = locate(&text, "masss", "masss");
    check(&e, at, None, &["unknown field `masss`", "`mass`"]);
}

#[test]
fn unknown_field_in_a_coordinate() {
    let text = "name = \"s\"\n[[coordinates]]\nname = \"x\"\nrnage = [0.0, 1.0]\n";
    let e = fail(text);
    check(&e, (4, 1), None, &["unknown field `rnage`", "`range`"]);
}

#[test]
fn unknown_field_in_a_parameter_table() {
    // Inline table: the position of the misspelt key itself.
    let text = "name = \"s\"\n[parameters]\nm = 1.0\nl = { value = 0.5, runtme = true }\n\
                [[coordinates]]\nname = \"x\"\n";
    let e = fail(text);
    check(&e, (4, 20), None, &["unknown field `runtme`", "`runtime`"]);
    // Standard table.
    let text = "name = \"s\"\n[parameters.l]\nvalue = 0.5\nruntme = true\n\
                [[coordinates]]\nname = \"x\"\n";
    let e = fail(text);
    check(&e, (4, 1), None, &["unknown field `runtme`"]);
}

#[test]
fn wrong_value_types_are_named() {
    let text = scene("[[components]]\ntype = \"point_mass\"\nmass = true\nposition = [0, 0, 0]\n");
    let e = fail(&text);
    let at = locate(&text, "mass = true", "true");
    check(
        &e,
        at,
        None,
        &["boolean", "expected a number or an expression"],
    );

    let text = "name = \"s\"\n[parameters]\nm = \"abc\"\n[[coordinates]]\nname = \"x\"\n";
    let e = fail(text);
    check(
        &e,
        (3, 5),
        None,
        &["string \"abc\"", "expected a number or a table"],
    );
}

#[test]
fn toml_syntax_errors_are_located() {
    let text = "name = \"s\"\n[[coordinates]\nname = \"x\"\n";
    let e = fail(text);
    // At the lone `]`, which should have been `]]`.
    check(&e, (2, 14), None, &["invalid table header", "`]]`"]);
    // A control character in a comment: toml gives no message of its own.
    let e = fail("# a\u{1}b\nname = \"s\"\n[[coordinates]]\nname = \"x\"\n");
    check(&e, (1, 4), None, &["unexpected character '\\u{1}'"]);

    let e = fail("name = \"s\"\n[[coordinates]]\n");
    check(&e, (2, 1), None, &["missing field `name`"]);
}

// 2. Undefined symbols, located inside the expression string.

#[test]
fn undefined_symbol_is_located_inside_the_expression() {
    let text = scene(
        "[[components]]\nname = \"bob\"\ntype = \"point_mass\"\nmass = \"m\"\n\
         position = [\n  \"l*sin(x)\",\n  0,\n  \"-l*cos(zeta) + y\",\n]\n",
    );
    let e = fail(&text);
    let at = locate(&text, "zeta", "zeta");
    check(
        &e,
        at,
        Some("component `bob`"),
        &["undefined symbol `zeta`"],
    );
    // The third entry's line, 11th character: `  "-l*cos(zeta`.
    assert_eq!(at, (21, 11));
}

#[test]
fn undefined_symbol_after_escapes_and_in_multi_line_strings() {
    // Escapes in basic strings occupy more bytes in the file than in the text.
    let text = scene("[[components]]\ntype = \"energy\"\npotential = \"m*\\t\\u0078 + m*zz\"\n");
    let e = fail(&text);
    let at = locate(&text, "potential", "zz");
    check(
        &e,
        at,
        Some("component `energy0`"),
        &["undefined symbol `zz`"],
    );
    let text = scene("[[components]]\ntype = \"energy\"\npotential = \"m*\\tx + m*zz\"\n");
    let e = fail(&text);
    let at = locate(&text, "potential", "zz");
    check(
        &e,
        at,
        Some("component `energy0`"),
        &["undefined symbol `zz`"],
    );

    // A multi-line string drops the newline after its opening quotes.
    let text =
        scene("[[components]]\ntype = \"energy\"\npotential = \"\"\"\nm*x\n  + l*zz\"\"\"\n");
    let e = fail(&text);
    let at = locate(&text, "+ l*zz", "zz");
    check(
        &e,
        at,
        Some("component `energy0`"),
        &["undefined symbol `zz`"],
    );

    // ... and a line-ending backslash drops the whitespace that follows.
    let text =
        scene("[[components]]\ntype = \"energy\"\npotential = \"\"\"\nm*x + \\\n     l*zz\"\"\"\n");
    let e = fail(&text);
    let at = locate(&text, "l*zz", "zz");
    check(
        &e,
        at,
        Some("component `energy0`"),
        &["undefined symbol `zz`"],
    );

    // Literal strings have no escapes.
    let text = scene("[[components]]\ntype = \"energy\"\npotential = '''\nm*x + \\t*zz'''\n");
    let e = fail(&text);
    let at = locate(&text, "zz", "\\t");
    check(
        &e,
        at,
        Some("component `energy0`"),
        &["syntax error", "character outside the grammar"],
    );

    // Non-ASCII text before the symbol counts as one column per character.
    let text = scene("[[constraints]]\nname = \"c\"\nexpression = 'x + y*(é + zz)'\n");
    let e = fail(&text);
    let at = locate(&text, "expression", "é");
    check(&e, at, Some("constraint `c`"), &["undefined symbol `é`"]);
}

// 3. A coordinate index beyond the declared ones.

#[test]
fn undeclared_coordinate_index_points_at_the_index() {
    let text = scene("[[constraints]]\nname = \"tie\"\nexpression = \"x - 2*q[5]\"\n");
    let e = fail(&text);
    let at = locate(&text, "q[5]", "5]");
    check(
        &e,
        at,
        Some("constraint `tie`"),
        &["q[5]", "not declared", "2 coordinates"],
    );
    assert_eq!(at, (16, 23));

    let text = scene("[[components]]\ntype = \"energy\"\nkinetic = \"m*qd[0]*qd[2]\"\n");
    let e = fail(&text);
    let at = locate(&text, "kinetic", "2]");
    check(
        &e,
        at,
        Some("component `energy0`"),
        &["qd[2]", "not declared"],
    );
}

// 4. Non-finite constants.

#[test]
fn overflowing_literal_in_an_expression() {
    let text = scene("[[components]]\ntype = \"energy\"\npotential = \"m * x * 1e999\"\n");
    let e = fail(&text);
    let at = locate(&text, "1e999", "1e999");
    check(&e, at, Some("component `energy0`"), &["not finite", "inf"]);
}

#[test]
fn non_finite_parameter_values() {
    for (value, shown) in [
        ("inf", "inf"),
        ("-inf", "-inf"),
        ("nan", "NaN"),
        ("{ value = nan, runtime = true }", "NaN"),
    ] {
        let text = format!(
            "name = \"s\"\n[parameters]\nm = 1.0\nbad = {value}\n[[coordinates]]\nname = \"x\"\n"
        );
        let e = fail(&text);
        check(
            &e,
            (4, 7),
            Some("parameter `bad`"),
            &["not finite", &format!("({shown})")],
        );
    }
}

#[test]
fn non_finite_number_in_a_field() {
    let text = scene(
        "[[components]]\nname = \"p\"\ntype = \"point_mass\"\nmass = inf\nposition = [0, 0, 0]\n",
    );
    let e = fail(&text);
    let at = locate(&text, "mass = inf", "inf");
    check(
        &e,
        at,
        Some("component `p`"),
        &["number is not finite (inf)"],
    );
}

#[test]
fn division_by_a_zero_constant() {
    // `l - 0.5` folds to 0 since `l = 0.5` is a constant parameter.
    let text = scene("[[components]]\ntype = \"energy\"\npotential = \"m * x / (l - 0.5)\"\n");
    let e = fail(&text);
    let at = locate(&text, "potential", "/");
    check(&e, at, Some("component `energy0`"), &["division by zero"]);

    let text = scene("[[components]]\ntype = \"energy\"\npotential = \"m * ln(l - 0.5) * x\"\n");
    let e = fail(&text);
    let at = locate(&text, "potential", "ln");
    check(
        &e,
        at,
        Some("component `energy0`"),
        &["`ln(0)` is not finite"],
    );
}

// 5. Masses.

#[test]
fn negative_mass_for_every_massive_type() {
    let cases = [
        ("point_mass", "position = [\"x\", 0, 0]\n"),
        ("rod", "from = [0, 0, 0]\nto = [\"x\", 0, 0]\n"),
        (
            "rigid_body",
            "frame = \"body\"\ninertia = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\n",
        ),
    ];
    for (kind, fields) in cases {
        for (mass, shown) in [("-2.5", "-2.5"), ("\"m - 3\"", "-2")] {
            let text = scene(&format!(
                "[[frames]]\nname = \"body\"\ntranslation = [\"x\", 0, 0]\n\n\
                 [[components]]\nname = \"part\"\ntype = \"{kind}\"\nmass = {mass}\n{fields}"
            ));
            let e = fail(&text);
            let at = locate(&text, "mass =", mass);
            // A rigid body may be massless (a URDF link), so only negative.
            let need = match kind {
                "rigid_body" => "mass must be non-negative",
                _ => "mass must be positive",
            };
            check(
                &e,
                at,
                Some("component `part`"),
                &[need, &format!("found {shown}")],
            );
        }
    }
}

#[test]
fn zero_mass_is_rejected() {
    let text = scene(
        "[[components]]\nname = \"p\"\ntype = \"point_mass\"\nmass = 0.0\nposition = [0, 0, 0]\n",
    );
    let e = fail(&text);
    let at = locate(&text, "mass = 0.0", "0.0");
    check(
        &e,
        at,
        Some("component `p`"),
        &["mass must be positive", "found 0"],
    );
}

#[test]
fn mass_depending_on_coordinates_is_rejected() {
    let text = scene("[[components]]\nname = \"p\"\ntype = \"point_mass\"\nmass = \"m*x\"\nposition = [0, 0, 0]\n");
    let e = fail(&text);
    let at = locate(&text, "mass =", "\"m*x\"");
    check(&e, at, Some("component `p`"), &["parameters only"]);
}

#[test]
fn negative_stiffness_is_rejected() {
    let text = scene(
        "[[components]]\nname = \"s1\"\ntype = \"spring\"\nstiffness = -1\nexpression = \"x\"\n",
    );
    let e = fail(&text);
    let at = locate(&text, "stiffness", "-1");
    check(
        &e,
        at,
        Some("component `s1`"),
        &["stiffness must be non-negative"],
    );
}

// 6. Inertia tensors.

fn rigid_body(inertia: &str) -> String {
    scene(&format!(
        "[[frames]]\nname = \"link\"\nrotation = [{{ axis = \"z\", angle = \"x\" }}]\n\n\
         [[components]]\nname = \"body\"\ntype = \"rigid_body\"\nmass = \"m\"\nframe = \"link\"\n\
         inertia = {inertia}\n"
    ))
}

#[test]
fn inertia_must_be_positive_semi_definite() {
    assert!(load(&rigid_body("[[1, 0, 0], [0, 2, 0], [0, 0, 3]]")).is_ok());
    // Singular tensors: a thin rod, a point.
    assert!(load(&rigid_body("[[1, 0, 0], [0, 0, 0], [0, 0, 1]]")).is_ok());
    assert!(load(&rigid_body("[0, 0, 0]")).is_ok());
    for inertia in [
        "[[1, 0, 0], [0, 1, 0], [0, 0, -0.5]]",
        "[[1, 2, 0], [2, 1, 0], [0, 0, 1]]",
    ] {
        let text = rigid_body(inertia);
        let e = fail(&text);
        let at = locate(&text, "inertia =", "[[");
        check(
            &e,
            at,
            Some("component `body`"),
            &["inertia tensor is not positive semi-definite"],
        );
    }
}

#[test]
fn inertia_must_be_symmetric_and_3x3() {
    let text = rigid_body("[[1, 0.1, 0], [0, 1, 0], [0, 0, 1]]");
    let e = fail(&text);
    let at = locate(&text, "inertia =", "[[");
    check(
        &e,
        at,
        Some("component `body`"),
        &["inertia tensor is not symmetric"],
    );

    let text = rigid_body("[[1, 0], [0, 1]]");
    let e = fail(&text);
    check(&e, at, Some("component `body`"), &["3x3"]);
}

// 7. Velocities where only positions may appear.

#[test]
fn velocity_in_a_potential_energy() {
    let text = scene("[[components]]\nname = \"v\"\ntype = \"energy\"\nkinetic = \"0.5*m*qd[0]*qd[0]\"\npotential = \"m * x * qd[1]\"\n");
    let e = fail(&text);
    let at = locate(&text, "potential", "qd");
    check(
        &e,
        at,
        Some("component `v`"),
        &["velocities are not allowed here"],
    );
}

#[test]
fn velocity_in_a_constraint() {
    let text = scene("[[constraints]]\nname = \"c\"\nexpression = \"x - y.sin() * dot(y)\"\n");
    let e = fail(&text);
    let at = locate(&text, "expression", "dot");
    check(
        &e,
        at,
        Some("constraint `c`"),
        &["velocities are not allowed here"],
    );
}

#[test]
fn velocity_in_a_position() {
    let text = scene(
        "[[components]]\nname = \"p\"\ntype = \"point_mass\"\nmass = 1\nposition = [\"x\", \"qd[0]\", 0]\n",
    );
    let e = fail(&text);
    let at = locate(&text, "position", "qd");
    check(
        &e,
        at,
        Some("component `p`"),
        &["velocities are not allowed here"],
    );
}

// 8. Component types and their fields.

#[test]
fn unknown_component_type() {
    let text = scene("[[components]]\nname = \"sp\"\ntype = \"spring_mass\"\n");
    let e = fail(&text);
    let at = locate(&text, "spring_mass", "\"spring_mass\"");
    check(
        &e,
        at,
        Some("component `sp`"),
        &["unknown component type `spring_mass`", "point_mass"],
    );
}

#[test]
fn field_that_does_not_apply_to_the_type() {
    let text = scene(
        "[[components]]\nname = \"p\"\ntype = \"point_mass\"\nmass = 1\nposition = [0, 0, 0]\nstiffness = 3\n",
    );
    let e = fail(&text);
    let at = locate(&text, "stiffness", "3");
    check(
        &e,
        at,
        Some("component `p`"),
        &[
            "field `stiffness` does not apply to a `point_mass` component",
            "allowed: mass, position, frame",
        ],
    );
}

#[test]
fn flexible_link_fields_that_do_not_apply() {
    let text = scene(
        "[[components]]\nname = \"beam\"\ntype = \"flexible_link\"\nframe = \"world\"\nlength = 1\n\
         material = { youngs_modulus = 1e9, poisson = 0.3, density = 1000 }\n\
         section = { radius = 0.01 }\nboundary = \"clamped_free\"\nfrom = [0, 0, 0]\n",
    );
    let e = fail(&text);
    let at = locate(&text, "from", "[");
    check(
        &e,
        at,
        Some("component `beam`"),
        &[
            "field `from` does not apply to a `flexible_link` component",
            "allowed: frame, length, material, section",
        ],
    );
    // And the flexible-link fields do not apply to the other types.
    let text = scene(
        "[[components]]\nname = \"p\"\ntype = \"point_mass\"\nmass = 1\nposition = [0, 0, 0]\nmodes = 3\n",
    );
    let e = fail(&text);
    let at = locate(&text, "modes", "3");
    check(
        &e,
        at,
        Some("component `p`"),
        &["field `modes` does not apply to a `point_mass` component"],
    );
}

#[test]
fn missing_required_fields() {
    let cases = [
        ("rod", "mass = 1\nfrom = [0, 0, 0]\n", "needs `to`"),
        ("point_mass", "position = [0, 0, 0]\n", "needs `mass`"),
        ("spring", "expression = \"x\"\n", "needs `stiffness`"),
        ("damper", "damping = 1\n", "needs `expression`"),
        (
            "energy",
            "",
            "needs `kinetic`, `potential` or `dissipation`",
        ),
        (
            "rigid_body",
            "mass = 1\ninertia = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\n",
            "needs `frame`",
        ),
        (
            "rigid_body",
            "mass = 1\nframe = \"world\"\n",
            "needs `inertia`",
        ),
        (
            "flexible_link",
            "length = 1\nmaterial = { youngs_modulus = 1e9, poisson = 0.3, density = 1000 }\n\
             section = { radius = 0.01 }\nboundary = \"clamped_free\"\n",
            "needs `frame`",
        ),
        (
            "flexible_link",
            "frame = \"world\"\nlength = 1\nsection = { radius = 0.01 }\nboundary = \"clamped_free\"\n",
            "needs `material`",
        ),
        (
            "flexible_link",
            "frame = \"world\"\nlength = 1\n\
             material = { youngs_modulus = 1e9, poisson = 0.3, density = 1000 }\n\
             boundary = \"clamped_free\"\n",
            "needs `section`",
        ),
    ];
    for (kind, fields, words) in cases {
        let text = scene(&format!(
            "[[components]]\nname = \"c\"\ntype = \"{kind}\"\n{fields}"
        ));
        let e = fail(&text);
        let at = locate(&text, "type =", "\"");
        check(
            &e,
            at,
            Some("component `c`"),
            &[&format!("`{kind}` component"), words],
        );
    }
}

// 9. Frames and names.

#[test]
fn undefined_frame() {
    let text = scene("[[components]]\nname = \"p\"\ntype = \"point_mass\"\nmass = 1\nframe = \"nowhere\"\nposition = [0, 0, 0]\n");
    let e = fail(&text);
    let at = locate(&text, "nowhere", "\"nowhere\"");
    check(
        &e,
        at,
        Some("component `p`"),
        &["frame `nowhere` is not defined"],
    );
}

#[test]
fn parent_frame_must_be_defined_above() {
    let text = scene(
        "[[frames]]\nname = \"forearm\"\nparent = \"upper\"\n\n[[frames]]\nname = \"upper\"\n",
    );
    let e = fail(&text);
    let at = locate(&text, "parent", "\"upper\"");
    check(
        &e,
        at,
        Some("frame `forearm`"),
        &["frame `upper` is not defined above"],
    );
}

#[test]
fn invalid_names() {
    // A Rust keyword as a coordinate.
    let text = "name = \"s\"\n[[coordinates]]\nname = \"fn\"\n";
    check(
        &fail(text),
        (3, 8),
        None,
        &["coordinate `fn` is a reserved word"],
    );
    // A reserved name of the grammar as a parameter.
    let text = "name = \"s\"\n[parameters]\nq = 1\n[[coordinates]]\nname = \"x\"\n";
    check(
        &fail(text),
        (3, 1),
        None,
        &["parameter `q` is a reserved word"],
    );
    // Bad characters.
    let text = scene(
        "[[components]]\nname = \"arm-1\"\ntype = \"point_mass\"\nmass = 1\nposition = [0, 0, 0]\n",
    );
    let at = locate(&text, "arm-1", "\"arm-1\"");
    check(
        &fail(&text),
        at,
        None,
        &["component `arm-1` is not a valid name"],
    );
    let text = "name = \"s\"\n[[coordinates]]\nname = \"2x\"\n";
    check(
        &fail(text),
        (3, 8),
        None,
        &["coordinate `2x` is not a valid name"],
    );
    // Scene names are Rust module names.
    let text = "name = \"Scene\"\n[[coordinates]]\nname = \"x\"\n";
    check(&fail(text), (1, 8), None, &["lower case"]);
    let text = "name = \"self\"\n[[coordinates]]\nname = \"x\"\n";
    check(
        &fail(text),
        (1, 8),
        None,
        &["scene name `self` is a reserved word"],
    );
    // A frame may not be called `world`, nor be defined twice.
    let text = scene("[[frames]]\nname = \"world\"\n");
    let at = locate(&text, "\"world\"", "\"world\"");
    check(&fail(&text), at, Some("frame `world`"), &["defined twice"]);
}

#[test]
fn duplicate_coordinate() {
    let text = "name = \"s\"\n[[coordinates]]\nname = \"x\"\n[[coordinates]]\nname = \"y\"\n\
                [[coordinates]]\nname = \"x\"\n";
    let e = fail(text);
    check(&e, (7, 8), None, &["coordinate `x` is declared twice"]);
}

#[test]
fn parameter_named_like_a_coordinate() {
    let text = "name = \"s\"\n[parameters]\nx = 1\n[[coordinates]]\nname = \"x\"\n";
    check(&fail(text), (3, 1), None, &["has the name of a coordinate"]);
}

const PENDULUM: &str = r#"name = "NAME"
[parameters]
m = 1.0
l = 0.5
[[coordinates]]
name = "theta"
[[components]]
name = "bob"
type = "point_mass"
mass = "m"
position = ["l*sin(theta)", 0, "-l*cos(theta)"]
"#;

fn pendulum(name: &str) -> String {
    PENDULUM.replace("NAME", name)
}

#[test]
fn duplicate_scene_names_across_files() {
    let dir = tempfile::tempdir().unwrap();
    let out = tempfile::tempdir().unwrap();
    let a = dir.path().join("a.toml");
    let b = dir.path().join("b.toml");
    fs::write(&a, pendulum("twin")).unwrap();
    fs::write(&b, pendulum("twin")).unwrap();
    let e = Builder::new()
        .scenes_in(dir.path())
        .out_dir(out.path())
        .generate()
        .unwrap_err();
    assert_eq!(e.file, b, "{e}");
    assert!(
        e.message.contains("scene name `twin` is already used by"),
        "{e}"
    );
    assert!(e.message.contains(&a.display().to_string()), "{e}");
    assert_eq!(rs_files(out.path()), Vec::<PathBuf>::new());
}

// 10. Syntax.

#[test]
fn syntax_errors_in_expressions() {
    let text = scene("[[components]]\ntype = \"energy\"\npotential = \"m * x y\"\n");
    let e = fail(&text);
    let at = locate(&text, "potential", "y\"");
    check(
        &e,
        at,
        Some("component `energy0`"),
        &["syntax error", "unexpected token"],
    );

    // Unexpected end: just past the last token, not at the start.
    let text = scene("[[components]]\ntype = \"energy\"\npotential = \"m * x +\"\n");
    let e = fail(&text);
    let at = locate(&text, "potential", "+\"");
    check(
        &e,
        (at.0, at.1 + 1),
        Some("component `energy0`"),
        &["syntax error", "unexpected end of input"],
    );

    // Unbalanced bracket: at the bracket.
    let text = scene("[[components]]\ntype = \"energy\"\npotential = \"m * sin(x + y\"\n");
    let e = fail(&text);
    let at = locate(&text, "potential", "(");
    check(
        &e,
        at,
        Some("component `energy0`"),
        &["syntax error", "unbalanced brackets"],
    );

    // `2pi` is not two times pi (Rust reads a number with a suffix).
    let text = scene("[[components]]\ntype = \"energy\"\npotential = \"m * 2pi * x\"\n");
    let e = fail(&text);
    let at = locate(&text, "potential", "2pi");
    check(
        &e,
        at,
        Some("component `energy0`"),
        &["malformed number", "`pi`"],
    );
}

#[test]
fn caret_is_not_a_power() {
    let text = scene("[[components]]\nname = \"s\"\ntype = \"spring\"\nstiffness = 1\nexpression = \"x^2 + y\"\n");
    let e = fail(&text);
    let at = locate(&text, "expression", "^");
    check(
        &e,
        at,
        Some("component `s`"),
        &["`^` is not a power", "powi"],
    );
}

#[test]
fn unknown_function_and_bad_arity() {
    let text = scene("[[constraints]]\nname = \"c\"\nexpression = \"x + cosh(y)\"\n");
    let at = locate(&text, "expression", "cosh");
    check(
        &fail(&text),
        at,
        Some("constraint `c`"),
        &["unknown function `cosh`"],
    );
    let text = scene("[[constraints]]\nname = \"c\"\nexpression = \"x + atan2(y)\"\n");
    let at = locate(&text, "expression", "atan2");
    check(
        &fail(&text),
        at,
        Some("constraint `c`"),
        &["`atan2` takes 2 argument(s), found 1"],
    );
}

// 11. Outputs.

#[test]
fn unknown_output_name() {
    let text =
        "name = \"s\"\noutputs = [\"forces\", \"coriolis\"]\n[[coordinates]]\nname = \"x\"\n";
    let e = fail(text);
    check(
        &e,
        (2, 22),
        None,
        &["unknown output `coriolis`", "coriolis_matrix"],
    );
}

#[test]
fn coriolis_matrix_needs_a_quadratic_kinetic_energy() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("linear.toml");
    let cases = [
        ("qd[0]", "not a quadratic form in the velocities"),
        (
            "0.5*qd[0]*qd[0] + qd[0]",
            "not a quadratic form in the velocities",
        ),
        ("0.5*(1 + t)*qd[0]*qd[0]", "depends explicitly on time"),
    ];
    for (kinetic, why) in cases {
        let text = format!(
            "name = \"linear\"\noutputs = [\"coriolis_matrix\"]\n\
             [[coordinates]]\nname = \"x\"\n\
             [[components]]\nname = \"cart\"\ntype = \"energy\"\nkinetic = \"0.5*qd[0]*qd[0]\"\n\
             [[components]]\nname = \"odd\"\ntype = \"energy\"\n\
             kinetic = \"{kinetic}\"\npotential = \"x*x\"\n"
        );
        fs::write(&path, &text).unwrap();
        let e = generate_scene(&path).unwrap_err();
        assert_eq!(e.file, path, "{e}");
        assert_eq!(e.line, 0, "{e}");
        assert_eq!(
            e.context.as_deref(),
            Some("output `coriolis_matrix`"),
            "{e}"
        );
        assert!(e.message.contains(why), "{e}");
        assert!(
            e.to_string().contains("in output `coriolis_matrix`: "),
            "{e}"
        );
        // The same scene without the output generates.
        fs::write(&path, text.replace("outputs = [\"coriolis_matrix\"]\n", "")).unwrap();
        generate_scene(&path).unwrap_or_else(|e| panic!("{e}"));
    }
}

// 12. All or nothing.

fn rs_files(dir: &Path) -> Vec<PathBuf> {
    let Ok(entries) = fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut out: Vec<PathBuf> = entries
        .map(|e| e.unwrap().path())
        .filter(|p| p.to_string_lossy().contains(".rs"))
        .collect();
    out.sort();
    out
}

#[test]
fn nothing_is_written_when_one_scene_is_broken() {
    let dir = tempfile::tempdir().unwrap();
    let out = tempfile::tempdir().unwrap();
    fs::write(dir.path().join("a_good.toml"), pendulum("good")).unwrap();
    let broken = pendulum("broken").replace("\"m\"", "\"m * undefined_thing\"");
    let broken_path = dir.path().join("b_broken.toml");
    fs::write(&broken_path, &broken).unwrap();
    for out_dir in [out.path().to_path_buf(), out.path().join("not_yet")] {
        let e = Builder::new()
            .scenes_in(dir.path())
            .out_dir(&out_dir)
            .generate()
            .unwrap_err();
        assert_eq!(e.file, broken_path, "{e}");
        let at = locate(&broken, "undefined_thing", "undefined_thing");
        assert_eq!((e.line, e.column), at, "{e}");
        assert_eq!(e.context.as_deref(), Some("component `bob`"), "{e}");
        assert!(e.message.contains("undefined symbol"), "{e}");
        assert_eq!(rs_files(&out_dir), Vec::<PathBuf>::new());
    }
    assert!(!out.path().join("not_yet").exists());
}

#[test]
fn valid_scenes_are_written_once() {
    let dir = tempfile::tempdir().unwrap();
    let out = tempfile::tempdir().unwrap();
    fs::write(dir.path().join("one.toml"), pendulum("one")).unwrap();
    fs::write(
        dir.path().join("two.toml"),
        pendulum("two").replace("l = 0.5", "l = 0.75"),
    )
    .unwrap();
    let run = || {
        Builder::new()
            .scenes_in(dir.path())
            .out_dir(out.path())
            .generate()
            .unwrap()
    };
    let first = run();
    let names: Vec<&str> = first.scenes.iter().map(|s| s.name.as_str()).collect();
    assert_eq!(names, ["one", "two"]);
    let expected = vec![out.path().join("one.rs"), out.path().join("two.rs")];
    assert_eq!(first.written, expected);
    assert_eq!(rs_files(out.path()), expected);
    for (path, g) in expected.iter().zip(&first.scenes) {
        assert_eq!(fs::read_to_string(path).unwrap(), g.source);
    }
    let second = run();
    assert!(second.written.is_empty(), "{:?}", second.written);
    assert_eq!(rs_files(out.path()), expected);
    // A change to one scene rewrites that one only.
    fs::write(
        dir.path().join("two.toml"),
        pendulum("two").replace("l = 0.5", "l = 0.8"),
    )
    .unwrap();
    let third = run();
    assert_eq!(third.written, vec![out.path().join("two.rs")]);
}

#[test]
fn negative_armature_is_rejected() {
    let text = scene(
        "[[components]]\nname = \"p\"\ntype = \"point_mass\"\nmass = 1\nposition = [\"x\", 0, 0]\n\n\
         [[actuators]]\nname = \"u\"\ncoordinate = \"x\"\narmature = -0.5\n",
    );
    let e = fail(&text);
    let at = locate(&text, "armature", "-0.5");
    check(
        &e,
        at,
        Some("actuator `u`"),
        &["armature must be non-negative"],
    );
    // A valid one adds `armature qd^2 / 2` to the kinetic energy.
    let m = load(&text.replace("-0.5", "0.5")).unwrap();
    let rotor = m
        .components
        .iter()
        .find(|c| c.name == "u_armature")
        .unwrap();
    let x = m.coordinates.iter().position(|c| c.name == "x").unwrap();
    let t = m.graph.eval(&[rotor.kinetic], &|s| match s {
        flexdyn_codegen::Symbol::Qd(i) if i as usize == x => 3.0,
        _ => 0.7,
    })[0];
    assert_eq!(t, 0.5 * 0.5 * 9.0);
}
