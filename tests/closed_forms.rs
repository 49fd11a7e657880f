//! Issue 2: the generated double pendulum and cart-pole equal their textbook
//! closed forms at seeded random states, to 1e-12 relative; their Coriolis
//! matrices satisfy the skew-symmetry property.

mod common;

use flexdyn::runtime::Model;
use flexdyn::scenes::{cart_pole::CartPole, double_pendulum::DoublePendulum};
use nalgebra::{SMatrix, SVector};
use rand::Rng;

type V2 = SVector<f64, 2>;
type M2 = SMatrix<f64, 2, 2>;

fn rel_close(a: f64, b: f64, scale: f64) -> bool {
    (a - b).abs() <= 1e-12 * scale.max(1.0)
}

// Parameters exactly as written in scenes/double_pendulum.toml.
const M1: f64 = 1.0;
const MM2: f64 = 0.7;
const L1: f64 = 0.6;
const L2: f64 = 0.4;
const G: f64 = 9.81;

#[test]
fn double_pendulum_matches_textbook() {
    let model = DoublePendulum;
    let mut rng = common::rng(2);
    for _ in 0..200 {
        let q = V2::new(rng.gen_range(-3.2..3.2), rng.gen_range(-3.2..3.2));
        let qd = V2::new(rng.gen_range(-8.0..8.0), rng.gen_range(-8.0..8.0));
        let d = q[0] - q[1];
        let m12 = MM2 * L1 * L2 * d.cos();
        let m_ref = M2::new((M1 + MM2) * L1 * L1, m12, m12, MM2 * L2 * L2);
        let c_ref = V2::new(
            MM2 * L1 * L2 * d.sin() * qd[1] * qd[1],
            -MM2 * L1 * L2 * d.sin() * qd[0] * qd[0],
        );
        let g_ref = V2::new((M1 + MM2) * G * L1 * q[0].sin(), MM2 * G * L2 * q[1].sin());

        let mut m = M2::zeros();
        model.mass_matrix(&q, 0.0, &mut m);
        let mut c = V2::zeros();
        model.coriolis_forces(&q, &qd, 0.0, &mut c);
        let mut g = V2::zeros();
        model.potential_forces(&q, 0.0, &mut g);
        let mut h = V2::zeros();
        model.bias(&q, &qd, 0.0, &mut h);
        let scale_m = m_ref.abs().max();
        let scale_c = c_ref.abs().max() + g_ref.abs().max();
        for k in 0..4 {
            assert!(rel_close(m[k], m_ref[k], scale_m), "M {m} vs {m_ref}");
        }
        for k in 0..2 {
            assert!(rel_close(c[k], c_ref[k], scale_c), "C qd {c} vs {c_ref}");
            assert!(rel_close(g[k], g_ref[k], scale_c), "G {g} vs {g_ref}");
            assert!(rel_close(h[k], c_ref[k] + g_ref[k], scale_c), "h {h}");
        }
    }
}

// Parameters as in scenes/cart_pole.toml; the textbook uses the half-length.
const MC: f64 = 1.0;
const MP: f64 = 0.1;
const HALF: f64 = 0.5;
const GZ: f64 = 9.81;

#[test]
fn cart_pole_matches_textbook() {
    let model = CartPole;
    let mut rng = common::rng(3);
    for _ in 0..200 {
        let q = V2::new(rng.gen_range(-2.0..2.0), rng.gen_range(-3.2..3.2));
        let qd = V2::new(rng.gen_range(-3.0..3.0), rng.gen_range(-6.0..6.0));
        let (s, c) = q[1].sin_cos();
        let m_ref = M2::new(
            MC + MP,
            MP * HALF * c,
            MP * HALF * c,
            4.0 / 3.0 * MP * HALF * HALF,
        );
        let c_ref = V2::new(-MP * HALF * s * qd[1] * qd[1], 0.0);
        let g_ref = V2::new(0.0, -MP * GZ * HALF * s);
        let mut m = M2::zeros();
        model.mass_matrix(&q, 0.0, &mut m);
        let mut cq = V2::zeros();
        model.coriolis_forces(&q, &qd, 0.0, &mut cq);
        let mut g = V2::zeros();
        model.potential_forces(&q, 0.0, &mut g);
        for k in 0..4 {
            assert!(
                rel_close(m[k], m_ref[k], m_ref.abs().max()),
                "M {m} vs {m_ref}"
            );
        }
        let scale = c_ref.abs().max() + g_ref.abs().max();
        for k in 0..2 {
            assert!(rel_close(cq[k], c_ref[k], scale), "C qd {cq} vs {c_ref}");
            assert!(rel_close(g[k], g_ref[k], scale), "G {g} vs {g_ref}");
        }
    }
}

/// `dM/dt - 2 C` is skew-symmetric and `C qd` equals the Coriolis forces;
/// `dM/dt` by central differences of the generated mass matrix along `qd`.
fn check_coriolis_matrix(
    mass: impl Fn(&V2) -> M2,
    cmat: impl Fn(&V2, &V2) -> M2,
    cvec: impl Fn(&V2, &V2) -> V2,
    seed: u64,
) {
    let mut rng = common::rng(seed);
    for _ in 0..100 {
        let q = V2::new(rng.gen_range(-3.0..3.0), rng.gen_range(-3.0..3.0));
        let qd = V2::new(rng.gen_range(-5.0..5.0), rng.gen_range(-5.0..5.0));
        let h = 1e-6;
        let mdot = (mass(&(q + qd * h)) - mass(&(q - qd * h))) / (2.0 * h);
        let c = cmat(&q, &qd);
        let n = mdot - 2.0 * c;
        let scale = mdot.abs().max().max(c.abs().max()).max(1.0);
        assert!((n + n.transpose()).abs().max() < 1e-7 * scale, "N = {n}");
        let cq = c * qd;
        let want = cvec(&q, &qd);
        assert!((cq - want).abs().max() < 1e-12 * want.abs().max().max(1.0));
    }
}

#[test]
fn coriolis_matrices_are_consistent_and_skew() {
    let dp = DoublePendulum;
    check_coriolis_matrix(
        |q| {
            let mut m = M2::zeros();
            dp.mass_matrix(q, 0.0, &mut m);
            m
        },
        |q, qd| {
            let mut c = M2::zeros();
            dp.coriolis_matrix(q, qd, 0.0, &mut c);
            c
        },
        |q, qd| {
            let mut c = V2::zeros();
            dp.coriolis_forces(q, qd, 0.0, &mut c);
            c
        },
        4,
    );
    let cp = CartPole;
    check_coriolis_matrix(
        |q| {
            let mut m = M2::zeros();
            cp.mass_matrix(q, 0.0, &mut m);
            m
        },
        |q, qd| {
            let mut c = M2::zeros();
            cp.coriolis_matrix(q, qd, 0.0, &mut c);
            c
        },
        |q, qd| {
            let mut c = V2::zeros();
            cp.coriolis_forces(q, qd, 0.0, &mut c);
            c
        },
        5,
    );
}
