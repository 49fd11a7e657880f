//! The generated `actuator_forces` (`f = B tau` from the non-zero entries of
//! the actuator map) of every shipped scene against the dense product of
//! the same scene's generated `actuator_map` with the inputs; the
//! interpreter has none (the runtime forms `B tau` from the map there), and
//! the runtime's forward dynamics takes the generated forces.

mod common;

use flexdyn::scenes as compiled;
use nalgebra::{DMatrix, DVector};
use rand::Rng;

/// Inputs per scene.
const INPUTS: usize = 10;

#[test]
fn generated_actuator_forces_are_the_actuator_map_times_the_inputs() {
    let mut rng = common::rng(21);
    let mut checked = 0;
    for (path, scene) in common::scenes() {
        let model = compiled::model(&scene.name).expect("compiled in");
        let (nq, nu) = (model.nq(), model.nu());
        let mut b = vec![0.0; nq * nu];
        model.actuator_map(&mut b);
        let b = DMatrix::from_column_slice(nq, nu, &b);
        for _ in 0..INPUTS {
            let tau = DVector::from_fn(nu, |_, _| rng.gen_range(-50.0..50.0));
            let want = &b * &tau;
            let mut f = vec![f64::NAN; nq];
            assert!(
                model.actuator_forces(tau.as_slice(), &mut f),
                "{}: generated",
                scene.name
            );
            let scale = want.amax().max(f64::MIN_POSITIVE);
            for (i, (got, want)) in f.iter().zip(want.iter()).enumerate() {
                assert!(
                    (got - want).abs() <= 1e-15 * scale,
                    "{} f[{i}]: {got} vs {want}",
                    scene.name
                );
            }
            checked += 1;
        }
        let interpreted = flexdyn::interpreted::InterpretedModel::load(&path).unwrap();
        let mut f = vec![0.0; nq];
        let tau = vec![1.0; nu];
        assert!(
            !flexdyn::dynamic::DynModel::actuator_forces(&interpreted, &tau, &mut f),
            "{}: the interpreter has no actuator_forces",
            scene.name
        );
    }
    assert!(checked >= 10 * INPUTS, "{checked} inputs checked");
}

/// The runtime's accelerations of an unconstrained scene take the
/// generated forces: the same numbers, bit for bit, as the generated
/// forward dynamics at those forces, which are `B tau` formed from the map.
#[test]
fn accelerations_take_the_generated_actuator_forces() {
    use flexdyn_runtime::{accelerations, DynamicsConfig, Model};
    use nalgebra::SVector;
    let model = flexdyn::scenes::cart_pole::CartPole;
    let (q, qd) = (SVector::from([0.2, -0.4]), SVector::from([0.7, 1.3]));
    let tau = SVector::<f64, 1>::from([2.5]);
    let mut generated = SVector::<f64, 2>::from([f64::NAN; 2]);
    assert!(model.actuator_forces(&tau, &mut generated));
    let mut b = nalgebra::SMatrix::<f64, 2, 1>::zeros();
    model.actuator_map(&mut b);
    assert_eq!(generated, b * tau);
    let a = accelerations(&model, &DynamicsConfig::default(), &q, &qd, 0.0, &tau).unwrap();
    let (mut qdd, mut d) = (SVector::zeros(), SVector::zeros());
    assert!(model.forward_dynamics(&q, &qd, &generated, 0.0, &mut qdd, &mut d));
    assert_eq!(a.qdd, qdd);
}
