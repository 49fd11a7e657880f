//! Every generated term of every robot scene (`scenes/` of this crate),
//! validated against CasADi's automatic differentiation through
//! `parallel-robot export` and `parallel-robot eval` (the shared
//! `tests/common/casadi.rs` of the repository), plus a negative run proving
//! that a perturbed coefficient of the rigid robot's mass matrix is caught.

#[path = "../../../tests/common/casadi.rs"]
mod casadi;
#[path = "../../../tests/common/python_env.rs"]
mod python_env;

#[test]
fn casadi_validates_every_term_of_every_robot_scene() {
    let here = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    casadi::validate_every_scene(&casadi::Suite {
        repo: here.join("../.."),
        binary: env!("CARGO_BIN_EXE_parallel-robot"),
        scenes: here.join("scenes"),
        negative: &[(
            "examples/parallel-robot/scenes/parallel_robot_rigid.toml",
            &["mass_matrix"],
        )],
    });
}
