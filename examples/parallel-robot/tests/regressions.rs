//! Regression tests, each named after the issue it came from.

use flexdyn::runtime::integrate::{GeneralizedAlpha, StepSettings};
use flexdyn::runtime::nalgebra::SVector;
use flexdyn::runtime::{total_energy, IntegratorOf};
use flexdyn_parallel_robot::robot::{initial_state, Circle, Geometry, Layout};
use flexdyn_parallel_robot::scenes::parallel_robot_flexible::ParallelRobotFlexible;

/// Issue 3: with the generated bias Jacobians (which leave out the
/// derivatives of `M a` and of the constraint forces), generalized-alpha's
/// Newton stalled at t = 0.69 s when the flexible robot falls from rest
/// under gravity with zero torque at the paper's 5 ms step. The fall is
/// conservative (no damping in the scene) and the scheme dissipates, so the
/// energy may only decrease: checked along the run.
#[test]
fn issue_3_generalized_alpha_with_generated_jacobians_survives_free_fall() {
    let model = ParallelRobotFlexible::default();
    let layout = Layout::of(&model).unwrap();
    let p0 = Circle::paper(2.0).at(0.0)[0];
    let mut state = initial_state(&model, &layout, &Geometry::SPEC, 0.0, p0, [0.0; 3]).unwrap();
    let e0 = total_energy(&model, &state);
    let mut integrator =
        GeneralizedAlpha::<39, 12>::new(StepSettings::default(), Default::default());
    let tau = SVector::<f64, 3>::zeros();
    let mut fallen = 0.0f64;
    for _ in 0..200 {
        integrator
            .step(&model, &mut state, &tau, 0.005)
            .unwrap_or_else(|e| panic!("step failed: {e:?}"));
        let e = total_energy(&model, &state);
        assert!(
            e <= e0 + 1e-6 * e0.abs().max(1.0),
            "energy grew at t = {}: {e} > {e0}",
            state.t
        );
        fallen = fallen.max((state.q[layout.platform[2]] - p0[2]).abs());
    }
    // It did fall (the test exercises large motion, not a resting robot).
    assert!(fallen > 0.05, "platform moved only {fallen} m");
}
