// Properties every shipped scene's generated code must have, at seeded
// random states in the scene's declared ranges, shared by the crates that
// compile scenes in: each test file declares `mod common;` and
// `use ... as compiled;` (its index module of generated scenes), then
// `include!`s this file. References are central finite differences of the
// generated lower-order functions (the energies and the constraint
// residuals), never the derived terms themselves.

use common::{max_abs, max_diff, random_state};
use flexdyn::dynamic::{matrix, vector, DynModel};
use flexdyn::runtime::nalgebra::{DMatrix, DVector};

const STATES: usize = 40;

// The model's terms as owned values (the model writes into storage its
// caller sizes).
fn mass_matrix(m: &dyn DynModel, q: &[f64], t: f64) -> DMatrix<f64> {
    matrix(m.nq(), m.nq(), |o| m.mass_matrix(q, t, o))
}
fn bias(m: &dyn DynModel, q: &[f64], qd: &[f64], t: f64) -> DVector<f64> {
    vector(m.nq(), |o| m.bias(q, qd, t, o))
}
fn constraints(m: &dyn DynModel, q: &[f64], t: f64) -> DVector<f64> {
    vector(m.nc(), |o| m.constraints(q, t, o))
}
fn constraint_jacobian(m: &dyn DynModel, q: &[f64], t: f64) -> DMatrix<f64> {
    matrix(m.nc(), m.nq(), |o| m.constraint_jacobian(q, t, o))
}
fn constraint_time_derivative(m: &dyn DynModel, q: &[f64], t: f64) -> DVector<f64> {
    vector(m.nc(), |o| m.constraint_time_derivative(q, t, o))
}
fn constraint_rhs(m: &dyn DynModel, q: &[f64], qd: &[f64], t: f64) -> DVector<f64> {
    vector(m.nc(), |o| m.constraint_rhs(q, qd, t, o))
}
fn damping_forces(m: &dyn DynModel, q: &[f64], qd: &[f64], t: f64) -> Option<DVector<f64>> {
    let mut d = DVector::zeros(m.nq());
    m.damping_forces(q, qd, t, d.as_mut_slice()).then_some(d)
}
fn bias_jacobians(
    m: &dyn DynModel,
    q: &[f64],
    qd: &[f64],
    t: f64,
) -> Option<(DMatrix<f64>, DMatrix<f64>)> {
    let (mut h_q, mut h_qd) = (DMatrix::zeros(m.nq(), m.nq()), DMatrix::zeros(m.nq(), m.nq()));
    m.bias_jacobians(q, qd, t, h_q.as_mut_slice(), h_qd.as_mut_slice())
        .then_some((h_q, h_qd))
}

fn model_of(name: &str) -> Box<dyn DynModel> {
    compiled::model(name).unwrap_or_else(|| panic!("scene `{name}` is not compiled in"))
}

/// Central difference of a vector function along `dir`, moving time by `dt`.
fn along(
    f: &dyn Fn(&[f64], f64) -> Vec<f64>,
    q: &[f64],
    dir: &[f64],
    t: f64,
    dt: f64,
    h: f64,
) -> Vec<f64> {
    let shift = |s: f64| -> Vec<f64> { q.iter().zip(dir).map(|(a, d)| a + s * d).collect() };
    let fp = f(&shift(h), t + h * dt);
    let fm = f(&shift(-h), t - h * dt);
    fp.iter()
        .zip(&fm)
        .map(|(a, b)| (a - b) / (2.0 * h))
        .collect()
}

fn unit(n: usize, i: usize) -> Vec<f64> {
    let mut e = vec![0.0; n];
    e[i] = 1.0;
    e
}

#[test]
fn every_scene_is_compiled_in() {
    let names: Vec<String> = common::scenes().into_iter().map(|(_, m)| m.name).collect();
    let mut compiled: Vec<&str> = compiled::SCENES.to_vec();
    compiled.sort();
    let mut names_sorted: Vec<&str> = names.iter().map(String::as_str).collect();
    names_sorted.sort();
    assert_eq!(compiled, names_sorted);
}

#[test]
fn mass_matrix_is_symmetric_positive_definite() {
    for (_, scene) in common::scenes() {
        let m = model_of(&scene.name);
        let mut rng = common::rng(11);
        for _ in 0..STATES {
            let (q, _, t) = random_state(&scene, &mut rng);
            let mm = mass_matrix(&*m, &q, t);
            assert_eq!(mm, mm.transpose(), "{}: M not symmetric", scene.name);
            assert!(
                mm.clone().cholesky().is_some(),
                "{}: M not positive definite at {q:?}: {mm}",
                scene.name
            );
        }
    }
}

#[test]
fn constraint_jacobian_and_time_derivative_match_differences() {
    for (_, scene) in common::scenes() {
        let m = model_of(&scene.name);
        if m.nc() == 0 {
            continue;
        }
        let n = m.nq();
        let phi = |q: &[f64], t: f64| constraints(&*m, q, t).as_slice().to_vec();
        let mut rng = common::rng(12);
        for _ in 0..STATES {
            let (q, _, t) = random_state(&scene, &mut rng);
            let jac = constraint_jacobian(&*m, &q, t);
            for j in 0..n {
                let fd = along(&phi, &q, &unit(n, j), t, 0.0, 1e-6);
                let col: Vec<f64> = jac.column(j).iter().copied().collect();
                let tol = 1e-6 * max_abs(&fd, 1.0);
                assert!(
                    max_diff(&col, &fd) < tol,
                    "{}: Phi_q column {j}: {col:?} vs {fd:?}",
                    scene.name
                );
            }
            let fd_t = along(&phi, &q, &vec![0.0; n], t, 1.0, 1e-6);
            let pt = constraint_time_derivative(&*m, &q, t);
            assert!(
                max_diff(pt.as_slice(), &fd_t) < 1e-6 * max_abs(&fd_t, 1.0),
                "{}: Phi_t",
                scene.name
            );
        }
    }
}

#[test]
fn gamma_matches_differences_of_velocity_residual() {
    for (_, scene) in common::scenes() {
        let m = model_of(&scene.name);
        if m.nc() == 0 {
            continue;
        }
        let mut rng = common::rng(13);
        for _ in 0..STATES {
            let (q, qd, t) = random_state(&scene, &mut rng);
            let qdv = DVector::from_column_slice(&qd);
            // v(q, t) = Phi_q qd + Phi_t with qd held fixed; gamma = -dv/dt.
            let v = |q: &[f64], t: f64| {
                let r = constraint_jacobian(&*m, q, t) * &qdv + constraint_time_derivative(&*m, q, t);
                r.as_slice().to_vec()
            };
            let fd: Vec<f64> = along(&v, &q, &qd, t, 1.0, 1e-6)
                .iter()
                .map(|x| -x)
                .collect();
            let gamma = constraint_rhs(&*m, &q, &qd, t);
            assert!(
                max_diff(gamma.as_slice(), &fd) < 1e-6 * max_abs(&fd, 1.0),
                "{}: gamma {gamma} vs {fd:?}",
                scene.name
            );
        }
    }
}

/// `M` is the Hessian of `T` in the velocities and `h` equals
/// `d/dt(dT/dqd) - dT/dq + dV/dq + dD/dqd`. Since `T` is quadratic in `qd`, differences in `qd`
/// are exact up to rounding.
#[test]
fn mass_matrix_and_bias_follow_from_the_energies() {
    for (_, scene) in common::scenes() {
        if scene.drop_below.is_some() {
            // A pruned scene matches its energies only to its stated
            // tolerance, by design: codegen/tests/reduce.rs and the CasADi
            // validation check that bound.
            continue;
        }
        let m = model_of(&scene.name);
        let n = m.nq();
        let mut rng = common::rng(14);
        for _ in 0..STATES {
            let (q, qd, t) = random_state(&scene, &mut rng);
            let momenta = |q: &[f64], t: f64| -> Vec<f64> {
                (0..n)
                    .map(|i| {
                        let f = |qd: &[f64], _t: f64| vec![m.kinetic_energy(q, qd, t)];
                        along(&f, &qd, &unit(n, i), t, 0.0, 0.5)[0]
                    })
                    .collect()
            };
            // Mass matrix: differences of the momenta in qd.
            let mm = mass_matrix(&*m, &q, t);
            for j in 0..n {
                let f = |qd: &[f64], _t: f64| -> Vec<f64> {
                    (0..n)
                        .map(|i| {
                            let g = |x: &[f64], _t: f64| vec![m.kinetic_energy(&q, x, t)];
                            along(&g, qd, &unit(n, i), t, 0.0, 0.5)[0]
                        })
                        .collect()
                };
                let fd = along(&f, &qd, &unit(n, j), t, 0.0, 0.5);
                let col: Vec<f64> = mm.column(j).iter().copied().collect();
                assert!(
                    max_diff(&col, &fd) < 1e-9 * max_abs(&fd, 1.0),
                    "{}: M column {j}",
                    scene.name
                );
            }
            // Bias forces.
            let dp = along(&momenta, &q, &qd, t, 1.0, 1e-5);
            let tq =
                |q: &[f64], t: f64| vec![m.kinetic_energy(q, &qd, t) - m.potential_energy(q, t)];
            let reference: Vec<f64> = (0..n)
                .map(|i| dp[i] - along(&tq, &q, &unit(n, i), t, 0.0, 1e-6)[0])
                .collect();
            // Damping forces come from the dissipation function, which the
            // energies do not see: take them from the generated split (checked
            // against CasADi's gradient of D); a damped scene without that
            // split cannot be checked here.
            let reference: Vec<f64> = match damping_forces(&*m, &q, &qd, t) {
                Some(d) => reference.iter().zip(d.iter()).map(|(r, d)| r + d).collect(),
                None if scene_is_damped(&scene) => break,
                None => reference,
            };
            let h = bias(&*m, &q, &qd, t);
            assert!(
                max_diff(h.as_slice(), &reference) < 1e-6 * max_abs(&reference, 1.0),
                "{}: bias {h} vs {reference:?}",
                scene.name
            );
        }
    }
}

/// Where a scene generates `bias_jacobians`, they equal central differences
/// of the generated bias forces in `q` and in `qd`.
#[test]
fn bias_jacobians_match_differences_of_bias() {
    let mut checked = 0;
    for (_, scene) in common::scenes() {
        if scene.drop_below.is_some() {
            // A pruned scene matches its energies only to its stated
            // tolerance, by design: codegen/tests/reduce.rs and the CasADi
            // validation check that bound.
            continue;
        }
        let m = model_of(&scene.name);
        let n = m.nq();
        let mut rng = common::rng(14);
        for _ in 0..STATES {
            let (q, qd, t) = random_state(&scene, &mut rng);
            let Some((h_q, h_qd)) = bias_jacobians(&*m, &q, &qd, t) else {
                break;
            };
            checked += 1;
            let by_q: &dyn Fn(&[f64], f64) -> Vec<f64> =
                &|x, t| bias(&*m, x, &qd, t).as_slice().to_vec();
            let by_qd: &dyn Fn(&[f64], f64) -> Vec<f64> =
                &|x, t| bias(&*m, &q, x, t).as_slice().to_vec();
            for j in 0..n {
                for (jac, f, x, what) in [(&h_q, by_q, &q, "dh/dq"), (&h_qd, by_qd, &qd, "dh/dqd")]
                {
                    let fd = along(f, x, &unit(n, j), t, 0.0, 1e-6);
                    let col: Vec<f64> = jac.column(j).iter().copied().collect();
                    let tol = 1e-6 * max_abs(&fd, 1.0);
                    assert!(
                        max_diff(&col, &fd) < tol,
                        "{}: {what} column {j}: {col:?} vs {fd:?}",
                        scene.name
                    );
                }
            }
        }
    }
    assert!(checked > 0, "no scene generates bias_jacobians");
}

/// Whether any component of the scene has a nonzero dissipation function.
fn scene_is_damped(scene: &flexdyn::codegen::Model) -> bool {
    let zero = scene.graph.find_constant(0.0);
    scene.components.iter().any(|c| Some(c.dissipation) != zero)
}
