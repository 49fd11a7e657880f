//! Stage 2, model: from a loaded scene to symbolic energies. Checks names,
//! parameters and physical data, builds kinematic frames, and turns every
//! component into its kinetic energy `T`, potential energy `V` and
//! dissipation function `D`.
//!
//! Order ([`build`]): coordinates and parameters ([`coordinates`]) and
//! gravity; then the components that add coordinates (a `flexible_link`,
//! whose finite-element model, [`crate::fem`], is built numerically and
//! whose modal coordinates `<name>_eta<j>` are appended to the declared
//! ones); then the frames in file order ([`frames`]; a frame with `station`
//! follows a flexible link's deformed centre line); then the components'
//! energies ([`components`], one file per kind), the constraints
//! ([`constraints`]) and the actuators ([`actuators`]). The reading of scene
//! values into graph nodes is in [`context`]; vectors and rotations in
//! [`crate::geometry`].

mod actuators;
mod assemble;
mod components;
mod constraints;
mod context;
mod coordinates;
mod frames;
mod markers;

use std::collections::BTreeMap;
use std::path::PathBuf;

use nalgebra::DMatrix;

use crate::expr::{Graph, Id, Symbol};
use crate::fem::{FeModel, Invariants, ModalBasis};

pub(crate) use assemble::build;
pub(crate) use context::overflow_message;

/// A generalized coordinate.
#[derive(Debug, Clone, PartialEq)]
pub struct Coordinate {
    /// Its name.
    pub name: String,
    /// Declared position range.
    pub range: Option<[f64; 2]>,
    /// Declared velocity range.
    pub velocity_range: Option<[f64; 2]>,
    /// Initial position of a simulation (scene key `initial`, default 0).
    pub initial: f64,
    /// Initial velocity of a simulation (scene key `initial_velocity`,
    /// default 0).
    pub initial_velocity: f64,
}

/// A parameter left as an input of the generated model.
#[derive(Debug, Clone, PartialEq)]
pub struct RuntimeParameter {
    /// Field name in the generated model struct.
    pub name: String,
    /// Nominal value (the struct's default).
    pub value: f64,
}

/// The energies of one component.
#[derive(Debug, Clone)]
pub struct Component {
    /// Name for reports.
    pub name: String,
    /// Kind (`rod`, `energy`, ...).
    pub kind: String,
    /// Kinetic energy.
    pub kinetic: Id,
    /// Potential energy.
    pub potential: Id,
    /// Rayleigh dissipation function.
    pub dissipation: Id,
    /// The kinetic energy's rigid-body form, for a rigid body, a point
    /// mass or a rod (`T` the sum of its bodies' energies); empty for other
    /// kinds.
    pub bodies: Vec<Body>,
    /// The part of `potential` that is the weight of its bodies, `-m g . r`
    /// at each centre (a rigid body, a point mass, a flexible joint's
    /// member): the derivation may apply gravity to them as an acceleration
    /// of the world instead.
    pub weight: Option<Id>,
}

/// A kinetic energy of rigid-body form, `T = (m v.v + w.I w) / 2`: `v` the
/// time derivative of a point's position (or of any vector, the rod's from
/// end to end), in the axes of a frame, `w` that frame's angular velocity
/// in its own axes, and `I` an inertia in those axes, constant (parameters
/// only). The derivation uses the form to write the body's Lagrange terms
/// as Newton-Euler forces ([`crate::derive`]).
#[derive(Debug, Clone, Copy)]
pub struct Body {
    /// Mass `m`.
    pub mass: Id,
    /// Velocity `v` (of the centre of mass; of the vector for a rod), in the frame's axes.
    pub velocity: [Id; 3],
    /// The frame's angular velocity `w`, in its own axes.
    pub omega: [Id; 3],
    /// Inertia about the centre of mass, in the frame's axes; `None` for a
    /// point mass.
    pub inertia: Option<[[Id; 3]; 3]>,
    /// Where it is fixed in the kinematic tree, when it moves with a frame
    /// of the scene (not for a rod, nor a body of the world).
    pub attached: Option<Attachment>,
}

/// A body's place in the kinematic tree.
#[derive(Debug, Clone, Copy)]
pub struct Attachment {
    /// The frame it moves with, an index into [`Model::placements`].
    pub node: usize,
    /// Its centre of mass in that frame's axes, from its origin.
    pub centre: [Id; 3],
}

/// How a frame of the scene is placed in its parent: translated by
/// `translation` (in the parent's axes), then rotated by each of
/// `rotations` in turn. The model's frames in this form are its kinematic
/// tree, which the derivation walks for the mass matrix
/// ([`crate::derive`]).
#[derive(Debug, Clone)]
pub struct Placement {
    /// The parent's index in [`Model::placements`] (always lower); `None`
    /// for the world.
    pub parent: Option<usize>,
    /// The translation, in the parent's axes.
    pub translation: [Id; 3],
    /// The rotations in turn: unit axis and angle.
    pub rotations: Vec<([f64; 3], Id)>,
    /// The frame's twist `(v, w)` in its own axes with its parent at rest:
    /// what its own coordinates add to its parent's motion.
    pub twist: [Id; 6],
    /// The frame's twist `(v, w)` in its own axes, as the model built it
    /// (what the components' energies read).
    pub velocity: [Id; 6],
}

impl Placement {
    /// The coordinates whose velocities its twist reads, in order.
    pub fn own_coordinates(&self, g: &Graph) -> Vec<u32> {
        let mut own: Vec<u32> = g
            .symbols(&self.twist)
            .into_iter()
            .filter_map(|s| match s {
                Symbol::Qd(i) => Some(i),
                _ => None,
            })
            .collect();
        own.sort_unstable();
        own
    }

    /// Its nodes: translation, angles, twist, velocity.
    fn nodes(&self) -> impl Iterator<Item = Id> + '_ {
        self.translation
            .into_iter()
            .chain(self.rotations.iter().map(|r| r.1))
            .chain(self.twist)
            .chain(self.velocity)
    }

    /// Replace its nodes, in the order of [`Self::nodes`].
    fn set_nodes(&mut self, it: &mut impl Iterator<Item = Id>) {
        let mut next = || it.next().expect("one node per root");
        self.translation = std::array::from_fn(|_| next());
        for r in &mut self.rotations {
            r.1 = next();
        }
        self.twist = std::array::from_fn(|_| next());
        self.velocity = std::array::from_fn(|_| next());
    }
}

impl Component {
    /// The nodes of the component's bodies, and its weight's.
    fn body_nodes(&self) -> Vec<Id> {
        let mut roots: Vec<Id> = self.weight.into_iter().collect();
        for b in &self.bodies {
            roots.push(b.mass);
            roots.extend(b.velocity);
            roots.extend(b.omega);
            roots.extend(b.inertia.iter().flatten().flatten());
            roots.extend(b.attached.iter().flat_map(|a| a.centre));
        }
        roots
    }

    /// Replace the nodes of the component's bodies, in the order of
    /// [`Self::body_nodes`].
    fn set_body_nodes(&mut self, it: &mut impl Iterator<Item = Id>) {
        let mut next = || it.next().expect("one node per root");
        if let Some(w) = &mut self.weight {
            *w = next();
        }
        for b in &mut self.bodies {
            b.mass = next();
            b.velocity = std::array::from_fn(|_| next());
            b.omega = std::array::from_fn(|_| next());
            if let Some(inertia) = &mut b.inertia {
                *inertia = std::array::from_fn(|_| std::array::from_fn(|_| next()));
            }
            if let Some(a) = &mut b.attached {
                a.centre = std::array::from_fn(|_| next());
            }
        }
    }
}

/// A holonomic constraint.
#[derive(Debug, Clone)]
pub struct Constraint {
    /// Name for reports.
    pub name: String,
    /// Residual `Phi(q, t)`.
    pub residual: Id,
    /// Byte offset of its definition in the scene file, for messages.
    pub at: usize,
}

/// A marker: a named point of a frame, with its world pose and velocity.
#[derive(Debug, Clone)]
pub struct Marker {
    /// Name.
    pub name: String,
    /// World position of the point.
    pub position: [Id; 3],
    /// Rotation from the frame's axes to world axes.
    pub rotation: [[Id; 3]; 3],
    /// Velocity in world axes: the point's linear velocity, then the
    /// frame's angular velocity (with explicit time terms).
    pub velocity: [Id; 6],
    /// The point's linear velocity again, written about the point (`w_i x
    /// (p - o_i)` per rotation): what the Jacobian is differentiated from.
    pub linear_about_point: [Id; 3],
}

impl Marker {
    /// Its pose's nodes: position, then rotation (by rows).
    pub fn pose_nodes(&self) -> impl Iterator<Item = Id> + '_ {
        self.position
            .into_iter()
            .chain(self.rotation.into_iter().flatten())
    }

    /// Its nodes: position, rotation (by rows), velocity, linear velocity
    /// about the point.
    fn nodes(&self) -> impl Iterator<Item = Id> + '_ {
        self.pose_nodes()
            .chain(self.velocity)
            .chain(self.linear_about_point)
    }

    /// Replace its nodes, in the order of [`Self::nodes`].
    fn set_nodes(&mut self, it: &mut impl Iterator<Item = Id>) {
        let mut next = || it.next().expect("one node per root");
        self.position = std::array::from_fn(|_| next());
        self.rotation = std::array::from_fn(|_| std::array::from_fn(|_| next()));
        self.velocity = std::array::from_fn(|_| next());
        self.linear_about_point = std::array::from_fn(|_| next());
    }
}

/// An actuator input.
#[derive(Debug, Clone, PartialEq)]
pub struct Actuator {
    /// Name.
    pub name: String,
    /// Coordinate it drives.
    pub coordinate: usize,
    /// Generalized force per unit input.
    pub gain: f64,
}

/// The names of the optional outputs a scene may list in `outputs`.
pub const OUTPUTS: &[&str] = &[
    "coriolis_matrix",
    "forces",
    "bias_jacobians",
    "dynamics_derivatives",
];

/// Optional outputs a scene may ask for.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Outputs {
    /// The Coriolis matrix from Christoffel symbols.
    pub coriolis_matrix: bool,
    /// Coriolis, potential and damping forces as separate functions.
    pub forces: bool,
    /// Exact Jacobians of the bias forces, `dh/dq` and `dh/dqd` (for the
    /// Newton matrix of implicit integrators).
    pub bias_jacobians: bool,
    /// Exact derivatives of the inverse dynamics, `d tau / d q` and
    /// `d tau / d qd` (`d tau / d qdd` is `M`), for linearization and
    /// optimal control.
    pub dynamics_derivatives: bool,
}

/// Scalar type of the generated code (scene key `precision`,
/// `Builder::precision`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Precision {
    /// `f64`: the module implements the runtime's `Model` trait.
    #[default]
    F64,
    /// `f32` (for microcontrollers with a single-precision FPU): the module
    /// implements `Model<NQ, NC, NU, f32>` (the same functions in `f32`,
    /// calling the runtime's `math::f32`), which the runtime's solvers take
    /// as they take an `f64` model.
    F32,
}

impl Precision {
    /// The Rust type name, `f64` or `f32`.
    pub fn rust_type(self) -> &'static str {
        match self {
            Precision::F64 => "f64",
            Precision::F32 => "f32",
        }
    }
}

/// The finite-element data behind a `flexible_link` component, built
/// numerically when the scene is read.
#[derive(Debug, Clone)]
pub struct FlexibleLink {
    /// Component name.
    pub name: String,
    /// Name of its reference frame.
    pub frame: String,
    /// Index in [`Model::coordinates`] of its first modal coordinate; the
    /// `k` modal coordinates follow in mode order.
    pub first_coordinate: usize,
    /// The constrained finite-element model.
    pub fe: FeModel,
    /// The kept modes.
    pub basis: ModalBasis,
    /// Their inertia invariants.
    pub invariants: Invariants,
    /// Modal damping ratio of each kept mode.
    pub damping_ratio: Vec<f64>,
    /// `Phi^T Kg1 Phi` for the centrifugal axial force per unit squared
    /// transverse spin rate, when geometric stiffening is on.
    pub geometric_stiffness: Option<DMatrix<f64>>,
}

impl FlexibleLink {
    /// Number of kept modes.
    pub fn modes(&self) -> usize {
        self.basis.len()
    }
}

/// A scene turned into symbolic energies.
#[derive(Debug, Clone)]
pub struct Model {
    /// Scene name (an identifier).
    pub name: String,
    /// The expression graph holding every expression below.
    pub graph: Graph,
    /// Coordinates in order.
    pub coordinates: Vec<Coordinate>,
    /// Runtime parameters, in the order of `Symbol::Param` indices.
    pub runtime_parameters: Vec<RuntimeParameter>,
    /// Nominal value of every parameter, folded or runtime, by name.
    pub parameters: BTreeMap<String, f64>,
    /// Components.
    pub components: Vec<Component>,
    /// Constraints.
    pub constraints: Vec<Constraint>,
    /// Actuators.
    pub actuators: Vec<Actuator>,
    /// Markers.
    pub markers: Vec<Marker>,
    /// The kinematic tree: every frame's placement in its parent, parents
    /// first.
    pub placements: Vec<Placement>,
    /// Gravity in world axes.
    pub gravity: [Id; 3],
    /// Optional outputs.
    pub outputs: Outputs,
    /// Scalar type of the generated code.
    pub precision: Precision,
    /// Finite-element data of the flexible links, in component order.
    pub flexible_links: Vec<FlexibleLink>,
    /// Relative tolerance below which summands of the mass matrix and bias
    /// forces are dropped after the derivation (a derived scene's
    /// `reduce.drop_below`, set by the reduce stage, applied by the prune
    /// stage).
    pub drop_below: Option<f64>,
    /// Every file the model was read from (a derived scene and its base).
    pub sources: Vec<PathBuf>,
    /// What the stages changed that a user should know (constraints
    /// dropped as redundant), one line each.
    pub notes: Vec<String>,
}

impl Model {
    /// Number of coordinates.
    pub fn nq(&self) -> usize {
        self.coordinates.len()
    }

    /// The components whose energies switch with the state: a `sign`,
    /// `step` or `abs` (also inside `min`, `max`) of an expression of the
    /// coordinates or rates, where the forces jump or kink and the Newton
    /// iterations of implicit integrators may not converge.
    pub fn switching_components(&self) -> Vec<&str> {
        use crate::expr::{Func, Node, Symbol};
        let g = &self.graph;
        self.components
            .iter()
            .filter(|c| {
                g.reachable(&[c.kinetic, c.potential, c.dissipation])
                    .into_iter()
                    .any(|id| match g.node(id) {
                        Node::Call(Func::Sign | Func::Step | Func::Abs, arg) => g
                            .symbols(&[*arg])
                            .iter()
                            .any(|s| matches!(s, Symbol::Q(_) | Symbol::Qd(_))),
                        _ => false,
                    })
            })
            .map(|c| c.name.as_str())
            .collect()
    }

    /// The scene's symbolic inputs: `T`, `V`, `D` of every component in
    /// order, then every constraint residual (what the export writes).
    pub fn input_roots(&self) -> Vec<Id> {
        let mut roots: Vec<Id> = Vec::new();
        for c in &self.components {
            roots.extend([c.kinetic, c.potential, c.dissipation]);
        }
        roots.extend(self.constraints.iter().map(|c| c.residual));
        roots
    }

    /// Every node the model refers to: [`Self::input_roots`], then the
    /// components' bodies', the markers', the placements' and gravity.
    pub fn roots(&self) -> Vec<Id> {
        let mut roots = self.input_roots();
        roots.extend(self.components.iter().flat_map(Component::body_nodes));
        roots.extend(self.markers.iter().flat_map(Marker::nodes));
        roots.extend(self.placements.iter().flat_map(Placement::nodes));
        roots.extend(self.gravity);
        roots
    }

    /// Replace every node the model refers to by `new`, in the order of
    /// [`Self::roots`].
    pub fn set_roots(&mut self, new: Vec<Id>) {
        let mut it = new.into_iter();
        let mut next = || it.next().expect("one node per root");
        for c in &mut self.components {
            c.kinetic = next();
            c.potential = next();
            c.dissipation = next();
        }
        for c in &mut self.constraints {
            c.residual = next();
        }
        for c in &mut self.components {
            c.set_body_nodes(&mut it);
        }
        for m in &mut self.markers {
            m.set_nodes(&mut it);
        }
        for p in &mut self.placements {
            p.set_nodes(&mut it);
        }
        self.gravity = std::array::from_fn(|_| it.next().expect("one node per root"));
    }
}
