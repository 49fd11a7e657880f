//! The emitted functions, each one program: which derived terms each
//! computes (the functions of the runtime's `Model` trait, the fused ones
//! sharing the subexpressions of several terms, and the optional outputs),
//! with the structurally zero entries of matrices and the lower triangle of
//! symmetric ones left out.

use super::{schedule, Program};
use crate::derive::Equations;
use crate::expr::{Graph, Id};
use crate::model::Model;

/// What an emitted function is called and how.
#[derive(Debug, Clone, Copy)]
pub struct Signature {
    /// Function name.
    pub name: &'static str,
    /// Its doc comment.
    pub doc: &'static str,
    /// Whether it takes the velocities.
    pub with_qd: bool,
    /// Whether it takes the accelerations (after the velocities).
    pub with_qdd: bool,
    /// Whether it overrides an optional trait method (returns `true`).
    pub optional: bool,
}

impl Signature {
    fn new(name: &'static str, doc: &'static str, with_qd: bool) -> Signature {
        Signature {
            name,
            doc,
            with_qd,
            with_qdd: false,
            optional: false,
        }
    }

    fn with_accelerations(mut self) -> Signature {
        self.with_qdd = true;
        self
    }

    fn optional(mut self) -> Signature {
        self.optional = true;
        self
    }
}

/// Storage of an output.
#[derive(Debug, Clone, Copy)]
pub enum Shape {
    /// A vector: one row of entries.
    Vector,
    /// A matrix; a symmetric one computes its upper triangle.
    Matrix {
        /// Whether it is symmetric.
        symmetric: bool,
    },
}

/// One output argument of an emitted function.
#[derive(Debug, Clone)]
pub struct Output {
    /// Argument name.
    pub name: &'static str,
    /// Its storage.
    pub shape: Shape,
    /// Its entries as rows (one row for a vector).
    pub entries: Vec<Vec<Id>>,
}

impl Output {
    fn vector(name: &'static str, entries: &[Id]) -> Output {
        Output {
            name,
            shape: Shape::Vector,
            entries: vec![entries.to_vec()],
        }
    }

    fn matrix(name: &'static str, entries: &[Vec<Id>], symmetric: bool) -> Output {
        Output {
            name,
            shape: Shape::Matrix { symmetric },
            entries: entries.to_vec(),
        }
    }
}

/// An emitted function and its program.
#[derive(Debug, Clone)]
pub struct Function {
    /// Its signature.
    pub sig: Signature,
    /// Its output arguments; none for a function returning one scalar.
    pub outputs: Vec<Output>,
    /// The computed entries, in program output order.
    pub ids: Vec<Id>,
    /// Where each computed entry goes: (output, row, column).
    pub slots: Vec<(usize, usize, usize)>,
    /// The program computing `ids`.
    pub program: Program,
}

impl Function {
    /// A function writing one or more outputs (vectors or matrices) from one
    /// jointly optimised program, so that all outputs share their common
    /// subexpressions. Matrix entries that are structurally zero are not
    /// computed (the emitted function zeroes the matrix first); symmetric
    /// matrices compute the upper triangle.
    fn new(graph: &Graph, sig: Signature, outputs: Vec<Output>) -> Function {
        let zero = graph.find_constant(0.0);
        let mut ids = Vec::new();
        let mut slots = Vec::new();
        for (k, o) in outputs.iter().enumerate() {
            for (i, row) in o.entries.iter().enumerate() {
                for (j, &e) in row.iter().enumerate() {
                    let skip = match o.shape {
                        Shape::Vector => false,
                        Shape::Matrix { symmetric } => (symmetric && j < i) || Some(e) == zero,
                    };
                    if !skip {
                        ids.push(e);
                        slots.push((k, i, j));
                    }
                }
            }
        }
        let program = schedule(graph, &ids);
        Function {
            sig,
            outputs,
            ids,
            slots,
            program,
        }
    }

    /// A function returning the scalar `id`.
    fn scalar(
        graph: &Graph,
        name: &'static str,
        doc: &'static str,
        id: Id,
        with_qd: bool,
    ) -> Function {
        Function {
            sig: Signature::new(name, doc, with_qd),
            outputs: Vec::new(),
            ids: vec![id],
            slots: Vec::new(),
            program: schedule(graph, &[id]),
        }
    }

    /// Whether it returns one scalar.
    pub fn is_scalar(&self) -> bool {
        self.outputs.is_empty()
    }
}

/// The functions of a scene's module, in emission order, each scheduled.
pub fn functions(model: &Model, eq: &Equations) -> Vec<Function> {
    let graph = &model.graph;
    let mut functions = vec![
        Function::new(
            graph,
            Signature::new(
                "mass_matrix",
                "Mass matrix `M(q, t)`; the upper triangle is computed and mirrored.",
                false,
            ),
            vec![Output::matrix("m", &eq.mass, true)],
        ),
        Function::new(
            graph,
            Signature::new(
                "bias",
                "Bias forces `h = C(q, qd) qd + dV/dq + dD/dqd`.",
                true,
            ),
            vec![Output::vector("h", &eq.bias)],
        ),
        Function::new(
            graph,
            Signature::new("constraints", "Constraint residuals `Phi(q, t)`.", false),
            vec![Output::vector("phi", &eq.phi)],
        ),
        Function::new(
            graph,
            Signature::new(
                "constraint_jacobian",
                "Constraint Jacobian `Phi_q(q, t)`.",
                false,
            ),
            vec![Output::matrix("phi_q", &eq.phi_q, false)],
        ),
        Function::new(
            graph,
            Signature::new(
                "constraint_time_derivative",
                "Explicit time derivative of the constraints `Phi_t(q, t)`.",
                false,
            ),
            vec![Output::vector("phi_t", &eq.phi_t)],
        ),
        Function::new(
            graph,
            Signature::new(
                "constraint_rhs",
                "Acceleration right-hand side `gamma` with `Phi_q qdd = gamma`.",
                true,
            ),
            vec![Output::vector("gamma", &eq.gamma)],
        ),
        Function::new(
            graph,
            Signature::new(
                "constraints_and_jacobian",
                "`Phi` and `Phi_q` together, from one program sharing their common subexpressions (what a Newton iteration on the constraints needs).",
                false,
            ),
            vec![
                Output::vector("phi", &eq.phi),
                Output::matrix("phi_q", &eq.phi_q, false),
            ],
        ),
        Function::new(
            graph,
            Signature::new(
                "dynamics_terms",
                "`M`, `h`, `Phi_q` and `gamma` together, from one program sharing all common subexpressions (what a solver needs per evaluation).",
                true,
            ),
            vec![
                Output::matrix("m", &eq.mass, true),
                Output::vector("h", &eq.bias),
                Output::matrix("phi_q", &eq.phi_q, false),
                Output::vector("gamma", &eq.gamma),
            ],
        ),
        Function::new(
            graph,
            Signature::new(
                "inverse_dynamics",
                "Inverse dynamics `tau = M(q, t) qdd + h(q, qd, t)`, the generalized forces that give the accelerations `qdd` (without constraint forces), as one program: the forward derivative of the momenta along the motion, not `M` times `qdd`.",
                true,
            )
            .with_accelerations(),
            vec![Output::vector("tau", &eq.inverse_dynamics)],
        ),
        Function::scalar(
            graph,
            "kinetic_energy",
            "Kinetic energy `T`.",
            eq.kinetic_energy,
            true,
        ),
        Function::scalar(
            graph,
            "potential_energy",
            "Potential energy `V` (gravity and elastic).",
            eq.potential_energy,
            false,
        ),
    ];

    // Optional outputs (the runtime trait's methods default to "not generated").
    if model.outputs.forces {
        for (name, doc, ids, qd) in [
            (
                "coriolis_forces",
                "Coriolis/centrifugal forces `C(q, qd) qd` (with explicit time terms).",
                &eq.coriolis,
                true,
            ),
            (
                "potential_forces",
                "Gravity and elastic forces `dV/dq`.",
                &eq.potential_forces,
                false,
            ),
            (
                "damping_forces",
                "Damping forces `dD/dqd`.",
                &eq.damping_forces,
                true,
            ),
        ] {
            functions.push(Function::new(
                graph,
                Signature::new(name, doc, qd).optional(),
                vec![Output::vector("out", ids)],
            ));
        }
    }
    if let Some(cm) = &eq.coriolis_matrix {
        functions.push(Function::new(
            graph,
            Signature::new(
                "coriolis_matrix",
                "Coriolis matrix from Christoffel symbols: `C qd` are the Coriolis forces and `dM/dt - 2 C` is skew-symmetric.",
                true,
            )
            .optional(),
            vec![Output::matrix("out", cm, false)],
        ));
    }

    if let Some((h_q, h_qd)) = &eq.bias_jacobians {
        functions.push(Function::new(
            graph,
            Signature::new(
                "bias_jacobians",
                "Exact Jacobians of the bias forces: `h_q = dh/dq`, `h_qd = dh/dqd` (entry `(i, j)` is `d h_i / d x_j`).",
                true,
            )
            .optional(),
            vec![
                Output::matrix("h_q", h_q, false),
                Output::matrix("h_qd", h_qd, false),
            ],
        ));
    }
    functions
}
