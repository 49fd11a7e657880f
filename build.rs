//! Regenerates the equations of every scene in `scenes/` into `$OUT_DIR`.
fn main() {
    let result = flexdyn_codegen::Builder::new()
        .scenes_in("scenes")
        .emit_rerun_if_changed(true)
        .index(
            "scenes.rs",
            "crate::dynamic::DynModel",
            "crate::dynamic::erase",
        )
        .generate();
    if let Err(e) = result {
        eprintln!("error: {e}");
        std::process::exit(1);
    }
}
