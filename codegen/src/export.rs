//! A neutral, documented JSON export of a scene's symbolic inputs, so that
//! other tools (the CasADi validation, SymPy benchmarks) can rebuild exactly
//! the same energies and derive the equations independently.
//!
//! Format `flexdyn-scene-export/1` (see `docs/export-format.md`): the
//! reachable expression nodes in topological order (children first), each
//! referring to earlier nodes by index, and the scene's items referring to
//! nodes by index. Derived terms are deliberately not exported.

use serde::Serialize;

use crate::expr::{Func, Id, Node, Symbol};
use crate::model::Model;

/// Version tag of the format.
pub const FORMAT: &str = "flexdyn-scene-export/1";

#[derive(Serialize)]
#[serde(tag = "op", rename_all = "snake_case")]
enum NodeOut {
    Const {
        value: f64,
    },
    Q {
        index: u32,
    },
    Qd {
        index: u32,
    },
    T,
    Param {
        index: u32,
    },
    Sum {
        constant: f64,
        terms: Vec<(usize, f64)>,
    },
    Prod {
        factors: Vec<(usize, i32)>,
    },
    Sin {
        arg: usize,
    },
    Cos {
        arg: usize,
    },
    Tan {
        arg: usize,
    },
    Exp {
        arg: usize,
    },
    Ln {
        arg: usize,
    },
    Sqrt {
        arg: usize,
    },
    Atan2 {
        y: usize,
        x: usize,
    },
}

#[derive(Serialize)]
struct CoordinateOut<'a> {
    name: &'a str,
    range: Option<[f64; 2]>,
    velocity_range: Option<[f64; 2]>,
}

#[derive(Serialize)]
struct ParameterOut<'a> {
    name: &'a str,
    value: f64,
}

#[derive(Serialize)]
struct ComponentOut<'a> {
    name: &'a str,
    kind: &'a str,
    kinetic: usize,
    potential: usize,
    dissipation: usize,
}

#[derive(Serialize)]
struct ConstraintOut<'a> {
    name: &'a str,
    residual: usize,
}

#[derive(Serialize)]
struct ActuatorOut<'a> {
    name: &'a str,
    coordinate: usize,
    gain: f64,
}

#[derive(Serialize)]
struct OutputsOut {
    coriolis_matrix: bool,
    forces: bool,
    bias_jacobians: bool,
}

#[derive(Serialize)]
struct Export<'a> {
    format: &'static str,
    name: &'a str,
    coordinates: Vec<CoordinateOut<'a>>,
    runtime_parameters: Vec<ParameterOut<'a>>,
    nodes: Vec<NodeOut>,
    components: Vec<ComponentOut<'a>>,
    constraints: Vec<ConstraintOut<'a>>,
    actuators: Vec<ActuatorOut<'a>>,
    outputs: OutputsOut,
    drop_below: Option<f64>,
}

/// The export of a model as pretty-printed JSON.
pub fn export_json(model: &Model) -> String {
    let g = &model.graph;
    let order = g.reachable(&model.input_roots());
    let index = |id: Id| order.binary_search(&id).expect("reachable node");
    let nodes = order
        .iter()
        .map(|&id| match g.node(id) {
            Node::Const(c) => NodeOut::Const { value: c.get() },
            Node::Sym(Symbol::Q(i)) => NodeOut::Q { index: *i },
            Node::Sym(Symbol::Qd(i)) => NodeOut::Qd { index: *i },
            Node::Sym(Symbol::Time) => NodeOut::T,
            Node::Sym(Symbol::Param(i)) => NodeOut::Param { index: *i },
            Node::Sym(Symbol::Qdd(_)) => {
                unreachable!("scene inputs (energies, constraints) never read accelerations")
            }
            Node::Sum(ts, k) => NodeOut::Sum {
                constant: k.get(),
                terms: ts.iter().map(|&(t, c)| (index(t), c.get())).collect(),
            },
            Node::Prod(fs) => NodeOut::Prod {
                factors: fs.iter().map(|&(b, e)| (index(b), e)).collect(),
            },
            Node::Call(f, a) => {
                let arg = index(*a);
                match f {
                    Func::Sin => NodeOut::Sin { arg },
                    Func::Cos => NodeOut::Cos { arg },
                    Func::Tan => NodeOut::Tan { arg },
                    Func::Exp => NodeOut::Exp { arg },
                    Func::Ln => NodeOut::Ln { arg },
                    Func::Sqrt => NodeOut::Sqrt { arg },
                }
            }
            Node::Atan2(y, x) => NodeOut::Atan2 {
                y: index(*y),
                x: index(*x),
            },
        })
        .collect();
    let export = Export {
        format: FORMAT,
        name: &model.name,
        coordinates: model
            .coordinates
            .iter()
            .map(|c| CoordinateOut {
                name: &c.name,
                range: c.range,
                velocity_range: c.velocity_range,
            })
            .collect(),
        runtime_parameters: model
            .runtime_parameters
            .iter()
            .map(|p| ParameterOut {
                name: &p.name,
                value: p.value,
            })
            .collect(),
        nodes,
        components: model
            .components
            .iter()
            .map(|c| ComponentOut {
                name: &c.name,
                kind: &c.kind,
                kinetic: index(c.kinetic),
                potential: index(c.potential),
                dissipation: index(c.dissipation),
            })
            .collect(),
        constraints: model
            .constraints
            .iter()
            .map(|c| ConstraintOut {
                name: &c.name,
                residual: index(c.residual),
            })
            .collect(),
        actuators: model
            .actuators
            .iter()
            .map(|a| ActuatorOut {
                name: &a.name,
                coordinate: a.coordinate,
                gain: a.gain,
            })
            .collect(),
        outputs: OutputsOut {
            coriolis_matrix: model.outputs.coriolis_matrix,
            forces: model.outputs.forces,
            bias_jacobians: model.outputs.bias_jacobians,
        },
        drop_below: model.drop_below,
    };
    serde_json::to_string_pretty(&export).expect("export serialises")
}
