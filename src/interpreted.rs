//! Any scene file behind [`DynModel`], without compiling it in: the
//! generator runs at run time and [`flexdyn_codegen::interpret`] evaluates
//! its scheduled programs, bitwise equal to the compiled module of the same
//! scene (`tests/interpreter_matches_compiled.rs`).

use std::cell::RefCell;
use std::path::Path;
use std::sync::Arc;

use flexdyn_codegen::interpret::{Function, Interpreted, Scratch, Tape};

use crate::dynamic::{DynModel, Fused, IdDerivatives, MarkerPose};

/// An interpreted scene with its runtime parameter values. Clones share
/// the tapes.
#[derive(Debug, Clone)]
pub struct InterpretedModel {
    scene: Arc<Interpreted>,
    params: Vec<f64>,
    /// `q = 0`, where the actuator map is evaluated.
    origin: Vec<f64>,
    /// Each tape's slots (by [`Tape::index`]), sized on first use.
    scratch: RefCell<Vec<Scratch>>,
    /// The outputs of a function with several, before they go to the
    /// caller's storage; sized on first use.
    outputs: RefCell<Vec<f64>>,
}

impl InterpretedModel {
    /// Generate a scene file in memory (the generator's error, with file and
    /// line, when it has one), with its nominal parameters.
    pub fn load(path: &Path) -> Result<InterpretedModel, String> {
        Interpreted::load(path)
            .map(InterpretedModel::new)
            .map_err(|e| e.to_string())
    }

    /// [`InterpretedModel::load`] of a scene file's text.
    pub fn from_source(source: &flexdyn_codegen::Source) -> Result<InterpretedModel, String> {
        Interpreted::from_source(source)
            .map(InterpretedModel::new)
            .map_err(|e| e.to_string())
    }

    /// A model of an interpreted scene, with its nominal parameters.
    pub fn new(scene: Interpreted) -> InterpretedModel {
        let params = scene.parameters().iter().map(|(_, v)| *v).collect();
        InterpretedModel {
            origin: vec![0.0; scene.nq()],
            scratch: RefCell::new(vec![Scratch::default(); scene.tape_count()]),
            scene: Arc::new(scene),
            params,
            outputs: RefCell::new(Vec::new()),
        }
    }

    /// The interpreted scene.
    pub fn scene(&self) -> &Interpreted {
        &self.scene
    }

    /// Runs `f` at `(q, qd, qdd, t)` and writes its outputs, in order, to
    /// `outs` (each as long as its output); `false` (nothing written) when
    /// the scene has no such function. One output is written in place, several
    /// through one buffer reused from call to call: no allocation once
    /// warm.
    fn run(&self, f: Function, at: (&[f64], &[f64], &[f64], f64), outs: &mut [&mut [f64]]) -> bool {
        self.scene
            .tape(f)
            .is_some_and(|tape| self.run_tape(tape, at, outs))
    }

    /// [`InterpretedModel::run`] of marker `marker`'s program of a
    /// per-marker function.
    fn run_marker(
        &self,
        f: Function,
        marker: usize,
        at: (&[f64], &[f64], &[f64], f64),
        outs: &mut [&mut [f64]],
    ) -> bool {
        self.scene
            .marker_tape(f, marker)
            .is_some_and(|tape| self.run_tape(tape, at, outs))
    }

    fn run_tape(
        &self,
        tape: &Tape,
        (q, qd, qdd, t): (&[f64], &[f64], &[f64], f64),
        outs: &mut [&mut [f64]],
    ) -> bool {
        let scratch = &mut self.scratch.borrow_mut()[tape.index()];
        if let [out] = outs {
            tape.eval_with_accelerations(q, qd, qdd, t, &self.params, scratch, out);
            return true;
        }
        let mut buffer = self.outputs.borrow_mut();
        buffer.resize(tape.output_len(), 0.0);
        tape.eval_with_accelerations(q, qd, qdd, t, &self.params, scratch, &mut buffer);
        let mut rest = buffer.as_slice();
        for out in outs {
            let (this, tail) = rest.split_at(out.len());
            out.copy_from_slice(this);
            rest = tail;
        }
        true
    }

    /// [`InterpretedModel::run`] of a function every scene has.
    fn core(&self, f: Function, at: (&[f64], &[f64], &[f64], f64), outs: &mut [&mut [f64]]) {
        if !self.run(f, at, outs) {
            unreachable!("`{}` is lowered for every scene", f.name())
        }
    }

    /// The value of a scalar function every scene has.
    fn scalar(&self, f: Function, q: &[f64], qd: &[f64], t: f64) -> f64 {
        let mut v = [0.0];
        self.core(f, (q, qd, &[], t), &mut [&mut v]);
        v[0]
    }
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
    fn mass_matrix(&self, q: &[f64], t: f64, m: &mut [f64]) {
        self.core(Function::MassMatrix, (q, &[], &[], t), &mut [m])
    }
    fn bias(&self, q: &[f64], qd: &[f64], t: f64, h: &mut [f64]) {
        self.core(Function::Bias, (q, qd, &[], t), &mut [h])
    }
    fn inverse_dynamics(&self, q: &[f64], qd: &[f64], qdd: &[f64], t: f64, tau: &mut [f64]) {
        self.core(Function::InverseDynamics, (q, qd, qdd, t), &mut [tau])
    }
    fn constraints(&self, q: &[f64], t: f64, phi: &mut [f64]) {
        self.core(Function::Constraints, (q, &[], &[], t), &mut [phi])
    }
    fn constraint_jacobian(&self, q: &[f64], t: f64, phi_q: &mut [f64]) {
        self.core(Function::ConstraintJacobian, (q, &[], &[], t), &mut [phi_q])
    }
    fn constraint_time_derivative(&self, q: &[f64], t: f64, phi_t: &mut [f64]) {
        let f = Function::ConstraintTimeDerivative;
        self.core(f, (q, &[], &[], t), &mut [phi_t])
    }
    fn constraint_rhs(&self, q: &[f64], qd: &[f64], t: f64, gamma: &mut [f64]) {
        self.core(Function::ConstraintRhs, (q, qd, &[], t), &mut [gamma])
    }
    fn constraints_and_jacobian(&self, q: &[f64], t: f64, phi: &mut [f64], phi_q: &mut [f64]) {
        let f = Function::ConstraintsAndJacobian;
        self.core(f, (q, &[], &[], t), &mut [phi, phi_q])
    }
    fn dynamics_terms(&self, q: &[f64], qd: &[f64], t: f64, out: Fused<'_>) {
        let outs: &mut [&mut [f64]] = &mut [out.m, out.h, out.phi_q, out.gamma];
        self.core(Function::DynamicsTerms, (q, qd, &[], t), outs)
    }
    fn actuator_map(&self, b: &mut [f64]) {
        let at = (self.origin.as_slice(), &[][..], &[][..], 0.0);
        self.core(Function::ActuatorMap, at, &mut [b])
    }
    fn kinetic_energy(&self, q: &[f64], qd: &[f64], t: f64) -> f64 {
        self.scalar(Function::KineticEnergy, q, qd, t)
    }
    fn potential_energy(&self, q: &[f64], t: f64) -> f64 {
        self.scalar(Function::PotentialEnergy, q, &[], t)
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
    fn coriolis_forces(&self, q: &[f64], qd: &[f64], t: f64, out: &mut [f64]) -> bool {
        self.run(Function::CoriolisForces, (q, qd, &[], t), &mut [out])
    }
    fn potential_forces(&self, q: &[f64], t: f64, out: &mut [f64]) -> bool {
        self.run(Function::PotentialForces, (q, &[], &[], t), &mut [out])
    }
    fn damping_forces(&self, q: &[f64], qd: &[f64], t: f64, out: &mut [f64]) -> bool {
        self.run(Function::DampingForces, (q, qd, &[], t), &mut [out])
    }
    fn coriolis_matrix(&self, q: &[f64], qd: &[f64], t: f64, out: &mut [f64]) -> bool {
        self.run(Function::CoriolisMatrix, (q, qd, &[], t), &mut [out])
    }
    fn bias_jacobians(
        &self,
        q: &[f64],
        qd: &[f64],
        t: f64,
        h_q: &mut [f64],
        h_qd: &mut [f64],
    ) -> bool {
        self.run(Function::BiasJacobians, (q, qd, &[], t), &mut [h_q, h_qd])
    }
    fn inverse_dynamics_derivatives(
        &self,
        q: &[f64],
        qd: &[f64],
        qdd: &[f64],
        t: f64,
        out: IdDerivatives<'_>,
    ) -> bool {
        let f = Function::InverseDynamicsDerivatives;
        self.run(f, (q, qd, qdd, t), &mut [out.tau, out.tau_q, out.tau_qd])
    }
    fn constraint_acceleration_derivatives(
        &self,
        q: &[f64],
        qd: &[f64],
        qdd: &[f64],
        t: f64,
        a_q: &mut [f64],
        a_qd: &mut [f64],
    ) -> bool {
        let f = Function::ConstraintAccelerationDerivatives;
        self.run(f, (q, qd, qdd, t), &mut [a_q, a_qd])
    }
    fn markers(&self) -> Vec<&str> {
        self.scene.markers().iter().map(String::as_str).collect()
    }
    fn marker_pose(
        &self,
        marker: usize,
        q: &[f64],
        t: f64,
        position: &mut [f64],
        rotation: &mut [f64],
    ) -> bool {
        let at = (q, &[][..], &[][..], t);
        self.run_marker(Function::MarkerPose, marker, at, &mut [position, rotation])
    }
    fn marker_jacobian(&self, marker: usize, q: &[f64], t: f64, out: MarkerPose<'_>) -> bool {
        let outs: &mut [&mut [f64]] = &mut [out.position, out.rotation, out.jacobian];
        let at = (q, &[][..], &[][..], t);
        self.run_marker(Function::MarkerJacobian, marker, at, outs)
    }
    fn marker_motion(
        &self,
        marker: usize,
        q: &[f64],
        qd: &[f64],
        t: f64,
        velocity: &mut [f64],
        acceleration_bias: &mut [f64],
    ) -> bool {
        let outs: &mut [&mut [f64]] = &mut [velocity, acceleration_bias];
        self.run_marker(Function::MarkerMotion, marker, (q, qd, &[], t), outs)
    }
}
