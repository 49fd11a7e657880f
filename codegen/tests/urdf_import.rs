//! `import_urdf`: the scene a URDF becomes, checked against scenes written
//! by hand (one `rigid_body` per link on its own frame: the generator's own
//! energies, independent of the importer's merging of fixed links), and
//! its errors on bad input. The comparison with Pinocchio on real robots is
//! `tests/pinocchio_validation.rs` in the root crate.

use std::path::Path;

#[path = "common/energies.rs"]
mod common;

use common::energies;
use flexdyn_codegen::{import_urdf, Error, Model, Source, Symbol, UrdfOptions};

fn import(urdf: &str) -> Result<String, Error> {
    import_with(urdf, &[])
}

fn import_with(urdf: &str, fix: &[&str]) -> Result<String, Error> {
    let options = UrdfOptions {
        fix: fix.iter().map(|s| s.to_string()).collect(),
        ..Default::default()
    };
    import_urdf(
        &Source::new(Path::new("robot.urdf"), urdf.to_owned()),
        &options,
    )
}

fn load(text: &str) -> Model {
    Model::from_source(&Source::new(Path::new("scene.toml"), text.to_owned()))
        .unwrap_or_else(|e| panic!("{e}\n{text}"))
}

fn assert_same_energies(a: &Model, b: &Model, n: usize) {
    for k in 0..25 {
        let x = k as f64;
        let q: Vec<f64> = (0..n).map(|i| (0.7 * x + i as f64).sin() * 2.0).collect();
        let qd: Vec<f64> = (0..n).map(|i| (1.3 * x - i as f64).cos() * 3.0).collect();
        let (ta, va) = energies(a, &q, &qd, &[]);
        let (tb, vb) = energies(b, &q, &qd, &[]);
        assert!(
            (ta - tb).abs() <= 1e-12 * tb.abs().max(1.0),
            "T {ta} vs {tb}"
        );
        assert!(
            (va - vb).abs() <= 1e-12 * vb.abs().max(1.0),
            "V {va} vs {vb}"
        );
    }
}

/// A revolute joint, a prismatic joint, and a fixed child carrying a
/// rotated inertial; a massless link and a point-like link.
const ARM: &str = r#"<?xml version="1.0"?>
<robot name="Test-Arm">
  <link name="world"/>
  <link name="base">
    <inertial><mass value="3"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial>
  </link>
  <link name="upper">
    <inertial>
      <origin xyz="0.1 0.02 0.3" rpy="0.3 -0.2 0.5"/>
      <mass value="2.5"/>
      <inertia ixx="0.04" ixy="0.001" ixz="-0.002" iyy="0.05" iyz="0.003" izz="0.02"/>
    </inertial>
  </link>
  <link name="tool">
    <inertial>
      <origin xyz="0 0.05 0.1" rpy="1.5707963267948966 0 0.4"/>
      <mass value="0.7"/>
      <inertia ixx="0.002" ixy="0" ixz="0" iyy="0.003" iyz="0" izz="0.004"/>
    </inertial>
  </link>
  <link name="slider">
    <inertial><mass value="0.4"/><inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial>
  </link>
  <link name="sensor"/>
  <joint name="anchor" type="fixed">
    <parent link="world"/><child link="base"/>
    <origin xyz="0 0 0.5"/>
  </joint>
  <joint name="shoulder" type="revolute">
    <parent link="base"/><child link="upper"/>
    <origin xyz="0 0 0.2" rpy="0 1.5707963267948966 0"/>
    <axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" velocity="3" effort="10"/>
    <dynamics damping="0.5"/>
  </joint>
  <joint name="tool-mount" type="fixed">
    <parent link="upper"/><child link="tool"/>
    <origin xyz="0.05 0 0.4" rpy="0.2 0.1 -3.141592653589793"/>
  </joint>
  <joint name="slide" type="prismatic">
    <parent link="upper"/><child link="slider"/>
    <origin xyz="0 0.1 0.2" rpy="-1.5707963267948966 0 0"/>
    <axis xyz="0 0.6 0.8"/>
    <limit lower="0" upper="0.3" velocity="1"/>
  </joint>
  <joint name="sensor_mount" type="fixed">
    <parent link="slider"/><child link="sensor"/>
    <axis xyz="0 0 0"/>
  </joint>
</robot>
"#;

/// The same arm by hand: one rigid body per link on its own frame.
const ARM_BY_HAND: &str = r#"name = "by_hand"
gravity = [0, 0, -9.81]
[[coordinates]]
name = "shoulder"
[[coordinates]]
name = "slide"
[[frames]]
name = "base"
translation = [0, 0, 0.5]
[[frames]]
name = "upper"
parent = "base"
translation = [0, 0, 0.2]
rotation = [{ axis = "y", angle = "pi/2" }, { axis = "y", angle = "shoulder" }]
[[frames]]
name = "tool"
parent = "upper"
translation = [0.05, 0, 0.4]
rotation = [{ axis = "z", angle = "-pi" }, { axis = "y", angle = 0.1 }, { axis = "x", angle = 0.2 }]
[[frames]]
name = "slide_origin"
parent = "upper"
translation = [0, 0.1, 0.2]
rotation = [{ axis = "x", angle = "-pi/2" }]
[[frames]]
name = "slider"
parent = "slide_origin"
translation = [0, "0.6*slide", "0.8*slide"]
[[components]]
type = "rigid_body"
frame = "upper"
mass = 2.5
position = [0.1, 0.02, 0.3]
inertia = [[0.04, 0.001, -0.002], [0.001, 0.05, 0.003], [-0.002, 0.003, 0.02]]
inertia_rpy = [0.3, -0.2, 0.5]
[[components]]
type = "rigid_body"
frame = "tool"
mass = 0.7
position = [0, 0.05, 0.1]
inertia = [0.002, 0.003, 0.004]
inertia_rpy = ["pi/2", 0, 0.4]
[[components]]
type = "point_mass"
frame = "slider"
mass = 0.4
position = [0, 0, 0]
[[components]]
type = "damper"
damping = 0.5
expression = "shoulder"
"#;

#[test]
fn imported_arm_has_the_energies_of_one_body_per_link() {
    let text = import(ARM).unwrap_or_else(|e| panic!("{e}"));
    let imported = load(&text);
    let by_hand = load(ARM_BY_HAND);
    assert_eq!(imported.nq(), 2);
    assert_same_energies(&imported, &by_hand, 2);
    // The damper: the same dissipation.
    let d = |m: &Model| {
        let ids: Vec<_> = m.components.iter().map(|c| c.dissipation).collect();
        m.graph
            .eval(&ids, &|s| if s == Symbol::Qd(0) { 1.7 } else { 0.3 })
            .iter()
            .sum::<f64>()
    };
    assert!((d(&imported) - d(&by_hand)).abs() < 1e-15);
    // Limits and names.
    assert!(text.contains("name = \"test_arm\""), "{text}");
    assert!(text.contains("range = [-2.0, 2.0]"), "{text}");
    assert!(text.contains("velocity_range = [-1.0, 1.0]"), "{text}");
    assert!(text.contains("# fixed joint \"tool-mount\""), "{text}");
}

#[test]
fn a_held_joint_merges_its_child_like_a_fixed_one() {
    let held = import_with(ARM, &["slide"]).unwrap_or_else(|e| panic!("{e}"));
    let fixed = import(&ARM.replace(
        r#"<joint name="slide" type="prismatic">"#,
        r#"<joint name="slide" type="fixed">"#,
    ))
    .unwrap_or_else(|e| panic!("{e}"));
    let (a, b) = (load(&held), load(&fixed));
    assert_eq!(a.nq(), 1);
    assert_same_energies(&a, &b, 1);
    // Three massive links merged into one body: the merged tensor, not the
    // per-link one, is in the file.
    assert!(fixed.contains("inertias combined"), "{fixed}");
}

#[test]
fn rotations_by_multiples_of_half_pi_leave_no_round_off() {
    let text = import(ARM).unwrap_or_else(|e| panic!("{e}"));
    let model = load(&text);
    let ids: Vec<_> = model
        .components
        .iter()
        .flat_map(|c| [c.kinetic, c.potential])
        .collect();
    for id in model.graph.reachable(&ids) {
        if let Some(c) = model.graph.as_const(id) {
            assert!(
                c == 0.0 || c.abs() > 1e-14,
                "constant {c:e} in the energies"
            );
        }
        if let flexdyn_codegen::Node::Sum(terms, k) = model.graph.node(id) {
            for c in terms.iter().map(|t| t.1.get()).chain([k.get()]) {
                assert!(
                    c == 0.0 || c.abs() > 1e-14,
                    "coefficient {c:e} in the energies"
                );
            }
        }
    }
}

fn error(urdf: &str) -> String {
    match import(urdf) {
        Ok(text) => panic!("imported:\n{text}"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn bad_urdf_is_refused_naming_the_element() {
    let cases: &[(&str, &str, &str)] = &[
        ("<robot name='a'><link name='x'>", "", "malformed XML"),
        ("<model/>", "", "not <robot>"),
        (
            ARM,
            r#"<link name="sensor"/>"#,
            "link `sensor` is defined twice",
        ),
        (
            ARM,
            r#"name="sensor_mount" type="fixed""#,
            "unknown joint type `weld`",
        ),
        (
            ARM,
            r#"name="shoulder" type="revolute""#,
            "floating joints are not supported",
        ),
        (ARM, r#"<mass value="2.5"/>"#, "negative mass"),
        (ARM, r#"ixx="0.04""#, "not positive semi-definite"),
        (ARM, r#"xyz="0.05 0 0.4""#, "at most 1e9"),
        (ARM, r#"<child link="sensor"/>"#, "`nowhere` is not defined"),
        (ARM, r#"<parent link="world"/>"#, "cycle"),
        (
            ARM,
            r#"<joint name="slide""#,
            "joint `sensor_mount` is defined twice",
        ),
    ];
    let replacements = [
        "",
        "",
        r#"<link name="sensor"/><link name="sensor"/>"#,
        r#"name="sensor_mount" type="weld""#,
        r#"name="shoulder" type="floating""#,
        r#"<mass value="-2.5"/>"#,
        r#"ixx="-0.04""#,
        r#"xyz="0.05 0 4e12""#,
        r#"<child link="nowhere"/>"#,
        r#"<parent link="sensor"/>"#,
        r#"<joint name="sensor_mount""#,
    ];
    for ((urdf, from, want), to) in cases.iter().zip(replacements) {
        let text = if from.is_empty() {
            urdf.to_string()
        } else {
            assert!(urdf.contains(from), "{from}");
            urdf.replacen(from, to, 1)
        };
        let e = error(&text);
        assert!(e.contains(want), "expected `{want}`, got: {e}");
        assert!(e.contains("robot.urdf"), "{e}");
    }
    // The line of the element.
    let e = error(&ARM.replacen(r#"<mass value="2.5"/>"#, r#"<mass value="-2.5"/>"#, 1));
    assert!(e.contains("robot.urdf:10:"), "{e}");
    assert!(
        import_with(ARM, &["elbow"])
            .unwrap_err()
            .to_string()
            .contains("`elbow`"),
        "an unknown joint to hold is named"
    );
}

#[test]
fn massless_and_point_like_rigid_bodies_are_accepted() {
    let scene = |body: &str| {
        format!(
            "name = \"m\"\n[[coordinates]]\nname = \"a\"\n[[frames]]\nname = \"f\"\n\
             rotation = [{{ axis = \"z\", angle = \"a\" }}]\n[[components]]\ntype = \"rigid_body\"\n\
             frame = \"f\"\n{body}\n[[components]]\ntype = \"point_mass\"\nframe = \"f\"\nmass = 1\n\
             position = [1, 0, 0]\n"
        )
    };
    load(&scene("mass = 0\ninertia = [0, 0, 0]"));
    load(&scene(
        "mass = 2\nposition = [0.5, 0, 0]\ninertia = [0, 0, 0]",
    ));
    let bad = Model::from_source(&Source::new(
        Path::new("scene.toml"),
        scene("mass = 2\ninertia = [1, -1, 1]"),
    ))
    .unwrap_err()
    .to_string();
    assert!(bad.contains("not positive semi-definite"), "{bad}");
    let bad = Model::from_source(&Source::new(
        Path::new("scene.toml"),
        scene("mass = 2\ninertia = [[1, 0], [0, 1]]"),
    ))
    .unwrap_err()
    .to_string();
    assert!(bad.contains("diagonal"), "{bad}");
}

#[test]
fn names_cannot_escape_into_the_scene_text() {
    // A newline (a character reference survives XML attribute
    // normalisation) in every name that reaches the scene.
    let hostile = ARM
        .replace("name=\"Test-Arm\"", "name=\"a&#10;gravity = [0, 0, 1]\"")
        .replace(
            "name=\"shoulder\"",
            "name=\"s&#10;[[constraints]]&#10;expression = &quot;x&quot;\"",
        )
        .replace("name=\"tool-mount\"", "name=\"m&#10;name = 1\"");
    let text = import(&hostile).unwrap_or_else(|e| panic!("{e}"));
    assert!(!text.contains("\ngravity = [0, 0, 1]"), "{text}");
    assert!(!text.contains("\n[[constraints]]"), "{text}");
    let model = load(&text);
    assert_eq!(model.nq(), 2);
    assert!(model.constraints.is_empty());
}

#[test]
fn angles_within_their_written_precision_of_a_multiple_of_pi_over_twelve_are_snapped() {
    let urdf = ARM
        .replace(
            r#"rpy="0 1.5707963267948966 0""#,
            r#"rpy="0 1.57079632679 3.1415926""#,
        )
        .replace(
            r#"rpy="-1.5707963267948966 0 0""#,
            r#"rpy="-1.570796325 1.57 5.4949E-05""#,
        )
        .replace(
            r#"<origin xyz="0 0 0.5"/>"#,
            r#"<origin xyz="0 0 0.5" rpy="-1.67685e-15 -1.86264e-08 0"/>"#,
        );
    let snapped = import(&urdf).unwrap();
    // Written to 1e-11 and 1e-7 (truncated): pi/2 and pi exactly.
    assert!(
        snapped.contains("angle = 1.5707963267948966 }"),
        "{snapped}"
    );
    assert!(snapped.contains("angle = 3.141592653589793 }"), "{snapped}");
    // 1.8e-9 from pi/2 but written to 1e-9; 8e-4 from pi/2 (beyond 1e-5);
    // 5.5e-5 and 1.9e-8 from zero written to finer digits: as written.
    for kept in ["-1.570796325", "angle = 1.57 ", "5.4949e-5", "-1.86264e-8"] {
        assert!(snapped.contains(kept), "{kept} kept in\n{snapped}");
    }
    // 1.7e-15 from zero, below 1e-12 rad: zero, however written.
    assert!(!snapped.contains("1.67685"), "{snapped}");
    assert!(
        snapped.contains("# 3 rpy angles agreeing with a multiple of pi/12"),
        "{snapped}"
    );
    assert!(snapped.contains("largest change 5.4e-8 rad"), "{snapped}");
    let options = UrdfOptions {
        keep_angles: true,
        ..Default::default()
    };
    let kept = import_urdf(&Source::new(Path::new("robot.urdf"), urdf), &options).unwrap();
    assert!(kept.contains("angle = 1.57079632679 }"), "{kept}");
    assert!(kept.contains("angle = 3.1415926 }"), "{kept}");
    assert!(!kept.contains("pi/12"), "{kept}");
    load(&snapped);
    load(&kept);
}

#[test]
fn round_off_of_zero_in_axes_and_origins_is_zero() {
    let noisy = ARM
        .replace(r#"<axis xyz="0 1 0"/>"#, r#"<axis xyz="0 1 6.12323e-17"/>"#)
        .replace(
            r#"<origin xyz="0 0 0.2" rpy="0 1.5707963267948966 0"/>"#,
            r#"<origin xyz="0 -1.36916e-17 0.2" rpy="0 1.5707963267948966 0"/>"#,
        );
    assert_ne!(noisy, ARM);
    let uncommented = |s: &str| -> String {
        s.lines()
            .filter(|l| !l.starts_with('#'))
            .collect::<Vec<_>>()
            .join("\n")
    };
    let snapped = import(&noisy).unwrap();
    // The same scene as the exact file's: a turn about `y`, no tiny terms.
    assert_eq!(uncommented(&snapped), uncommented(&import(ARM).unwrap()));
    assert!(
        snapped.contains("# 2 axis components and origin coordinates within 1e-12 of zero"),
        "{snapped}"
    );
    // Kept as written on request, and where it is not round-off (1e-9 of
    // the axis).
    let options = UrdfOptions {
        keep_angles: true,
        ..Default::default()
    };
    let kept = import_urdf(&Source::new(Path::new("robot.urdf"), noisy), &options).unwrap();
    assert!(
        kept.contains("6.12323e-17") && kept.contains("-1.36916e-17"),
        "{kept}"
    );
    let tilted = ARM.replace(r#"<axis xyz="0 1 0"/>"#, r#"<axis xyz="0 1 1e-9"/>"#);
    assert!(import(&tilted).unwrap().contains("1e-9"));
    load(&snapped);
}

#[test]
fn an_unphysical_inertia_is_accepted_only_where_no_energy_depends_on_it() {
    // The base is fixed to the world: it carries no energy (as TIAGo's
    // 1e-6 kg antennas, whose tensors are not positive semi-definite).
    let base = ARM.replacen(
        r#"<inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/>"#,
        r#"<inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="-1e-8"/>"#,
        1,
    );
    let scene = import(&base).unwrap();
    assert!(
        scene.contains("base (its inertia tensor is not physical)"),
        "{scene}"
    );
    load(&scene);
    // The tool is merged into the upper arm: its own tensor slightly off,
    // the combined one physical.
    let tool = ARM.replacen(
        r#"<inertia ixx="0.002" ixy="0" ixz="0" iyy="0.003" iyz="0" izz="0.004"/>"#,
        r#"<inertia ixx="0.002" ixy="0" ixz="0" iyy="0.003" iyz="0" izz="-1e-6"/>"#,
        1,
    );
    let scene = import(&tool).unwrap();
    assert!(
        scene.contains("# link \"tool\"'s own inertia tensor is not physical (the inertia")
            && scene.contains("# the combined one is physical")
            && !scene.contains("allow_unphysical_inertia"),
        "{scene}"
    );
    load(&scene);
    // Far off, the combined body is not physical either: refused at the
    // tool's <inertia>.
    let e = import(&tool.replacen(r#"izz="-1e-6""#, r#"izz="-1""#, 1))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("robot.urdf:18:")
            && e.contains("link `tool`")
            && e.contains("so is the body it is merged into (upper, tool)"),
        "{e}"
    );
}

/// One revolute joint about `z`, its child link of 0.5 kg with its centre
/// of mass at `com`, the tensor `inertia` (`ixx="..." ... izz="..."`) and
/// the joint's `limit`: the tensor is on line 7, the limit on line 13.
fn one_joint(inertia: &str, com: &str, limit: &str) -> String {
    format!(
        r#"<robot name="r">
  <link name="base"/>
  <link name="arm">
    <inertial>
      <origin xyz="{com}"/>
      <mass value="0.5"/>
      <inertia {inertia}/>
    </inertial>
  </link>
  <joint name="j" type="revolute">
    <parent link="base"/><child link="arm"/>
    <axis xyz="0 0 1"/>
    <limit {limit}/>
  </joint>
</robot>
"#
    )
}

/// `M` of a one-coordinate scene: twice its kinetic energy at `qd = 1`.
fn one_mass(scene: &str) -> f64 {
    2.0 * energies(&load(scene), &[0.3], &[1.0], &[]).0
}

const LIMIT: &str = r#"lower="-2" upper="2" velocity="3" effort="1""#;

#[test]
fn a_tensor_that_breaks_the_triangle_inequality_imports_as_published() {
    // As Romeo's arm links: positive semi-definite, no mass distribution's.
    let text = one_joint(
        r#"ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.0065""#,
        "0.1 0 0",
        LIMIT,
    );
    let scene = import(&text).unwrap_or_else(|e| panic!("{e}"));
    assert!(
        scene.contains("allow_unphysical_inertia = true")
            && scene.contains("breaks the triangle inequality")
            && scene.contains("kept as published"),
        "{scene}"
    );
    // `izz + m |c|^2` about the joint's axis: the tensor as written.
    let want = 0.0065 + 0.5 * 0.1 * 0.1;
    assert!((one_mass(&scene) - want).abs() < 1e-15 * want, "{scene}");
    // Without the flag the scene is refused, and the error names the flag.
    let bare = scene.replace("allow_unphysical_inertia = true\n", "");
    let e = Model::from_source(&Source::new(Path::new("scene.toml"), bare))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("triangle inequality") && e.contains("allow_unphysical_inertia"),
        "{e}"
    );
}

#[test]
fn rounding_noise_in_a_tensor_is_zero_next_to_the_body() {
    // iCub's head: only `ixz` written, at 2.4e-35; 0.5 kg 0.11 m off.
    let noise = r#"ixx="0" ixy="0" ixz="2.40741e-35" iyy="0" iyz="0" izz="0""#;
    let scene =
        import(&one_joint(noise, "0.0185 -0.1108 0", LIMIT)).unwrap_or_else(|e| panic!("{e}"));
    assert!(!scene.contains("allow_unphysical_inertia"), "{scene}");
    let want = 0.5 * (0.0185f64.powi(2) + 0.1108f64.powi(2));
    assert!((one_mass(&scene) - want).abs() < 1e-15 * want);
    // At the frame's origin the body has no other scale: the same tensor is
    // then refused, at its `<inertia>`.
    let e = error(&one_joint(noise, "0 0 0", LIMIT));
    assert!(
        e.contains("robot.urdf:7:") && e.contains("not positive semi-definite"),
        "{e}"
    );
}

#[test]
fn an_indefinite_tensor_on_a_moving_link_is_refused_where_it_is_written() {
    let text = one_joint(
        r#"ixx="0.003" ixy="0.004" ixz="0" iyy="0.001" iyz="0" izz="0.002""#,
        "0.1 0 0",
        LIMIT,
    );
    let e = error(&text);
    assert!(
        e.contains("robot.urdf:7:")
            && e.contains("link `arm`")
            && e.contains("not positive semi-definite"),
        "{e}"
    );
}

#[test]
fn limits_beyond_any_scale_mean_no_limit() {
    let inertia = r#"ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001""#;
    // As the Iris quadrotor's rotors: `1e+16` for "no limit".
    let scene = import(&one_joint(
        inertia,
        "0 0 0",
        r#"lower="-1e+16" upper="1e+16" velocity="1e16" effort="0""#,
    ))
    .unwrap_or_else(|e| panic!("{e}"));
    assert!(
        !scene.contains("range = ") && !scene.contains("velocity_range"),
        "{scene}"
    );
    let scene = import(&one_joint(inertia, "0 0 0", LIMIT)).unwrap();
    assert!(scene.contains("range = [-2"), "{scene}");
    // Not a number is still an error, where it is written.
    let e = error(&one_joint(inertia, "0 0 0", r#"lower="nan" upper="1""#));
    assert!(e.contains("robot.urdf:13:") && e.contains("`lower`"), "{e}");
}
