//! Precision as a generation option: the scene key `precision` (`f64` by
//! default, `f32`, anything else an error at the value), the builder's
//! override, what an f32 module looks like, and the combinations that cannot
//! work (the C interface and the index module need f64 models).

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
