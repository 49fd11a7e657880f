//! Constrained forward dynamics and coordinate projection against closed
//! forms.

mod models;

use flexdyn_runtime::{
    accelerations, constraint_drift, project, Baumgarte, DynamicsConfig, Model, ProjectionConfig,
    State,
};
use models::*;

#[test]
fn pendulum_acceleration_matches_closed_form() {
    let p = Pendulum {
        c: 0.3,
        ..Default::default()
    };
    let (th, thd, tau): (f64, f64, f64) = (0.9, -1.7, 2.5);
    let acc = accelerations(
        &p,
        &DynamicsConfig::default(),
        &V::<1>::new(th),
        &V::<1>::new(thd),
        0.0,
        &V::<1>::new(tau),
    )
    .expect("solve");
    let expected = (tau - p.c * thd - p.m * p.g * p.l * th.sin()) / (p.m * p.l * p.l);
    assert!((acc.qdd[0] - expected).abs() < 1e-14);
    assert_eq!(acc.condition, 1.0);
}

#[test]
fn cartesian_pendulum_matches_polar_closed_form() {
    // x = L sin th, y = -L cos th. Polar: th'' = (F L cos th - m g L sin th) / (m L^2)
    // with F the horizontal input force; rod tension from the radial balance.
    let p = CartesianPendulum {
        m: 1.3,
        l: 0.7,
        g: 9.81,
    };
    let (th, thd, f): (f64, f64, f64) = (0.6, 2.1, 0.8);
    let (s, c) = th.sin_cos();
    let q = V::<2>::new(p.l * s, -p.l * c);
    let qd = V::<2>::new(p.l * c * thd, p.l * s * thd);
    let cfg = DynamicsConfig {
        baumgarte: Baumgarte::NONE,
        ..Default::default()
    };
    let acc = accelerations(&p, &cfg, &q, &qd, 0.0, &V::<1>::new(f)).expect("solve");
    let thdd = (f * p.l * c - p.m * p.g * p.l * s) / (p.m * p.l * p.l);
    let xdd = p.l * (c * thdd - s * thd * thd);
    let ydd = p.l * (s * thdd + c * thd * thd);
    assert!(
        (acc.qdd[0] - xdd).abs() < 1e-12 && (acc.qdd[1] - ydd).abs() < 1e-12,
        "{:?}",
        acc.qdd
    );
    // Tension T (along the rod towards the pivot): m L thd^2 = T - m g cos th - f sin th.
    // Constraint force Phi_q^T lambda = lambda * (2x, 2y) = -T (sin th, -cos th)  =>  lambda = -T / (2L).
    let tension = p.m * p.l * thd * thd + p.m * p.g * c + f * s;
    assert!(
        (acc.lambda[0] + tension / (2.0 * p.l)).abs() < 1e-12,
        "{} vs {}",
        acc.lambda[0],
        -tension / (2.0 * p.l)
    );
}

#[test]
fn slider_crank_solution_satisfies_the_kkt_system_with_baumgarte() {
    let m = SliderCrank::default();
    // A state off the manifold, so the Baumgarte terms are active.
    let mut s = m.consistent_state(1.2, 3.0);
    s.q[1] += 1e-3;
    s.qd[2] += 2e-2;
    let cfg = DynamicsConfig {
        baumgarte: Baumgarte {
            alpha: 7.0,
            beta: 5.0,
        },
        ..Default::default()
    };
    let tau = V::<1>::new(0.4);
    let acc = accelerations(&m, &cfg, &s.q, &s.qd, 0.0, &tau).expect("solve");
    let (mut mm, mut h, mut b, mut jac) = (
        Mat::<3, 3>::zeros(),
        V::<3>::zeros(),
        Mat::<3, 1>::zeros(),
        Mat::<2, 3>::zeros(),
    );
    let (mut phi, mut phit, mut gamma) = (V::<2>::zeros(), V::<2>::zeros(), V::<2>::zeros());
    m.mass_matrix(&s.q, 0.0, &mut mm);
    m.bias(&s.q, &s.qd, 0.0, &mut h);
    m.actuator_map(&mut b);
    m.constraint_jacobian(&s.q, 0.0, &mut jac);
    m.constraints(&s.q, 0.0, &mut phi);
    m.constraint_time_derivative(&s.q, 0.0, &mut phit);
    m.constraint_rhs(&s.q, &s.qd, 0.0, &mut gamma);
    let r1 = mm * acc.qdd + h - jac.transpose() * acc.lambda - b * tau;
    let r2 = jac * acc.qdd - (gamma - (jac * s.qd + phit) * 14.0 - phi * 25.0);
    assert!(r1.amax() < 1e-12 && r2.amax() < 1e-12, "{r1} {r2}");
    assert!(acc.condition >= 1.0 && acc.condition < 1e3);
}

#[test]
fn projection_restores_the_manifold_with_mass_weighted_velocity_correction() {
    let m = SliderCrank::default();
    let mut s: State<3> = m.consistent_state(0.7, 5.0);
    s.q += V::<3>::new(2e-3, -1e-3, 3e-3);
    s.qd += V::<3>::new(0.05, 0.02, -0.04);
    let before = s;
    let report = project(&m, &mut s, &ProjectionConfig::default()).expect("projection");
    let d = constraint_drift(&m, &s);
    assert!(d.position <= 1e-12 && d.velocity <= 1e-12, "{d:?}");
    assert!(report.iterations >= 1 && report.iterations <= 5 && report.velocity_projected);
    assert!(report.before.position > 1e-4);
    // Velocity correction is M-orthogonal to the admissible velocities:
    // M (qd_new - qd_old') lies in range(Phi_q^T), i.e. is orthogonal to the
    // null space of Phi_q (one-dimensional here: cross product of the rows).
    // qd_old' includes the SHAKE-free projection: plain `project` does not
    // alter velocities before projecting them.
    let (mut mm, mut jac) = (Mat::<3, 3>::zeros(), Mat::<2, 3>::zeros());
    m.mass_matrix(&s.q, 0.0, &mut mm);
    m.constraint_jacobian(&s.q, 0.0, &mut jac);
    let n = jac.row(0).transpose().cross(&jac.row(1).transpose());
    let dv = s.qd - before.qd;
    assert!((mm * dv).dot(&n).abs() < 1e-12 * (mm * dv).norm().max(1.0));
    // Already on the manifold: nothing to do.
    let again = project(&m, &mut s, &ProjectionConfig::default()).expect("projection");
    assert_eq!(again.iterations, 0);
}
