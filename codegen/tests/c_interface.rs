//! The C interface (`Builder::c_interface`): the modules of the pendulum,
//! the four-bar and the rigid parallel robot, generated with their
//! `extern "C"` wrappers, are built as a static library in a throwaway
//! crate; a C program compiled with the system C compiler includes the
//! generated headers, calls the model terms, the four-bar's marker
//! kinematics (pose, Jacobian, velocity, acceleration bias, by the index
//! macro the header defines) and the inverse dynamics through them and
//! prints every result bit for bit. A Rust program calling the same
//! models through the `Model` trait (and the runtime's `InverseDynamics`)
//! must print exactly the same bits, matrices row-major as the header says;
//! the pendulum's mass also matches its closed form `m l^2` with parameters
//! passed from C in the header's order. The C program also checks the
//! status codes: null pointers, non-finite inputs, invalid prescribed
//! coordinates, a marker index out of range and an unreachable pose.

use std::path::{Path, PathBuf};
use std::process::Command;

use flexdyn_codegen::Builder;

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the codegen crate lies in the workspace")
        .to_path_buf()
}

/// The scenes: module name and scene file.
const SCENES: [(&str, &str); 3] = [
    ("pendulum", "scenes/pendulum.toml"),
    ("four_bar", "scenes/four_bar.toml"),
    (
        "parallel_robot_rigid",
        "examples/parallel-robot/scenes/parallel_robot_rigid.toml",
    ),
];

/// The robot's pose at `t = 0` on the paper's circle: the inverse
/// dynamics' initial guess (as in examples/cortex-m-bench).
const Q0: &str = "0.07077240198480617, 2.299032285161347, 0.0, 0.4172169655179958, \
    2.497066771033036, -0.10846573026975444, 0.4172169655179958, 2.497066771033036, \
    0.1084657302697544, 0.1, 0.0, 0.7";

/// The platform's position, velocity and acceleration on the circle at
/// `t = 0.01` s (radius 0.1 m, 2 rad/s), as C and Rust initialisers.
const CIRCLE: &str = "P[3] = {0.09998000066665778, 0.0019998666693333083, 0.7}, \
    V[3] = {-0.0039997333386666166, 0.19996000133331557, 0.0}, \
    A[3] = {-0.39992000266663114, -0.007999466677333233, 0.0}";

const C_MAIN: &str = r#"
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>
#include "pendulum.h"
#include "four_bar.h"
#include "parallel_robot_rigid.h"

static void print(const char *name, const double *x, int n) {
    for (int k = 0; k < n; k++) {
        uint64_t bits;
        memcpy(&bits, &x[k], sizeof bits);
        printf("%s %d %016llx\n", name, k, (unsigned long long)bits);
    }
}

/* Every term of scene prefix P (macro prefix U) at a fixed state. */
#define TERMS(P, U, PARAMS)                                                          \
    do {                                                                             \
        double q[U##_NQ], qd[U##_NQ], m[U##_NQ * U##_NQ], h[U##_NQ];                 \
        double phi_q[U##_NC * U##_NQ + 1], gamma[U##_NC + 1], b[U##_NQ * U##_NU + 1]; \
        double m2[U##_NQ * U##_NQ], h2[U##_NQ], phi_q2[U##_NC * U##_NQ + 1];          \
        double gamma2[U##_NC + 1], e, tau[U##_NU + 1], f[U##_NQ];                    \
        for (int i = 0; i < U##_NQ; i++) {                                           \
            q[i] = 0.1 * (i + 1) - 0.3;                                              \
            qd[i] = 0.05 * i - 0.2;                                                  \
        }                                                                            \
        for (int j = 0; j < U##_NU; j++) {                                           \
            tau[j] = 0.7 * j - 0.4;                                                  \
        }                                                                            \
        int s = P##_mass_matrix(PARAMS, q, 0.3, m);                                  \
        s |= P##_bias(PARAMS, q, qd, 0.3, h);                                        \
        s |= P##_constraint_jacobian(PARAMS, q, 0.3, phi_q);                         \
        s |= P##_constraint_rhs(PARAMS, q, qd, 0.3, gamma);                          \
        s |= P##_actuator_map(PARAMS, b);                                            \
        print(#P ".mass_matrix", m, U##_NQ * U##_NQ);                                \
        print(#P ".bias", h, U##_NQ);                                                \
        print(#P ".constraint_jacobian", phi_q, U##_NC * U##_NQ);                    \
        print(#P ".constraint_rhs", gamma, U##_NC);                                  \
        print(#P ".actuator_map", b, U##_NQ * U##_NU);                               \
        s |= P##_actuator_forces(PARAMS, tau, f);                                    \
        print(#P ".actuator_forces", f, U##_NQ);                                     \
        s |= P##_dynamics_terms(PARAMS, q, qd, 0.3, m2, h2, phi_q2, gamma2);         \
        print(#P ".dynamics_terms.m", m2, U##_NQ * U##_NQ);                          \
        print(#P ".dynamics_terms.h", h2, U##_NQ);                                   \
        print(#P ".dynamics_terms.phi_q", phi_q2, U##_NC * U##_NQ);                  \
        print(#P ".dynamics_terms.gamma", gamma2, U##_NC);                           \
        s |= P##_kinetic_energy(PARAMS, q, qd, 0.3, &e);                             \
        print(#P ".kinetic_energy", &e, 1);                                          \
        s |= P##_potential_energy(PARAMS, q, 0.3, &e);                               \
        print(#P ".potential_energy", &e, 1);                                        \
        printf("status " #P ".terms %d\n", s);                                       \
    } while (0)

int main(void) {
    double pendulum[PENDULUM_NPARAMS];
    pendulum[PENDULUM_PARAM_m] = 2.0;
    pendulum[PENDULUM_PARAM_l] = 0.7;
    pendulum[PENDULUM_PARAM_c] = 0.1;
    TERMS(pendulum, PENDULUM, pendulum);
    TERMS(four_bar, FOUR_BAR, NULL);
    TERMS(parallel_robot_rigid, PARALLEL_ROBOT_RIGID, NULL);

    /* The four-bar's marker: pose, Jacobian, velocity and acceleration
       bias; an index out of range is refused. */
    {
        double q[FOUR_BAR_NQ] = {0.4, 0.9, -0.2}, qd[FOUR_BAR_NQ] = {0.3, -0.1, 0.5};
        double position[3], rotation[9], jacobian[6 * FOUR_BAR_NQ], velocity[6], bias[6];
        int s = four_bar_marker_jacobian(NULL, FOUR_BAR_MARKER_coupler_mid, q, 0.3, position, rotation, jacobian);
        s |= four_bar_marker_motion(NULL, FOUR_BAR_MARKER_coupler_mid, q, qd, 0.3, velocity, bias);
        print("four_bar.marker.position", position, 3);
        print("four_bar.marker.rotation", rotation, 9);
        print("four_bar.marker.jacobian", jacobian, 6 * FOUR_BAR_NQ);
        print("four_bar.marker.velocity", velocity, 6);
        print("four_bar.marker.acceleration_bias", bias, 6);
        printf("status four_bar.marker %d\n", s);
        printf("status marker_out_of_range %d\n",
               four_bar_marker_pose(NULL, FOUR_BAR_NM, q, 0.3, position, rotation));
    }

    size_t prescribed[PARALLEL_ROBOT_RIGID_NP] = {9, 10, 11};
    double q[PARALLEL_ROBOT_RIGID_NQ] = {Q0};
    double CIRCLE;
    double qd[PARALLEL_ROBOT_RIGID_NQ], qdd[PARALLEL_ROBOT_RIGID_NQ];
    double tau[PARALLEL_ROBOT_RIGID_NU], lambda[PARALLEL_ROBOT_RIGID_NC];
    int s = parallel_robot_rigid_solve_inverse_dynamics(NULL, prescribed, q, 0.01, P, V, A, qd, qdd, tau, lambda);
    printf("status inverse %d\n", s);
    print("inverse.q", q, PARALLEL_ROBOT_RIGID_NQ);
    print("inverse.qd", qd, PARALLEL_ROBOT_RIGID_NQ);
    print("inverse.qdd", qdd, PARALLEL_ROBOT_RIGID_NQ);
    print("inverse.tau", tau, PARALLEL_ROBOT_RIGID_NU);
    print("inverse.lambda", lambda, PARALLEL_ROBOT_RIGID_NC);

    /* Status codes. */
    double x[PENDULUM_NQ] = {NAN}, y[PENDULUM_NQ] = {0.0}, out[PENDULUM_NQ];
    printf("status null_q %d\n", pendulum_mass_matrix(NULL, NULL, 0.0, out));
    printf("status null_out %d\n", pendulum_bias(NULL, y, y, 0.0, NULL));
    printf("status nan_q %d\n", pendulum_bias(NULL, x, y, 0.0, out));
    size_t repeated[PARALLEL_ROBOT_RIGID_NP] = {9, 9, 11};
    printf("status repeated %d\n",
           parallel_robot_rigid_solve_inverse_dynamics(NULL, repeated, q, 0.01, P, V, A, qd, qdd, tau, lambda));
    double far[3] = {0.0, 0.0, 5.0};
    printf("status unreachable %d\n",
           parallel_robot_rigid_solve_inverse_dynamics(NULL, prescribed, q, 0.01, far, V, A, qd, qdd, tau, lambda));
    return 0;
}
"#;

const RUST_MAIN: &str = r#"
use c_interface_check::{four_bar, parallel_robot_rigid, pendulum};
use flexdyn_runtime::nalgebra::{SMatrix, SVector};
use flexdyn_runtime::{InverseConfig, InverseDynamics, InverseSolution, Model};

fn print<const R: usize, const C: usize>(name: &str, x: &SMatrix<f64, R, C>) {
    for (k, v) in x.transpose().iter().enumerate() {
        println!("{name} {k} {:016x}", v.to_bits());
    }
}

fn terms<M: Model<NQ, NC, NU>, const NQ: usize, const NC: usize, const NU: usize>(p: &str, model: &M) {
    let q = SVector::<f64, NQ>::from_fn(|i, _| 0.1 * (i + 1) as f64 - 0.3);
    let qd = SVector::<f64, NQ>::from_fn(|i, _| 0.05 * i as f64 - 0.2);
    let mut m = SMatrix::<f64, NQ, NQ>::zeros();
    let mut h = SVector::<f64, NQ>::zeros();
    let mut phi_q = SMatrix::<f64, NC, NQ>::zeros();
    let mut gamma = SVector::<f64, NC>::zeros();
    let mut b = SMatrix::<f64, NQ, NU>::zeros();
    model.mass_matrix(&q, 0.3, &mut m);
    model.bias(&q, &qd, 0.3, &mut h);
    model.constraint_jacobian(&q, 0.3, &mut phi_q);
    model.constraint_rhs(&q, &qd, 0.3, &mut gamma);
    model.actuator_map(&mut b);
    print(&format!("{p}.mass_matrix"), &m);
    print(&format!("{p}.bias"), &h);
    print(&format!("{p}.constraint_jacobian"), &phi_q);
    print(&format!("{p}.constraint_rhs"), &gamma);
    print(&format!("{p}.actuator_map"), &b);
    let tau = SVector::<f64, NU>::from_fn(|j, _| 0.7 * j as f64 - 0.4);
    let mut f = SVector::<f64, NQ>::zeros();
    assert!(model.actuator_forces(&tau, &mut f), "{p}: actuator_forces generated");
    print(&format!("{p}.actuator_forces"), &f);
    model.dynamics_terms(&q, &qd, 0.3, &mut m, &mut h, &mut phi_q, &mut gamma);
    print(&format!("{p}.dynamics_terms.m"), &m);
    print(&format!("{p}.dynamics_terms.h"), &h);
    print(&format!("{p}.dynamics_terms.phi_q"), &phi_q);
    print(&format!("{p}.dynamics_terms.gamma"), &gamma);
    print(&format!("{p}.kinetic_energy"), &SVector::<f64, 1>::new(model.kinetic_energy(&q, &qd, 0.3)));
    print(&format!("{p}.potential_energy"), &SVector::<f64, 1>::new(model.potential_energy(&q, 0.3)));
}

fn main() {
    terms("pendulum", &pendulum::Pendulum { m: 2.0, l: 0.7, c: 0.1 });
    terms("four_bar", &four_bar::FourBar);
    let robot = parallel_robot_rigid::ParallelRobotRigid;
    terms("parallel_robot_rigid", &robot);
    let bar = four_bar::FourBar;
    let q = SVector::from([0.4, 0.9, -0.2]);
    let qd = SVector::from([0.3, -0.1, 0.5]);
    let (mut position, mut rotation) = (SVector::<f64, 3>::zeros(), SMatrix::<f64, 3, 3>::zeros());
    let mut jacobian = SMatrix::<f64, 6, 3>::zeros();
    let (mut velocity, mut bias) = (SVector::<f64, 6>::zeros(), SVector::<f64, 6>::zeros());
    assert!(bar.marker_jacobian(0, &q, 0.3, &mut position, &mut rotation, &mut jacobian));
    assert!(bar.marker_motion(0, &q, &qd, 0.3, &mut velocity, &mut bias));
    print("four_bar.marker.position", &position);
    print("four_bar.marker.rotation", &rotation);
    print("four_bar.marker.jacobian", &jacobian);
    print("four_bar.marker.velocity", &velocity);
    print("four_bar.marker.acceleration_bias", &bias);
    const Q0: [f64; 12] = [Q0];
    const CIRCLE;
    let mut solver = InverseDynamics::<12, 9, 3, 3>::new([9, 10, 11], SVector::from(Q0), InverseConfig::default()).unwrap();
    let mut sol = InverseSolution::<12, 9, 3>::default();
    let v = |x: [f64; 3]| SVector::from(x);
    solver.solve(&robot, 0.01, &v(P), &v(V), &v(A), &mut sol).unwrap();
    print("inverse.q", &sol.q);
    print("inverse.qd", &sol.qd);
    print("inverse.qdd", &sol.qdd);
    print("inverse.tau", &sol.tau);
    print("inverse.lambda", &sol.lambda);
}
"#;

/// Runs `cmd`; its standard output, or a panic with what went wrong.
fn run(cmd: &mut Command, what: &str) -> String {
    let out = cmd
        .output()
        .unwrap_or_else(|e| panic!("cannot run {what}: {e}"));
    assert!(
        out.status.success(),
        "{what} failed:\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

#[test]
fn c_program_gets_the_rust_results_through_the_generated_header() {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("src");
    std::fs::create_dir_all(src.join("bin")).unwrap();
    let mut builder = Builder::new().c_interface(true).out_dir(&src);
    for (_, scene) in SCENES {
        builder = builder.scene(workspace().join(scene));
    }
    let report = builder.generate().unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(
        report.written.len(),
        2 * SCENES.len(),
        "a module and a header per scene"
    );
    let lib: String = SCENES
        .iter()
        .map(|(m, _)| format!("pub mod {m} {{ include!(\"{m}.rs\"); }}\n"))
        .collect();
    std::fs::write(src.join("lib.rs"), lib).unwrap();
    let circle_rust = CIRCLE
        .replace("P[3] = {", "P: [f64; 3] = [")
        .replace("V[3] = {", "V: [f64; 3] = [")
        .replace("A[3] = {", "A: [f64; 3] = [")
        .replace('}', "]")
        .replace("], ", "];\n    const ");
    std::fs::write(
        src.join("bin/reference.rs"),
        RUST_MAIN
            .replace("[Q0]", &format!("[{Q0}]"))
            .replace("CIRCLE", &circle_rust),
    )
    .unwrap();
    std::fs::write(
        dir.path().join("main.c"),
        C_MAIN
            .replace("{Q0}", &format!("{{{Q0}}}"))
            .replace("CIRCLE", CIRCLE),
    )
    .unwrap();
    let manifest = format!(
        "[package]\nname = \"c_interface_check\"\nversion = \"0.0.0\"\nedition = \"2021\"\n\
         publish = false\n\n[lib]\ncrate-type = [\"staticlib\", \"rlib\"]\n\n\
         [dependencies]\nflexdyn-runtime = {{ path = {:?} }}\n\n[workspace]\n",
        workspace().join("runtime").display().to_string()
    );
    std::fs::write(dir.path().join("Cargo.toml"), manifest).unwrap();
    std::fs::copy(
        workspace().join("Cargo.lock"),
        dir.path().join("Cargo.lock"),
    )
    .unwrap();

    // The static library and the Rust reference.
    let target = workspace().join("target").join("c_interface_check");
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    run(
        Command::new(&cargo)
            .args([
                "build",
                "--quiet",
                "--offline",
                "--release",
                "--manifest-path",
            ])
            .arg(dir.path().join("Cargo.toml"))
            .env("CARGO_TARGET_DIR", &target)
            .env_remove("RUSTFLAGS"),
        "cargo build of the static library",
    );
    let reference = run(
        &mut Command::new(target.join("release/reference")),
        "the Rust reference",
    );

    // The C program against the static library.
    let program = dir.path().join("c_check");
    run(
        Command::new("cc")
            .args(["-std=c99", "-Wall", "-Wextra", "-Werror", "-o"])
            .arg(&program)
            .arg(dir.path().join("main.c"))
            .arg("-I")
            .arg(&src)
            .arg(target.join("release/libc_interface_check.a"))
            .args(["-lm", "-lpthread", "-ldl"]),
        "the system C compiler (cc)",
    );
    let c = run(&mut Command::new(&program), "the C program");

    let (status, values): (Vec<&str>, Vec<&str>) =
        c.lines().partition(|l| l.starts_with("status "));
    let expected_values: Vec<&str> = reference.lines().collect();
    assert!(expected_values.len() > 500, "{}", expected_values.len());
    for (c_line, rust_line) in values.iter().zip(&expected_values) {
        assert_eq!(c_line, rust_line, "C and Rust differ");
    }
    assert_eq!(values.len(), expected_values.len());

    let mass = values
        .iter()
        .find_map(|l| l.strip_prefix("pendulum.mass_matrix 0 "))
        .map(|bits| f64::from_bits(u64::from_str_radix(bits, 16).unwrap()))
        .unwrap();
    assert!((mass - 2.0 * 0.7 * 0.7).abs() < 1e-14, "M = {mass}");

    let status: Vec<&str> = status.iter().map(|l| &l[7..]).collect();
    assert_eq!(
        status,
        [
            "pendulum.terms 0",
            "four_bar.terms 0",
            "parallel_robot_rigid.terms 0",
            "four_bar.marker 0",
            "marker_out_of_range 3",
            "inverse 0",
            "null_q 1",
            "null_out 1",
            "nan_q 2",
            "repeated 3",
            "unreachable 4",
        ]
    );
}

#[test]
fn the_header_and_the_unsafe_wrappers_come_only_when_asked_for() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("odd.toml");
    std::fs::write(
        &scene,
        std::fs::read_to_string(workspace().join("scenes/pendulum.toml"))
            .unwrap()
            .replacen("name = \"pendulum\"", "name = \"pendulum_2\"", 1),
    )
    .unwrap();
    let plain = Builder::new()
        .scene(&scene)
        .out_dir(dir.path().join("plain"))
        .generate()
        .unwrap();
    assert_eq!(plain.written.len(), 1);
    assert!(plain.scenes[0].c_header.is_none());
    assert!(!plain.scenes[0].source.contains("extern \"C\""));
    assert!(!plain.scenes[0].source.contains("unsafe"));
    let c = Builder::new()
        .scene(&scene)
        .c_interface(true)
        .out_dir(dir.path().join("c"))
        .generate()
        .unwrap();
    let header = std::fs::read_to_string(dir.path().join("c/pendulum_2.h")).unwrap();
    assert_eq!(Some(&header), c.scenes[0].c_header.as_ref());
    assert!(header.contains("#define PENDULUM_2_NQ 1"));
    assert!(header.contains("int pendulum_2_mass_matrix(const double *params"));
    assert!(c.scenes[0]
        .source
        .contains("pub unsafe extern \"C\" fn pendulum_2_mass_matrix("));
}
