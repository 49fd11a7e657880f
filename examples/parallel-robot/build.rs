//! Regenerates the equations of every robot scene in `scenes/` (the rigid
//! robot and its flexible variants) into `$OUT_DIR`, and a test-only copy of
//! the rigid robot with one emitted coefficient of its mass matrix perturbed
//! by 1e-6 (relative), which `parallel-robot eval --perturbed` evaluates and
//! the CasADi validation must reject (`tests/casadi_validation.rs`).
use flexdyn_codegen::Builder;

fn main() {
    let out = std::path::PathBuf::from(std::env::var_os("OUT_DIR").unwrap_or_default());
    let index = |b: Builder| {
        b.index(
            "scenes.rs",
            "flexdyn::dynamic::DynModel",
            "flexdyn::dynamic::erase",
        )
    };
    let result = index(
        Builder::new()
            .scenes_in("scenes")
            .emit_rerun_if_changed(true),
    )
    .generate()
    .and_then(|_| {
        index(Builder::new())
            .scene("scenes/parallel_robot_rigid.toml")
            .perturb_coefficient("parallel_robot_rigid", "mass_matrix", 0, 1e-6)
            .out_dir(out.join("perturbed"))
            .generate()
    });
    if let Err(e) = result {
        eprintln!("error: {e}");
        std::process::exit(1);
    }
}
