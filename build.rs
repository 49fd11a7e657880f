//! Regenerates the equations of every scene in `scenes/` into `$OUT_DIR`,
//! and test-only copies of the pendulum, of a small-scale pendulum
//! (`tests/casadi/small_pendulum.toml`), of the four-bar (its marker's
//! Jacobian) and of the cart-pole (its inverse-dynamics derivatives) with one
//! emitted coefficient perturbed by 1e-6 (relative),
//! which `flexdyn eval --perturbed` evaluates and the CasADi validation must
//! reject (`tests/casadi_validation.rs`).
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
            // Coefficient 5 of the four-bar's marker_jacobian is the -1 of
            // `jacobian[(0, 0)] = -sin(th1)`: only the marker's Jacobian is
            // wrong (its position and rotation, computed by the same
            // program, stay right).
            .scene("scenes/four_bar.toml")
            .perturb_coefficient("four_bar", "marker_jacobian", 5, 1e-6)
            // Coefficient 12 of the cart-pole's inverse_dynamics_derivatives
            // is the second -0.05 of `tau_q[(0, 1)]`: only `d tau/dq` is
            // wrong (the forward dynamics' derivatives have their own
            // program).
            .scene("scenes/cart_pole.toml")
            .perturb_coefficient("cart_pole", "inverse_dynamics_derivatives", 12, 1e-6)
            // Coefficient 51 of the double pendulum's
            // forward_dynamics_derivatives is in a sum read only by
            // `d qdd/dqd` (perturbing each coefficient of its tape in turn:
            // 50 to 53 and 63 to 66 change entries of `d qdd/dqd` alone).
            .scene("scenes/double_pendulum.toml")
            .perturb_coefficient("double_pendulum", "forward_dynamics_derivatives", 51, 1e-6)
            .out_dir(out.join("perturbed"))
            .generate()
    });
    if let Err(e) = result {
        eprintln!("error: {e}");
        std::process::exit(1);
    }
}
