//! Imports each benchmarked robot's URDF (from example-robot-data in the
//! Pinocchio virtual environment) with flexdyn's importer into
//! `$OUT_DIR/<name>.toml` and generates its module into `$OUT_DIR/flexdyn/`;
//! loads the same URDF with Pinocchio's own parser (`dump_model.py`, in
//! Python) and writes its joints as numbers into `$OUT_DIR/robots.rs`; and
//! compiles `src/shim.cpp`, which rebuilds that Pinocchio model joint by
//! joint, against Pinocchio's headers at -O3. Pinocchio's algorithms are
//! compiled here from its templates and nothing of its prebuilt libraries is
//! linked, so `FLEXDYN_NATIVE=1` gives both sides native code (the prebuilt
//! parser, compiled for SSE2, cannot fill a `-march=native` Model).
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
    println!("cargo:rerun-if-changed=dump_model.py");
    let python = std::env::var_os("FLEXDYN_PINOCCHIO_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| repo.join("target/pinocchio-venv/bin/python"));
    let prefix = cmeel_prefix(&python);
    let robots_dir = prefix.join("share/example-robot-data/robots");

    let mut builder = flexdyn_codegen::Builder::new()
        .out_dir(out.join("flexdyn"))
        .emit_rerun_if_changed(true);
    let mut list = String::from("pub const ROBOTS: &[(&str, &[Joint])] = &[\n");
    for (name, urdf, fixed) in ROBOTS {
        let urdf = robots_dir.join(urdf);
        let text = std::fs::read_to_string(&urdf)
            .unwrap_or_else(|e| fail(&format!("cannot read {}: {e}", urdf.display())));
        let options = flexdyn_codegen::UrdfOptions {
            fix: fixed.iter().map(|s| s.to_string()).collect(),
            outputs: vec!["dynamics_derivatives".into()],
            ..Default::default()
        };
        let scene =
            flexdyn_codegen::import_urdf(&flexdyn_codegen::Source::new(&urdf, text), &options)
                .unwrap_or_else(|e| fail(&e.to_string()));
        let file = out.join(format!("{name}.toml"));
        std::fs::write(&file, scene)
            .unwrap_or_else(|e| fail(&format!("cannot write {}: {e}", file.display())));
        builder = builder.scene(file);
        list.push_str(&format!("    ({name:?}, &[\n"));
        for joint in pinocchio_joints(&python, &here.join("dump_model.py"), &urdf, fixed) {
            list.push_str(&format!("        {joint},\n"));
        }
        list.push_str("    ]),\n");
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
        .include(include.join("eigen3"));
    // Pinocchio's own compile definitions (from its CMake targets).
    for (key, value) in [
        ("BOOST_MPL_LIMIT_LIST_SIZE", Some("30")),
        ("BOOST_MPL_LIMIT_VECTOR_SIZE", Some("30")),
        ("BOOST_MPL_CFG_NO_PREPROCESSED_HEADERS", None),
        ("BOOST_FUSION_INVOKE_MAX_ARITY", Some("12")),
    ] {
        build.define(key, value);
    }
    if std::env::var_os("FLEXDYN_NATIVE").is_some() {
        build.flag("-march=native");
    }
    build.file("src/shim.cpp").compile("pinocchio_shim");
}

/// Pinocchio's model of `urdf` with the `fixed` joints locked, one
/// `Joint { .. }` literal (see `benches/compare.rs`) per joint, from
/// `dump_model.py` run by `python`.
fn pinocchio_joints(python: &Path, script: &Path, urdf: &Path, fixed: &[&str]) -> Vec<String> {
    let run = Command::new(python)
        .arg(script)
        .arg(urdf)
        .arg(fixed.join(","))
        .output()
        .unwrap_or_else(|e| fail(&format!("cannot run {}: {e}", python.display())));
    let stderr = String::from_utf8_lossy(&run.stderr);
    if !run.status.success() {
        fail(&format!(
            "{} {} failed: {}",
            script.display(),
            urdf.display(),
            stderr.trim()
        ));
    }
    let where_ = |line: usize| format!("{} on {}, line {line}", script.display(), urdf.display());
    String::from_utf8_lossy(&run.stdout)
        .lines()
        .enumerate()
        .map(|(i, line)| {
            let fields: Vec<&str> = line.split('\t').collect();
            if fields.len() != 3 + JOINT_NUMBERS {
                fail(&format!(
                    "{}: {} fields, expected {}",
                    where_(i + 1),
                    fields.len(),
                    3 + JOINT_NUMBERS
                ));
            }
            let parent: usize = fields[2].parse().unwrap_or_else(|_| {
                fail(&format!(
                    "{}: parent {:?} is not an index",
                    where_(i + 1),
                    fields[2]
                ))
            });
            let numbers: Vec<f64> = fields[3..]
                .iter()
                .map(|x| {
                    x.parse().unwrap_or_else(|_| {
                        fail(&format!("{}: {x:?} is not a number", where_(i + 1)))
                    })
                })
                .collect();
            format!(
                "Joint {{ name: {:?}, kind: {:?}, parent: {parent}, axis: {:?}, placement: {:?}, \
                 inertia: {:?}, damping: {:?} }}",
                fields[0],
                fields[1],
                &numbers[0..3],
                &numbers[3..15],
                &numbers[15..28],
                numbers[28]
            )
        })
        .collect()
}

/// Numbers per joint line of `dump_model.py`: axis 3, placement 12,
/// inertia 13, damping 1.
const JOINT_NUMBERS: usize = 29;

/// `cmeel.prefix` of the Python environment that has Pinocchio's wheel.
fn cmeel_prefix(python: &Path) -> PathBuf {
    let hint = "python3 -m venv target/pinocchio-venv && \
                target/pinocchio-venv/bin/pip install pin example-robot-data cmeel-eigen \
                (or set FLEXDYN_PINOCCHIO_PYTHON)";
    let run = Command::new(python)
        .args([
            "-c",
            "import sysconfig; print(sysconfig.get_paths()['purelib'])",
        ])
        .output()
        .unwrap_or_else(|e| fail(&format!("cannot run {}: {e}; {hint}", python.display())));
    let site = String::from_utf8_lossy(&run.stdout).trim().to_string();
    let prefix = PathBuf::from(site).join("cmeel.prefix");
    for needed in ["include/pinocchio", "include/eigen3"] {
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
