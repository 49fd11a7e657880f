//! Issue 8: command-line misuse of `flexdyn`. Every bad invocation fails
//! with a non-zero exit status and a clear one-line error on stderr (no
//! panic, no usage dump for a value that parsed), and leaves no output file
//! behind, partial or complete. (The parallel-robot example's
//! `tests/cli_misuse.rs` covers its `inverse` and `simulate`.)

#[path = "common/cli.rs"]
mod cli;

use cli::{p, refused};

const BIN: &str = env!("CARGO_BIN_EXE_flexdyn");

#[test]
fn generate_and_export_refuse_missing_and_bad_files() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = p(d, "out");
    refused(
        d,
        &[],
        &["generate", "--scene", "scenes/none.toml", "--out", &out],
        "cannot read scene file",
    );
    // One bad scene among good ones: nothing at all is written.
    std::fs::write(
        d.join("bad.toml"),
        "name = \"bad\"\n[[coordinates]]\nname = 1\n",
    )
    .unwrap();
    refused(
        d,
        &["bad.toml"],
        &[
            "generate",
            "--scene",
            "scenes/pendulum.toml",
            "--scene",
            &p(d, "bad.toml"),
            "--out",
            &out,
        ],
        "bad.toml:3:",
    );
    // Output directory that is a file.
    std::fs::write(d.join("file"), "x").unwrap();
    refused(
        d,
        &["bad.toml", "file"],
        &[
            "generate",
            "--scene",
            "scenes/pendulum.toml",
            "--out",
            &p(d, "file"),
        ],
        "file",
    );
    refused(
        d,
        &["bad.toml", "file"],
        &[
            "export",
            "--scene",
            "scenes/none.toml",
            "--out",
            &p(d, "e.json"),
        ],
        "cannot read scene file",
    );
    refused(
        d,
        &["bad.toml", "file"],
        &[
            "export",
            "--scene",
            "scenes/pendulum.toml",
            "--out",
            &p(d, "no/e.json"),
        ],
        "cannot write",
    );
    refused(
        d,
        &["bad.toml", "file"],
        &[
            "export",
            "--scene",
            "scenes/pendulum.toml",
            "--out",
            &p(d, ""),
        ],
        "cannot write",
    );
}

#[test]
fn eval_refuses_bad_state_files() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let states = p(d, "s.json");
    let out = p(d, "ev.json");
    let eval = [
        "eval",
        "--scene",
        "scenes/pendulum.toml",
        "--states",
        &states,
        "--out",
        &out,
    ];
    refused(d, &[], &eval, "cannot read");
    let cases: [(&[u8], &str); 7] = [
        (b"\xff\xfe{", "cannot read"),
        (b"{\"states\": [", "s.json"),
        (
            b"{\"states\": [{\"q\": [NaN], \"qd\": [0], \"t\": 0}]}",
            "s.json",
        ),
        (
            b"{\"states\": [{\"q\": [1e999], \"qd\": [0], \"t\": 0}]}",
            "out of range",
        ),
        (
            b"{\"states\": [{\"q\": [1, 2], \"qd\": [0], \"t\": 0}]}",
            "has 1 coordinates",
        ),
        (
            b"{\"states\": [{\"q\": [1], \"qd\": [0], \"t\": 0, \"params\": {\"zz\": 1}}]}",
            "no runtime parameter `zz`",
        ),
        (b"{\"stats\": []}", "s.json"),
    ];
    for (text, needle) in cases {
        std::fs::write(&states, text).unwrap();
        refused(d, &["s.json"], &eval, needle);
    }
    // A scene that is not compiled into the binary is interpreted, and
    // its states checked against it.
    std::fs::write(&states, "{\"states\": [{\"q\": [1, 2], \"qd\": [0, 0]}]}").unwrap();
    std::fs::write(
        d.join("other.toml"),
        "name = \"other\"\n[[coordinates]]\nname = \"x\"\n\
         [[components]]\nname = \"m\"\ntype = \"point_mass\"\nmass = 1\n\
         position = [\"x\", 0, 0]\n",
    )
    .unwrap();
    refused(
        d,
        &["s.json", "other.toml"],
        &[
            "eval",
            "--scene",
            &p(d, "other.toml"),
            "--states",
            &states,
            "--out",
            &out,
        ],
        "state 0: scene `other` has 1 coordinates, got 2 positions and 2 velocities",
    );
}

#[test]
fn import_refuses_bad_urdf_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = p(d, "robot.toml");
    let urdf = |name: &str, text: &str| {
        std::fs::write(d.join(name), text).unwrap();
        p(d, name)
    };
    refused(
        d,
        &[],
        &["import", "urdf", &p(d, "none.urdf"), "--out", &out],
        "cannot read",
    );
    let bad = urdf(
        "bad.urdf",
        "<robot name=\"r\">\n  <link name=\"a\">\n</robot>\n",
    );
    refused(
        d,
        &["bad.urdf"],
        &["import", "urdf", &bad, "--out", &out],
        "bad.urdf:3:",
    );
    let floating = urdf(
        "floating.urdf",
        "<robot name=\"r\">\n<link name=\"a\"/><link name=\"b\"/>\n\
         <joint name=\"free\" type=\"floating\"><parent link=\"a\"/><child link=\"b\"/></joint>\n\
         </robot>\n",
    );
    refused(
        d,
        &["bad.urdf", "floating.urdf"],
        &["import", "urdf", &floating, "--out", &out],
        "joint `free`: floating joints are not supported",
    );
}

/// A scene whose coordinate `b` turns a massless body: its mass matrix is
/// singular at every state.
const MASSLESS: &str = "name = \"massless\"\n[[coordinates]]\nname = \"a\"\n\
    [[coordinates]]\nname = \"b\"\n\
    [[frames]]\nname = \"f\"\nrotation = [{ axis = \"z\", angle = \"a\" }]\n\
    [[frames]]\nname = \"g\"\nparent = \"f\"\ntranslation = [1, 0, 0]\n\
    rotation = [{ axis = \"y\", angle = \"b\" }]\n\
    [[components]]\ntype = \"rigid_body\"\nframe = \"f\"\nmass = 1\ninertia = [1, 1, 1]\n\
    [[components]]\ntype = \"rigid_body\"\nframe = \"g\"\nmass = 0\ninertia = [0, 0, 0]\n";

#[test]
fn simulate_names_a_coordinate_that_moves_no_mass() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("massless.toml"), MASSLESS).unwrap();
    // (simulate prints its integrator first, so not `refused`.)
    let (code, err) = cli::run(&[
        "simulate",
        "--scene",
        &p(d, "massless.toml"),
        "--duration",
        "0.1",
        "--csv",
        &p(d, "out.csv"),
        "--quiet",
    ]);
    assert_eq!(code, Some(1), "{err}");
    assert!(
        err.contains("error: ") && err.contains("coordinate `b`: no mass or inertia"),
        "{err}"
    );
    assert!(!err.contains("panicked"), "{err}");
    assert!(!d.join("out.csv").exists());
}

#[test]
fn linearize_names_a_coordinate_that_moves_no_mass() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = MASSLESS.replacen('\n', "\noutputs = [\"dynamics_derivatives\"]\n", 1);
    std::fs::write(d.join("massless.toml"), scene).unwrap();
    std::fs::write(d.join("state.json"), r#"{"q": [0.1, 0.2], "qd": [0, 0]}"#).unwrap();
    refused(
        d,
        &["massless.toml", "state.json"],
        &[
            "linearize",
            "--scene",
            &p(d, "massless.toml"),
            "--state",
            &p(d, "state.json"),
            "--out",
            &p(d, "out.json"),
        ],
        "coordinate `b`: no mass or inertia",
    );
}

/// `eval` of a scene without forward dynamics writes every other term, and
/// says at each state why the forward dynamics are left out.
#[test]
fn eval_leaves_out_the_forward_dynamics_of_a_coordinate_that_moves_no_mass() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("massless.toml"), MASSLESS).unwrap();
    std::fs::write(
        d.join("states.json"),
        r#"{"states": [{"q": [0.1, 0.2], "qd": [0.3, 0.4], "t": 0}, {"q": [1, 2], "qd": [0, 0], "t": 0}]}"#,
    )
    .unwrap();
    let (code, err) = cli::run(&[
        "eval",
        "--scene",
        &p(d, "massless.toml"),
        "--states",
        &p(d, "states.json"),
        "--out",
        &p(d, "out.json"),
    ]);
    assert_eq!(code, Some(0), "{err}");
    assert!(
        err.contains("warning: the forward dynamics are left out at 2 of 2 states"),
        "{err}"
    );
    let out: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("out.json")).unwrap()).unwrap();
    for r in out["results"].as_array().unwrap() {
        assert!(r.get("forward_dynamics").is_none(), "{r}");
        let why = r["forward_dynamics_error"].as_str().unwrap();
        assert!(why.contains("coordinate `b`: no mass or inertia"), "{why}");
        // The mass matrix is there, with `b`'s row zero.
        assert_eq!(r["mass_matrix"][1], serde_json::json!([0.0, 0.0]), "{r}");
        assert!(r["mass_matrix"][0][0].as_f64().unwrap() > 0.0, "{r}");
    }
}

/// The URDF import names the joints that move no mass (a massless finger).
#[test]
fn import_notes_joints_that_move_no_mass() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let link = |name: &str, mass: f64| {
        format!(
            "<link name=\"{name}\"><inertial><mass value=\"{mass}\"/>\
             <inertia ixx=\"{mass}\" ixy=\"0\" ixz=\"0\" iyy=\"{mass}\" iyz=\"0\" izz=\"{mass}\"/>\
             </inertial></link>"
        )
    };
    let joint = |name: &str, parent: &str, child: &str| {
        format!(
            "<joint name=\"{name}\" type=\"revolute\"><parent link=\"{parent}\"/>\
             <child link=\"{child}\"/><origin xyz=\"0.1 0 0\"/><axis xyz=\"0 0 1\"/>\
             <limit lower=\"-1\" upper=\"1\" effort=\"1\" velocity=\"1\"/></joint>"
        )
    };
    let urdf = format!(
        "<robot name=\"hand\">{}{}{}{}{}</robot>",
        link("base", 1.0),
        link("palm", 1.0),
        link("finger", 0.0),
        joint("wrist", "base", "palm"),
        joint("knuckle", "palm", "finger"),
    );
    std::fs::write(d.join("hand.urdf"), urdf).unwrap();
    let (code, err) = cli::run(&[
        "import",
        "urdf",
        &p(d, "hand.urdf"),
        "--out",
        &p(d, "hand.toml"),
    ]);
    assert_eq!(code, Some(0), "{err}");
    assert!(
        err.contains("note: 1 of the 2 coordinates move no mass or inertia (`knuckle`)"),
        "{err}"
    );
    // Held fixed, the finger is part of the palm: nothing to note.
    let (code, err) = cli::run(&[
        "import",
        "urdf",
        &p(d, "hand.urdf"),
        "--fix",
        "knuckle",
        "--out",
        &p(d, "held.toml"),
    ]);
    assert_eq!(code, Some(0), "{err}");
    assert!(!err.contains("note"), "{err}");
}
