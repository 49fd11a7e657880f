//! `flexdyn` for Python: a scene file (or a URDF) generated in memory and
//! interpreted (bitwise the numbers of its compiled module), its terms on
//! numpy arrays, single states or batches evaluated in Rust (in parallel
//! over the cores for large batches), and the command line's `simulate`,
//! `inverse` and `generate` run in-process on the same code.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use clap::Parser;
use nalgebra::DVector;
use numpy::ndarray::{Array1, ArrayD, Axis, IxDyn};
use numpy::{
    AllowTypeChange, Complex64, IntoPyArray, PyArray1, PyArrayDyn, PyArrayLikeDyn, PyArrayMethods,
    PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use rayon::prelude::*;

use flexdyn_lib::codegen::interpret::LANES;
use flexdyn_lib::codegen::{import_urdf, Source, UrdfOptions};
use flexdyn_lib::compiled::COMPILED_SCENES;
use flexdyn_lib::dynamic::{DynModel, Function};
use flexdyn_lib::interpreted::InterpretedModel;
use flexdyn_runtime::{accelerations, forward_dynamics_derivatives, Baumgarte, DynamicsConfig};

/// Batches at least this long are split over the cores.
const PARALLEL_BATCH: usize = 256;

/// A scene's equations of motion, interpreted.
#[pyclass(name = "Model", module = "flexdyn", unsendable)]
struct Model {
    model: InterpretedModel,
    /// The scene file (a temporary copy for a URDF import), which
    /// `simulate`, `inverse` and `generate` read.
    scene: PathBuf,
    /// Keeps an imported scene's temporary folder alive.
    _dir: Option<tempfile::TempDir>,
}

/// An array argument's values, row-major, and its shape: a C-contiguous
/// `float64` numpy array is copied as it is, anything else goes through
/// numpy's conversion first (a list, another dtype, a strided view).
struct Arg {
    values: Vec<f64>,
    shape: Vec<usize>,
}

impl<'py> FromPyObject<'py> for Arg {
    fn extract_bound(ob: &Bound<'py, PyAny>) -> PyResult<Self> {
        if let Ok(a) = ob.downcast::<PyArrayDyn<f64>>() {
            if a.is_c_contiguous() {
                if let Ok(values) = a.to_vec() {
                    let shape = a.shape().to_vec();
                    return Ok(Arg { values, shape });
                }
            }
        }
        let a: PyArrayLikeDyn<'py, f64, AllowTypeChange> = ob.extract()?;
        let view = a.as_array();
        Ok(Arg {
            shape: view.shape().to_vec(),
            values: view.iter().copied().collect(),
        })
    }
}

/// A function evaluated state by state: the arguments of one state, its
/// time and one slice per output; `false` when the scene does not generate
/// it.
type EachState<'a> =
    &'a (dyn Fn(&InterpretedModel, &[&[f64]], f64, &mut [&mut [f64]]) -> bool + Sync);

/// How [`Model::apply_many`] evaluates a function.
#[derive(Clone, Copy)]
enum Eval<'a> {
    /// A function of the table (of a marker), its arguments `q`, then `qd`,
    /// then `qdd`: states side by side on its tape
    /// ([`InterpretedModel::call_batch`]).
    Table(Function, Option<usize>),
    /// Anything else, one state at a time.
    Each(EachState<'a>),
}

impl Model {
    /// A function at one state or a batch: `args` are arrays of `sizes`
    /// entries (or `(N, size)`), `t` a number or `N` numbers; one array per
    /// output of `shapes` (then `(N, *shape)` for a batch). `function` names
    /// it in the error when the scene does not generate it.
    #[allow(clippy::too_many_arguments)]
    fn apply_many(
        &self,
        py: Python<'_>,
        args: &[Arg],
        sizes: &[usize],
        t: Option<&Bound<'_, PyAny>>,
        shapes: &[&[usize]],
        eval: Eval<'_>,
        function: &str,
    ) -> PyResult<Vec<PyObject>> {
        let batch = match args.first().map(|a| a.shape.len()) {
            Some(1) | None => None,
            Some(2) => Some(args[0].shape[0]),
            Some(d) => {
                return Err(PyValueError::new_err(format!(
                    "expected 1 or 2 dimensions, got {d}"
                )))
            }
        };
        for (k, (a, &n)) in args.iter().zip(sizes).enumerate() {
            let ok = match batch {
                None => a.shape == [n],
                Some(b) => a.shape == [b, n],
            };
            if !ok {
                return Err(PyValueError::new_err(format!(
                    "argument {} has shape {:?}; scene `{}` needs {}",
                    k + 1,
                    a.shape,
                    self.model.name(),
                    match batch {
                        None => format!("({n},)"),
                        Some(b) => format!("({b}, {n})"),
                    }
                )));
            }
        }
        let count = batch.unwrap_or(1);
        let times: Vec<f64> = match t {
            None => vec![0.0; count],
            Some(t) => match t.extract::<f64>() {
                Ok(t) => vec![t; count],
                Err(_) => {
                    let v: Vec<f64> = t
                        .extract()
                        .map_err(|_| PyValueError::new_err("t: a number or one per state"))?;
                    if v.len() != count {
                        return Err(PyValueError::new_err(format!(
                            "t: {} times for {count} states",
                            v.len()
                        )));
                    }
                    v
                }
            },
        };
        let lens: Vec<usize> = shapes.iter().map(|s| s.iter().product()).collect();
        let size: usize = lens.iter().sum();
        let mut out = vec![0.0; size * count];
        let missing = AtomicBool::new(false);
        // States `first..first + n` into `part` (their outputs, state after
        // state).
        let run = |m: &InterpretedModel, first: usize, n: usize, part: &mut [f64]| {
            let found = match eval {
                Eval::Table(f, marker) => {
                    let nq = m.nq();
                    let arg = |i: usize| {
                        args.get(i)
                            .map_or(&[][..], |a| &a.values[first * nq..(first + n) * nq])
                    };
                    let t = &times[first..first + n];
                    m.call_batch(f, marker, arg(0), arg(1), arg(2), t, part)
                }
                Eval::Each(f) => (0..n).all(|j| {
                    let k = first + j;
                    let mut at: [&[f64]; 3] = [&[]; 3];
                    for (i, (a, &len)) in args.iter().zip(sizes).enumerate() {
                        at[i] = &a.values[k * len..(k + 1) * len];
                    }
                    let mut o = &mut part[j * size..(j + 1) * size];
                    let mut outs: Vec<&mut [f64]> = Vec::with_capacity(lens.len());
                    for &len in &lens {
                        let (this, rest) = std::mem::take(&mut o).split_at_mut(len);
                        outs.push(this);
                        o = rest;
                    }
                    f(m, &at[..args.len()], times[k], &mut outs)
                }),
            };
            if !found {
                missing.store(true, Ordering::Relaxed);
            }
        };
        if count >= PARALLEL_BATCH && size > 0 {
            // One copy of the model (its own scratch) per chunk of states,
            // a whole number of the tapes' lanes.
            let chunk = count
                .div_ceil(rayon::current_num_threads())
                .next_multiple_of(LANES);
            let copies: Vec<InterpretedModel> = (0..count.div_ceil(chunk))
                .map(|_| self.model.clone())
                .collect();
            py.allow_threads(|| {
                out.par_chunks_mut(chunk * size)
                    .zip(copies.into_par_iter())
                    .enumerate()
                    .for_each(|(c, (part, m))| run(&m, c * chunk, part.len() / size, part))
            });
        } else {
            run(&self.model, 0, count, &mut out);
        }
        if missing.into_inner() {
            return Err(PyValueError::new_err(format!(
                "scene `{}` does not generate `{function}` (for derivatives: \
                 `outputs = [\"dynamics_derivatives\"]` in the scene, or \
                 `from_urdf(..., outputs=[\"dynamics_derivatives\"])`)",
                self.model.name()
            )));
        }
        if let [shape] = shapes {
            return Ok(vec![numpy_array(py, out, count, shape, batch.is_some())?]);
        }
        let mut results = Vec::with_capacity(shapes.len());
        let mut offset = 0;
        for (shape, &len) in shapes.iter().zip(&lens) {
            let values: Vec<f64> = (0..count)
                .flat_map(|k| &out[k * size + offset..k * size + offset + len])
                .copied()
                .collect();
            offset += len;
            results.push(numpy_array(py, values, count, shape, batch.is_some())?);
        }
        Ok(results)
    }

    /// The table's function `f` (of marker `marker` for a per-marker one)
    /// at `args` (`q`, then `qd`, then `qdd`): one array per output, of
    /// `shapes`.
    fn table(
        &self,
        py: Python<'_>,
        f: Function,
        marker: Option<usize>,
        args: &[Arg],
        t: Option<&Bound<'_, PyAny>>,
        shapes: &[&[usize]],
    ) -> PyResult<Vec<PyObject>> {
        let sizes = vec![self.model.nq(); args.len()];
        let eval = Eval::Table(f, marker);
        self.apply_many(py, args, &sizes, t, shapes, eval, f.name())
    }

    /// [`Model::table`] of a function with one output.
    fn table_one(
        &self,
        py: Python<'_>,
        f: Function,
        args: &[Arg],
        t: Option<&Bound<'_, PyAny>>,
        shape: &[usize],
    ) -> PyResult<PyObject> {
        let mut arrays = self.table(py, f, None, args, t, &[shape])?;
        Ok(arrays.remove(0))
    }

    /// [`Model::table`] of a function with several outputs, as a tuple.
    fn table_tuple(
        &self,
        py: Python<'_>,
        f: Function,
        marker: Option<usize>,
        args: &[Arg],
        t: Option<&Bound<'_, PyAny>>,
        shapes: &[&[usize]],
    ) -> PyResult<Py<PyTuple>> {
        let arrays = self.table(py, f, marker, args, t, shapes)?;
        Ok(PyTuple::new(py, arrays)?.unbind())
    }

    /// The index of a marker given by name or index.
    fn marker_index(&self, marker: &Bound<'_, PyAny>) -> PyResult<usize> {
        let names = self.model.markers();
        let found = match marker.extract::<usize>() {
            Ok(k) => (k < names.len()).then_some(k),
            Err(_) => {
                let name: String = marker
                    .extract()
                    .map_err(|_| PyValueError::new_err("marker: a name or an index"))?;
                names.iter().position(|n| *n == name)
            }
        };
        found.ok_or_else(|| {
            PyValueError::new_err(format!(
                "scene `{}` has no marker {marker}; its markers: [{}]",
                self.model.name(),
                names.join(", ")
            ))
        })
    }
}

/// `count` outputs of `shape` (column-major matrices, nalgebra's layout,
/// one after the other) as a numpy array `shape` (row-major), stacked as
/// `(count, *shape)` for a batch.
fn numpy_array(
    py: Python<'_>,
    values: Vec<f64>,
    count: usize,
    shape: &[usize],
    batch: bool,
) -> PyResult<PyObject> {
    if let ([_], false) = (shape, batch) {
        return Ok(PyArray1::from_slice(py, &values).into_any().unbind());
    }
    let per_state: Vec<usize> = match shape {
        [r, c] => vec![*c, *r],
        other => other.to_vec(),
    };
    let stacked: Vec<usize> = std::iter::once(count).chain(per_state).collect();
    let mut array = ArrayD::from_shape_vec(IxDyn(&stacked), values)
        .map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
    if shape.len() == 2 {
        array.swap_axes(1, 2);
        array = array.as_standard_layout().into_owned();
    }
    if !batch {
        array = array.index_axis_move(Axis(0), 0);
    }
    Ok(array.into_pyarray(py).into_any().unbind())
}

#[pymethods]
impl Model {
    /// The scene's name.
    #[getter]
    fn name(&self) -> String {
        self.model.name().to_owned()
    }
    /// Number of coordinates.
    #[getter]
    fn nq(&self) -> usize {
        self.model.nq()
    }
    /// Number of constraints.
    #[getter]
    fn nc(&self) -> usize {
        self.model.nc()
    }
    /// Number of actuator inputs.
    #[getter]
    fn nu(&self) -> usize {
        self.model.nu()
    }
    /// Coordinate names.
    #[getter]
    fn coordinates(&self) -> Vec<String> {
        self.model
            .coordinates()
            .iter()
            .map(|s| s.to_string())
            .collect()
    }
    /// Actuator names.
    #[getter]
    fn actuators(&self) -> Vec<String> {
        self.model
            .actuators()
            .iter()
            .map(|s| s.to_string())
            .collect()
    }
    /// Marker names.
    #[getter]
    fn markers(&self) -> Vec<String> {
        self.model.markers().iter().map(|s| s.to_string()).collect()
    }
    /// The scene file the model was generated from.
    #[getter]
    fn scene(&self) -> String {
        self.scene.display().to_string()
    }

    /// Mass matrix `M(q, t)`: `(nq, nq)`, or `(N, nq, nq)` for a batch.
    #[pyo3(signature = (q, t = None))]
    fn mass_matrix(
        &self,
        py: Python<'_>,
        q: Arg,
        t: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<PyObject> {
        let n = self.model.nq();
        self.table_one(py, Function::MassMatrix, &[q], t, &[n, n])
    }
    /// Bias forces `h(q, qd, t)`.
    #[pyo3(signature = (q, qd, t = None))]
    fn bias(
        &self,
        py: Python<'_>,
        q: Arg,
        qd: Arg,
        t: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<PyObject> {
        let n = self.model.nq();
        self.table_one(py, Function::Bias, &[q, qd], t, &[n])
    }
    /// Inverse dynamics `M qdd + h` (no constraint forces).
    #[pyo3(signature = (q, qd, qdd, t = None))]
    fn inverse_dynamics(
        &self,
        py: Python<'_>,
        q: Arg,
        qd: Arg,
        qdd: Arg,
        t: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<PyObject> {
        let n = self.model.nq();
        self.table_one(py, Function::InverseDynamics, &[q, qd, qdd], t, &[n])
    }
    /// Accelerations under actuator inputs `tau`: `M^-1 (B tau - h)`, or for
    /// a constrained scene those of `M qdd - Phi_q^T lambda = B tau - h`,
    /// `Phi_q qdd = gamma` (no Baumgarte terms). NaN where the solve fails
    /// (a mass matrix that is not positive definite, a singular constraint
    /// Jacobian).
    #[pyo3(signature = (q, qd, tau, t = None))]
    fn forward_dynamics(
        &self,
        py: Python<'_>,
        q: Arg,
        qd: Arg,
        tau: Arg,
        t: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<PyObject> {
        let (n, nu) = (self.model.nq(), self.model.nu());
        let config = DynamicsConfig {
            baumgarte: Baumgarte::NONE,
            ..DynamicsConfig::default()
        };
        let f = |m: &InterpretedModel, a: &[&[f64]], t: f64, o: &mut [&mut [f64]]| {
            let model: &dyn DynModel = m;
            let (q, qd, tau) = (
                DVector::from_column_slice(a[0]),
                DVector::from_column_slice(a[1]),
                DVector::from_column_slice(a[2]),
            );
            match accelerations(model, &config, &q, &qd, t, &tau) {
                Ok(s) => o[0].copy_from_slice(s.qdd.as_slice()),
                Err(_) => o[0].fill(f64::NAN),
            }
            true
        };
        let args = [q, qd, tau];
        let name = "forward_dynamics";
        let mut arrays =
            self.apply_many(py, &args, &[n, n, nu], t, &[&[n]], Eval::Each(&f), name)?;
        Ok(arrays.remove(0))
    }
    /// Constraint residuals `Phi(q, t)`.
    #[pyo3(signature = (q, t = None))]
    fn constraints(
        &self,
        py: Python<'_>,
        q: Arg,
        t: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<PyObject> {
        let nc = self.model.nc();
        self.table_one(py, Function::Constraints, &[q], t, &[nc])
    }
    /// Constraint Jacobian `Phi_q(q, t)`: `(nc, nq)`.
    #[pyo3(signature = (q, t = None))]
    fn constraint_jacobian(
        &self,
        py: Python<'_>,
        q: Arg,
        t: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<PyObject> {
        let (n, nc) = (self.model.nq(), self.model.nc());
        self.table_one(py, Function::ConstraintJacobian, &[q], t, &[nc, n])
    }
    /// Acceleration right-hand side `gamma(q, qd, t)`.
    #[pyo3(signature = (q, qd, t = None))]
    fn constraint_rhs(
        &self,
        py: Python<'_>,
        q: Arg,
        qd: Arg,
        t: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<PyObject> {
        let nc = self.model.nc();
        self.table_one(py, Function::ConstraintRhs, &[q, qd], t, &[nc])
    }
    /// Kinetic energy `T(q, qd, t)`.
    #[pyo3(signature = (q, qd, t = None))]
    fn kinetic_energy(
        &self,
        py: Python<'_>,
        q: Arg,
        qd: Arg,
        t: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<PyObject> {
        self.table_one(py, Function::KineticEnergy, &[q, qd], t, &[])
    }
    /// Potential energy `V(q, t)`.
    #[pyo3(signature = (q, t = None))]
    fn potential_energy(
        &self,
        py: Python<'_>,
        q: Arg,
        t: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<PyObject> {
        self.table_one(py, Function::PotentialEnergy, &[q], t, &[])
    }

    /// Position `(3,)` and rotation `(3, 3)` (marker axes in world
    /// axes) of a marker, by name or index.
    #[pyo3(signature = (marker, q, t = None))]
    fn marker_pose(
        &self,
        py: Python<'_>,
        marker: &Bound<'_, PyAny>,
        q: Arg,
        t: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Py<PyTuple>> {
        let k = self.marker_index(marker)?;
        self.table_tuple(py, Function::MarkerPose, Some(k), &[q], t, &[&[3], &[3, 3]])
    }
    /// Position `(3,)`, rotation `(3, 3)` and Jacobian `(6, nq)` of a
    /// marker: rows 0-2 the velocity of its point, rows 3-5 its angular
    /// velocity, in world axes (Pinocchio's `LOCAL_WORLD_ALIGNED`).
    #[pyo3(signature = (marker, q, t = None))]
    fn marker_jacobian(
        &self,
        py: Python<'_>,
        marker: &Bound<'_, PyAny>,
        q: Arg,
        t: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Py<PyTuple>> {
        let k = self.marker_index(marker)?;
        let shapes: &[&[usize]] = &[&[3], &[3, 3], &[6, self.model.nq()]];
        self.table_tuple(py, Function::MarkerJacobian, Some(k), &[q], t, shapes)
    }
    /// Velocity `(6,)` (linear, angular; world axes) and acceleration bias
    /// `(6,)` (the marker's acceleration at `qdd = 0`: `J' qd` and the
    /// explicit time terms) of a marker.
    #[pyo3(signature = (marker, q, qd, t = None))]
    fn marker_motion(
        &self,
        py: Python<'_>,
        marker: &Bound<'_, PyAny>,
        q: Arg,
        qd: Arg,
        t: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Py<PyTuple>> {
        let k = self.marker_index(marker)?;
        self.table_tuple(
            py,
            Function::MarkerMotion,
            Some(k),
            &[q, qd],
            t,
            &[&[6], &[6]],
        )
    }
    /// Inverse dynamics with its exact derivatives: `(tau, d tau/d q,
    /// d tau/d qd)`, shapes `(nq,)`, `(nq, nq)`, `(nq, nq)`; for scenes
    /// generated with `outputs = ["dynamics_derivatives"]`.
    #[pyo3(signature = (q, qd, qdd, t = None))]
    fn inverse_dynamics_derivatives(
        &self,
        py: Python<'_>,
        q: Arg,
        qd: Arg,
        qdd: Arg,
        t: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Py<PyTuple>> {
        let n = self.model.nq();
        let f = Function::InverseDynamicsDerivatives;
        self.table_tuple(py, f, None, &[q, qd, qdd], t, &[&[n], &[n, n], &[n, n]])
    }
    /// Forward dynamics with its exact derivatives (the runtime's
    /// `forward_dynamics_derivatives`; constrained scenes: the ideal
    /// equations, no Baumgarte terms, at a consistent state): a dict of
    /// `qdd`, `lambda`, `qdd_q`, `qdd_qd`, `qdd_tau`, `lambda_q`,
    /// `lambda_qd`, `lambda_tau`. NaN where the solve fails.
    #[pyo3(signature = (q, qd, tau, t = None))]
    fn forward_dynamics_derivatives(
        &self,
        py: Python<'_>,
        q: Arg,
        qd: Arg,
        tau: Arg,
        t: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Py<PyDict>> {
        let (n, nc, nu) = (self.model.nq(), self.model.nc(), self.model.nu());
        let name = "inverse_dynamics_derivatives";
        let generated = self
            .model
            .scene()
            .tape(Function::InverseDynamicsDerivatives);
        let f = |m: &InterpretedModel, a: &[&[f64]], t: f64, o: &mut [&mut [f64]]| {
            if generated.is_none() {
                return false;
            }
            let model: &dyn DynModel = m;
            let (q, qd, tau) = (
                DVector::from_column_slice(a[0]),
                DVector::from_column_slice(a[1]),
                DVector::from_column_slice(a[2]),
            );
            match forward_dynamics_derivatives(model, &q, &qd, t, &tau) {
                Ok(d) => {
                    let parts = [
                        d.qdd.as_slice(),
                        d.lambda.as_slice(),
                        d.qdd_q.as_slice(),
                        d.qdd_qd.as_slice(),
                        d.qdd_tau.as_slice(),
                        d.lambda_q.as_slice(),
                        d.lambda_qd.as_slice(),
                        d.lambda_tau.as_slice(),
                    ];
                    for (out, part) in o.iter_mut().zip(parts) {
                        out.copy_from_slice(part);
                    }
                    true
                }
                Err(_) => {
                    o.iter_mut().for_each(|out| out.fill(f64::NAN));
                    true
                }
            }
        };
        let shapes: &[&[usize]] = &[
            &[n],
            &[nc],
            &[n, n],
            &[n, n],
            &[n, nu],
            &[nc, n],
            &[nc, n],
            &[nc, nu],
        ];
        let arrays = self.apply_many(
            py,
            &[q, qd, tau],
            &[n, n, nu],
            t,
            shapes,
            Eval::Each(&f),
            name,
        )?;
        let dict = PyDict::new(py);
        let keys = [
            "qdd",
            "lambda",
            "qdd_q",
            "qdd_qd",
            "qdd_tau",
            "lambda_q",
            "lambda_qd",
            "lambda_tau",
        ];
        for (key, array) in keys.into_iter().zip(arrays) {
            dict.set_item(key, array)?;
        }
        Ok(dict.unbind())
    }

    fn __repr__(&self) -> String {
        format!(
            "flexdyn.Model({:?}: {} coordinates, {} constraints, {} actuators)",
            self.model.name(),
            self.model.nq(),
            self.model.nc(),
            self.model.nu()
        )
    }
}

/// Generate a scene file in memory: its model, interpreted.
#[pyfunction]
fn load(path: PathBuf) -> PyResult<Model> {
    let model = InterpretedModel::load(&path).map_err(PyValueError::new_err)?;
    Ok(Model {
        model,
        scene: path,
        _dir: None,
    })
}

/// Import a URDF robot (`flexdyn import urdf`): joints in `fix` held at
/// zero, `outputs` the scene's optional outputs, `keep_angles` keeps every
/// angle, axis and origin as written (no snapping of near-multiples of
/// `pi/12` or of round-off of zero).
#[pyfunction]
#[pyo3(signature = (path, fix = Vec::new(), outputs = Vec::new(), keep_angles = false))]
fn from_urdf(
    path: PathBuf,
    fix: Vec<String>,
    outputs: Vec<String>,
    keep_angles: bool,
) -> PyResult<Model> {
    let text = flexdyn_lib::table::read_input(&path, "URDF file").map_err(PyValueError::new_err)?;
    let options = UrdfOptions {
        fix,
        outputs,
        keep_angles,
    };
    let scene = import_urdf(&Source::new(&path, text), &options)
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    let dir = tempfile::tempdir().map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "robot".into());
    let file = dir.path().join(format!("{stem}.toml"));
    std::fs::write(&file, &scene).map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
    let model = InterpretedModel::load(&file).map_err(PyValueError::new_err)?;
    Ok(Model {
        model,
        scene: file,
        _dir: Some(dir),
    })
}

/// The command line's arguments of one command.
#[derive(Parser)]
#[command(name = "flexdyn")]
enum Command {
    Simulate(Box<flexdyn_lib::cli::simulate::Args>),
    Inverse(flexdyn_lib::cli::inverse::Args),
    Generate(flexdyn_lib::cli::generate::Args),
    Linearize(flexdyn_lib::cli::linearize::Args),
}

/// Parses `argv` (after the program name) as the command line would:
/// `ValueError` with clap's message otherwise.
fn command(argv: Vec<String>) -> PyResult<Command> {
    Command::try_parse_from(std::iter::once("flexdyn".to_owned()).chain(argv))
        .map_err(|e| PyValueError::new_err(e.render().to_string().trim().to_owned()))
}

/// `"name=value"` options of a dict.
fn assignments(option: &str, dict: Option<&Bound<'_, PyDict>>) -> PyResult<Vec<String>> {
    let mut out = Vec::new();
    for (k, v) in dict.into_iter().flat_map(|d| d.iter()) {
        out.push(option.to_owned());
        out.push(format!("{}={}", k.str()?, v.str()?));
    }
    Ok(out)
}

/// A CSV written by a command, as a dict of numpy arrays (one per column),
/// plus `q`, `qd` (and `tau` for `inverse`) as `(N, n)` arrays.
fn columns(py: Python<'_>, path: &Path, model: &Model, tau: bool) -> PyResult<PyObject> {
    let table = flexdyn_lib::table::Table::read(path).map_err(PyRuntimeError::new_err)?;
    let out = PyDict::new(py);
    let column = |name: &str| table.column(name).map_err(PyRuntimeError::new_err);
    for name in &table.columns {
        out.set_item(name, Array1::from(column(name)?).into_pyarray(py))?;
    }
    let stack = |names: Vec<String>| -> PyResult<PyObject> {
        let mut a = numpy::ndarray::Array2::<f64>::zeros((table.rows.len(), names.len()));
        for (j, n) in names.iter().enumerate() {
            for (i, v) in column(n)?.into_iter().enumerate() {
                a[(i, j)] = v;
            }
        }
        Ok(a.into_pyarray(py).into_any().unbind())
    };
    let coordinates = model.coordinates();
    if table.columns.iter().any(|c| c.ends_with("_dot")) {
        out.set_item(
            "qd",
            stack(coordinates.iter().map(|c| format!("{c}_dot")).collect())?,
        )?;
    }
    if tau {
        // `inverse`: the actuators come first after `t`, then the coordinates.
        let actuators: Vec<String> = table.columns[1..=model.model.nu()].to_vec();
        out.set_item("tau", stack(actuators)?)?;
        let q: Vec<String> =
            table.columns[1 + model.model.nu()..1 + model.model.nu() + coordinates.len()].to_vec();
        out.set_item("q", stack(q)?)?;
    } else {
        out.set_item("q", stack(coordinates)?)?;
    }
    Ok(out.into_any().unbind())
}

/// Simulate the model (`flexdyn simulate`): `initial` a dict with `q`, `qd`
/// (and `t`), `inputs` actuator name to an expression of `t`, `integrator`
/// one of the command line's (default adaptive-rk4), any other
/// option of the command line as `options` (e.g. `{"integrator": "rk4",
/// "dt": 0.001}`). Returns the CSV's columns as numpy arrays, and `q`,
/// `qd` as `(N, nq)` arrays. `ValueError` for bad arguments,
/// `RuntimeError` when the run fails, with the command line's message.
#[pyfunction]
#[pyo3(signature = (model, duration, initial = None, inputs = None, integrator = None, dt = None, quiet = false, options = None))]
#[allow(clippy::too_many_arguments)]
fn simulate(
    py: Python<'_>,
    model: &Model,
    duration: f64,
    initial: Option<&Bound<'_, PyDict>>,
    inputs: Option<&Bound<'_, PyDict>>,
    integrator: Option<&str>,
    dt: Option<f64>,
    quiet: bool,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<PyObject> {
    let dir = tempfile::tempdir().map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
    let csv = dir.path().join("simulate.csv");
    let mut argv: Vec<String> = vec![
        "simulate".into(),
        "--scene".into(),
        model.scene.display().to_string(),
    ];
    argv.extend(["--duration".into(), duration.to_string()]);
    if let Some(integrator) = integrator {
        argv.extend(["--integrator".into(), integrator.into()]);
    }
    argv.extend(["--csv".into(), csv.display().to_string()]);
    if let Some(dt) = dt {
        argv.extend(["--dt".into(), dt.to_string()]);
    }
    if quiet {
        argv.push("--quiet".into());
    }
    if let Some(initial) = initial {
        let get = |key: &str| -> PyResult<Vec<f64>> {
            initial
                .get_item(key)?
                .ok_or_else(|| PyValueError::new_err(format!("initial: no `{key}`")))?
                .extract()
                .map_err(|_| PyValueError::new_err(format!("initial `{key}`: a list of numbers")))
        };
        let t: f64 = match initial.get_item("t")? {
            Some(t) => t.extract()?,
            None => 0.0,
        };
        let state = dir.path().join("initial.json");
        let text = format!(
            "{{\"q\": {:?}, \"qd\": {:?}, \"t\": {t:?}}}",
            get("q")?,
            get("qd")?
        );
        std::fs::write(&state, text).map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
        argv.extend(["--initial".into(), state.display().to_string()]);
    }
    argv.extend(assignments("--input", inputs)?);
    argv.extend(flags(options)?);
    let Command::Simulate(args) = command(argv)? else {
        unreachable!("parsed as simulate")
    };
    py.allow_threads(|| flexdyn_lib::cli::simulate::run(&args, &COMPILED_SCENES))
        .map_err(run_error)?;
    columns(py, &csv, model, false)
}

/// Inverse dynamics along prescribed coordinates or marker coordinates
/// (`flexdyn inverse`): `prescribe` name to an expression of `t`. Returns
/// the CSV's columns as numpy arrays, with `tau` `(N, nu)` and `q` `(N,
/// nq)`.
#[pyfunction]
#[pyo3(signature = (model, duration, dt, prescribe, quiet = false, options = None))]
fn inverse(
    py: Python<'_>,
    model: &Model,
    duration: f64,
    dt: f64,
    prescribe: &Bound<'_, PyDict>,
    quiet: bool,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<PyObject> {
    let dir = tempfile::tempdir().map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
    let csv = dir.path().join("inverse.csv");
    let mut argv: Vec<String> = vec![
        "inverse".into(),
        "--scene".into(),
        model.scene.display().to_string(),
    ];
    argv.extend([
        "--duration".into(),
        duration.to_string(),
        "--dt".into(),
        dt.to_string(),
    ]);
    argv.extend(["--csv".into(), csv.display().to_string()]);
    if quiet {
        argv.push("--quiet".into());
    }
    argv.extend(assignments("--prescribe", Some(prescribe))?);
    argv.extend(flags(options)?);
    let Command::Inverse(args) = command(argv)? else {
        unreachable!("parsed as inverse")
    };
    py.allow_threads(|| flexdyn_lib::cli::inverse::run(&args, &COMPILED_SCENES))
        .map_err(run_error)?;
    columns(py, &csv, model, true)
}

/// A command's error: `RuntimeError` when the run itself failed (a step of
/// `simulate`, `step k (t = ...)`, or a solve at a time, `at t = ...`),
/// `ValueError` for its arguments and input files.
fn run_error(e: String) -> PyErr {
    if e.starts_with("step ") || e.contains("at t = ") {
        PyRuntimeError::new_err(e)
    } else {
        PyValueError::new_err(e)
    }
}

/// Generate a scene's Rust module (`flexdyn generate`) into `out`.
#[pyfunction]
#[pyo3(signature = (scene, out, precision = "f64", c_header = false))]
fn generate(scene: PathBuf, out: PathBuf, precision: &str, c_header: bool) -> PyResult<()> {
    let mut argv = vec![
        "generate".to_owned(),
        "--scene".into(),
        scene.display().to_string(),
        "--out".into(),
        out.display().to_string(),
        "--precision".into(),
        precision.into(),
        "--quiet".into(),
    ];
    if c_header {
        argv.push("--c-header".into());
    }
    let Command::Generate(args) = command(argv)? else {
        unreachable!("parsed as generate")
    };
    flexdyn_lib::cli::generate::run(&args).map_err(PyValueError::new_err)
}

/// Linearize the model at `(q, qd, t)` (`flexdyn linearize`): `x' = f(x,
/// u)` with `x = (q, qd)` (independent coordinates of a constrained scene:
/// named by `independent`, else chosen by a pivoted factorisation),
/// `inputs` actuator name to value (zero otherwise). Returns the command's
/// JSON as a dict: `A`, `B`, `x0`, `u0`, `f0` as numpy arrays,
/// `eigenvalues_A` complex, `states`, `inputs` and (constrained scenes)
/// `reduction` as written.
#[pyfunction]
#[pyo3(signature = (model, q, qd, t = 0.0, inputs = None, independent = None))]
fn linearize(
    py: Python<'_>,
    model: &Model,
    q: Vec<f64>,
    qd: Vec<f64>,
    t: f64,
    inputs: Option<&Bound<'_, PyDict>>,
    independent: Option<Vec<String>>,
) -> PyResult<PyObject> {
    let dir = tempfile::tempdir().map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
    let (state, out) = (
        dir.path().join("state.json"),
        dir.path().join("linear.json"),
    );
    let text = format!("{{\"q\": {q:?}, \"qd\": {qd:?}, \"t\": {t:?}}}");
    std::fs::write(&state, text).map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
    let mut argv: Vec<String> = vec![
        "linearize".into(),
        "--scene".into(),
        model.scene.display().to_string(),
        "--state".into(),
        state.display().to_string(),
        "--out".into(),
        out.display().to_string(),
    ];
    argv.extend(assignments("--input", inputs)?);
    if let Some(names) = independent {
        argv.extend(["--independent".into(), names.join(",")]);
    }
    let Command::Linearize(args) = command(argv)? else {
        unreachable!("parsed as linearize")
    };
    py.allow_threads(|| flexdyn_lib::cli::linearize::run(&args, &COMPILED_SCENES))
        .map_err(run_error)?;
    let text = std::fs::read_to_string(&out).map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
    let json = py.import("json")?.call_method1("loads", (text,))?;
    let np = py.import("numpy")?;
    let dict = json.downcast::<PyDict>()?;
    for key in ["A", "B", "x0", "u0", "f0"] {
        if let Some(v) = dict.get_item(key)? {
            dict.set_item(key, np.call_method1("array", (v, "float64"))?)?;
        }
    }
    if let Some(v) = dict.get_item("eigenvalues_A")? {
        let pairs: Vec<[f64; 2]> = v.extract()?;
        let values: Vec<Complex64> = pairs
            .iter()
            .map(|[re, im]| Complex64::new(*re, *im))
            .collect();
        dict.set_item("eigenvalues_A", Array1::from(values).into_pyarray(py))?;
    }
    Ok(dict.clone().into_any().unbind())
}

/// `{"integrator": "rk4", "max_steps": 10}` as `--integrator rk4 --max-steps
/// 10` (`True` a bare flag).
fn flags(options: Option<&Bound<'_, PyDict>>) -> PyResult<Vec<String>> {
    let mut out = Vec::new();
    for (k, v) in options.into_iter().flat_map(|d| d.iter()) {
        let flag = format!("--{}", k.str()?.to_string().replace('_', "-"));
        if let Ok(b) = v.extract::<bool>() {
            if b {
                out.push(flag);
            }
            continue;
        }
        out.push(flag);
        out.push(v.str()?.to_string());
    }
    Ok(out)
}

/// The module.
#[pymodule]
fn flexdyn(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Model>()?;
    m.add_function(wrap_pyfunction!(load, m)?)?;
    m.add_function(wrap_pyfunction!(from_urdf, m)?)?;
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(inverse, m)?)?;
    m.add_function(wrap_pyfunction!(generate, m)?)?;
    m.add_function(wrap_pyfunction!(linearize, m)?)?;
    Ok(())
}
