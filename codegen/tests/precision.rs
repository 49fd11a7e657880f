//! Precision as a generation option: the scene key `precision` (`f64` by
//! default, `f32`, anything else an error at the value), the builder's
//! override, what an f32 module looks like, the combinations that cannot
//! work (the C interface and the index module need f64 models), and the
//! refusal of f32 for scenes whose stiffness spread f32 does not resolve.

use std::path::{Path, PathBuf};

use flexdyn_codegen::{Builder, Model, Precision, Source};

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

const SCENE: &str = "name = \"p\"\n[[coordinates]]\nname = \"a\"\n\
    [[components]]\nname = \"bob\"\ntype = \"point_mass\"\nmass = 2\n\
    position = [\"0.5*sin(a)\", 0, \"-0.5*cos(a)\"]\n";

fn load(text: &str) -> Result<Model, flexdyn_codegen::Error> {
    Model::from_source(&Source::new(Path::new("scene.toml"), text.to_owned()))
}

#[test]
fn the_scene_key_sets_the_precision() {
    assert_eq!(load(SCENE).unwrap().precision, Precision::F64);
    for (value, p) in [("f64", Precision::F64), ("f32", Precision::F32)] {
        let text = format!("precision = \"{value}\"\n{SCENE}");
        assert_eq!(load(&text).unwrap().precision, p);
    }
    let e = load(&format!("precision = \"f16\"\n{SCENE}")).unwrap_err();
    assert_eq!((e.line, e.column), (1, 13), "{e}");
    assert!(
        e.message
            .contains("unknown precision `f16` (known: f64, f32)"),
        "{e}"
    );
}

#[test]
fn an_f32_module_implements_the_f32_model_trait_and_the_builder_overrides_the_scene() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("p.toml");
    std::fs::write(&scene, format!("precision = \"f32\"\n{SCENE}")).unwrap();
    let f32 = Builder::new()
        .scene(&scene)
        .out_dir(dir.path().join("a"))
        .generate()
        .unwrap();
    let src = &f32.scenes[0].source;
    assert_eq!(f32.scenes[0].precision, Precision::F32);
    assert!(
        src.contains("use flexdyn_runtime::math::f32 as math;"),
        "{src}"
    );
    assert!(
        src.contains("impl flexdyn_runtime::Model<1, 0, 0, f32> for P {"),
        "{src}"
    );
    for piece in [
        "fn mass_matrix(",
        "_q: &SVector<f32, 1>,",
        "_t: f32,",
        "m: &mut SMatrix<f32, 1, 1>,",
    ] {
        assert!(src.contains(piece), "no `{piece}` in {src}");
    }
    let code: Vec<&str> = src.lines().filter(|l| !l.starts_with("//")).collect();
    assert!(!code.iter().any(|l| l.contains("f64")), "{src}");
    let f64 = Builder::new()
        .scene(&scene)
        .precision(Precision::F64)
        .out_dir(dir.path().join("b"))
        .generate()
        .unwrap();
    assert!(f64.scenes[0]
        .source
        .contains("impl flexdyn_runtime::Model<1, 0, 0> for P {"));
    // The f64 module of a scene without the key is the f64 override's.
    std::fs::write(&scene, SCENE).unwrap();
    let plain = Builder::new()
        .scene(&scene)
        .out_dir(dir.path().join("c"))
        .generate()
        .unwrap();
    assert_eq!(plain.scenes[0].source, f64.scenes[0].source);
}

#[test]
fn the_c_interface_and_the_index_refuse_f32_models() {
    let dir = tempfile::tempdir().unwrap();
    let pendulum = workspace().join("scenes/pendulum.toml");
    let e = Builder::new()
        .scene(&pendulum)
        .precision(Precision::F32)
        .c_interface(true)
        .out_dir(dir.path())
        .generate()
        .unwrap_err();
    assert!(
        e.to_string()
            .contains("the C interface is generated for f64 models only"),
        "{e}"
    );
    let e = Builder::new()
        .scene(&pendulum)
        .precision(Precision::F32)
        .index("index.rs", "crate::Dyn", "crate::erase")
        .out_dir(dir.path())
        .generate()
        .unwrap_err();
    assert!(
        e.to_string().contains(
            "scene `pendulum` is generated in f32: the index module `index.rs` needs f64 models"
        ),
        "{e}"
    );
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        0,
        "nothing is written"
    );
}

/// Two decoupled oscillators: `a` (mass 1, spring 1: `w^2 = 1`) and `b`
/// (mass 4, spring `k`: `w^2 = k / 4`), so the stiffness spread is `k / 4`.
fn two_oscillators(k: f64) -> String {
    format!(
        "name = \"two_oscillators\"\nprecision = \"f32\"\n\
         [[coordinates]]\nname = \"a\"\n[[coordinates]]\nname = \"b\"\n\
         [[components]]\nname = \"m1\"\ntype = \"point_mass\"\nmass = 1\nposition = [\"a\", 0, 0]\n\
         [[components]]\nname = \"m2\"\ntype = \"point_mass\"\nmass = 4\nposition = [\"b\", 0, 0]\n\
         [[components]]\nname = \"s1\"\ntype = \"spring\"\nstiffness = 1\nexpression = \"a\"\n\
         [[components]]\nname = \"s2\"\ntype = \"spring\"\nstiffness = {k:e}\nexpression = \"b\"\n"
    )
}

#[test]
fn f32_is_refused_where_the_stiffness_spread_exceeds_its_resolution() {
    let dir = tempfile::tempdir().unwrap();
    let generate = |scene: &Path, allow: bool| {
        Builder::new()
            .scene(scene)
            .precision(Precision::F32)
            .allow_unresolved_f32(allow)
            .out_dir(dir.path())
            .generate()
    };
    // Closed form: the spread is k / 4; f32's limit is 1 / eps = 8.389e6.
    let scene = dir.path().join("two_oscillators.toml");
    std::fs::write(&scene, two_oscillators(4e6)).unwrap();
    generate(&scene, false).unwrap_or_else(|e| panic!("spread 1e6: {e}"));
    std::fs::write(&scene, two_oscillators(4e8)).unwrap();
    let message = generate(&scene, false).unwrap_err().to_string();
    for part in [
        "in precision: scene `two_oscillators` cannot be computed in f32",
        "stiffness spread",
        "is 1.000e8",
        "stiffest mode at 1.000e8 1/s^2 (mostly b",
        "softest at 1.000e0 1/s^2 (mostly a",
        "limit 1/eps = 8.389e6",
        "Generate it in f64",
        "Builder::allow_unresolved_f32(true)",
    ] {
        assert!(message.contains(part), "`{part}` not in: {message}");
    }
    // The flexible parallel robot (its flexible joints at 1.8e10 1/s^2
    // against the rigid-body motion under gravity) is refused; the rigid
    // robot and the spin-up beam are not; the override generates it.
    let flexible = workspace().join("examples/parallel-robot/scenes/parallel_robot_flexible.toml");
    let message = generate(&flexible, false).unwrap_err().to_string();
    for part in [
        "scene `parallel_robot_flexible` cannot be computed in f32",
        "stiffest mode at 1.778e10 1/s^2 (mostly th",
        "limit 1/eps = 8.389e6",
    ] {
        assert!(message.contains(part), "`{part}` not in: {message}");
    }
    assert!(!dir.path().join("parallel_robot_flexible.rs").exists());
    for scene in [
        "examples/parallel-robot/scenes/parallel_robot_rigid.toml",
        "scenes/spin_up_beam.toml",
    ] {
        generate(&workspace().join(scene), false).unwrap_or_else(|e| panic!("{scene}: {e}"));
    }
    generate(&flexible, true).unwrap_or_else(|e| panic!("with the override: {e}"));
    assert!(dir.path().join("parallel_robot_flexible.rs").exists());
}
