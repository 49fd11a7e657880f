//! Linear state feedback `u = u0 - K (x - x0)` read from JSON (`flexdyn
//! simulate --feedback K.json`): the output of `flexdyn linearize` with a
//! gain matrix `K` added, so that a controller designed on a linearization
//! (LQR, pole placement) runs on the nonlinear model.
//!
//! ```json
//! {"states": ["x", "theta", "x_dot", "theta_dot"], "inputs": ["force"],
//!  "K": [[-1.0, -30.2, -2.1, -6.5]], "x0": [0, 0, 0, 0], "u0": [0]}
//! ```
//!
//! A state entry is a coordinate's name or `<coordinate>_dot` (its rate);
//! `inputs` are actuator names, one row of `K` each; `x0` and `u0` default
//! to zeros. Other keys (those `linearize` writes) are ignored.

use std::path::Path;

use nalgebra::{DMatrix, DVector};

use crate::dynamic::DynModel;

/// The file as read.
#[derive(serde::Deserialize)]
struct File {
    states: Vec<String>,
    inputs: Vec<String>,
    #[serde(rename = "K")]
    k: Vec<Vec<f64>>,
    #[serde(default)]
    x0: Option<Vec<f64>>,
    #[serde(default)]
    u0: Option<Vec<f64>>,
}

/// Which part of the state an entry of `x` is.
#[derive(Clone, Copy, Debug)]
enum Entry {
    Position(usize),
    Rate(usize),
}

/// `u = u0 - K (x - x0)`, checked against a model.
#[derive(Clone, Debug)]
pub struct StateFeedback {
    entries: Vec<Entry>,
    /// The actuator of each row of `k`.
    actuators: Vec<usize>,
    k: DMatrix<f64>,
    x0: DVector<f64>,
    u0: DVector<f64>,
    nu: usize,
}

impl StateFeedback {
    /// The feedback in `path`, for `model`; errors name the file and what is
    /// wrong (an unknown state or input name, a size, a non-finite value).
    pub fn read(path: &Path, model: &dyn DynModel) -> Result<StateFeedback, String> {
        let at = |e: String| format!("{}: {e}", path.display());
        let text = crate::table::read_input(path, "feedback file")?;
        let file: File = serde_json::from_str(&text).map_err(|e| at(e.to_string()))?;
        let coordinates = model.coordinates();
        let entries = file
            .states
            .iter()
            .map(|name| {
                let find = |n: &str| coordinates.iter().position(|c| *c == n);
                match (find(name), name.strip_suffix("_dot").and_then(find)) {
                    (Some(i), _) => Ok(Entry::Position(i)),
                    (None, Some(i)) => Ok(Entry::Rate(i)),
                    (None, None) => Err(at(format!(
                        "state `{name}` is neither a coordinate of scene `{}` nor the rate \
                         (`<coordinate>_dot`) of one (coordinates: {})",
                        model.name(),
                        coordinates.join(", ")
                    ))),
                }
            })
            .collect::<Result<Vec<_>, _>>()?;
        let names = model.actuators();
        let mut actuators = Vec::new();
        for name in &file.inputs {
            let j = names.iter().position(|a| a == name).ok_or_else(|| {
                at(format!(
                    "input `{name}` is not an actuator of scene `{}` (actuators: {})",
                    model.name(),
                    names.join(", ")
                ))
            })?;
            if actuators.contains(&j) {
                return Err(at(format!("input `{name}` is listed twice")));
            }
            actuators.push(j);
        }
        let (rows, cols) = (file.inputs.len(), file.states.len());
        if file.k.len() != rows || file.k.iter().any(|r| r.len() != cols) {
            return Err(at(format!(
                "`K` must have one row per input ({rows}) of one gain per state ({cols})"
            )));
        }
        let vector = |v: Option<Vec<f64>>, n: usize, what: &str| match v {
            None => Ok(DVector::zeros(n)),
            Some(v) if v.len() == n => Ok(DVector::from_vec(v)),
            Some(v) => Err(at(format!(
                "`{what}` has {} entries, expected {n}",
                v.len()
            ))),
        };
        let x0 = vector(file.x0, cols, "x0")?;
        let u0 = vector(file.u0, rows, "u0")?;
        let k = DMatrix::from_fn(rows, cols, |i, j| file.k[i][j]);
        if !(k.iter().chain(x0.iter()).chain(u0.iter())).all(|v| v.is_finite()) {
            return Err(at("a gain, `x0` or `u0` entry is not finite".into()));
        }
        Ok(StateFeedback {
            entries,
            actuators,
            k,
            x0,
            u0,
            nu: names.len(),
        })
    }

    /// The actuator inputs at `(q, qd)` (zero for actuators it does not
    /// drive).
    pub fn input(&self, q: &DVector<f64>, qd: &DVector<f64>) -> DVector<f64> {
        let dx = DVector::from_iterator(
            self.entries.len(),
            self.entries
                .iter()
                .zip(self.x0.iter())
                .map(|(e, x0)| match *e {
                    Entry::Position(i) => q[i] - x0,
                    Entry::Rate(i) => qd[i] - x0,
                }),
        );
        let rows = &self.u0 - &self.k * dx;
        let mut u = DVector::zeros(self.nu);
        for (r, &j) in self.actuators.iter().enumerate() {
            u[j] = rows[r];
        }
        u
    }
}
