//! Hostile URDF never panics the importer: random byte mutations of a valid
//! robot description (a tree with revolute, continuous, prismatic and fixed
//! joints, rotated inertials, a massless link) either import or give an
//! error whose position exists in the text; and whatever imports is a scene
//! the loader accepts. Same runner, seed and case count
//! (`FLEXDYN_FUZZ_CASES`) as the scene fuzzing ([`super::parser_fuzz`]).

use std::path::Path;

use proptest::prelude::*;

use super::parser_fuzz::{mutate, mutation, runner, showing};
use crate::error::Source;
use crate::import::{import_urdf, UrdfOptions};
use crate::model::Model;

const ROBOT: &str = r#"<?xml version="1.0"?>
<robot name="fuzz">
  <link name="base"/>
  <link name="a">
    <inertial>
      <origin xyz="0.1 0 0.2" rpy="0 1.5707963267948966 0"/>
      <mass value="2"/>
      <inertia ixx="0.1" ixy="0.01" ixz="0" iyy="0.2" iyz="0" izz="0.3"/>
    </inertial>
  </link>
  <link name="b">
    <inertial><mass value="1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>
  </link>
  <link name="c">
    <inertial><mass value="0.5"/><inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial>
  </link>
  <link name="tip"/>
  <joint name="j1" type="revolute">
    <parent link="base"/><child link="a"/>
    <origin xyz="0 0 0.3" rpy="0 0 3.141592653589793"/>
    <axis xyz="0 0 1"/>
    <limit lower="-2" upper="2" velocity="3" effort="1"/>
    <dynamics damping="0.1"/>
  </joint>
  <joint name="j2" type="continuous">
    <parent link="a"/><child link="b"/>
    <origin xyz="0.4 0 0" rpy="-1.5707963267948966 0 0"/>
    <axis xyz="0 1 0"/>
  </joint>
  <joint name="j3" type="prismatic">
    <parent link="b"/><child link="c"/>
    <axis xyz="1 0 0"/>
    <limit lower="0" upper="0.2" velocity="1" effort="1"/>
  </joint>
  <joint name="j4" type="fixed">
    <parent link="c"/><child link="tip"/>
    <origin xyz="0 0 0.1"/>
  </joint>
</robot>
"#;

fn import(text: &str) -> Result<String, crate::error::Error> {
    import_urdf(
        &Source::new(Path::new("fuzz.urdf"), text.to_owned()),
        &UrdfOptions::default(),
    )
}

#[test]
fn the_seed_robot_imports() {
    let scene = import(ROBOT).unwrap_or_else(|e| panic!("{e}"));
    let model = Model::from_source(&Source::new(Path::new("fuzz.toml"), scene))
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(model.nq(), 3);
}

#[test]
fn mutated_urdf_never_panics_and_imports_load() {
    let input = proptest::collection::vec(mutation(), 1..4);
    runner(21)
        .run(&input, |mutations| {
            let text = mutate(ROBOT, &mutations);
            showing(&text, || {
                match import(&text) {
                    Ok(scene) => {
                        let loaded =
                            Model::from_source(&Source::new(Path::new("fuzz.toml"), scene.clone()));
                        prop_assert!(loaded.is_ok(), "{:?}\n{}", loaded.err(), scene);
                    }
                    Err(e) => {
                        prop_assert!(!e.message.trim().is_empty());
                        prop_assert_eq!(e.file.as_path(), Path::new("fuzz.urdf"));
                        let lines = text.split('\n').count();
                        prop_assert!(e.line <= lines, "line past the end: {}", e);
                    }
                }
                Ok(())
            })
        })
        .unwrap();
}
