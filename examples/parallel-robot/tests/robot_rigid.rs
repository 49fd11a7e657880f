//! Issue 4: the rigid parallel robot's inverse dynamics checked against
//! independent references: the power balance, the principle of virtual work
//! (with the geometry written out here, not taken from generated code), and
//! the three-fold symmetry of the centred circle.

use flexdyn::runtime::Model;
use flexdyn_parallel_robot::robot::{
    azimuth, inverse_along, inverse_kinematics, Circle, Geometry, RigidSolution,
};
use flexdyn_parallel_robot::scenes::parallel_robot_rigid::ParallelRobotRigid;

const G: Geometry = Geometry::SPEC;

fn solve(circle: &Circle, times: &[f64]) -> Vec<RigidSolution> {
    inverse_along(&ParallelRobotRigid, &G, circle, times, &mut || {}).unwrap()
}

fn energy(s: &RigidSolution) -> f64 {
    let m = ParallelRobotRigid;
    m.kinetic_energy(&s.q, &s.qd, s.t) + m.potential_energy(&s.q, s.t)
}

#[test]
fn power_balance_along_the_circle() {
    let off_centre = Circle {
        omega: 3.0,
        radius: 0.08,
        center: [0.05, -0.03, 0.65],
    };
    for circle in [Circle::paper(2.0), off_centre] {
        power_balance(&circle);
    }
}

fn power_balance(circle: &Circle) {
    let h = 1e-4;
    let mut worst: f64 = 0.0;
    let mut peak: f64 = 0.0;
    for k in 0..60 {
        let t = 0.05 + k as f64 * 0.05;
        let s = solve(circle, &[t - h, t, t + h]);
        // Actuator power: tau_i times the rate of theta_i1.
        let power: f64 = (0..3).map(|i| s[1].tau[i] * s[1].qd[3 * i]).sum();
        // d(T+V)/dt by central differences in time along the motion.
        let de = (energy(&s[2]) - energy(&s[0])) / (2.0 * h);
        worst = worst.max((power - de).abs());
        peak = peak.max(power.abs());
    }
    assert!(peak > 1e-3, "the motion does work: peak power {peak}");
    eprintln!("power balance: worst error {worst:.3e} W, peak power {peak:.3e} W");
    assert!(
        worst <= 1e-6 * peak,
        "power balance error {worst} W against peak {peak} W"
    );
}

/// Centre of mass positions and masses of every body for a platform
/// position, from the closed-form inverse kinematics and the spec's geometry.
fn bodies(p: [f64; 3]) -> Vec<(f64, [f64; 3])> {
    let q = inverse_kinematics(&G, p).unwrap();
    let mut out = vec![(2.6, p)];
    for i in 0..3 {
        let (s, c) = azimuth(i).sin_cos();
        let u = [c, s, 0.0];
        let y = [-s, c, 0.0];
        let (t1, t2, t3) = (q[3 * i], q[3 * i + 1], q[3 * i + 2]);
        let a: [f64; 3] = std::array::from_fn(|k| G.ra * u[k]);
        let e1: [f64; 3] = std::array::from_fn(|k| t1.cos() * u[k] + t1.sin() * [0.0, 0.0, 1.0][k]);
        let d: [f64; 3] = std::array::from_fn(|k| t2.cos() * u[k] + t2.sin() * [0.0, 0.0, 1.0][k]);
        let e: [f64; 3] = std::array::from_fn(|k| t3.cos() * d[k] + t3.sin() * y[k]);
        let b: [f64; 3] = std::array::from_fn(|k| a[k] + G.l1 * e1[k]);
        let cc: [f64; 3] = std::array::from_fn(|k| b[k] + G.l2 * d[k]);
        let tip: [f64; 3] = std::array::from_fn(|k| cc[k] + G.l3 * e[k]);
        let mid =
            |x: [f64; 3], z: [f64; 3]| -> [f64; 3] { std::array::from_fn(|k| 0.5 * (x[k] + z[k])) };
        out.push((2.0, mid(a, b)));
        out.push((0.3, mid(b, cc)));
        out.push((1.5, mid(cc, tip)));
    }
    out
}

fn gravity_potential(p: [f64; 3]) -> f64 {
    bodies(p).iter().map(|(m, c)| m * 9.81 * c[2]).sum()
}

fn actuated(p: [f64; 3]) -> [f64; 3] {
    let q = inverse_kinematics(&G, p).unwrap();
    [q[0], q[3], q[6]]
}

#[test]
fn static_torques_follow_virtual_work() {
    for p in [[0.0, 0.0, 0.7], [0.08, -0.05, 0.65], [-0.1, 0.06, 0.75]] {
        let at_rest = Circle {
            omega: 0.0,
            radius: 0.0,
            center: p,
        };
        let tau = solve(&at_rest, &[0.0])[0].tau;
        // tau^T d(theta_a)/dP = dV/dP, all derivatives by central differences.
        let h = 1e-6;
        let mut jac = flexdyn::runtime::nalgebra::Matrix3::<f64>::zeros();
        let mut dv = flexdyn::runtime::nalgebra::Vector3::<f64>::zeros();
        for k in 0..3 {
            let mut pp = p;
            pp[k] += h;
            let mut pm = p;
            pm[k] -= h;
            let (ap, am) = (actuated(pp), actuated(pm));
            for i in 0..3 {
                jac[(i, k)] = (ap[i] - am[i]) / (2.0 * h);
            }
            dv[k] = (gravity_potential(pp) - gravity_potential(pm)) / (2.0 * h);
        }
        let reference = jac.transpose().lu().solve(&dv).unwrap();
        for i in 0..3 {
            assert!(
                (tau[i] - reference[i]).abs() < 1e-6 * reference.abs().max(),
                "at {p:?}: tau {tau:?} vs virtual work {reference:?}"
            );
        }
    }
}

#[test]
fn centred_circle_torques_are_one_curve_shifted_by_a_third() {
    let omega = 2.0;
    let circle = Circle::paper(omega);
    let third = 2.0 * std::f64::consts::PI / 3.0 / omega;
    let times: Vec<f64> = (0..40).map(|k| 1.0 + 0.07 * k as f64).collect();
    let now = solve(&circle, &times);
    let earlier: Vec<f64> = times.iter().map(|t| t - third).collect();
    let before = solve(&circle, &earlier);
    let later: Vec<f64> = times.iter().map(|t| t - 2.0 * third).collect();
    let before2 = solve(&circle, &later);
    for k in 0..times.len() {
        assert!(
            (now[k].tau[1] - before[k].tau[0]).abs() < 1e-9,
            "tau_2(t) = tau_1(t - T/3)"
        );
        assert!(
            (now[k].tau[2] - before2[k].tau[0]).abs() < 1e-9,
            "tau_3(t) = tau_1(t - 2T/3)"
        );
    }
}

#[test]
fn unreachable_points_are_clear_errors() {
    let far = Circle {
        omega: 1.0,
        radius: 0.1,
        center: [0.0, 0.0, 1.6],
    };
    let e = inverse_along(&ParallelRobotRigid, &G, &far, &[0.0], &mut || {}).unwrap_err();
    assert!(e.contains("out of reach"), "{e}");
    // A circle that leaves the workspace part-way: the error names the time.
    let wide = Circle {
        omega: 1.0,
        radius: 1.2,
        center: [0.0, 0.0, 0.7],
    };
    let times: Vec<f64> = (0..700).map(|k| k as f64 * 0.01).collect();
    let e = match inverse_along(&ParallelRobotRigid, &G, &wide, &times, &mut || {}) {
        Ok(_) => panic!("the wide circle should leave the workspace"),
        Err(e) => e,
    };
    assert!(e.starts_with("at t = "), "{e}");
}

/// Issue 4: a platform position that puts chain 1's planar arm (driving link
/// l1 and L = l2 + l3, the driven link in the plane) within `eps` of fully
/// stretched is refused as near-singular, and the reported condition number
/// equals that of the arm's 2x2 Jacobian computed here by SVD; slightly
/// further in, the same arm is accepted.
#[test]
fn near_singular_poses_are_refused_with_their_condition_number() {
    use flexdyn::runtime::nalgebra::Matrix2;
    use flexdyn_parallel_robot::robot::{IkError, MAX_CONDITION};
    let big_l = G.l2 + G.l3;
    let direction = -1.2f64; // of the stretched arm in chain 1's x-z plane, rad
    let pose = |eps: f64| {
        let d = G.l1 + big_l - eps;
        let p = [G.ra - G.rp + d * direction.cos(), 0.0, d * direction.sin()];
        // The arm's Jacobian in absolute link angles, from the law of cosines.
        let beta = ((d * d - G.l1 * G.l1 - big_l * big_l) / (2.0 * G.l1 * big_l)).acos();
        let th1 = direction - (big_l * beta.sin()).atan2(G.l1 + big_l * beta.cos());
        let th2 = th1 + beta;
        let j = Matrix2::new(
            -G.l1 * th1.sin(),
            -big_l * th2.sin(),
            G.l1 * th1.cos(),
            big_l * th2.cos(),
        );
        let sv = j.singular_values();
        (p, sv.max() / sv.min())
    };
    let (p, expected) = pose(1e-12);
    assert!(expected > MAX_CONDITION, "{expected:e}");
    match inverse_kinematics(&G, p) {
        Err(IkError::NearSingular { chain, condition }) => {
            assert_eq!(chain, 0);
            assert!(
                (condition / expected - 1.0).abs() < 1e-3,
                "{condition:e} vs {expected:e}"
            );
            let msg = IkError::NearSingular { chain, condition }.to_string();
            assert!(
                msg.contains("chain 1") && msg.contains("condition number"),
                "{msg}"
            );
        }
        other => panic!("expected a near-singular refusal, got {other:?}"),
    }
    let (p, expected) = pose(1e-3);
    assert!(expected < MAX_CONDITION, "{expected:e}");
    assert!(
        flexdyn_parallel_robot::robot::chain_ik(&G, 0, p).is_ok(),
        "a pose 1 mm from stretched must still solve for chain 1"
    );
}
