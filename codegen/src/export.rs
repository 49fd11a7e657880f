//! A neutral, documented JSON export of a scene's symbolic inputs, so that
//! other tools (the CasADi validation, SymPy benchmarks) can rebuild exactly
//! the same energies and derive the equations independently.
//!
//! Format `flexdyn-scene-export/1` (see `docs/export-format.md`): the
//! reachable expression nodes in topological order (children first), each
//! referring to earlier nodes by index, and the scene's items referring to
//! nodes by index: the nodes of the energies and constraints first (numbered
//! as if the scene had no markers), then those only the markers' poses
//! reach. Derived terms (a marker's velocity among them) are deliberately
//! not exported.

use std::collections::{HashMap, HashSet};

use serde::Serialize;

use crate::expr::{Func, Id, Node, Symbol};
use crate::model::{Marker, Model};

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
    Abs {
        arg: usize,
    },
    Sign {
        arg: usize,
    },
    Step {
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
struct MarkerOut<'a> {
    name: &'a str,
    position: [usize; 3],
    rotation: [[usize; 3]; 3],
}

#[derive(Serialize)]
struct OutputsOut {
    coriolis_matrix: bool,
    forces: bool,
    bias_jacobians: bool,
    dynamics_derivatives: bool,
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
    markers: Vec<MarkerOut<'a>>,
    outputs: OutputsOut,
    drop_below: Option<f64>,
}

/// The nodes to export, in topological order: those the energies and
/// constraints reach (in increasing id), then those only the markers' poses
/// reach (in increasing id, children first too: what the first part reaches
/// is closed under children). A scene without markers exports exactly the
/// first part, and adding markers to a scene leaves its numbering.
fn exported_nodes(model: &Model) -> Vec<Id> {
    let g = &model.graph;
    let mut order = g.reachable(&model.input_roots());
    let inputs: HashSet<Id> = order.iter().copied().collect();
    let pose: Vec<Id> = model.markers.iter().flat_map(Marker::pose_nodes).collect();
    order.extend(
        g.reachable(&pose)
            .into_iter()
            .filter(|id| !inputs.contains(id)),
    );
    order
}

/// The export of a model as pretty-printed JSON.
pub fn export_json(model: &Model) -> String {
    let g = &model.graph;
    let order = exported_nodes(model);
    let position: HashMap<Id, usize> = order.iter().enumerate().map(|(k, &id)| (id, k)).collect();
    let index = |id: Id| position[&id];
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
                    Func::Abs => NodeOut::Abs { arg },
                    Func::Sign => NodeOut::Sign { arg },
                    Func::Step => NodeOut::Step { arg },
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
        markers: model
            .markers
            .iter()
            .map(|m| MarkerOut {
                name: &m.name,
                position: m.position.map(index),
                rotation: m.rotation.map(|row| row.map(index)),
            })
            .collect(),
        outputs: OutputsOut {
            coriolis_matrix: model.outputs.coriolis_matrix,
            forces: model.outputs.forces,
            bias_jacobians: model.outputs.bias_jacobians,
            dynamics_derivatives: model.outputs.dynamics_derivatives,
        },
        drop_below: model.drop_below,
    };
    serde_json::to_string_pretty(&export).expect("export serialises")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shipped(scene: &str) -> Model {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../scenes")
            .join(scene);
        Model::load(&path).expect("shipped scene loads")
    }

    fn json(model: &Model) -> serde_json::Value {
        serde_json::from_str(&export_json(model)).expect("export is JSON")
    }

    #[test]
    fn markers_leave_the_numbering_of_the_energies_and_constraints() {
        let with = shipped("four_bar.toml");
        let mut without = with.clone();
        without.markers.clear();
        let (a, b) = (json(&with), json(&without));
        assert_eq!(b["markers"], serde_json::json!([]));
        let (na, nb) = (
            a["nodes"].as_array().unwrap(),
            b["nodes"].as_array().unwrap(),
        );
        assert!(na.len() > nb.len(), "the marker's pose adds nodes");
        assert_eq!(na[..nb.len()], nb[..]);
        for key in ["components", "constraints"] {
            assert_eq!(a[key], b[key], "{key}");
        }
    }

    #[test]
    fn every_marker_exports_its_position_and_rotation_nodes() {
        for scene in ["four_bar.toml", "ur5.toml"] {
            let model = shipped(scene);
            let order = exported_nodes(&model);
            let out = json(&model);
            let markers = out["markers"].as_array().unwrap();
            assert_eq!(markers.len(), model.markers.len(), "{scene}");
            for (m, e) in model.markers.iter().zip(markers) {
                assert_eq!(e["name"], m.name.as_str());
                let exported: Vec<Id> = e["position"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .chain(
                        e["rotation"]
                            .as_array()
                            .unwrap()
                            .iter()
                            .flat_map(|r| r.as_array().unwrap()),
                    )
                    .map(|k| order[k.as_u64().unwrap() as usize])
                    .collect();
                assert_eq!(
                    exported,
                    m.pose_nodes().collect::<Vec<_>>(),
                    "{scene}: {}",
                    m.name
                );
            }
        }
    }
}
