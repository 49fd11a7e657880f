//! `scenes/ur5_flexible.toml` is `scenes/ur5_flexible_forearm.toml` with
//! harmonic-drive torsion at the shoulder-lift and elbow joints, and
//! nothing else: with `P` the map from its coordinates to the forearm
//! robot's (link angle = motor angle + twist, every other coordinate
//! copied), its energies are the forearm robot's at `P q` plus the rotors'
//! `J qd_m^2 / 2`, the gears' `k e^2 / 2` and their dampers' `c ed^2 / 2`,
//! so `M = P^T M_ff P + J` on the motor diagonals and
//! `h = P^T h_ff(P q, P qd) + k e + c ed` on the twist rows. Checked at
//! seeded states against the independently generated forearm scene.

use flexdyn::runtime::nalgebra::{SMatrix, SVector};
use flexdyn::runtime::Model;
use flexdyn::scenes::{ur5_flexible::Ur5Flexible, ur5_flexible_forearm::Ur5FlexibleForearm};

/// Rotor inertia (the actuators' armature), gear stiffness and damping of
/// the shoulder lift and the elbow, as stated in the scene file.
const ARMATURE: [f64; 2] = [0.1, 0.1];
const STIFFNESS: [f64; 2] = [1.1e5, 6.7e4];
const DAMPING: [f64; 2] = [10.0, 10.0];
/// Indices of the motor angles and the twists in the flexible scene.
const MOTOR: [usize; 2] = [1, 2];
const TWIST: [usize; 2] = [6, 7];

/// The forearm robot's coordinates from the flexible robot's.
fn map() -> SMatrix<f64, 8, 10> {
    let mut p = SMatrix::<f64, 8, 10>::zeros();
    for i in 0..6 {
        p[(i, i)] = 1.0;
    }
    for j in 0..2 {
        p[(MOTOR[j], TWIST[j])] = 1.0;
        p[(6 + j, 8 + j)] = 1.0;
    }
    p
}

#[test]
fn flexible_ur5_is_the_forearm_robot_with_geared_joints() {
    let p = map();
    let mut seed = 0x2545_f491_4f6c_dd1d_u64;
    let mut uniform = move |lo: f64, hi: f64| {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        lo + (hi - lo) * (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    for _ in 0..200 {
        let mut q = SVector::<f64, 10>::zeros();
        let mut qd = SVector::<f64, 10>::zeros();
        for i in 0..10 {
            // Twists and modal coordinates small, as in service.
            let (a, v) = if i < 6 { (3.0, 3.0) } else { (0.01, 0.5) };
            q[i] = uniform(-a, a);
            qd[i] = uniform(-v, v);
        }
        let (qf, qdf) = (p * q, p * qd);

        let mut m = SMatrix::<f64, 10, 10>::zeros();
        let mut mf = SMatrix::<f64, 8, 8>::zeros();
        Ur5Flexible.mass_matrix(&q, 0.0, &mut m);
        Ur5FlexibleForearm.mass_matrix(&qf, 0.0, &mut mf);
        let mut expected_m = p.transpose() * mf * p;
        let mut h = SVector::<f64, 10>::zeros();
        let mut hf = SVector::<f64, 8>::zeros();
        Ur5Flexible.bias(&q, &qd, 0.0, &mut h);
        Ur5FlexibleForearm.bias(&qf, &qdf, 0.0, &mut hf);
        let mut expected_h = p.transpose() * hf;
        for j in 0..2 {
            expected_m[(MOTOR[j], MOTOR[j])] += ARMATURE[j];
            expected_h[TWIST[j]] += STIFFNESS[j] * q[TWIST[j]] + DAMPING[j] * qd[TWIST[j]];
        }

        let m_err = (m - expected_m).abs().max() / expected_m.abs().max();
        let h_err = (h - expected_h).abs().max() / expected_h.abs().max();
        assert!(m_err < 1e-12, "mass matrix differs by {m_err:e} at q = {q}");
        assert!(
            h_err < 1e-12,
            "bias differs by {h_err:e} at q = {q}, qd = {qd}"
        );
    }
}
