//! The two paths of the inverse-dynamics solver: the fast path (square
//! systems inverted by Gauss–Jordan elimination, chord Newton, `lambda`
//! eliminated through the free-coordinate Jacobian) must give what the SVD
//! path gives, and every case outside its assumptions (redundant constraints,
//! redundant actuation, ill-conditioning near a limit) must fall back to the
//! SVD path with unchanged results.

mod models;

use flexdyn_runtime::{
    forces, InverseConfig, InverseDynamics, InverseReport, InverseSolution, Model, SolvePath,
};
use models::*;

const SVD: InverseConfig = InverseConfig {
    position_tolerance: 1e-12,
    max_iterations: 20,
    rank_tolerance: 1e-10,
    max_condition: 1e8,
    max_sweeps: 40,
    fast_path: false,
};

/// Largest deviation of `a` from `b` relative to the size of `b` (at least 1).
fn rel<const R: usize, const C: usize>(a: &Mat<R, C>, b: &Mat<R, C>) -> f64 {
    if R * C == 0 {
        return 0.0;
    }
    (a - b).amax() / b.amax().max(1.0)
}

/// Largest relative deviation between two solutions, over all fields.
fn deviation<const NQ: usize, const NC: usize, const NU: usize>(
    a: &InverseSolution<NQ, NC, NU>,
    b: &InverseSolution<NQ, NC, NU>,
) -> f64 {
    rel(&a.q, &b.q)
        .max(rel(&a.qd, &b.qd))
        .max(rel(&a.qdd, &b.qdd))
        .max(rel(&a.tau, &b.tau))
        .max(rel(&a.lambda, &b.lambda))
}

/// Platform circle of the five-bar tests (radius 4 cm around (0, 0.32)).
fn platform(t: f64) -> (V<2>, V<2>, V<2>) {
    let w = 2.0 + (1.3 * t).sin();
    let wd = 1.3 * (1.3 * t).cos();
    let psi = 2.0 * t - (1.3 * t).cos() / 1.3;
    let (s, c) = psi.sin_cos();
    let r = 0.04;
    (
        V::<2>::new(r * c, 0.32 + r * s),
        V::<2>::new(-r * s * w, r * c * w),
        V::<2>::new(-r * c * w * w - r * s * wd, -r * s * w * w + r * c * wd),
    )
}

/// Solves one point with a fresh solver started at `guess`.
fn one<M, const NQ: usize, const NC: usize, const NU: usize, const NP: usize>(
    model: &M,
    prescribed: [usize; NP],
    guess: V<NQ>,
    config: InverseConfig,
    (p, v, a): (V<NP>, V<NP>, V<NP>),
) -> (InverseSolution<NQ, NC, NU>, InverseReport)
where
    M: Model<NQ, NC, NU>,
{
    let mut id = InverseDynamics::<NQ, NC, NU, NP>::new(prescribed, guess, config).expect("set-up");
    let mut sol = InverseSolution::default();
    let rep = id.solve(model, 0.7, &p, &v, &a, &mut sol).expect("solve");
    (sol, rep)
}

#[test]
fn fast_and_svd_paths_agree_on_the_five_bar() {
    let model = FiveBar::<2>::default();
    // Same positions (exact assembly, no Newton step): the linear solves alone.
    let mut max_same = 0.0f64;
    for k in 0..200 {
        let t = 0.013 * k as f64;
        let x = platform(t);
        let guess = model.assemble(x.0[0], x.0[1]);
        let (fast, rf) = one(&model, [4, 5], guess, InverseConfig::default(), x);
        let (slow, rs) = one(&model, [4, 5], guess, SVD, x);
        assert_eq!((rf.iterations, rs.iterations), (0, 0));
        assert_eq!(rf.kinematics, SolvePath::Elimination);
        assert_eq!(rf.forces.path, SolvePath::Elimination);
        assert_eq!(rs.kinematics, SolvePath::Svd);
        assert_eq!(rs.forces.path, SolvePath::Svd);
        assert_eq!(fast.q, slow.q);
        // The fast path's conditions bound the SVD's from above.
        assert!(rf.jacobian_condition >= rs.jacobian_condition * (1.0 - 1e-12));
        assert!(rf.jacobian_condition <= 4.0 * rs.jacobian_condition);
        assert!(
            rf.forces.actuation_condition >= rs.forces.actuation_condition * (1.0 - 1e-12),
            "{} vs {}",
            rf.forces.actuation_condition,
            rs.forces.actuation_condition
        );
        assert_eq!(rf.forces.constraint_rank, rs.forces.constraint_rank);
        assert!(rf.forces.residual < 1e-12 && rf.velocity_residual < 1e-14);
        max_same = max_same.max(deviation(&fast, &slow));
    }
    // Warm-started trajectories: chord Newton against minimum-norm Newton.
    let x0 = platform(0.0).0;
    let guess = model.assemble(x0[0], x0[1]) + V::<6>::from_element(0.01);
    let mut fast = InverseDynamics::<6, 4, 2, 2>::new([4, 5], guess, InverseConfig::default())
        .expect("set-up");
    let mut slow = InverseDynamics::<6, 4, 2, 2>::new([4, 5], guess, SVD).expect("set-up");
    let (mut sf, mut ss) = (InverseSolution::default(), InverseSolution::default());
    let (mut max_traj, mut max_iter_fast, mut max_iter_svd) = (0.0f64, 0, 0);
    for k in 0..=1000 {
        let t = 1e-3 * k as f64;
        let (p, v, a) = platform(t);
        let rf = fast.solve(&model, t, &p, &v, &a, &mut sf).expect("fast");
        let rs = slow.solve(&model, t, &p, &v, &a, &mut ss).expect("svd");
        if k > 0 {
            max_iter_fast = max_iter_fast.max(rf.iterations);
            max_iter_svd = max_iter_svd.max(rs.iterations);
        }
        max_traj = max_traj.max(deviation(&sf, &ss));
    }
    println!(
        "five-bar fast vs SVD path: max relative deviation {max_same:.1e} (same q), \
         {max_traj:.1e} (warm trajectory); max warm Newton iterations {max_iter_fast} (chord) vs {max_iter_svd}"
    );
    assert!(max_same < 1e-12, "{max_same:e}");
    assert!(max_traj < 1e-11, "{max_traj:e}");
    assert!(max_iter_fast <= 3);
}

#[test]
fn fast_and_svd_paths_agree_on_the_slider_crank() {
    let sc = SliderCrank::default();
    let mut max_dev = 0.0f64;
    for k in 0..40 {
        let theta = 0.3 + 0.15 * k as f64;
        let s = sc.consistent_state(theta, 2.0 - 0.1 * k as f64);
        // Driven by the crank (the actuated coordinate is prescribed) ...
        let x = (V::<1>::new(s.q[0]), V::<1>::new(s.qd[0]), V::<1>::new(1.5));
        let (fast, rf) = one(&sc, [0], s.q, InverseConfig::default(), x);
        let (slow, _) = one(&sc, [0], s.q, SVD, x);
        assert_eq!(
            (rf.kinematics, rf.forces.path),
            (SolvePath::Elimination, SolvePath::Elimination)
        );
        max_dev = max_dev.max(deviation(&fast, &slow));
        // ... and through the slider (actuator on a free coordinate), away
        // from the dead centres.
        if theta.sin().abs() > 0.2 {
            let x = (V::<1>::new(s.q[2]), V::<1>::new(s.qd[2]), V::<1>::new(-0.3));
            let (fast, rf) = one(&sc, [2], s.q, InverseConfig::default(), x);
            let (slow, _) = one(&sc, [2], s.q, SVD, x);
            assert_eq!(
                (rf.kinematics, rf.forces.path),
                (SolvePath::Elimination, SolvePath::Elimination)
            );
            max_dev = max_dev.max(deviation(&fast, &slow));
        }
    }
    println!("slider-crank fast vs SVD path: max relative deviation {max_dev:.1e}");
    assert!(max_dev < 1e-12, "{max_dev:e}");
}

#[test]
fn public_force_solve_paths_agree() {
    // `forces` inverts [Phi_q^T B] when it is square (NC + NU = NQ).
    let model = FiveBar::<2>::default();
    let mut max_dev = 0.0f64;
    for k in 0..50 {
        let x = platform(0.1 * k as f64);
        let (s, _) = one(&model, [4, 5], model.assemble(x.0[0], x.0[1]), SVD, x);
        let (tf, lf, rf) =
            forces(&model, &InverseConfig::default(), &s.q, &s.qd, &s.qdd, 0.0).expect("fast");
        let (ts, ls, rs) = forces(&model, &SVD, &s.q, &s.qd, &s.qdd, 0.0).expect("svd");
        assert_eq!((rf.path, rs.path), (SolvePath::Elimination, SolvePath::Svd));
        assert_eq!(rf.constraint_rank, 4);
        assert!(rf.actuation_condition >= rs.actuation_condition * (1.0 - 1e-12));
        assert!(rf.residual < 1e-12);
        max_dev = max_dev.max(rel(&tf, &ts)).max(rel(&lf, &ls));
    }
    assert!(max_dev < 1e-12, "{max_dev:e}");
}

/// The five-bar with its first closure constraint repeated (scaled by 2):
/// five constraints on four free coordinates, `Phi_q` of rank 4.
struct Repeated(FiveBar<2>);

impl Model<6, 5, 2> for Repeated {
    const NAME: &'static str = "five_bar_repeated_constraint";
    const COORDINATES: [&'static str; 6] = <FiveBar<2> as Model<6, 4, 2>>::COORDINATES;
    const ACTUATORS: [&'static str; 2] = <FiveBar<2> as Model<6, 4, 2>>::ACTUATORS;
    fn mass_matrix(&self, q: &V<6>, t: f64, m: &mut Mat<6, 6>) {
        self.0.mass_matrix(q, t, m)
    }
    fn bias(&self, q: &V<6>, qd: &V<6>, t: f64, h: &mut V<6>) {
        self.0.bias(q, qd, t, h)
    }
    fn constraints(&self, q: &V<6>, t: f64, phi: &mut V<5>) {
        let mut x = V::<4>::zeros();
        self.0.constraints(q, t, &mut x);
        *phi = V::<5>::new(x[0], x[1], x[2], x[3], 2.0 * x[0]);
    }
    fn constraint_jacobian(&self, q: &V<6>, t: f64, j: &mut Mat<5, 6>) {
        let mut x = Mat::<4, 6>::zeros();
        self.0.constraint_jacobian(q, t, &mut x);
        for c in 0..6 {
            for r in 0..4 {
                j[(r, c)] = x[(r, c)];
            }
            j[(4, c)] = 2.0 * x[(0, c)];
        }
    }
    fn constraint_time_derivative(&self, q: &V<6>, t: f64, p: &mut V<5>) {
        let mut x = V::<4>::zeros();
        self.0.constraint_time_derivative(q, t, &mut x);
        *p = V::<5>::new(x[0], x[1], x[2], x[3], 2.0 * x[0]);
    }
    fn constraint_rhs(&self, q: &V<6>, qd: &V<6>, t: f64, g: &mut V<5>) {
        let mut x = V::<4>::zeros();
        self.0.constraint_rhs(q, qd, t, &mut x);
        *g = V::<5>::new(x[0], x[1], x[2], x[3], 2.0 * x[0]);
    }
    fn actuator_map(&self, b: &mut Mat<6, 2>) {
        self.0.actuator_map(b)
    }
    fn kinetic_energy(&self, q: &V<6>, qd: &V<6>, t: f64) -> f64 {
        self.0.kinetic_energy(q, qd, t)
    }
    fn potential_energy(&self, q: &V<6>, t: f64) -> f64 {
        self.0.potential_energy(q, t)
    }
}

#[test]
fn redundant_cases_fall_back_to_the_svd() {
    let fb2 = FiveBar::<2>::default();
    let fb3 = FiveBar::<3>::default();
    let repeated = Repeated(fb2);
    let mut max_dev = 0.0f64;
    for k in 0..30 {
        let x = platform(0.2 * k as f64);
        let guess = fb2.assemble(x.0[0], x.0[1]) + V::<6>::from_element(0.005);
        // Redundant actuation: kinematics on the fast path, forces (6 x 7)
        // by the SVD: minimum-norm torques exactly as with the fast path off.
        let (fast, rf) = one(&fb3, [4, 5], guess, InverseConfig::default(), x);
        let (slow, rs) = one(&fb3, [4, 5], guess, SVD, x);
        assert_eq!(rf.kinematics, SolvePath::Elimination);
        assert_eq!(
            (rf.forces.path, rs.forces.path),
            (SolvePath::Svd, SolvePath::Svd)
        );
        assert!(
            (rf.forces.actuation_condition - rs.forces.actuation_condition).abs()
                < 1e-12 * rs.forces.actuation_condition
        );
        max_dev = max_dev.max(deviation(&fast, &slow));
        // Redundant constraints: J_f is 5 x 4, everything by the SVDs, same
        // motion and torques as the non-redundant model.
        let (red, rr) = one(&repeated, [4, 5], guess, InverseConfig::default(), x);
        let (plain, _) = one(&fb2, [4, 5], guess, SVD, x);
        assert_eq!(
            (rr.kinematics, rr.forces.path),
            (SolvePath::Svd, SolvePath::Svd)
        );
        assert_eq!(rr.forces.constraint_rank, 4);
        assert!(rr.forces.residual < 1e-10);
        for (a, b) in [(red.q, plain.q), (red.qd, plain.qd), (red.qdd, plain.qdd)] {
            max_dev = max_dev.max(rel(&a, &b));
        }
        max_dev = max_dev.max(rel(&red.tau, &plain.tau));
    }
    println!("redundant cases: max relative deviation from the reference {max_dev:.1e}");
    assert!(max_dev < 1e-11, "{max_dev:e}");
}

#[test]
fn ill_conditioning_near_the_limit_is_decided_by_the_svd() {
    // Slider-crank driven through the slider close to the dead centre: J_f
    // is ill conditioned. With the limit just above the SVD's condition
    // number (below the fast path's upper bound |J|_F |J^-1|_F = k + 1/k for
    // a 2 x 2 matrix of condition k) the fast path must defer to the SVD,
    // which accepts; with a looser limit the fast path takes it.
    let sc = SliderCrank::default();
    let s = sc.consistent_state(0.01, 0.5);
    let x = (V::<1>::new(s.q[2]), V::<1>::new(s.qd[2]), V::<1>::zeros());
    let (reference, r0) = one(&sc, [2], s.q, SVD, x);
    let kappa = r0.jacobian_condition;
    assert!(kappa > 50.0, "ill conditioned: {kappa}");
    let tight = InverseConfig {
        max_condition: kappa + 0.5 / kappa,
        ..Default::default()
    };
    let (sol, rep) = one(&sc, [2], s.q, tight, x);
    assert_eq!(rep.kinematics, SolvePath::Svd);
    assert_eq!(rep.jacobian_condition, kappa);
    assert!(deviation(&sol, &reference) < 1e-12);
    let loose = InverseConfig {
        max_condition: 2.0 * kappa,
        ..Default::default()
    };
    let (sol, rep) = one(&sc, [2], s.q, loose, x);
    assert_eq!(rep.kinematics, SolvePath::Elimination);
    assert!(rep.jacobian_condition >= kappa && rep.jacobian_condition <= 2.0 * kappa);
    // Ill-conditioned systems lose digits on both paths.
    assert!(
        deviation(&sol, &reference) < 1e-12 * kappa,
        "{:e}",
        deviation(&sol, &reference)
    );
    // Beyond the limit on both paths: the SVD's error, with its condition.
    let strict = InverseConfig {
        max_condition: 0.5 * kappa,
        ..Default::default()
    };
    let mut id = InverseDynamics::<3, 2, 1, 1>::new([2], s.q, strict).expect("set-up");
    let e = id
        .solve(&sc, 0.0, &x.0, &x.1, &x.2, &mut InverseSolution::default())
        .expect_err("ill conditioned");
    assert_eq!(
        e.kind,
        flexdyn_runtime::ErrorKind::SingularConstraintJacobian {
            condition: kappa,
            limit: 0.5 * kappa
        }
    );
}

#[test]
fn chord_newton_recovers_from_jumps_and_stale_inverses() {
    let model = FiveBar::<2>::default();
    let x0 = platform(0.0).0;
    let guess = model.assemble(x0[0], x0[1]);
    let mut fast = InverseDynamics::<6, 4, 2, 2>::new([4, 5], guess, InverseConfig::default())
        .expect("set-up");
    let mut sol = InverseSolution::default();
    for k in 0..50 {
        let t = 1e-3 * k as f64;
        let (p, v, a) = platform(t);
        fast.solve(&model, t, &p, &v, &a, &mut sol).expect("warm");
    }
    // A jump of several centimetres: the stale inverse does not contract,
    // Newton re-factors and lands on the same assembly as the closed form.
    let far = (
        V::<2>::new(-0.05, 0.36),
        V::<2>::new(0.1, 0.0),
        V::<2>::zeros(),
    );
    let rep = fast
        .solve(&model, 1.0, &far.0, &far.1, &far.2, &mut sol)
        .expect("jump");
    assert!((sol.q - model.assemble(-0.05, 0.36)).amax() < 1e-10);
    assert!(rep.iterations <= 8, "{}", rep.iterations);
    let (reference, _) = one(&model, [4, 5], model.assemble(-0.05, 0.36), SVD, far);
    assert!(deviation(&sol, &reference) < 1e-11);
    // A different model (longer distal links) with the inverse left from
    // this one: still converges to that model's assembly.
    let other = FiveBar::<2> { l2: 0.31, ..model };
    let mut copy = fast;
    copy.solve(&other, 1.0, &far.0, &far.1, &far.2, &mut sol)
        .expect("other model");
    assert!((sol.q - other.assemble(-0.05, 0.36)).amax() < 1e-10);
    // set_guess drops the inverse with the old guess.
    let mut reset = fast;
    reset.set_guess(guess);
    let (p, v, a) = platform(0.0);
    reset
        .solve(&model, 0.0, &p, &v, &a, &mut sol)
        .expect("reset");
    assert!((sol.q - guess).amax() < 1e-10);
}
