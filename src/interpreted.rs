//! Any scene file behind [`DynModel`], without compiling it in: the
//! generator runs at run time and [`flexdyn_codegen::interpret`] evaluates
//! its scheduled programs, bitwise equal to the compiled module of the same
//! scene (`tests/interpreter_matches_compiled.rs`).

use std::cell::RefCell;
use std::path::Path;
use std::sync::Arc;

use flexdyn_codegen::interpret::{Function, Interpreted, Scratch, Tape, LANES};

use crate::dynamic::{At, DynModel};

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
    /// The slots of batched calls ([`InterpretedModel::call_batch`]), for
    /// any tape.
    lanes: RefCell<Scratch<LANES>>,
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
            lanes: RefCell::new(Scratch::default()),
            scene: Arc::new(scene),
            params,
            outputs: RefCell::new(Vec::new()),
        }
    }

    /// The interpreted scene.
    pub fn scene(&self) -> &Interpreted {
        &self.scene
    }

    /// [`DynModel::call`] at `t.len()` states at once: `q`, `qd` and `qdd`
    /// hold the states' values one after the other (`qd`, `qdd` may be
    /// empty where `f` does not read them), and `out` receives each state's
    /// outputs, state after state, as `call` writes them one after the
    /// other. Several states run side by side on the tape
    /// ([`Tape::eval_batch`]), bitwise as `call` computes each alone.
    /// `false`, nothing written, when the scene does not generate `f` or
    /// has no such marker.
    ///
    /// # Panics
    ///
    /// When a slice's length differs from the states' dimensions.
    #[allow(clippy::too_many_arguments)]
    pub fn call_batch(
        &self,
        f: Function,
        marker: Option<usize>,
        q: &[f64],
        qd: &[f64],
        qdd: &[f64],
        t: &[f64],
        out: &mut [f64],
    ) -> bool {
        let tape = match marker {
            None => self.scene.tape(f),
            Some(k) => self.scene.marker_tape(f, k),
        };
        let Some(tape) = tape else {
            return false;
        };
        if 2 * t.len() >= LANES {
            let lanes = &mut self.lanes.borrow_mut();
            tape.eval_batch(q, qd, qdd, t, &self.params, lanes, out);
            return true;
        }
        // Too few states to fill the lanes: one at a time.
        let (nq, len) = (self.scene.nq(), tape.output_len());
        if len == 0 {
            return true;
        }
        fn state(x: &[f64], nq: usize, k: usize) -> &[f64] {
            x.get(k * nq..(k + 1) * nq).unwrap_or(&[])
        }
        for (k, (out, &t)) in out.chunks_exact_mut(len).zip(t).enumerate() {
            let at = At {
                q: state(q, nq, k),
                qd: state(qd, nq, k),
                qdd: state(qdd, nq, k),
                t,
            };
            self.run_tape(tape, at, &mut [out]);
        }
        true
    }

    /// Runs `tape` at `at` and writes its outputs, in order, to `outs`
    /// (each as long as its output): one output in place, several through
    /// one buffer reused from call to call, so no allocation once warm.
    fn run_tape(&self, tape: &Tape, at: At<'_>, outs: &mut [&mut [f64]]) -> bool {
        let At { q, qd, qdd, t } = at;
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
    fn nq(&self) -> usize {
        self.scene.nq()
    }
    fn nc(&self) -> usize {
        self.scene.nc()
    }
    fn nu(&self) -> usize {
        self.scene.nu()
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
    fn markers(&self) -> Vec<&str> {
        self.scene.markers().iter().map(String::as_str).collect()
    }
    /// The function's tape (each marker's for a per-marker function), at
    /// `q = 0` for the actuator map (which reads no state).
    fn call(
        &self,
        f: Function,
        marker: Option<usize>,
        at: At<'_>,
        outs: &mut [&mut [f64]],
    ) -> bool {
        let tape = match marker {
            None => self.scene.tape(f),
            Some(k) => self.scene.marker_tape(f, k),
        };
        let q = if at.q.is_empty() { &self.origin } else { at.q };
        tape.is_some_and(|tape| self.run_tape(tape, At { q, ..at }, outs))
    }
}
