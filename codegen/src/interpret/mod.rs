//! A scene's emitted functions evaluated at run time, without compiling
//! Rust: each scheduled function is lowered once, exactly as the emitter
//! lowers it before printing ([`crate::schedule::lower`]: the operations of
//! the emitted Rust expressions as Rust parses them), and that lowering is
//! assembled into a compact instruction tape (`assemble`) over one array of
//! `f64` slots (inputs, literals, then intermediate values), which
//! [`Tape::eval`] runs (`tape`). The results are therefore bitwise those of
//! the compiled module, by construction: the printed expressions and the
//! tape come from the same operations, and the tape calls the runtime's
//! `math` functions that generated code calls (a batched `sin_cos_array` is
//! bitwise `sin_cos` lane by lane).

mod assemble;
mod eval;
#[cfg(feature = "jit")]
mod machine;
#[cfg(feature = "jit")]
mod native;
mod tape;

use std::path::Path;

use crate::derive::Equations;
use crate::error::{Error, Source};
use crate::model::Model;
use crate::schedule::{functions, lower, mirror_of, Inputs};

pub use crate::schedule::Function;
pub use tape::{Scratch, Tape, LANES};

/// A scene's functions as tapes, built from its file at run time.
#[derive(Debug, Clone)]
pub struct Interpreted {
    name: String,
    coordinates: Vec<String>,
    actuators: Vec<String>,
    nc: usize,
    markers: Vec<String>,
    parameters: Vec<(String, f64)>,
    /// Each function's tape, a per-marker function's once per marker.
    tapes: Vec<(Function, Option<usize>, Tape)>,
}

impl Interpreted {
    /// Read, derive and schedule a scene file (the generator's own errors
    /// when it has any), and lower every function it would emit.
    pub fn load(path: &Path) -> Result<Interpreted, Error> {
        let mut model = Model::load(path)?;
        let eq = model.equations()?;
        Ok(Interpreted::new(&model, &eq))
    }

    /// [`Interpreted::load`] of a scene file's text.
    pub fn from_source(source: &Source) -> Result<Interpreted, Error> {
        let mut model = Model::from_source(source)?;
        let eq = model.equations()?;
        Ok(Interpreted::new(&model, &eq))
    }

    /// The tapes of a derived model.
    pub(crate) fn new(model: &Model, eq: &Equations) -> Interpreted {
        let (nq, nc) = (model.nq(), model.constraints.len());
        let params = model.runtime_parameters.len();
        // Not `actuator_forces`: a tape reads inputs of NQ entries, and the
        // runtime forms `B tau` from the actuator map for these models.
        let mirrored = mirror_of(model).iter().any(Option::is_some);
        let tapes = functions(model, eq)
            .iter()
            .filter(|f| f.function.spec().inputs != Inputs::Actuation)
            .enumerate()
            .map(|(index, f)| {
                let mut tape = assemble::assemble(&lower(f, true, mirrored), nq, params);
                tape.index = index;
                (f.function, f.marker, tape)
            })
            .collect();
        Interpreted {
            name: model.name.clone(),
            coordinates: model.coordinates.iter().map(|c| c.name.clone()).collect(),
            actuators: model.actuators.iter().map(|a| a.name.clone()).collect(),
            nc,
            markers: model.markers.iter().map(|m| m.name.clone()).collect(),
            parameters: model
                .runtime_parameters
                .iter()
                .map(|p| (p.name.clone(), p.value))
                .collect(),
            tapes,
        }
    }

    /// Scene name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Coordinate names.
    pub fn coordinates(&self) -> &[String] {
        &self.coordinates
    }

    /// Actuator names.
    pub fn actuators(&self) -> &[String] {
        &self.actuators
    }

    /// Number of coordinates.
    pub fn nq(&self) -> usize {
        self.coordinates.len()
    }

    /// Number of constraints.
    pub fn nc(&self) -> usize {
        self.nc
    }

    /// Number of actuators.
    pub fn nu(&self) -> usize {
        self.actuators.len()
    }

    /// Runtime parameters with their nominal values, in the order
    /// [`Tape::eval`] takes them.
    pub fn parameters(&self) -> &[(String, f64)] {
        &self.parameters
    }

    /// Marker names, in index order.
    pub fn markers(&self) -> &[String] {
        &self.markers
    }

    /// The tape of a function; `None` for an optional output the scene does
    /// not generate, or a per-marker function.
    pub fn tape(&self, f: Function) -> Option<&Tape> {
        self.find(f, None)
    }

    /// The tape of a per-marker function for marker `marker`; `None` where
    /// the scene has no such marker.
    pub fn marker_tape(&self, f: Function, marker: usize) -> Option<&Tape> {
        self.find(f, Some(marker))
    }

    /// Number of tapes ([`Tape::index`] is below it).
    pub fn tape_count(&self) -> usize {
        self.tapes.len()
    }

    fn find(&self, f: Function, marker: Option<usize>) -> Option<&Tape> {
        self.tapes
            .iter()
            .find(|(g, k, _)| *g == f && *k == marker)
            .map(|(_, _, t)| t)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::expr::{Id, Symbol};
    use crate::schedule::Terms;

    fn scene(name: &str) -> std::path::PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../scenes")
            .join(format!("{name}.toml"))
    }

    /// Every function's tape against the expression graph evaluated node by
    /// node (no scheduling, sharing or printing), at states spread over the
    /// coordinates and with runtime parameters away from their nominal
    /// values: equal to rounding.
    #[test]
    fn tapes_compute_the_derived_terms() {
        for name in ["pendulum", "four_bar", "slider_crank", "spin_up_beam"] {
            let mut model = Model::load(&scene(name)).unwrap();
            let eq = model.equations().unwrap();
            let it = Interpreted::new(&model, &eq);
            let (nq, np) = (it.nq(), it.parameters().len());
            let mut scratch = Scratch::default();
            for k in 0..5 {
                let x = |i: usize, s: f64| ((k * 7 + i * 3) as f64 * s).sin() * 1.3;
                let q: Vec<f64> = (0..nq).map(|i| x(i, 0.37)).collect();
                let qd: Vec<f64> = (0..nq).map(|i| x(i, 0.91)).collect();
                let qdd: Vec<f64> = (0..nq).map(|i| x(i, 1.73)).collect();
                let t = 0.25 * k as f64;
                let params: Vec<f64> = it
                    .parameters()
                    .iter()
                    .enumerate()
                    .map(|(i, (_, v))| v * 1.1 + 0.05 * (i + 1) as f64)
                    .collect();
                assert_eq!(params.len(), np);
                let env = |s: Symbol| match s {
                    Symbol::Q(i) => q[i as usize],
                    Symbol::Qd(i) => qd[i as usize],
                    Symbol::Qdd(i) => qdd[i as usize],
                    Symbol::Time => t,
                    Symbol::Param(i) => params[i as usize],
                };
                let mut checked = 0;
                // Every function (each marker's of a per-marker one), with
                // its entries column-major.
                let mut cases = Vec::new();
                for &f in Function::ALL {
                    // (No tape for the actuators' forces, above.)
                    let interpreted = f.spec().inputs != Inputs::Actuation;
                    let Some(terms) = f.spec().terms(&model, &eq).filter(|_| interpreted) else {
                        assert!(it.tape(f).is_none(), "{name} {}", f.name());
                        continue;
                    };
                    let nodes = |outputs: &[Vec<Vec<Id>>]| -> Vec<f64> {
                        outputs
                            .iter()
                            .flat_map(|o| column_major(o))
                            .map(|id| model.graph.eval(&[id], &env)[0])
                            .collect()
                    };
                    match terms {
                        Terms::Nodes(outputs) => cases.push((f, it.tape(f), nodes(&outputs))),
                        Terms::Constants(outputs) => {
                            let want = outputs.iter().flat_map(|o| column_major(o)).collect();
                            cases.push((f, it.tape(f), want));
                        }
                        Terms::Markers(each) => {
                            for (m, outputs) in each.iter().enumerate() {
                                cases.push((f, it.marker_tape(f, m), nodes(outputs)));
                            }
                            assert!(it.marker_tape(f, each.len()).is_none());
                        }
                    }
                }
                for (f, tape, want) in cases {
                    let tape = tape.unwrap();
                    let mut got = vec![f64::NAN; tape.output_len()];
                    tape.eval_with_accelerations(&q, &qd, &qdd, t, &params, &mut scratch, &mut got);
                    assert_eq!(got.len(), want.len(), "{name} {}", f.name());
                    let scale = want.iter().fold(1.0f64, |m, w| m.max(w.abs()));
                    for (p, (a, b)) in got.iter().zip(&want).enumerate() {
                        assert!(
                            (a - b).abs() <= 1e-14 * scale,
                            "{name} {} entry {p}: {a} vs {b}",
                            f.name()
                        );
                    }
                    checked += 1;
                }
                assert!(checked >= 11, "{name}: {checked} functions");
            }
        }
    }

    /// A batch (not a multiple of the lanes, with states far apart, where
    /// the sines leave the inline reduction) bitwise equal to its states
    /// one by one, for every tape of scenes with constraints, time,
    /// markers, runtime parameters and derivatives; on the lanes of the
    /// interpreter, and by [`Tape::eval_batch`] (machine code where the
    /// tape has it), both against the interpreter and [`Tape::eval`].
    #[test]
    fn batches_equal_their_states_one_by_one() {
        for name in ["four_bar", "spin_up_beam", "cart_pole", "ur5"] {
            let it = Interpreted::load(&scene(name)).unwrap();
            let nq = it.nq();
            let params: Vec<f64> = it.parameters().iter().map(|(_, v)| v * 1.3).collect();
            let n = 2 * LANES + 3;
            let x = |k: usize, s: f64| {
                let v = ((k * 13) as f64 * s).sin() * 1.7;
                if k == 5 {
                    v * 1e7
                } else {
                    v
                }
            };
            let q: Vec<f64> = (0..n * nq).map(|k| x(k, 0.37)).collect();
            let qd: Vec<f64> = (0..n * nq).map(|k| x(k, 0.91)).collect();
            let qdd: Vec<f64> = (0..n * nq).map(|k| x(k, 1.73)).collect();
            let t: Vec<f64> = (0..n).map(|k| 0.1 * k as f64).collect();
            let mut one = Scratch::default();
            let mut lanes = Scratch::<LANES>::default();
            for (f, _, tape) in &it.tapes {
                let len = tape.output_len();
                let mut batch = vec![f64::NAN; n * len];
                let (v, a) = (
                    if tape.uses_qd() { &qd[..] } else { &[][..] },
                    if tape.uses_qdd() { &qdd[..] } else { &[][..] },
                );
                tape.eval_batch(&q, v, a, &t, &params, &mut lanes, &mut batch);
                let mut interpreted = vec![f64::NAN; n * len];
                tape.interpret_batch(&q, v, a, &t, &params, &mut lanes, &mut interpreted);
                for k in 0..n {
                    let mut want = vec![f64::NAN; len];
                    let state = |x: &[f64]| x[k * nq..(k + 1) * nq].to_vec();
                    let (qk, qdk, qddk) = (state(&q), state(&qd), state(&qdd));
                    tape.eval_with_accelerations(
                        &qk, &qdk, &qddk, t[k], &params, &mut one, &mut want,
                    );
                    let mut alone = vec![f64::NAN; len];
                    tape.interpret(&qk, &qdk, &qddk, t[k], &params, &mut one, &mut alone);
                    for got in [&batch, &interpreted] {
                        let got = &got[k * len..(k + 1) * len];
                        assert!(
                            got.iter()
                                .zip(&want)
                                .chain(got.iter().zip(&alone))
                                .all(|(a, b)| a.to_bits() == b.to_bits()),
                            "{name} {} state {k}: {got:?} vs {want:?}",
                            f.name()
                        );
                    }
                }
            }
        }
    }

    /// A matrix given as rows, column by column.
    fn column_major<T: Copy>(rows: &[Vec<T>]) -> Vec<T> {
        let cols = rows.first().map_or(0, Vec::len);
        (0..cols)
            .flat_map(|j| rows.iter().map(move |r| r[j]))
            .collect()
    }

    /// The printed association, not the program's tree: `2 a b` is
    /// `(2 a) b`, a leading negative term negates its first operand, terms
    /// ready first are added first (a quotient is ready last). Chosen so
    /// that the tree's association rounds differently.
    #[test]
    fn sums_and_products_associate_as_printed() {
        use crate::schedule::{Code, Program, Scheduled};
        let (a, b) = (0.1, 3.0f64.sqrt());
        let (x, y) = (Code::Sym(Symbol::Q(0)), Code::Sym(Symbol::Q(1)));
        let prod = Code::Prod {
            num: vec![x.clone(), y.clone()],
            den: vec![],
        };
        let term = |c: f64| Code::Sum {
            constant: 0.0,
            terms: vec![(c, prod.clone())],
        };
        let ratio = Code::Prod {
            num: vec![x.clone()],
            den: vec![y.clone()],
        };
        let sum = Code::Sum {
            constant: 0.3,
            terms: vec![(-1.0, y.clone()), (1.0, ratio)],
        };
        let lead_negative = Code::Sum {
            constant: -0.7,
            terms: vec![(-1.0, y.clone()), (-2.0, x.clone())],
        };
        let quotient = Code::Prod {
            num: vec![],
            den: vec![x, y],
        };
        let outputs = vec![term(0.3), term(-0.3), sum, lead_negative, quotient];
        // The constraints of a scene of 2 coordinates and 5 constraints.
        let f = Scheduled::constraints(2, Program::new(Vec::new(), outputs));
        let tape = assemble::assemble(&lower(&f, true, false), 2, 0);
        let mut got = vec![f64::NAN; 5];
        tape.eval(&[a, b], &[], 0.0, &[], &mut Scratch::default(), &mut got);
        // What Rust computes for the printed expressions.
        let want = [
            0.3 * a * b,
            -0.3 * a * b,
            0.3 - b + a / b,
            -0.7 - b - 2.0 * a,
            1.0 / (a * b),
        ];
        assert_eq!(got, want);
        assert_ne!(0.3 * a * b, 0.3 * (a * b), "the example distinguishes");
    }

    #[test]
    fn intermediate_slots_are_reused() {
        let mut model = Model::load(&scene("ur5")).unwrap();
        let eq = model.equations().unwrap();
        let it = Interpreted::new(&model, &eq);
        let tape = it.tape(Function::DynamicsTerms).unwrap();
        let inputs = 3 * it.nq() + 1 + it.parameters().len() + tape.literals.len();
        assert!(
            tape.slots - inputs < tape.instructions() / 2,
            "{} slots for {} instructions",
            tape.slots - inputs,
            tape.instructions()
        );
    }

    #[test]
    fn a_scene_with_errors_gives_the_generators_error() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.toml");
        std::fs::write(
            &path,
            "name = \"bad\"\n[[coordinates]]\nname = \"a\"\n\
             [[components]]\nname = \"m\"\ntype = \"point_mass\"\nmass = 1\n\
             position = [\"a*\", 0, 0]\n",
        )
        .unwrap();
        let e = Interpreted::load(&path).unwrap_err().to_string();
        let generator = crate::generate_scene(&path).unwrap_err().to_string();
        assert_eq!(e, generator);
        assert!(e.contains("bad.toml"), "{e}");
    }
}
