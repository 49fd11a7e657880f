//! Regenerates the equations of every scene in `scenes/` into `$OUT_DIR`,
//! and test-only copies of the pendulum and of a small-scale pendulum
//! (`tests/casadi/small_pendulum.toml`) with one emitted coefficient
//! perturbed by 1e-6 (relative), which `flexdyn eval --perturbed` evaluates
//! and the CasADi validation must reject (`tests/casadi_validation.rs`).
use flexdyn_codegen::Builder;

fn main() {
    let out = std::path::PathBuf::from(std::env::var_os("OUT_DIR").unwrap_or_default());
    let index = |b: Builder| {
        b.index(
            "scenes.rs",
            "crate::dynamic::DynModel",
            "crate::dynamic::erase",
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
            .scene("scenes/pendulum.toml")
            .perturb_coefficient("pendulum", "bias", 0, 1e-6)
            .scene("tests/casadi/small_pendulum.toml")
            .perturb_coefficient("small_pendulum", "bias", 0, 1e-6)
            .out_dir(out.join("perturbed"))
            .generate()
    });
    if let Err(e) = result {
        eprintln!("error: {e}");
        std::process::exit(1);
    }
}
