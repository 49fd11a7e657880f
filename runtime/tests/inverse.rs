//! Inverse dynamics: five-bar parallel robot with a prescribed platform
//! trajectory, a redundantly actuated variant, and the slider-crank driven
//! through its slider. Checks against closed-form kinematics, finite
//! differences, energy (power balance) and a forward-dynamics round trip.

mod models;

use flexdyn_runtime::{
    total_energy, FromFn, InverseConfig, InverseDynamics, InverseSolution, Model, Rk4, State,
    StepSettings,
};
use flexdyn_runtime::{IntegratorOf, ProjectionConfig};
use models::*;

/// Platform trajectory: a circle of radius 4 cm around (0, 0.32) traversed
/// with a non-uniform speed. Returns (p, v, a).
fn platform(t: f64) -> (V<2>, V<2>, V<2>) {
    let (xc, yc, r) = (0.0, 0.32, 0.04);
    let psi = 2.0 * core::f64::consts::PI * 0.5 * t + 0.5 * (3.0 * t).sin();
    let psid = core::f64::consts::PI + 1.5 * (3.0 * t).cos();
    let psidd = -4.5 * (3.0 * t).sin();
    let (s, c) = psi.sin_cos();
    let p = V::<2>::new(xc + r * c, yc + r * s);
    let v = V::<2>::new(-r * s * psid, r * c * psid);
    let a = V::<2>::new(
        -r * c * psid * psid - r * s * psidd,
        -r * s * psid * psid + r * c * psidd,
    );
    (p, v, a)
}

fn five_bar_solver<const NU: usize>(model: &FiveBar<NU>) -> InverseDynamics<6, 4, NU, 2> {
    let (p0, _, _) = platform(0.0);
    // Start the Newton iteration from a rough guess near the assembly.
    let guess = model.assemble(p0[0], p0[1]) + V::<6>::from_element(0.02);
    InverseDynamics::new([4, 5], guess, InverseConfig::default()).expect("valid set-up")
}

#[test]
fn five_bar_kinematics_match_closed_form_and_finite_differences() {
    let model = FiveBar::<2>::default();
    let mut solver = five_bar_solver(&model);
    let mut sol = InverseSolution::default();
    let (dt, n) = (1e-3, 2000);
    let (mut max_iter, mut max_cond, mut max_res, mut max_fd) = (0u32, 0.0f64, 0.0f64, 0.0f64);
    for k in 0..=n {
        let t = k as f64 * dt;
        let (p, v, a) = platform(t);
        let rep = solver
            .solve(&model, t, &p, &v, &a, &mut sol)
            .expect("inverse dynamics");
        if k > 0 {
            max_iter = max_iter.max(rep.iterations);
        }
        max_cond = max_cond.max(rep.jacobian_condition);
        max_res = max_res.max(rep.position_residual).max(rep.forces.residual);
        // Closed-form inverse kinematics (independent of the solver).
        let q_exact = model.assemble(p[0], p[1]);
        assert!(
            (sol.q - q_exact).amax() < 1e-10,
            "t={t}: {} vs {}",
            sol.q,
            q_exact
        );
        // Velocities and accelerations against central differences of the
        // closed-form positions and of the velocities.
        if k % 100 == 50 {
            let d = 1e-5;
            let (pp, vp, _) = platform(t + d);
            let (pm, vm, _) = platform(t - d);
            let qd_fd = (model.assemble(pp[0], pp[1]) - model.assemble(pm[0], pm[1])) / (2.0 * d);
            let mut aux = five_bar_solver(&model);
            let mut sp = InverseSolution::default();
            let mut sm = InverseSolution::default();
            aux.solve(&model, t + d, &pp, &vp, &platform(t + d).2, &mut sp)
                .expect("id");
            aux.solve(&model, t - d, &pm, &vm, &platform(t - d).2, &mut sm)
                .expect("id");
            let qdd_fd = (sp.qd - sm.qd) / (2.0 * d);
            max_fd = max_fd
                .max((sol.qd - qd_fd).amax())
                .max((sol.qdd - qdd_fd).amax() * 1e-2);
            assert!((sol.qd - qd_fd).amax() < 1e-7 * sol.qd.amax().max(1.0));
            assert!((sol.qdd - qdd_fd).amax() < 1e-5 * sol.qdd.amax().max(1.0));
        }
    }
    println!(
        "five-bar ID, 2001 ticks: max Newton iterations (warm) {max_iter}, max Jacobian condition {max_cond:.1}, \
         max residual {max_res:.1e}, max FD deviation {max_fd:.1e}"
    );
    assert!(max_iter <= 3);
    assert!(max_res < 1e-11);
}

/// Along any inverse-dynamics trajectory of a conservative scene the input
/// power tau . (B^T qd) equals d(T + V)/dt (constraint forces do no work).
fn power_balance<const NU: usize>(model: &FiveBar<NU>) -> f64 {
    let mut solver = five_bar_solver(model);
    let mut sol = InverseSolution::default();
    let mut b = Mat::<6, NU>::zeros();
    model.actuator_map(&mut b);
    let energy_at = |solver: &mut InverseDynamics<6, 4, NU, 2>, t: f64| {
        let (p, v, a) = platform(t);
        let mut s = InverseSolution::default();
        solver.solve(model, t, &p, &v, &a, &mut s).expect("id");
        total_energy(model, &State::new(s.q, s.qd, t))
    };
    let (mut max_err, mut max_power) = (0.0f64, 0.0f64);
    for k in 0..40 {
        let t = 0.05 * k as f64;
        let (p, v, a) = platform(t);
        solver.solve(model, t, &p, &v, &a, &mut sol).expect("id");
        let power = sol.tau.dot(&(b.transpose() * sol.qd));
        let d = 1e-4;
        let mut aux = solver;
        let de_dt = (energy_at(&mut aux, t + d) - energy_at(&mut aux, t - d)) / (2.0 * d);
        max_err = max_err.max((power - de_dt).abs());
        max_power = max_power.max(power.abs());
    }
    max_err / max_power
}

#[test]
fn power_balance_along_inverse_dynamics_trajectories() {
    let rel2 = power_balance(&FiveBar::<2>::default());
    let rel3 = power_balance(&FiveBar::<3>::default());
    println!("power balance |tau.B^T qd - dE/dt| / max|power|: five-bar {rel2:.1e}, redundantly actuated {rel3:.1e}");
    assert!(rel2 < 1e-6 && rel3 < 1e-6);
}

#[test]
fn redundant_actuation_gives_minimum_norm_torques() {
    let model = FiveBar::<3>::default();
    let mut solver = five_bar_solver(&model);
    let mut sol = InverseSolution::default();
    let (mut m, mut h, mut b, mut jac) = (
        Mat::<6, 6>::zeros(),
        V::<6>::zeros(),
        Mat::<6, 3>::zeros(),
        Mat::<4, 6>::zeros(),
    );
    model.actuator_map(&mut b);
    for k in 0..10 {
        let t = 0.13 * k as f64;
        let (p, v, a) = platform(t);
        let rep = solver.solve(&model, t, &p, &v, &a, &mut sol).expect("id");
        model.mass_matrix(&sol.q, t, &mut m);
        model.bias(&sol.q, &sol.qd, t, &mut h);
        model.constraint_jacobian(&sol.q, t, &mut jac);
        let r = m * sol.qdd + h;
        // Equations satisfied exactly.
        assert!(
            (jac.transpose() * sol.lambda + b * sol.tau - r).amax() < 1e-10 * r.amax().max(1.0)
        );
        assert!(rep.forces.residual < 1e-10);
        // Minimum norm <=> tau is orthogonal to the null space of N B, where
        // N projects onto the null space of Phi_q. N B has rank 2 with 3
        // columns, so its null space is spanned by the cross product of two
        // independent rows (largest cross product taken).
        let inv = (jac * jac.transpose()).try_inverse().expect("full rank");
        let nb = (Mat::<6, 6>::identity() - jac.transpose() * inv * jac) * b;
        let mut n = V::<3>::zeros();
        for i in 0..6 {
            for j in 0..6 {
                let c = nb.row(i).transpose().cross(&nb.row(j).transpose());
                if c.norm() > n.norm() {
                    n = c;
                }
            }
        }
        let n = n.normalize();
        assert!((nb * n).amax() < 1e-12);
        println!(
            "t {t:.2}: tau {:?}, tau . null(NB) = {:.1e}",
            sol.tau.as_slice(),
            sol.tau.dot(&n)
        );
        assert!(
            sol.tau.dot(&n).abs() < 1e-12 * sol.tau.norm(),
            "not minimum norm"
        );
    }
}

#[test]
fn inverse_then_forward_reproduces_the_motion() {
    // Horizontal five-bar (no gravity: the open-loop motion is not
    // exponentially unstable, so the comparison measures the solvers, not
    // the amplification of round-off).
    let model = FiveBar::<2> {
        g: 0.0,
        ..Default::default()
    };
    let dt = 1e-3;
    let n = 1000;
    // Torques on the half-step grid, where RK4 samples its input.
    let mut solver = five_bar_solver(&model);
    let mut sol = InverseSolution::default();
    let mut table = Vec::with_capacity(2 * n + 1);
    let mut start = State::new(V::<6>::zeros(), V::<6>::zeros(), 0.0);
    for k in 0..=2 * n {
        let t = 0.5 * dt * k as f64;
        let (p, v, a) = platform(t);
        solver.solve(&model, t, &p, &v, &a, &mut sol).expect("id");
        if k == 0 {
            start = State::new(sol.q, sol.qd, 0.0);
        }
        table.push(sol.tau);
    }
    let input = FromFn(|t: f64| {
        let i = ((t / (0.5 * dt)).round() as usize).min(table.len() - 1);
        table[i]
    });
    let settings = StepSettings {
        projection: Some(ProjectionConfig::default()),
        ..Default::default()
    };
    let mut rk4 = Rk4::new(settings);
    let mut s = start;
    let mut max_err = 0.0f64;
    for _ in 0..n {
        rk4.step(&model, &mut s, &input, dt).expect("forward step");
        let (p, _, _) = platform(s.t);
        max_err = max_err.max((s.q[4] - p[0]).abs().max((s.q[5] - p[1]).abs()));
    }
    println!("five-bar inverse -> forward (RK4, dt 1 ms, 1 s): max platform position error {max_err:.1e} m");
    assert!(max_err < 1e-8, "round trip error {max_err:e}");

    // Same for the slider-crank under gravity, prescribing the crank angle.
    let sc = SliderCrank::default();
    let theta = |t: f64| {
        (
            0.3 + 4.0 * t + 0.5 * (2.0 * t).sin(),
            4.0 + (2.0 * t).cos(),
            -2.0 * (2.0 * t).sin(),
        )
    };
    let s0 = sc.consistent_state(theta(0.0).0, theta(0.0).1);
    let mut id =
        InverseDynamics::<3, 2, 1, 1>::new([0], s0.q, InverseConfig::default()).expect("set-up");
    let mut table = Vec::new();
    let mut sol = InverseSolution::default();
    for k in 0..=2 * n {
        let t = 0.5 * dt * k as f64;
        let (p, v, a) = theta(t);
        id.solve(
            &sc,
            t,
            &V::<1>::new(p),
            &V::<1>::new(v),
            &V::<1>::new(a),
            &mut sol,
        )
        .expect("id");
        table.push(sol.tau);
    }
    let input = FromFn(|t: f64| table[((t / (0.5 * dt)).round() as usize).min(table.len() - 1)]);
    let mut s = s0;
    let mut max_err = 0.0f64;
    for _ in 0..n {
        rk4.step(&sc, &mut s, &input, dt).expect("forward step");
        max_err = max_err.max((s.q[0] - theta(s.t).0).abs());
    }
    println!("slider-crank inverse -> forward (RK4, dt 1 ms, 1 s): max crank angle error {max_err:.1e} rad");
    assert!(max_err < 1e-8, "round trip error {max_err:e}");
}

#[test]
fn slider_crank_driven_through_its_slider() {
    // Prescribe the slider position (the "platform"); the crank torque is the
    // actuator. Quasi-static motion: the torque balances gravity along the
    // manifold, tau = dV/dtheta (finite differences of V on the closed-form
    // manifold parametrisation).
    let sc = SliderCrank::default();
    let manifold = |theta: f64| sc.consistent_state(theta, 0.0).q;
    let theta0: f64 = 1.2;
    let mut id =
        InverseDynamics::<3, 2, 1, 1>::new([2], manifold(theta0 + 0.05), InverseConfig::default())
            .expect("set-up");
    let mut sol = InverseSolution::default();
    for k in 0..8 {
        let theta = theta0 + 0.2 * k as f64;
        let x = manifold(theta)[2];
        let rep = id
            .solve(
                &sc,
                0.0,
                &V::<1>::new(x),
                &V::<1>::zeros(),
                &V::<1>::zeros(),
                &mut sol,
            )
            .expect("id");
        // Closed-form crank angle for a slider position: cos th = (x^2 + r^2 - l^2) / (2 x r).
        let th = ((x * x + sc.r * sc.r - sc.l * sc.l) / (2.0 * x * sc.r)).acos();
        assert!((sol.q[0] - th).abs() < 1e-10, "{} vs {th}", sol.q[0]);
        let d = 1e-6;
        let dv = (sc.potential_energy(&manifold(theta + d), 0.0)
            - sc.potential_energy(&manifold(theta - d), 0.0))
            / (2.0 * d);
        assert!(
            (sol.tau[0] - dv).abs() < 1e-8,
            "tau {} vs dV/dtheta {dv}",
            sol.tau[0]
        );
        assert!(rep.jacobian_condition.is_finite());
    }
}
