//! Any scene file behind [`DynModel`], without compiling it in: the
//! generator runs at run time and [`flexdyn_codegen::interpret`] evaluates
//! its scheduled programs, bitwise equal to the compiled module of the same
//! scene (`tests/interpreter_matches_compiled.rs`).

use std::cell::RefCell;
use std::path::Path;
use std::rc::Rc;

use flexdyn_codegen::interpret::{Function, Interpreted};
use nalgebra::{DMatrix, DVector};

use crate::dynamic::{DynModel, Fused};

/// An interpreted scene with its runtime parameter values. Clones share
/// the tapes.
#[derive(Debug, Clone)]
pub struct InterpretedModel {
    scene: Rc<Interpreted>,
    params: Vec<f64>,
    scratch: RefCell<Vec<f64>>,
}

impl InterpretedModel {
    /// Generate a scene file in memory (the generator's error, with file and
    /// line, when it has one), with its nominal parameters.
    pub fn load(path: &Path) -> Result<InterpretedModel, String> {
        Interpreted::load(path)
            .map(InterpretedModel::new)
            .map_err(|e| e.to_string())
    }

    /// A model of an interpreted scene, with its nominal parameters.
    pub fn new(scene: Interpreted) -> InterpretedModel {
        let params = scene.parameters().iter().map(|(_, v)| *v).collect();
        InterpretedModel {
            scene: Rc::new(scene),
            params,
            scratch: RefCell::new(Vec::new()),
        }
    }

    /// The scene's tapes.
    pub fn scene(&self) -> &Interpreted {
        &self.scene
    }

    /// The outputs of `f` (vectors as one-column matrices), `None` when the
    /// scene does not generate it.
    fn outputs(&self, f: Function, q: &[f64], qd: &[f64], t: f64) -> Option<Vec<DMatrix<f64>>> {
        self.outputs_with_accelerations(f, q, qd, &[], t)
    }

    /// [`InterpretedModel::outputs`] of a function that reads the
    /// accelerations `qdd` too.
    fn outputs_with_accelerations(
        &self,
        f: Function,
        q: &[f64],
        qd: &[f64],
        qdd: &[f64],
        t: f64,
    ) -> Option<Vec<DMatrix<f64>>> {
        let tape = self.scene.tape(f)?;
        let mut out = vec![0.0; tape.output_len()];
        tape.eval_with_accelerations(
            q,
            qd,
            qdd,
            t,
            &self.params,
            &mut self.scratch.borrow_mut(),
            &mut out,
        );
        let mut rest = out.as_slice();
        Some(
            tape.shapes()
                .iter()
                .map(|&(r, c)| {
                    let (this, tail) = rest.split_at(r * c);
                    rest = tail;
                    DMatrix::from_column_slice(r, c, this)
                })
                .collect(),
        )
    }

    /// The first output of `f`.
    fn first(&self, f: Function, q: &[f64], qd: &[f64], t: f64) -> Option<DMatrix<f64>> {
        self.outputs(f, q, qd, t).map(|mut o| o.swap_remove(0))
    }

    /// The outputs of a function every scene has.
    fn core(&self, f: Function, q: &[f64], qd: &[f64], t: f64) -> Vec<DMatrix<f64>> {
        self.outputs(f, q, qd, t)
            .unwrap_or_else(|| panic!("`{}` is lowered for every scene", f.name()))
    }

    fn core_matrix(&self, f: Function, q: &[f64], qd: &[f64], t: f64) -> DMatrix<f64> {
        self.core(f, q, qd, t).swap_remove(0)
    }

    fn core_vector(&self, f: Function, q: &[f64], qd: &[f64], t: f64) -> DVector<f64> {
        vector(self.core_matrix(f, q, qd, t))
    }
}

fn vector(m: DMatrix<f64>) -> DVector<f64> {
    DVector::from_column_slice(m.as_slice())
}

impl DynModel for InterpretedModel {
    fn name(&self) -> &str {
        self.scene.name()
    }
    fn coordinates(&self) -> Vec<&str> {
        self.scene
            .coordinates()
            .iter()
            .map(String::as_str)
            .collect()
    }
    fn actuators(&self) -> Vec<&str> {
        self.scene.actuators().iter().map(String::as_str).collect()
    }
    fn nc(&self) -> usize {
        self.scene.nc()
    }
    fn mass_matrix(&self, q: &[f64], t: f64) -> DMatrix<f64> {
        self.core_matrix(Function::MassMatrix, q, &[], t)
    }
    fn bias(&self, q: &[f64], qd: &[f64], t: f64) -> DVector<f64> {
        self.core_vector(Function::Bias, q, qd, t)
    }
    fn inverse_dynamics(&self, q: &[f64], qd: &[f64], qdd: &[f64], t: f64) -> DVector<f64> {
        let f = Function::InverseDynamics;
        let mut o = self
            .outputs_with_accelerations(f, q, qd, qdd, t)
            .unwrap_or_else(|| panic!("`{}` is lowered for every scene", f.name()));
        vector(o.swap_remove(0))
    }
    fn constraints(&self, q: &[f64], t: f64) -> DVector<f64> {
        self.core_vector(Function::Constraints, q, &[], t)
    }
    fn constraint_jacobian(&self, q: &[f64], t: f64) -> DMatrix<f64> {
        self.core_matrix(Function::ConstraintJacobian, q, &[], t)
    }
    fn constraint_time_derivative(&self, q: &[f64], t: f64) -> DVector<f64> {
        self.core_vector(Function::ConstraintTimeDerivative, q, &[], t)
    }
    fn constraint_rhs(&self, q: &[f64], qd: &[f64], t: f64) -> DVector<f64> {
        self.core_vector(Function::ConstraintRhs, q, qd, t)
    }
    fn constraints_and_jacobian(&self, q: &[f64], t: f64) -> (DVector<f64>, DMatrix<f64>) {
        let mut o = self
            .core(Function::ConstraintsAndJacobian, q, &[], t)
            .into_iter();
        let phi = vector(o.next().expect("Phi"));
        (phi, o.next().expect("Phi_q"))
    }
    fn dynamics_terms(&self, q: &[f64], qd: &[f64], t: f64) -> Fused {
        let mut o = self.core(Function::DynamicsTerms, q, qd, t).into_iter();
        let m = o.next().expect("M");
        let h = vector(o.next().expect("h"));
        let phi_q = o.next().expect("Phi_q");
        (m, h, phi_q, vector(o.next().expect("gamma")))
    }
    fn actuator_map(&self) -> DMatrix<f64> {
        let q = vec![0.0; self.scene.nq()];
        self.core_matrix(Function::ActuatorMap, &q, &[], 0.0)
    }
    fn kinetic_energy(&self, q: &[f64], qd: &[f64], t: f64) -> f64 {
        self.core_matrix(Function::KineticEnergy, q, qd, t)[0]
    }
    fn potential_energy(&self, q: &[f64], t: f64) -> f64 {
        self.core_matrix(Function::PotentialEnergy, q, &[], t)[0]
    }
    fn parameters(&self) -> Vec<&str> {
        self.scene
            .parameters()
            .iter()
            .map(|(n, _)| n.as_str())
            .collect()
    }
    fn set_parameter(&mut self, name: &str, value: f64) -> bool {
        let found = self.scene.parameters().iter().position(|(n, _)| n == name);
        if let Some(i) = found {
            self.params[i] = value;
        }
        found.is_some()
    }
    fn coriolis_forces(&self, q: &[f64], qd: &[f64], t: f64) -> Option<DVector<f64>> {
        self.first(Function::CoriolisForces, q, qd, t).map(vector)
    }
    fn potential_forces(&self, q: &[f64], t: f64) -> Option<DVector<f64>> {
        self.first(Function::PotentialForces, q, &[], t).map(vector)
    }
    fn damping_forces(&self, q: &[f64], qd: &[f64], t: f64) -> Option<DVector<f64>> {
        self.first(Function::DampingForces, q, qd, t).map(vector)
    }
    fn coriolis_matrix(&self, q: &[f64], qd: &[f64], t: f64) -> Option<DMatrix<f64>> {
        self.first(Function::CoriolisMatrix, q, qd, t)
    }
    fn bias_jacobians(
        &self,
        q: &[f64],
        qd: &[f64],
        t: f64,
    ) -> Option<(DMatrix<f64>, DMatrix<f64>)> {
        let mut o = self.outputs(Function::BiasJacobians, q, qd, t)?.into_iter();
        Some((o.next()?, o.next()?))
    }
}
