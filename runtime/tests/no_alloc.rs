//! Zero heap allocations in every step and inverse-dynamics call: a counting
//! global allocator (per thread, so the test harness's own threads do not
//! interfere) observes full simulated runs with every integrator, a full
//! inverse-dynamics trajectory, and failing calls.

mod models;

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use flexdyn_runtime::control::{
    servo_run, Coordinates, Feedback, JointPd, Servo, ServoConfig, Target,
};
use flexdyn_runtime::{
    run, AdaptiveRk4, GaussLegendre4, GeneralizedAlpha, GeneralizedAlphaConfig, Integrator,
    IntegratorOf, InverseConfig, InverseDynamics, InverseSolution, Rk4, SemiImplicitEuler, State,
    StepSettings,
};
use models::*;

struct Counting;

thread_local! {
    static ALLOCATIONS: Cell<usize> = const { Cell::new(0) };
}

fn bump() {
    let _ = ALLOCATIONS.try_with(|c| c.set(c.get() + 1));
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        bump();
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        bump();
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        bump();
        unsafe { System.realloc(ptr, layout, new_size) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Allocations made by `f` on this thread.
fn allocations_in(f: impl FnOnce()) -> usize {
    let before = ALLOCATIONS.with(|c| c.get());
    f();
    ALLOCATIONS.with(|c| c.get()) - before
}

#[test]
fn counter_sees_allocations() {
    let n = allocations_in(|| {
        let v = std::hint::black_box(vec![1u8; 16]);
        drop(v);
    });
    assert!(n >= 1);
}

fn simulate<G: Integrator<3, 2, 1>>(mut g: G, dt: f64, steps: usize) -> usize {
    let model = SliderCrank::default();
    let mut s = model.consistent_state(0.3, 8.0);
    let tau = V::<1>::new(0.05);
    allocations_in(|| {
        let summary = run(&mut g, &model, &mut s, &tau, dt, steps, |_, _| {}).expect("run");
        assert_eq!(summary.steps, steps);
    })
}

#[test]
fn full_runs_allocate_nothing() {
    let p = StepSettings::with_projection();
    assert_eq!(simulate(Rk4::new(p), 1e-3, 2000), 0, "RK4");
    assert_eq!(
        simulate(SemiImplicitEuler::new(p), 1e-4, 2000),
        0,
        "semi-implicit Euler"
    );
    assert_eq!(
        simulate(GaussLegendre4::new(p), 1e-3, 2000),
        0,
        "Gauss-Legendre"
    );
    assert_eq!(
        simulate(
            GeneralizedAlpha::<3, 2>::new(p, GeneralizedAlphaConfig::default()),
            2e-3,
            1000
        ),
        0,
        "gen-alpha"
    );
    assert_eq!(
        simulate(AdaptiveRk4::default(), 1e-2, 100),
        0,
        "adaptive RK4 (fixed intervals)"
    );

    // Adaptive stepping to a target time.
    let model = SliderCrank::default();
    let mut s = model.consistent_state(0.3, 8.0);
    let mut g = AdaptiveRk4::new(1e-9, 1e-11);
    let n = allocations_in(|| {
        let r = g
            .advance_to(&model, &mut s, &V::<1>::zeros(), 2.0, 1e-3, 1_000_000)
            .expect("advance");
        assert!(r.reached);
    });
    assert_eq!(n, 0, "adaptive advance_to");

    // Stiff model with the implicit scheme, finite-difference Jacobians.
    let chain = SpringChain::<4>::stiff();
    let mut s = State::new(V::<4>::from_element(0.01), V::<4>::zeros(), 0.0);
    let mut g = GeneralizedAlpha::<4, 0>::default();
    let n = allocations_in(|| {
        run(
            &mut g,
            &chain,
            &mut s,
            &V::<1>::zeros(),
            5e-3,
            2000,
            |_, _| {},
        )
        .expect("run");
    });
    assert_eq!(n, 0, "gen-alpha stiff chain");
}

#[test]
fn inverse_dynamics_trajectory_allocates_nothing() {
    let model = FiveBar::<2>::default();
    let mut id = InverseDynamics::<6, 4, 2, 2>::new(
        [4, 5],
        model.assemble(0.04, 0.32),
        InverseConfig::default(),
    )
    .expect("set-up");
    let mut out = InverseSolution::default();
    let n = allocations_in(|| {
        for k in 0..2000 {
            let t = k as f64 * 1e-3;
            let w = core::f64::consts::PI;
            let (s, c) = (w * t).sin_cos();
            let p = V::<2>::new(0.04 * c, 0.32 + 0.04 * s);
            let v = V::<2>::new(-0.04 * w * s, 0.04 * w * c);
            let a = V::<2>::new(-0.04 * w * w * c, -0.04 * w * w * s);
            id.solve(&model, t, &p, &v, &a, &mut out)
                .expect("inverse dynamics");
        }
    });
    assert_eq!(n, 0);
}

#[test]
fn failing_calls_allocate_nothing() {
    let model = Pendulum::default();
    let mut s = State::new(V::<1>::new(f64::NAN), V::<1>::zeros(), 0.0);
    let n = allocations_in(|| {
        assert!(Rk4::default()
            .step(&model, &mut s, &V::<1>::zeros(), 1e-3)
            .is_err());
        assert!(GeneralizedAlpha::<1, 0>::default()
            .step(&model, &mut s, &V::<1>::zeros(), 1e-3)
            .is_err());
        s.q[0] = 0.1;
        assert!(Rk4::default()
            .step(&model, &mut s, &V::<1>::zeros(), -1.0)
            .is_err());
    });
    assert_eq!(n, 0);
}

#[test]
fn control_loops_allocate_nothing() {
    let model = FiveBar::<2>::default();
    let q0 = model.assemble(0.04, 0.32);
    let d = platform_circle(0.0);
    let mut id =
        InverseDynamics::<6, 4, 2, 2>::new([4, 5], q0, InverseConfig::default()).expect("set-up");
    let mut start = InverseSolution::default();
    id.solve(
        &model,
        0.0,
        &d.position,
        &d.velocity,
        &d.acceleration,
        &mut start,
    )
    .expect("start on the circle");
    let settings = StepSettings::with_projection();
    // PD on the two base joints towards their starting angles.
    let (th1, th2) = (start.q[0], start.q[2]);
    let hold = move |_t: f64| Target {
        position: V::<2>::new(th1, th2),
        velocity: V::<2>::zeros(),
        acceleration: V::<2>::zeros(),
    };
    let pd = JointPd::<_, 6, 2>::new([0, 2], [50.0; 2], [5.0; 2], hold).expect("PD");
    let closed = Feedback::new(&model, pd);
    let mut s = State::new(start.q, start.qd, 0.0);
    let mut g = GeneralizedAlpha::<6, 4>::new(settings, GeneralizedAlphaConfig::default());
    let n = allocations_in(|| {
        run(
            &mut g,
            &closed,
            &mut s,
            &V::<2>::zeros(),
            2e-3,
            500,
            |_, _| {},
        )
        .expect("PD run");
    });
    assert_eq!(n, 0, "PD feedback");
    // Servo constraints on the platform, and a failing solve.
    let servo = Servo::new(
        &model,
        Coordinates([4, 5]),
        platform_circle,
        ServoConfig::default(),
    )
    .expect("servo");
    let mut s = State::new(start.q, start.qd, 0.0);
    let mut g = GeneralizedAlpha::<6, 4>::new(settings, GeneralizedAlphaConfig::default());
    let mut samples = 0;
    let n = allocations_in(|| {
        servo_run(&servo, &mut g, &mut s, 2e-3, 500, |_| {
            samples += 1;
            core::ops::ControlFlow::Continue(())
        })
        .expect("servo run");
        let bad = V::<6>::from_element(f64::NAN);
        assert!(servo.solve(&bad, &bad, 0.0).is_err());
    });
    assert_eq!((n, samples), (0, 501), "servo run");
}
