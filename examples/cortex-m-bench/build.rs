//! Generates the flexible parallel robot
//! (`examples/parallel-robot/scenes/parallel_robot_flexible.toml`) into
//! `$OUT_DIR/f64` and, with `precision = f32`, into `$OUT_DIR/f32`, for the
//! tests `f32_models` and `flexible_robot_servo_f32` (the modules are too
//! large to check in twice). Its stiffness spread is beyond what f32
//! resolves, so the generator refuses it in f32 by default; these tests
//! measure what f32 makes of it, hence the explicit opt-in.
use flexdyn_codegen::{Builder, Precision};

const SCENE: &str = "../parallel-robot/scenes/parallel_robot_flexible.toml";

fn main() {
    let out = std::path::PathBuf::from(std::env::var_os("OUT_DIR").unwrap_or_default());
    let result = Builder::new()
        .scene(SCENE)
        .emit_rerun_if_changed(true)
        .out_dir(out.join("f64"))
        .generate()
        .and_then(|_| {
            Builder::new()
                .scene(SCENE)
                .precision(Precision::F32)
                .allow_unresolved_f32(true)
                .out_dir(out.join("f32"))
                .generate()
        });
    if let Err(e) = result {
        eprintln!("error: {e}");
        std::process::exit(1);
    }
}
