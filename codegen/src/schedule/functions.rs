//! The table of emitted functions ([`Function`], one entry each: name, doc,
//! inputs, outputs with their shapes and symmetry, whether optional, and
//! which derived terms it computes), and each function of a scene scheduled
//! as one program ([`functions()`]), with the structurally zero entries of
//! matrices and the lower triangle of symmetric ones left out. Everything
//! else (the Rust and C emitters, the interpreter, the command line's
//! dispatch) is derived from this table: adding a function is one entry.

use super::{schedule, Code, Program};
use crate::derive::{Equations, MarkerTerms};
use crate::expr::{Graph, Id};
use crate::model::Model;

/// A dimension of a scene.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dim {
    /// The number of coordinates `NQ`.
    Coordinates,
    /// The number of constraints `NC`.
    Constraints,
    /// The number of actuator inputs `NU`.
    Actuators,
    /// A size of its own (a marker's 3-vectors, 6-vectors, 3 x 3 rotation).
    Fixed(usize),
}

/// A scene's dimensions, `(NQ, NC, NU)`.
pub type Dims = (usize, usize, usize);

impl Dim {
    /// Its size in a scene of dimensions `dims`.
    pub fn size(self, (nq, nc, nu): Dims) -> usize {
        match self {
            Dim::Coordinates => nq,
            Dim::Constraints => nc,
            Dim::Actuators => nu,
            Dim::Fixed(n) => n,
        }
    }
}

/// Storage of an output.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Shape {
    /// One value, returned by the function.
    Scalar,
    /// A vector (`SVector`).
    Vector(Dim),
    /// A matrix (`SMatrix`); a symmetric one computes its upper triangle
    /// and mirrors it.
    Matrix {
        /// Rows.
        rows: Dim,
        /// Columns.
        cols: Dim,
        /// Whether it is symmetric.
        symmetric: bool,
    },
}

impl Shape {
    /// `(rows, columns)` in a scene of dimensions `dims` (a vector has one
    /// column, a value is 1 x 1).
    pub fn size(self, dims: Dims) -> (usize, usize) {
        match self {
            Shape::Scalar => (1, 1),
            Shape::Vector(n) => (n.size(dims), 1),
            Shape::Matrix { rows, cols, .. } => (rows.size(dims), cols.size(dims)),
        }
    }
}

/// One output argument of a function in the table.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OutputSpec {
    /// Argument name (`out` for a returned value).
    pub name: &'static str,
    /// Its storage.
    pub shape: Shape,
}

/// The arrays a function reads besides the runtime parameters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Inputs {
    /// None: a constant (the actuator map).
    Constant,
    /// The actuator inputs `tau` (NU) only (the graph's `Symbol::Qdd`).
    Actuation,
    /// `q` and `t`.
    Positions,
    /// `q`, `qd` and `t`.
    Velocities,
    /// `q`, `qd`, `qdd` and `t`.
    Accelerations,
    /// `q`, `qd`, the generalized forces `f` and `t` (`f` in the place of
    /// `qdd`: the graph's `Symbol::Qdd`).
    Forces,
}

/// The terms a function computes: per output, its entries as rows.
pub enum Terms {
    /// Nodes of the expression graph, computed by one program.
    Nodes(Vec<Vec<Vec<Id>>>),
    /// Constants (the actuator map), written as literals.
    Constants(Vec<Vec<Vec<f64>>>),
    /// One set of nodes per marker, each computed by a program of its own
    /// (a function with a `marker` index).
    Markers(Vec<Vec<Vec<Vec<Id>>>>),
}

/// What a function of the table is called, reads, writes and computes.
#[derive(Clone, Copy)]
pub struct Spec {
    /// Function name (the method of the runtime's `Model` trait).
    pub name: &'static str,
    /// Its doc comment.
    pub doc: &'static str,
    /// What it reads.
    pub inputs: Inputs,
    /// What it writes, in argument order.
    pub outputs: &'static [OutputSpec],
    /// Whether it overrides an optional trait method (returns `true`).
    pub optional: bool,
    /// Whether it computes one marker's kinematics, chosen by a `marker`
    /// index (its first argument; `false` for an index the scene does not
    /// have). Such functions are optional.
    pub per_marker: bool,
    /// Its terms, `None` where the scene does not generate it (an optional
    /// output it does not ask for).
    terms: fn(&Model, &Equations) -> Option<Terms>,
}

/// A vector of `n`.
const fn vector(name: &'static str, n: Dim) -> OutputSpec {
    OutputSpec {
        name,
        shape: Shape::Vector(n),
    }
}

/// A matrix with `nq` columns.
const fn matrix(name: &'static str, rows: Dim, symmetric: bool) -> OutputSpec {
    OutputSpec {
        name,
        shape: Shape::Matrix {
            rows,
            cols: Dim::Coordinates,
            symmetric,
        },
    }
}

/// A returned value.
const SCALAR: OutputSpec = OutputSpec {
    name: "out",
    shape: Shape::Scalar,
};

const NQ: Dim = Dim::Coordinates;
const NC: Dim = Dim::Constraints;

/// A marker's position (3).
const POSITION: OutputSpec = vector("position", Dim::Fixed(3));

/// A marker's rotation (3 x 3).
const ROTATION: OutputSpec = OutputSpec {
    name: "rotation",
    shape: Shape::Matrix {
        rows: Dim::Fixed(3),
        cols: Dim::Fixed(3),
        symmetric: false,
    },
};

/// Each marker's outputs from its terms.
fn per_marker(eq: &Equations, outputs: fn(&MarkerTerms) -> Vec<Vec<Vec<Id>>>) -> Option<Terms> {
    Some(Terms::Markers(eq.markers.iter().map(outputs).collect()))
}

/// A marker's position and rotation.
fn pose(m: &MarkerTerms) -> [Vec<Vec<Id>>; 2] {
    [
        column(&m.position),
        m.rotation.iter().map(|r| r.to_vec()).collect(),
    ]
}

/// A vector's entries as one column.
fn column(ids: &[Id]) -> Vec<Vec<Id>> {
    ids.iter().map(|&id| vec![id]).collect()
}

/// The terms of a function of vectors and matrices.
fn nodes(outputs: Vec<Vec<Vec<Id>>>) -> Option<Terms> {
    Some(Terms::Nodes(outputs))
}

/// The table: every function, in emission order, with its [`Spec`].
macro_rules! table {
    ($($(#[$doc:meta])* $variant:ident => $spec:expr,)*) => {
        /// The functions of a generated model (the runtime's `Model` trait), in
        /// emission order.
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        pub enum Function {
            $($(#[$doc])* $variant,)*
        }

        impl Function {
            /// Every function, in emission order.
            pub const ALL: &'static [Function] = &[$(Function::$variant),*];

            /// Its entry in the table.
            pub fn spec(self) -> &'static Spec {
                match self {
                    $(Function::$variant => {
                        const SPEC: Spec = $spec;
                        &SPEC
                    })*
                }
            }
        }
    };
}

table! {
    /// `mass_matrix`: `M` (nq x nq).
    MassMatrix => Spec {
        name: "mass_matrix",
        doc: "Mass matrix `M(q, t)`; the upper triangle is computed and mirrored.",
        inputs: Inputs::Positions,
        outputs: &[matrix("m", NQ, true)],
        optional: false,
        per_marker: false,
        terms: |_, eq| nodes(vec![eq.mass.clone()]),
    },
    /// `bias`: `h` (nq).
    Bias => Spec {
        name: "bias",
        doc: "Bias forces `h = C(q, qd) qd + dV/dq + dD/dqd`.",
        inputs: Inputs::Velocities,
        outputs: &[vector("h", NQ)],
        optional: false,
        per_marker: false,
        terms: |_, eq| nodes(vec![column(&eq.bias)]),
    },
    /// `constraints`: `Phi` (nc).
    Constraints => Spec {
        name: "constraints",
        doc: "Constraint residuals `Phi(q, t)`.",
        inputs: Inputs::Positions,
        outputs: &[vector("phi", NC)],
        optional: false,
        per_marker: false,
        terms: |_, eq| nodes(vec![column(&eq.phi)]),
    },
    /// `constraint_jacobian`: `Phi_q` (nc x nq).
    ConstraintJacobian => Spec {
        name: "constraint_jacobian",
        doc: "Constraint Jacobian `Phi_q(q, t)`.",
        inputs: Inputs::Positions,
        outputs: &[matrix("phi_q", NC, false)],
        optional: false,
        per_marker: false,
        terms: |_, eq| nodes(vec![eq.phi_q.clone()]),
    },
    /// `constraint_time_derivative`: `Phi_t` (nc).
    ConstraintTimeDerivative => Spec {
        name: "constraint_time_derivative",
        doc: "Explicit time derivative of the constraints `Phi_t(q, t)`.",
        inputs: Inputs::Positions,
        outputs: &[vector("phi_t", NC)],
        optional: false,
        per_marker: false,
        terms: |_, eq| nodes(vec![column(&eq.phi_t)]),
    },
    /// `constraint_rhs`: `gamma` (nc).
    ConstraintRhs => Spec {
        name: "constraint_rhs",
        doc: "Acceleration right-hand side `gamma` with `Phi_q qdd = gamma`.",
        inputs: Inputs::Velocities,
        outputs: &[vector("gamma", NC)],
        optional: false,
        per_marker: false,
        terms: |_, eq| nodes(vec![column(&eq.gamma)]),
    },
    /// `constraints_and_jacobian`: `Phi`, then `Phi_q`.
    ConstraintsAndJacobian => Spec {
        name: "constraints_and_jacobian",
        doc: "`Phi` and `Phi_q` together, from one program sharing their common subexpressions (what a Newton iteration on the constraints needs).",
        inputs: Inputs::Positions,
        outputs: &[vector("phi", NC), matrix("phi_q", NC, false)],
        optional: false,
        per_marker: false,
        terms: |_, eq| nodes(vec![column(&eq.phi), eq.phi_q.clone()]),
    },
    /// `dynamics_terms`: `M`, `h`, `Phi_q`, `gamma`.
    DynamicsTerms => Spec {
        name: "dynamics_terms",
        doc: "`M`, `h`, `Phi_q` and `gamma` together, from one program sharing all common subexpressions (what a solver needs per evaluation).",
        inputs: Inputs::Velocities,
        outputs: &[
            matrix("m", NQ, true),
            vector("h", NQ),
            matrix("phi_q", NC, false),
            vector("gamma", NC),
        ],
        optional: false,
        per_marker: false,
        terms: |_, eq| {
            nodes(vec![
                eq.mass.clone(),
                column(&eq.bias),
                eq.phi_q.clone(),
                column(&eq.gamma),
            ])
        },
    },
    /// `inverse_dynamics`: `M qdd + h` (nq), reads the accelerations.
    InverseDynamics => Spec {
        name: "inverse_dynamics",
        doc: "Inverse dynamics `tau = M(q, t) qdd + h(q, qd, t)`, the generalized forces that give the accelerations `qdd` (without constraint forces), as one program: the forward derivative of the momenta along the motion, not `M` times `qdd`.",
        inputs: Inputs::Accelerations,
        outputs: &[vector("tau", NQ)],
        optional: false,
        per_marker: false,
        terms: |_, eq| nodes(vec![column(&eq.inverse_dynamics)]),
    },
    /// `actuator_map`: `B` (nq x nu), constant.
    ActuatorMap => Spec {
        name: "actuator_map",
        doc: "Actuator map `B` (constant): actuator `j` adds `B[:, j] tau[j]` to the generalized forces.",
        inputs: Inputs::Constant,
        outputs: &[OutputSpec {
            name: "b",
            shape: Shape::Matrix {
                rows: NQ,
                cols: Dim::Actuators,
                symmetric: false,
            },
        }],
        optional: false,
        per_marker: false,
        terms: |_, eq| Some(Terms::Constants(vec![eq.actuator_map.clone()])),
    },
    /// `actuator_forces`: `B tau` (nq), reads the actuator inputs.
    ActuatorForces => Spec {
        name: "actuator_forces",
        doc: "The actuators' generalized forces `f = B tau` for the actuator inputs `tau` (the non-zero entries of `B` only).",
        inputs: Inputs::Actuation,
        outputs: &[vector("f", NQ)],
        optional: true,
        per_marker: false,
        terms: |_, eq| nodes(vec![column(&eq.actuator_forces)]),
    },
    /// `kinetic_energy`: `T` (one value).
    KineticEnergy => Spec {
        name: "kinetic_energy",
        doc: "Kinetic energy `T`.",
        inputs: Inputs::Velocities,
        outputs: &[SCALAR],
        optional: false,
        per_marker: false,
        terms: |_, eq| nodes(vec![vec![vec![eq.kinetic_energy]]]),
    },
    /// `potential_energy`: `V` (one value).
    PotentialEnergy => Spec {
        name: "potential_energy",
        doc: "Potential energy `V` (gravity and elastic).",
        inputs: Inputs::Positions,
        outputs: &[SCALAR],
        optional: false,
        per_marker: false,
        terms: |_, eq| nodes(vec![vec![vec![eq.potential_energy]]]),
    },
    /// `coriolis_forces` (optional output).
    CoriolisForces => Spec {
        name: "coriolis_forces",
        doc: "Coriolis/centrifugal forces `C(q, qd) qd` (with explicit time terms).",
        inputs: Inputs::Velocities,
        outputs: &[vector("out", NQ)],
        optional: true,
        per_marker: false,
        terms: |m, eq| m.outputs.forces.then(|| Terms::Nodes(vec![column(&eq.coriolis)])),
    },
    /// `potential_forces` (optional output).
    PotentialForces => Spec {
        name: "potential_forces",
        doc: "Gravity and elastic forces `dV/dq`.",
        inputs: Inputs::Positions,
        outputs: &[vector("out", NQ)],
        optional: true,
        per_marker: false,
        terms: |m, eq| {
            m.outputs
                .forces
                .then(|| Terms::Nodes(vec![column(&eq.potential_forces)]))
        },
    },
    /// `damping_forces` (optional output).
    DampingForces => Spec {
        name: "damping_forces",
        doc: "Damping forces `dD/dqd`.",
        inputs: Inputs::Velocities,
        outputs: &[vector("out", NQ)],
        optional: true,
        per_marker: false,
        terms: |m, eq| {
            m.outputs
                .forces
                .then(|| Terms::Nodes(vec![column(&eq.damping_forces)]))
        },
    },
    /// `coriolis_matrix` (optional output).
    CoriolisMatrix => Spec {
        name: "coriolis_matrix",
        doc: "Coriolis matrix from Christoffel symbols: `C qd` are the Coriolis forces and `dM/dt - 2 C` is skew-symmetric.",
        inputs: Inputs::Velocities,
        outputs: &[matrix("out", NQ, false)],
        optional: true,
        per_marker: false,
        terms: |_, eq| eq.coriolis_matrix.as_ref().map(|c| Terms::Nodes(vec![c.clone()])),
    },
    /// `bias_jacobians`: `dh/dq`, then `dh/dqd` (optional output).
    BiasJacobians => Spec {
        name: "bias_jacobians",
        doc: "Exact Jacobians of the bias forces: `h_q = dh/dq`, `h_qd = dh/dqd` (entry `(i, j)` is `d h_i / d x_j`).",
        inputs: Inputs::Velocities,
        outputs: &[matrix("h_q", NQ, false), matrix("h_qd", NQ, false)],
        optional: true,
        per_marker: false,
        terms: |_, eq| {
            eq.bias_jacobians
                .as_ref()
                .map(|(h_q, h_qd)| Terms::Nodes(vec![h_q.clone(), h_qd.clone()]))
        },
    },
    /// `inverse_dynamics_derivatives`: `tau`, `d tau/dq`, `d tau/dqd`
    /// (optional output).
    InverseDynamicsDerivatives => Spec {
        name: "inverse_dynamics_derivatives",
        doc: "Inverse dynamics `tau = M qdd + h` and its exact derivatives `tau_q = d tau/dq`, `tau_qd = d tau/dqd` at the accelerations `qdd` (entry `(i, j)` is `d tau_i / d x_j`; `d tau/dqdd` is `M`), from one program.",
        inputs: Inputs::Accelerations,
        outputs: &[vector("tau", NQ), matrix("tau_q", NQ, false), matrix("tau_qd", NQ, false)],
        optional: true,
        per_marker: false,
        terms: |_, eq| {
            eq.inverse_dynamics_derivatives.as_ref().map(|(tau_q, tau_qd)| {
                Terms::Nodes(vec![column(&eq.inverse_dynamics), tau_q.clone(), tau_qd.clone()])
            })
        },
    },
    /// `constraint_acceleration_derivatives`: `da/dq`, `da/dqd` of `a = Phi_q
    /// qdd - gamma` (optional output, constrained scenes).
    ConstraintAccelerationDerivatives => Spec {
        name: "constraint_acceleration_derivatives",
        doc: "Exact derivatives `a_q = da/dq`, `a_qd = da/dqd` (each nc x nq) of the acceleration constraint `a = Phi_q qdd - gamma` (the second time derivative of `Phi` along the motion) at the accelerations `qdd`; `a_qd` is `2 d(Phi_q qd + Phi_t)/dq`.",
        inputs: Inputs::Accelerations,
        outputs: &[matrix("a_q", NC, false), matrix("a_qd", NC, false)],
        optional: true,
        per_marker: false,
        terms: |_, eq| {
            eq.constraint_acceleration_derivatives
                .as_ref()
                .map(|(a_q, a_qd)| Terms::Nodes(vec![a_q.clone(), a_qd.clone()]))
        },
    },
    /// `forward_dynamics`: `qdd = M^-1 (f - h)` and the pivots of `M`
    /// (unconstrained scenes).
    ForwardDynamics => Spec {
        name: "forward_dynamics",
        doc: "Forward dynamics of an unconstrained scene, `qdd = M^-1 (f - h)` for the generalized forces `f` (`B tau` and any others), as one program: `M` and `h` with `M = L^T D L` factored and solved on them, keeping the zeros that a tree's branches give `M`. Writes the pivots of `D` too, each relative to its diagonal entry of `M` (`d`, in (0, 1] for a positive definite `M`): the solve is only valid where every one is positive and not negligible (the runtime checks them).",
        inputs: Inputs::Forces,
        outputs: &[vector("qdd", NQ), vector("d", NQ)],
        optional: true,
        per_marker: false,
        terms: |_, eq| {
            eq.forward_dynamics
                .as_ref()
                .map(|(qdd, d)| Terms::Nodes(vec![column(qdd), column(d)]))
        },
    },
    /// `forward_dynamics_derivatives`: `forward_dynamics` with the
    /// derivatives of `qdd` (unconstrained scenes that ask for
    /// `dynamics_derivatives`).
    ForwardDynamicsDerivatives => Spec {
        name: "forward_dynamics_derivatives",
        doc: "Forward dynamics of an unconstrained scene with its exact derivatives, as one program: `qdd = M^-1 (f - h)` and the relative pivots `d` as `forward_dynamics` writes them, `qdd_q = d qdd/dq` and `qdd_qd = d qdd/dqd` at the generalized forces `f` (`-M^-1 d tau/dx` of the inverse dynamics at `qdd`), and `qdd_f = d qdd/df = M^-1` (entry `(i, j)` is `d qdd_i / d x_j`), every solve on the factors of `M = L^T D L`. Valid where `forward_dynamics` is.",
        inputs: Inputs::Forces,
        outputs: &[
            vector("qdd", NQ),
            vector("d", NQ),
            matrix("qdd_q", NQ, false),
            matrix("qdd_qd", NQ, false),
            matrix("qdd_f", NQ, true),
        ],
        optional: true,
        per_marker: false,
        terms: |_, eq| {
            let (qdd, d) = eq.forward_dynamics.as_ref()?;
            eq.forward_dynamics_derivatives
                .as_ref()
                .map(|(qdd_q, qdd_qd, qdd_f)| {
                    Terms::Nodes(vec![
                        column(qdd),
                        column(d),
                        qdd_q.clone(),
                        qdd_qd.clone(),
                        qdd_f.clone(),
                    ])
                })
        },
    },
    /// `marker_pose`: a marker's position (3) and rotation (3 x 3).
    MarkerPose => Spec {
        name: "marker_pose",
        doc: "World position of marker `marker` and its rotation (marker axes to world axes).",
        inputs: Inputs::Positions,
        outputs: &[POSITION, ROTATION],
        optional: true,
        per_marker: true,
        terms: |_, eq| per_marker(eq, |m| pose(m).to_vec()),
    },
    /// `marker_jacobian`: a marker's position, rotation and Jacobian (6 x nq).
    MarkerJacobian => Spec {
        name: "marker_jacobian",
        doc: "World position and rotation of marker `marker`, and its Jacobian (6 x nq) in world-aligned axes at the marker: rows 0-2 the velocity of the marker point, rows 3-5 the angular velocity (Pinocchio's `LOCAL_WORLD_ALIGNED`), from one program.",
        inputs: Inputs::Positions,
        outputs: &[
            POSITION,
            ROTATION,
            OutputSpec {
                name: "jacobian",
                shape: Shape::Matrix {
                    rows: Dim::Fixed(6),
                    cols: NQ,
                    symmetric: false,
                },
            },
        ],
        optional: true,
        per_marker: true,
        terms: |_, eq| {
            per_marker(eq, |m| {
                let [p, r] = pose(m);
                vec![p, r, m.jacobian.clone()]
            })
        },
    },
    /// `marker_motion`: a marker's velocity (6) and acceleration bias (6).
    MarkerMotion => Spec {
        name: "marker_motion",
        doc: "Velocity of marker `marker` in world axes (the point's linear velocity, then the angular velocity; `J qd` plus explicit time terms) and its acceleration bias (its acceleration when `qdd = 0`: `J' qd` plus explicit time terms; the point's classical acceleration, then the angular acceleration).",
        inputs: Inputs::Velocities,
        outputs: &[vector("velocity", Dim::Fixed(6)), vector("acceleration_bias", Dim::Fixed(6))],
        optional: true,
        per_marker: true,
        terms: |_, eq| {
            per_marker(eq, |m| vec![column(&m.velocity), column(&m.acceleration_bias)])
        },
    },
}

impl Spec {
    /// The terms of the function in `model`, `None` where the scene does
    /// not generate it.
    pub fn terms(&self, model: &Model, eq: &Equations) -> Option<Terms> {
        (self.terms)(model, eq)
    }
}

impl Function {
    /// The method's name in generated code.
    pub fn name(self) -> &'static str {
        self.spec().name
    }

    /// The function called `name`, if any.
    pub fn from_name(name: &str) -> Option<Function> {
        Function::ALL.iter().copied().find(|f| f.name() == name)
    }
}

/// A function of a scene, scheduled.
#[derive(Debug, Clone)]
pub struct Scheduled {
    /// Which function.
    pub function: Function,
    /// The marker it computes, for a per-marker function.
    pub marker: Option<usize>,
    /// The scene's dimensions.
    pub dims: Dims,
    /// Where each computed entry goes: (output, row, column).
    pub slots: Vec<(usize, usize, usize)>,
    /// The program computing the entries (literals only for a constant).
    pub program: Program,
}

impl Scheduled {
    /// Its entry in the table.
    pub fn spec(&self) -> &'static Spec {
        self.function.spec()
    }

    /// For tests: `program` as the constraints of a scene of `nq`
    /// coordinates, one constraint per output.
    #[cfg(test)]
    pub(crate) fn constraints(nq: usize, program: Program) -> Scheduled {
        let nc = program.outputs.len();
        Scheduled {
            function: Function::Constraints,
            marker: None,
            dims: (nq, nc, 0),
            slots: (0..nc).map(|i| (0, i, 0)).collect(),
            program,
        }
    }

    /// The function of `terms`: one jointly optimised program for all
    /// outputs, so that they share their common subexpressions. Matrix
    /// entries that are structurally zero are not computed (the emitted
    /// function zeroes the matrix first); symmetric matrices compute the
    /// upper triangle.
    fn new(
        graph: &Graph,
        function: Function,
        marker: Option<usize>,
        dims: Dims,
        terms: Terms,
    ) -> Scheduled {
        let outputs = function.spec().outputs;
        // The entries to compute, and where each goes.
        fn place<T: Copy>(
            outputs: &[OutputSpec],
            entries: &[Vec<Vec<T>>],
            zero: impl Fn(T) -> bool,
        ) -> (Vec<T>, Vec<(usize, usize, usize)>) {
            let (mut kept, mut slots) = (Vec::new(), Vec::new());
            for (k, o) in entries.iter().enumerate() {
                for (i, row) in o.iter().enumerate() {
                    for (j, &e) in row.iter().enumerate() {
                        let skip = match outputs[k].shape {
                            Shape::Matrix { symmetric, .. } => (symmetric && j < i) || zero(e),
                            Shape::Scalar | Shape::Vector(_) => false,
                        };
                        if !skip {
                            kept.push(e);
                            slots.push((k, i, j));
                        }
                    }
                }
            }
            (kept, slots)
        }
        let (slots, program) = match terms {
            Terms::Nodes(entries) => {
                let zero = graph.find_constant(0.0);
                let (ids, slots) = place(outputs, &entries, |e| Some(e) == zero);
                (slots, schedule(graph, &ids))
            }
            Terms::Constants(entries) => {
                let (values, slots) = place(outputs, &entries, |x| x == 0.0);
                let literals = values.into_iter().map(Code::Lit).collect();
                (slots, Program::new(Vec::new(), literals))
            }
            Terms::Markers(_) => unreachable!("a marker's terms are scheduled one by one"),
        };
        Scheduled {
            function,
            marker,
            dims,
            slots,
            program,
        }
    }
}

/// The functions of a scene's module, in emission order, each scheduled
/// (a per-marker function once per marker, in marker order).
pub fn functions(model: &Model, eq: &Equations) -> Vec<Scheduled> {
    let dims = (model.nq(), model.constraints.len(), model.actuators.len());
    let g = &model.graph;
    let mut out = Vec::new();
    for &f in Function::ALL {
        match f.spec().terms(model, eq) {
            None => {}
            Some(Terms::Markers(each)) => out.extend(
                each.into_iter()
                    .enumerate()
                    .map(|(k, t)| Scheduled::new(g, f, Some(k), dims, Terms::Nodes(t))),
            ),
            Some(terms) => out.push(Scheduled::new(g, f, None, dims, terms)),
        }
    }
    out
}
