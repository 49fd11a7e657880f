//! Imports each benchmarked robot's URDF (from example-robot-data in the
//! Pinocchio virtual environment) with flexdyn's importer into
//! `$OUT_DIR/<name>.toml` and generates its module into `$OUT_DIR/flexdyn/`;
//! loads the same URDF with Pinocchio's own parser (`dump_model.py`, in
//! Python) and writes its joints as numbers into `$OUT_DIR/robots.rs`;
//! compiles `src/shim.cpp`, which rebuilds that Pinocchio model joint by
//! joint, against Pinocchio's headers at -O3; and generates Pinocchio's
//! algorithms to C (`src/generate_c.cpp`, over `casadi::SX`, exported by
//! CasADi's `CodeGenerator`), compiled at -O3 with their table in
//! `$OUT_DIR/pinocchio_c.rs`. Pinocchio's algorithms are compiled here from
//! its templates and nothing of its prebuilt libraries is linked, so
//! `FLEXDYN_NATIVE=1` gives every side native code (the prebuilt parser,
//! compiled for SSE2, cannot fill a `-march=native` Model).
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

/// A robot compared.
struct Robot {
    /// Module name (a lower-case identifier).
    name: String,
    /// URDF: absolute, or relative to example-robot-data's `robots/` folder.
    urdf: String,
    /// Joints held fixed, as `dump_model.py` takes them: comma-separated, or
    /// `only:` and the joints that keep moving.
    locked: String,
    /// Link whose frame Jacobian is compared (a marker of the import).
    link: Option<String>,
    /// Whether the derivatives are compared (generated with
    /// `outputs = ["dynamics_derivatives"]`).
    derivatives: bool,
}

/// The robots compared by default (`FLEXDYN_BENCH_ROBOTS` unset or
/// `default` in it): name, URDF, locked joints, link, derivatives.
const DEFAULT_ROBOTS: &[(&str, &str, &str, Option<&str>, bool)] = &[
    (
        "ur5",
        "ur_description/urdf/ur5_robot.urdf",
        "",
        Some("tool0"),
        true,
    ),
    (
        "panda",
        "panda_description/urdf/panda.urdf",
        "panda_finger_joint1,panda_finger_joint2",
        Some("panda_hand"),
        true,
    ),
    // Torso, arm and head; as published (quarter turns written as
    // `1.57079632679`, 1e-6 kg antennas with inertias that are not positive
    // semi-definite).
    (
        "tiago",
        "tiago_description/robots/tiago.urdf",
        "only:torso_lift_joint,arm_1_joint,arm_2_joint,arm_3_joint,arm_4_joint,\
         arm_5_joint,arm_6_joint,arm_7_joint,head_1_joint,head_2_joint",
        None,
        false,
    ),
    // Legs on a fixed base.
    (
        "solo",
        "solo_description/robots/solo12.urdf",
        "",
        None,
        false,
    ),
    // Fixed base, grippers held: 30 joints. Its derivatives are generated
    // to C too: about 150,000 operations, some 8 minutes of gcc -O3.
    (
        "talos",
        "talos_data/robots/talos_reduced.urdf",
        "gripper_left_joint,gripper_right_joint",
        None,
        true,
    ),
];

/// The robots of `FLEXDYN_BENCH_ROBOTS`, white-space separated entries
/// `NAME=URDF[;fix=J1,J2|;only=J1,J2][;link=LINK][;derivatives]` (`default`
/// for the default five), or the default five when it is unset: any robot
/// imported from URDF as published, compared on the same terms.
fn robots() -> Vec<Robot> {
    let defaults = || {
        DEFAULT_ROBOTS
            .iter()
            .map(|&(name, urdf, locked, link, derivatives)| Robot {
                name: name.into(),
                urdf: urdf.into(),
                locked: locked.into(),
                link: link.map(String::from),
                derivatives,
            })
    };
    let Ok(list) = std::env::var("FLEXDYN_BENCH_ROBOTS") else {
        return defaults().collect();
    };
    let mut robots: Vec<Robot> = Vec::new();
    for entry in list.split_whitespace() {
        if entry == "default" {
            robots.extend(defaults());
            continue;
        }
        let bad = |why: &str| -> ! {
            fail(&format!(
                "FLEXDYN_BENCH_ROBOTS entry {entry:?}: {why} (expected \
                 NAME=URDF[;fix=J1,J2|;only=J1,J2][;link=LINK][;derivatives])"
            ))
        };
        let (name, rest) = entry.split_once('=').unwrap_or_else(|| bad("no `=`"));
        let named = name.starts_with(|c: char| c.is_ascii_lowercase())
            && name
                .chars()
                .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_');
        if !named {
            bad("NAME must be a lower-case identifier");
        }
        let mut parts = rest.split(';');
        let mut robot = Robot {
            name: name.into(),
            urdf: parts.next().unwrap_or_default().into(),
            locked: String::new(),
            link: None,
            derivatives: false,
        };
        for part in parts {
            match part.split_once('=') {
                Some(("fix", joints)) => robot.locked = joints.into(),
                Some(("only", joints)) => robot.locked = format!("only:{joints}"),
                Some(("link", link)) => robot.link = Some(link.into()),
                None if part == "derivatives" => robot.derivatives = true,
                _ => bad(&format!("unknown option {part:?}")),
            }
        }
        if robot.urdf.is_empty() {
            bad("no URDF");
        }
        robots.push(robot);
    }
    if robots.is_empty() {
        fail("FLEXDYN_BENCH_ROBOTS names no robot");
    }
    for (i, robot) in robots.iter().enumerate() {
        if robots[..i].iter().any(|r| r.name == robot.name) {
            fail(&format!(
                "FLEXDYN_BENCH_ROBOTS: robot {} named twice",
                robot.name
            ));
        }
    }
    robots
}

/// Pinocchio's functions generated to C per robot, in the order of the
/// table's fields (`benches/compare.rs`), the frame last and optional.
const C_FUNCTIONS: [&str; 8] = [
    "rnea",
    "crba_nle",
    "crba",
    "nle",
    "aba",
    "frame",
    "rnea_derivatives",
    "aba_derivatives",
];

fn main() {
    let here = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").unwrap());
    let repo = here.join("../..");
    let out = PathBuf::from(std::env::var("OUT_DIR").unwrap());
    println!("cargo:rerun-if-env-changed=FLEXDYN_PINOCCHIO_PYTHON");
    println!("cargo:rerun-if-env-changed=FLEXDYN_NATIVE");
    println!("cargo:rerun-if-env-changed=FLEXDYN_BENCH_ROBOTS");
    for file in [
        "src/shim.cpp",
        "src/model.hpp",
        "src/generate_c.cpp",
        "dump_model.py",
    ] {
        println!("cargo:rerun-if-changed={file}");
    }
    let python = std::env::var_os("FLEXDYN_PINOCCHIO_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| repo.join("target/pinocchio-venv/bin/python"));
    let site = site_packages(&python);
    let prefix = site.join("cmeel.prefix");
    let casadi = site.join("casadi");
    let robots_dir = prefix.join("share/example-robot-data/robots");
    let models = out.join("pinocchio_c");
    std::fs::create_dir_all(&models).unwrap_or_else(|e| fail(&e.to_string()));

    // The scenes are written below, from the URDFs (watched one by one):
    // watching the scene files themselves would rerun this script, and
    // rebuild the bench, on every `cargo bench`.
    let mut builder = flexdyn_codegen::Builder::new()
        .out_dir(out.join("flexdyn"))
        .emit_rerun_if_changed(false);
    let robots = robots();
    // One robot: name, joints, (coordinate, URDF joint) pairs, largest snap.
    let mut list = String::from(
        "pub type Robot = (&'static str, &'static [Joint], &'static [(&'static str, &'static str)], f64);\n\
         pub const ROBOTS: &[Robot] = &[\n",
    );
    for robot in &robots {
        let urdf = robots_dir.join(&robot.urdf);
        println!("cargo:rerun-if-changed={}", urdf.display());
        let text = std::fs::read_to_string(&urdf)
            .unwrap_or_else(|e| fail(&format!("cannot read {}: {e}", urdf.display())));
        let dump = dump_model(&python, &here.join("dump_model.py"), &urdf, robot);
        std::fs::write(models.join(format!("{}.model", robot.name)), &dump.text)
            .unwrap_or_else(|e| fail(&e.to_string()));
        let options = flexdyn_codegen::UrdfOptions {
            fix: dump.locked.clone(),
            outputs: if robot.derivatives {
                vec!["dynamics_derivatives".into()]
            } else {
                Vec::new()
            },
            ..Default::default()
        };
        let scene =
            flexdyn_codegen::import_urdf(&flexdyn_codegen::Source::new(&urdf, text), &options)
                .unwrap_or_else(|e| fail(&e.to_string()));
        // Named after the robot's module, not the URDF's `<robot name>`.
        let scene = renamed(&scene, &robot.name);
        let file = out.join(format!("{}.toml", robot.name));
        std::fs::write(&file, &scene)
            .unwrap_or_else(|e| fail(&format!("cannot write {}: {e}", file.display())));
        builder = builder.scene(file);
        list.push_str(&format!("    ({:?}, &[\n", robot.name));
        for joint in &dump.joints {
            list.push_str(&format!("        {joint},\n"));
        }
        list.push_str(&format!(
            "    ], &{:?}, {:?}),\n",
            urdf_joints(&scene),
            largest_snap(&scene)
        ));
    }
    list.push_str("];\n");
    std::fs::write(out.join("robots.rs"), list).unwrap_or_else(|e| fail(&e.to_string()));
    let report = builder.generate().unwrap_or_else(|e| fail(&e.to_string()));
    write_robot_list(&robots, &report, &out.join("robot_list.rs"));

    let native = std::env::var_os("FLEXDYN_NATIVE").is_some();
    let include = prefix.join("include");
    let shim = here.join("src/shim.cpp");
    unless_built(&out, "shim", &[shim.as_path()], &[&include], native, || {
        let mut build = pinocchio_build(&include);
        if native {
            build.flag("-march=native");
        }
        build
            .cargo_metadata(false)
            .file("src/shim.cpp")
            .compile("pinocchio_shim");
    });
    println!("cargo:rustc-link-search=native={}", out.display());
    println!("cargo:rustc-link-lib=static=pinocchio_shim");
    println!("cargo:rustc-link-lib=stdc++");
    generate_c(
        &robots,
        &include,
        &casadi,
        &models,
        native,
        &out.join("pinocchio_c.rs"),
    );
}

/// Each coordinate of an imported scene with the URDF joint it comes from:
/// the importer writes `# URDF joint "NAME"` above a coordinate whose name
/// is not the joint's (docs/urdf-import.md).
fn urdf_joints(scene: &str) -> Vec<(String, String)> {
    let mut pairs = Vec::new();
    let mut urdf = None;
    let mut in_coordinate = false;
    for line in scene.lines() {
        if line.starts_with("[[") {
            in_coordinate = line == "[[coordinates]]";
            urdf = None;
        } else if let Some(quoted) = line.strip_prefix("# URDF joint ") {
            urdf = Some(unquoted(quoted));
        } else if let (true, Some(name)) = (in_coordinate, line.strip_prefix("name = ")) {
            let name = unquoted(name);
            pairs.push((name.clone(), urdf.take().unwrap_or(name)));
        }
    }
    pairs
}

/// The largest change (rad) the import's snapping made to an angle, from
/// the scene's header (`(largest change 3.7e-6 rad; ...`), 0 if none.
fn largest_snap(scene: &str) -> f64 {
    scene
        .lines()
        .take_while(|l| l.starts_with('#'))
        .find_map(|l| {
            l.split_once("(largest change ")?
                .1
                .split_once(" rad")?
                .0
                .parse()
                .ok()
        })
        .unwrap_or(0.0)
}

/// The text of a TOML basic string (`"..."`, escapes `\"` and `\\`).
fn unquoted(s: &str) -> String {
    let inner = s.trim().trim_start_matches('"').trim_end_matches('"');
    inner.replace("\\\"", "\"").replace("\\\\", "\\")
}

/// The scene text `scene` with its name set to `name` (its first
/// `name = ...` line).
fn renamed(scene: &str, name: &str) -> String {
    let mut done = false;
    let lines: Vec<String> = scene
        .lines()
        .map(|l| {
            if !done && l.starts_with("name = ") {
                done = true;
                format!("name = {name:?}")
            } else {
                l.to_owned()
            }
        })
        .collect();
    if !done {
        fail(&format!("the imported scene of {name} has no name"));
    }
    lines.join("\n") + "\n"
}

/// `robot_list.rs`, included by `benches/compare.rs`: the flexdyn module of
/// every robot (`flexdyn_modules!`) and `robots`, which compares them all.
fn write_robot_list(robots: &[Robot], report: &flexdyn_codegen::Report, path: &Path) {
    let types: Vec<String> = robots
        .iter()
        .map(|r| {
            report
                .scenes
                .iter()
                .find(|g| g.name == r.name)
                .unwrap_or_else(|| fail(&format!("no module generated for {}", r.name)))
                .struct_name()
        })
        .collect();
    let mut text = String::from("flexdyn_modules!(");
    text += &robots
        .iter()
        .map(|r| r.name.as_str())
        .collect::<Vec<_>>()
        .join(", ");
    text += ");\n\n/// Every robot's comparisons.\nfn robots(c: &mut Criterion<ThreadCpuTime>) {\n";
    let call = |f: &str, r: &Robot, ty: &str, extra: &str| {
        format!(
            "    {f}::<{0}::{ty}, {{ {0}::NQ }}>(c, {0:?}{extra});\n",
            r.name
        )
    };
    for (r, ty) in robots.iter().zip(&types) {
        text += &call("compare", r, ty, "");
    }
    for (r, ty) in robots.iter().zip(&types).filter(|(r, _)| r.derivatives) {
        text += &call("compare_derivatives", r, ty, "");
    }
    for (r, ty) in robots.iter().zip(&types) {
        if let Some(link) = &r.link {
            text += &call("compare_marker", r, ty, &format!(", {link:?}"));
        }
    }
    text += "}\n";
    std::fs::write(path, text).unwrap_or_else(|e| fail(&e.to_string()));
}

/// Runs `build` unless the stamp `<name>.stamp` in `out` says it ran on
/// the same `sources` (and `src/model.hpp`), include folders and `native`
/// flag. The two C++ builds take minutes each and do not depend on
/// flexdyn's generator, whose every change reruns this script.
fn unless_built(
    out: &Path,
    name: &str,
    sources: &[&Path],
    includes: &[&Path],
    native: bool,
    build: impl FnOnce(),
) {
    use std::hash::{Hash, Hasher};
    let mut hasher = std::collections::hash_map::DefaultHasher::new();
    let here = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").unwrap());
    let model = here.join("src/model.hpp");
    for source in sources.iter().copied().chain([model.as_path()]) {
        std::fs::read(source)
            .unwrap_or_else(|e| fail(&format!("cannot read {}: {e}", source.display())))
            .hash(&mut hasher);
    }
    includes.hash(&mut hasher);
    native.hash(&mut hasher);
    let key = format!("{:016x}\n", hasher.finish());
    let stamp = out.join(format!("{name}.stamp"));
    if std::fs::read_to_string(&stamp).ok().as_deref() == Some(key.as_str()) {
        return;
    }
    build();
    std::fs::write(&stamp, key).unwrap_or_else(|e| fail(&e.to_string()));
}

/// A C++ build against Pinocchio's headers (and Eigen's) at -O3 with
/// Pinocchio's own compile definitions (from its CMake targets).
fn pinocchio_build(include: &Path) -> cc::Build {
    let mut build = cc::Build::new();
    build
        .cpp(true)
        .std("c++17")
        .opt_level(3)
        .warnings(false)
        .define("NDEBUG", None)
        .include(include)
        .include(include.join("eigen3"));
    for (key, value) in [
        ("BOOST_MPL_LIMIT_LIST_SIZE", Some("30")),
        ("BOOST_MPL_LIMIT_VECTOR_SIZE", Some("30")),
        ("BOOST_MPL_CFG_NO_PREPROCESSED_HEADERS", None),
        ("BOOST_FUSION_INVOKE_MAX_ARITY", Some("12")),
    ] {
        build.define(key, value);
    }
    build
}

/// Builds `src/generate_c.cpp` (linked with CasADi's library from its
/// wheel), runs it on every robot's model in `models`, compiles the C it
/// writes at -O3 (`-march=native` too when `native`) and writes the Rust
/// table of the functions (`pinocchio_c.rs`: declarations, operation
/// counts, work sizes) to `table`.
fn generate_c(
    robots: &[Robot],
    include: &Path,
    casadi: &Path,
    models: &Path,
    native: bool,
    table: &Path,
) {
    let generator = models.join("generate_c");
    let source = PathBuf::from("src/generate_c.cpp");
    unless_built(
        models,
        "generate_c",
        &[source.as_path()],
        &[include, casadi],
        false,
        || {
            // The generator runs at build time: compiled without optimisation
            // to save minutes (the code it writes is what is timed).
            let compiler = pinocchio_build(include).opt_level(0).get_compiler();
            let mut command = compiler.to_command();
            command
                .arg("-I")
                .arg(casadi.join("include"))
                .arg(&source)
                .arg("-o")
                .arg(&generator)
                .arg("-L")
                .arg(casadi)
                .arg("-lcasadi")
                .arg(format!("-Wl,-rpath,{}", casadi.display()));
            run(&mut command, "compiling src/generate_c.cpp");
        },
    );

    let mut declarations = String::new();
    let mut entries = String::new();
    for robot in robots {
        let c_file = models.join(format!("{}.c", robot.name));
        let stdout = run(
            Command::new(&generator)
                .arg(models.join(format!("{}.model", robot.name)))
                .arg(format!("pin_{}", robot.name))
                .arg(&c_file)
                .args(robot.derivatives.then_some("derivatives")),
            &format!("generating Pinocchio's C for {}", robot.name),
        );
        // The C changes only with Pinocchio's model and CasADi, not with
        // flexdyn's generator: compiled again only when its text changes
        // (TALOS's derivatives take minutes of gcc -O3), one library per
        // robot so that adding a robot compiles its C alone.
        let library = format!("pinocchio_c_{}", robot.name);
        unless_built(models, &library, &[c_file.as_path()], &[], native, || {
            let mut build = cc::Build::new();
            build.opt_level(3).warnings(false);
            if native {
                build.flag("-march=native");
            }
            build.cargo_metadata(false).file(&c_file).compile(&library);
        });
        println!("cargo:rustc-link-lib=static={library}");
        let mut fields = Vec::new();
        for function in C_FUNCTIONS {
            let symbol = format!("pin_{}_{function}", robot.name);
            let line = stdout
                .lines()
                .find(|l| l.split('\t').next() == Some(&symbol));
            let Some(line) = line else {
                fields.push(format!("{function}: None"));
                continue;
            };
            let numbers: Vec<usize> = line
                .split('\t')
                .skip(1)
                .map(|x| {
                    x.parse()
                        .unwrap_or_else(|_| fail(&format!("generate_c: {line:?}")))
                })
                .collect();
            let [operations, sz_arg, sz_res, sz_iw, sz_w] = numbers[..] else {
                fail(&format!("generate_c: {line:?}: expected 6 fields"));
            };
            writeln!(
                declarations,
                "    pub fn {symbol}(arg: *const *const f64, res: *const *mut f64, \
                 iw: *mut i64, w: *mut f64, mem: i32) -> i32;"
            )
            .unwrap();
            fields.push(format!(
                "{function}: Some(CFunction {{ call: {symbol}, operations: {operations}, \
                 sz_arg: {sz_arg}, sz_res: {sz_res}, sz_iw: {sz_iw}, sz_w: {sz_w} }})"
            ));
        }
        writeln!(
            entries,
            "    ({:?}, Generated {{ {} }}),",
            robot.name,
            fields.join(", ")
        )
        .unwrap();
    }
    let out = std::env::var("OUT_DIR").unwrap();
    println!("cargo:rustc-link-search=native={out}");
    let text = format!(
        "extern \"C\" {{\n{declarations}}}\n\
         pub const GENERATED: &[(&str, Generated)] = &[\n{entries}];\n"
    );
    std::fs::write(table, text).unwrap_or_else(|e| fail(&e.to_string()));
}

/// Runs `command`, failing the build with its standard error when it
/// fails; its standard output.
fn run(command: &mut Command, what: &str) -> String {
    let output = command
        .output()
        .unwrap_or_else(|e| fail(&format!("{what}: {e}")));
    if !output.status.success() {
        fail(&format!(
            "{what} failed: {}",
            String::from_utf8_lossy(&output.stderr).trim()
        ));
    }
    String::from_utf8_lossy(&output.stdout).into_owned()
}

/// What `dump_model.py` wrote for a robot: its text, the joints it locked
/// and one `Joint { .. }` literal (see `benches/compare.rs`) per joint.
struct Dump {
    text: String,
    locked: Vec<String>,
    joints: Vec<String>,
}

/// Pinocchio's model of `robot` (its URDF at `urdf`) from `dump_model.py`
/// run by `python`.
fn dump_model(python: &Path, script: &Path, urdf: &Path, robot: &Robot) -> Dump {
    let mut command = Command::new(python);
    command.arg(script).arg(urdf).arg(&robot.locked);
    if let Some(link) = &robot.link {
        command.arg(link);
    }
    let text = run(
        &mut command,
        &format!("{} {}", script.display(), urdf.display()),
    );
    let where_ = |line: usize| format!("{} on {}, line {line}", script.display(), urdf.display());
    let mut dump = Dump {
        text: text.clone(),
        locked: Vec::new(),
        joints: Vec::new(),
    };
    for (i, line) in text.lines().enumerate() {
        let fields: Vec<&str> = line.split('\t').collect();
        match fields[0] {
            "locked" => {
                dump.locked = fields[1..]
                    .join("")
                    .split(',')
                    .filter(|s| !s.is_empty())
                    .map(String::from)
                    .collect()
            }
            "joint" => dump
                .joints
                .push(joint_literal(&fields[1..], &where_(i + 1))),
            "frame" => {}
            other => fail(&format!("{}: unknown record {other:?}", where_(i + 1))),
        }
    }
    dump
}

/// A `Joint { .. }` literal of the fields of a `joint` record.
fn joint_literal(fields: &[&str], where_: &str) -> String {
    if fields.len() != 3 + JOINT_NUMBERS {
        fail(&format!(
            "{where_}: {} fields, expected {}",
            fields.len(),
            3 + JOINT_NUMBERS
        ));
    }
    let parent: usize = fields[2]
        .parse()
        .unwrap_or_else(|_| fail(&format!("{where_}: parent {:?} is not an index", fields[2])));
    let numbers: Vec<f64> = fields[3..]
        .iter()
        .map(|x| {
            x.parse()
                .unwrap_or_else(|_| fail(&format!("{where_}: {x:?} is not a number")))
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
}

/// Numbers per joint line of `dump_model.py`: axis 3, placement 12,
/// inertia 13, damping 1.
const JOINT_NUMBERS: usize = 29;

/// `site-packages` of the Python environment that has Pinocchio's wheel,
/// Eigen's headers (`cmeel-eigen`) and CasADi's wheel.
fn site_packages(python: &Path) -> PathBuf {
    let hint = "python3 -m venv target/pinocchio-venv && \
                target/pinocchio-venv/bin/pip install pin example-robot-data cmeel-eigen casadi \
                (or set FLEXDYN_PINOCCHIO_PYTHON)";
    let run = Command::new(python)
        .args([
            "-c",
            "import sysconfig; print(sysconfig.get_paths()['purelib'])",
        ])
        .output()
        .unwrap_or_else(|e| fail(&format!("cannot run {}: {e}; {hint}", python.display())));
    let site = PathBuf::from(String::from_utf8_lossy(&run.stdout).trim());
    for needed in [
        "cmeel.prefix/include/pinocchio",
        "cmeel.prefix/include/eigen3",
        "casadi/include/casadi",
    ] {
        if !site.join(needed).exists() {
            fail(&format!(
                "{} is missing: {hint}",
                site.join(needed).display()
            ));
        }
    }
    site
}

fn fail(message: &str) -> ! {
    eprintln!("error: {message}");
    std::process::exit(1);
}
