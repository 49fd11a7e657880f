//! Imports each benchmarked robot's URDF (from example-robot-data in the
//! Pinocchio virtual environment) with flexdyn's importer into
//! `$OUT_DIR/<name>.toml`, generates its module into `$OUT_DIR/flexdyn/`, and
//! compiles `src/shim.cpp` against Pinocchio's headers at -O3 (Pinocchio's
//! algorithms are compiled here from its templates, not taken from its
//! prebuilt library, so `FLEXDYN_NATIVE=1` gives both sides native code).
//! `$OUT_DIR/robots.rs` lists the URDF paths and the joints each side locks.
use std::path::{Path, PathBuf};
use std::process::Command;

/// Robots compared: module name, URDF relative to example-robot-data's
/// `robots/` folder, joints held fixed (the Panda's fingers: arm only).
const ROBOTS: &[(&str, &str, &[&str])] = &[
    ("ur5", "ur_description/urdf/ur5_robot.urdf", &[]),
    (
        "panda",
        "panda_description/urdf/panda.urdf",
        &["panda_finger_joint1", "panda_finger_joint2"],
    ),
];

fn main() {
    let here = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").unwrap());
    let repo = here.join("../..");
    let out = PathBuf::from(std::env::var("OUT_DIR").unwrap());
    println!("cargo:rerun-if-env-changed=FLEXDYN_PINOCCHIO_PYTHON");
    println!("cargo:rerun-if-env-changed=FLEXDYN_NATIVE");
    println!("cargo:rerun-if-changed=src/shim.cpp");
    let python = std::env::var_os("FLEXDYN_PINOCCHIO_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| repo.join("target/pinocchio-venv/bin/python"));
    let prefix = cmeel_prefix(&python);
    let robots_dir = prefix.join("share/example-robot-data/robots");

    let mut builder = flexdyn_codegen::Builder::new()
        .out_dir(out.join("flexdyn"))
        .emit_rerun_if_changed(true);
    let mut list = String::from("pub const ROBOTS: &[(&str, &str, &str)] = &[\n");
    for (name, urdf, fixed) in ROBOTS {
        let urdf = robots_dir.join(urdf);
        let text = std::fs::read_to_string(&urdf)
            .unwrap_or_else(|e| fail(&format!("cannot read {}: {e}", urdf.display())));
        let options = flexdyn_codegen::UrdfOptions {
            fix: fixed.iter().map(|s| s.to_string()).collect(),
        };
        let scene =
            flexdyn_codegen::import_urdf(&flexdyn_codegen::Source::new(&urdf, text), &options)
                .unwrap_or_else(|e| fail(&e.to_string()));
        let file = out.join(format!("{name}.toml"));
        std::fs::write(&file, scene)
            .unwrap_or_else(|e| fail(&format!("cannot write {}: {e}", file.display())));
        builder = builder.scene(file);
        list.push_str(&format!(
            "    ({name:?}, {:?}, {:?}),\n",
            urdf.display().to_string(),
            fixed.join(",")
        ));
    }
    list.push_str("];\n");
    std::fs::write(out.join("robots.rs"), list).unwrap_or_else(|e| fail(&e.to_string()));
    builder.generate().unwrap_or_else(|e| fail(&e.to_string()));

    let include = prefix.join("include");
    let mut build = cc::Build::new();
    build
        .cpp(true)
        .std("c++17")
        .opt_level(3)
        .warnings(false)
        .define("NDEBUG", None)
        .include(&include)
        .include(include.join("eigen3"))
        .include(include.join("urdfdom_headers"))
        .include(include.join("urdfdom"));
    // Pinocchio's own compile definitions (from its CMake targets).
    for (key, value) in [
        ("BOOST_MPL_LIMIT_LIST_SIZE", Some("30")),
        ("BOOST_MPL_LIMIT_VECTOR_SIZE", Some("30")),
        ("BOOST_MPL_CFG_NO_PREPROCESSED_HEADERS", None),
        ("BOOST_FUSION_INVOKE_MAX_ARITY", Some("12")),
        ("PINOCCHIO_WITH_URDFDOM", None),
        ("PINOCCHIO_URDFDOM_HEADERS_MAJOR_VERSION", Some("3")),
        ("PINOCCHIO_URDFDOM_HEADERS_MINOR_VERSION", Some("0")),
        ("PINOCCHIO_URDFDOM_HEADERS_PATCH_VERSION", Some("0")),
    ] {
        build.define(key, value);
    }
    if std::env::var_os("FLEXDYN_NATIVE").is_some() {
        build.flag("-march=native");
    }
    build.file("src/shim.cpp").compile("pinocchio_shim");
    let lib = prefix.join("lib");
    println!("cargo:rustc-link-search=native={}", lib.display());
    println!("cargo:rustc-link-arg=-Wl,-rpath,{}", lib.display());
    for l in [
        "pinocchio_parsers",
        "pinocchio_default",
        "urdfdom_model",
        "console_bridge",
        "tinyxml2",
    ] {
        println!("cargo:rustc-link-lib=dylib={l}");
    }
}

/// `cmeel.prefix` of the Python environment that has Pinocchio's wheel.
fn cmeel_prefix(python: &Path) -> PathBuf {
    let hint = "python3 -m venv target/pinocchio-venv && \
                target/pinocchio-venv/bin/pip install pin example-robot-data cmeel-eigen \
                cmeel-urdfdom-headers (or set FLEXDYN_PINOCCHIO_PYTHON)";
    let run = Command::new(python)
        .args([
            "-c",
            "import sysconfig; print(sysconfig.get_paths()['purelib'])",
        ])
        .output()
        .unwrap_or_else(|e| fail(&format!("cannot run {}: {e}; {hint}", python.display())));
    let site = String::from_utf8_lossy(&run.stdout).trim().to_string();
    let prefix = PathBuf::from(site).join("cmeel.prefix");
    for needed in [
        "include/pinocchio",
        "include/eigen3",
        "include/urdfdom_headers",
    ] {
        if !prefix.join(needed).exists() {
            fail(&format!(
                "{} is missing: {hint}",
                prefix.join(needed).display()
            ));
        }
    }
    prefix
}

fn fail(message: &str) -> ! {
    eprintln!("error: {message}");
    std::process::exit(1);
}
