//! Generates each benchmarked scene's flexdyn module into `$OUT_DIR/flexdyn/`,
//! exports the scene, has CasADi generate C for its `M`, `h`,
//! `Phi_q` and `gamma` (tests/casadi/codegen_c.py, CSE on), and compiles
//! that C at -O3 with the `cc` crate. CasADi's arithmetic operation counts
//! go to `$OUT_DIR/casadi_ops.rs`.
use std::path::PathBuf;
use std::process::Command;

/// Scenes compared: name and scene file, relative to the repository root.
const SCENES: &[(&str, &str)] = &[
    ("slider_crank", "scenes/slider_crank.toml"),
    ("five_bar", "scenes/five_bar.toml"),
    (
        "parallel_robot_rigid",
        "examples/parallel-robot/scenes/parallel_robot_rigid.toml",
    ),
];

fn main() {
    let here = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").unwrap());
    let repo = here.join("../..");
    let out = PathBuf::from(std::env::var("OUT_DIR").unwrap());
    let python = std::env::var_os("FLEXDYN_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| repo.join("target/casadi-venv/bin/python"));
    if !python.exists() {
        fail(&format!(
            "no Python with CasADi at {}: run `cargo test --release --test casadi_validation` \
             once (it creates that environment) or set FLEXDYN_PYTHON",
            python.display()
        ));
    }
    let script = repo.join("tests/casadi/codegen_c.py");
    println!("cargo:rerun-if-changed={}", script.display());
    println!(
        "cargo:rerun-if-changed={}",
        repo.join("tests/casadi/validate.py").display()
    );
    println!("cargo:rerun-if-env-changed=FLEXDYN_PYTHON");
    let mut ops = String::new();
    let mut build = cc::Build::new();
    build.opt_level(3).warnings(false);
    SCENES
        .iter()
        .fold(flexdyn_codegen::Builder::new(), |b, (_, file)| {
            b.scene(repo.join(file))
        })
        .out_dir(out.join("flexdyn"))
        .emit_rerun_if_changed(true)
        .generate()
        .unwrap_or_else(|e| fail(&e.to_string()));
    for (name, file) in SCENES {
        let scene = repo.join(file);
        let model =
            flexdyn_codegen::Model::load(&scene).unwrap_or_else(|e| fail(&e.to_string()));
        let export = out.join(format!("{name}.json"));
        std::fs::write(&export, flexdyn_codegen::export_json(&model))
            .unwrap_or_else(|e| fail(&format!("cannot write {}: {e}", export.display())));
        let run = Command::new(&python)
            .arg(&script)
            .arg(&export)
            .arg(&out)
            .arg(name)
            .output()
            .unwrap_or_else(|e| fail(&format!("cannot run {}: {e}", python.display())));
        if !run.status.success() {
            fail(&format!(
                "CasADi code generation failed for {name}:\n{}",
                String::from_utf8_lossy(&run.stderr)
            ));
        }
        let line = String::from_utf8_lossy(&run.stdout);
        let total = json_number(&line, "\"total\": ")
            .unwrap_or_else(|| fail(&format!("no op count in `{line}`")));
        let calls = json_number(&line, "\"call\": ").unwrap_or(0);
        ops.push_str(&format!(
            "pub const {}: (u64, u64) = ({total}, {calls});\n",
            name.to_uppercase()
        ));
        build.file(out.join(format!("{name}.c")));
    }
    build.compile("casadi_terms");
    std::fs::write(out.join("casadi_ops.rs"), ops).unwrap_or_else(|e| fail(&e.to_string()));
}

fn json_number(line: &str, key: &str) -> Option<u64> {
    let rest = &line[line.find(key)? + key.len()..];
    let end = rest
        .find(|c: char| !c.is_ascii_digit())
        .unwrap_or(rest.len());
    rest[..end].parse().ok()
}

fn fail(message: &str) -> ! {
    eprintln!("error: {message}");
    std::process::exit(1)
}
