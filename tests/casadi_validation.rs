//! Every generated term of every scene in `scenes/`, validated against
//! CasADi's automatic differentiation through `flexdyn export` and
//! `flexdyn eval` (see `common/casadi.rs` and `docs/export-format.md`), plus
//! negative runs proving that a perturbed coefficient of the pendulum, of
//! a pendulum at a small scale (`tests/casadi/small_pendulum.toml`), of
//! the four-bar's marker Jacobian, of the cart-pole's inverse-dynamics
//! derivatives and of the double pendulum's forward-dynamics derivatives
//! is caught. The robot scenes are validated the same way by
//! `examples/parallel-robot/tests/casadi_validation.rs`.

#[path = "common/casadi.rs"]
mod casadi;
#[path = "common/python_env.rs"]
mod python_env;

#[test]
fn casadi_validates_every_term_of_every_scene() {
    let repo = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    casadi::validate_every_scene(&casadi::Suite {
        scenes: repo.join("scenes"),
        repo,
        binary: env!("CARGO_BIN_EXE_flexdyn"),
        negative: &[
            ("scenes/pendulum.toml", &["bias"]),
            // Bias forces at most 9.81e-5: caught relative to the term's
            // own scale.
            ("tests/casadi/small_pendulum.toml", &["bias"]),
            // A coefficient of `marker_jacobian` in the marker's Jacobian
            // (not its position or rotation, which the program also
            // computes): CasADi derives the Jacobian from the exported pose.
            ("scenes/four_bar.toml", &["markers.coupler_mid.jacobian"]),
            // A coefficient of `d tau/dq` in `inverse_dynamics_derivatives`
            // (the forward dynamics' derivatives have their own program).
            ("scenes/cart_pole.toml", &["inverse_dynamics_q"]),
            // A coefficient of `d qdd/dqd` in `forward_dynamics_derivatives`
            // (`qdd` and the other derivatives, from the same program, stay
            // right).
            ("scenes/double_pendulum.toml", &["forward_dynamics_qd"]),
        ],
    });
}
