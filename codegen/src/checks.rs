//! Checks of the derived model that the earlier stages cannot make: a
//! derivation whose constants overflow `f64`, and `energy` components whose
//! kinetic energy or dissipation decreases along a velocity (a negative
//! mass, a damper that feeds energy in) at the sample states of pruning,
//! the literals of an `f32` module outside `f32`'s normal range, and the
//! coordinates of an unconstrained scene that move no mass.

use crate::derive::Equations;
use crate::expr::{Graph, Id, Node, Symbol};
use crate::model::{Component, Model};
use crate::samples::Samples;
use crate::schedule::{Code, Scheduled, Stmt};

/// A check that failed: the component (or part of the model) and what is
/// wrong.
pub(crate) struct Failure {
    /// `component `name``, or the part of the model.
    pub(crate) context: String,
    /// What is wrong.
    pub(crate) message: String,
}

/// The largest magnitude of the constants (constant nodes and the
/// coefficients and constants of sums) reachable from `roots`.
fn largest_constant(g: &Graph, roots: &[Id]) -> f64 {
    g.reachable(roots)
        .into_iter()
        .map(|id| match g.node(id) {
            Node::Const(c) => c.get().abs(),
            Node::Sum(ts, k) => ts
                .iter()
                .fold(k.get().abs(), |m, (_, c)| m.max(c.get().abs())),
            _ => 0.0,
        })
        .fold(0.0, f64::max)
}

/// Where a derivation that overflowed most likely overflowed: the component
/// with the largest constant in its energies, or `None` without components.
pub(crate) fn largest_component(model: &Model) -> Option<(&Component, f64)> {
    model
        .components
        .iter()
        .map(|c| {
            let roots = [c.kinetic, c.potential, c.dissipation];
            (c, largest_constant(&model.graph, &roots))
        })
        .max_by(|a, b| a.1.total_cmp(&b.1))
}

/// `energy` components (energies written as expressions, the only kind
/// whose signs a scene chooses freely): the second derivative of the
/// kinetic energy and of the dissipation function in each velocity they
/// read must not be negative at any sample state (declared ranges, fixed
/// seed; beyond rounding, `1e-9` of the largest over the samples).
pub(crate) fn energy_signs(model: &mut Model) -> Result<(), Failure> {
    let samples = Samples::new(&model.coordinates);
    for c in model.components.iter().filter(|c| c.kind == "energy") {
        for (energy, what, meaning) in [
            (c.kinetic, "kinetic energy", "a negative mass"),
            (
                c.dissipation,
                "dissipation function",
                "a damper that feeds energy in",
            ),
        ] {
            let g = &mut model.graph;
            let velocities: Vec<u32> = g
                .symbols(&[energy])
                .into_iter()
                .filter_map(|s| match s {
                    Symbol::Qd(i) => Some(i),
                    _ => None,
                })
                .collect();
            let second: Vec<Id> = velocities
                .iter()
                .map(|&i| {
                    let d = g.diff(energy, Symbol::Qd(i));
                    g.diff(d, Symbol::Qd(i))
                })
                .collect();
            let mut values = Vec::new();
            samples.each(g, &second, &model.runtime_parameters, |v| values.push(v));
            let scale = values.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
            let negative = values
                .iter()
                .flat_map(|v| v.iter().zip(&velocities))
                .find(|&(&v, _)| v < -1e-9 * scale);
            if let Some((&v, &i)) = negative {
                let name = &model.coordinates[i as usize].name;
                return Err(Failure {
                    context: format!("component `{}`", c.name),
                    message: format!(
                        "the {what} decreases along the velocity of `{name}` (its second \
                         derivative in it is {v:e} at a sample state of the declared ranges): \
                         {meaning}"
                    ),
                });
            }
        }
    }
    Ok(())
}

/// A note naming the coordinates of an unconstrained scene whose diagonal
/// entry of the mass matrix is identically zero (no mass or inertia moves
/// with them: a URDF's massless fingers): its mass matrix is singular at
/// every state, so it has no forward dynamics. A constrained scene's
/// constraints may still determine such a coordinate.
pub(crate) fn massless_coordinates(model: &Model, eq: &Equations) -> Option<String> {
    if !model.constraints.is_empty() {
        return None;
    }
    let zero = |id: Id| matches!(model.graph.node(id), Node::Const(k) if k.get() == 0.0);
    let names: Vec<String> = (0..eq.mass.len())
        .filter(|&i| zero(eq.mass[i][i]))
        .map(|i| format!("`{}`", model.coordinates[i].name))
        .collect();
    (!names.is_empty()).then(|| {
        format!(
            "{} of the {} coordinates move no mass or inertia ({}): the mass matrix is \
             singular at every state, so the scene has no forward dynamics (`simulate` stops, \
             `eval` leaves them out); give them inertia (a body, or an actuator's `armature`) \
             or hold them fixed (`flexdyn import urdf --fix JOINT`)",
            names.len(),
            eq.mass.len(),
            names.join(", ")
        )
    })
}

/// The literals of `code`, coefficients and constants of sums included.
fn literals(code: &Code, out: &mut Vec<f64>) {
    match code {
        Code::Var(_) | Code::Sym(_) => {}
        Code::Lit(x) => out.push(*x),
        Code::Sum { constant, terms } => {
            out.push(*constant);
            for (c, t) in terms {
                out.push(*c);
                literals(t, out);
            }
        }
        Code::Prod { num, den } => num.iter().chain(den).for_each(|f| literals(f, out)),
        Code::Call(_, a) => literals(a, out),
        Code::Atan2(y, x) => {
            literals(y, out);
            literals(x, out);
        }
    }
}

/// An `f32` module's literals: every literal of every emitted function's
/// program must be a normal `f32` or zero (beyond `f32::MAX` the literal does
/// not compile; below `f32::MIN_POSITIVE` it becomes subnormal or zero).
pub(crate) fn f32_literals(functions: &[Scheduled]) -> Result<(), Failure> {
    for f in functions {
        let mut constants = Vec::new();
        for st in &f.program.stmts {
            match st {
                Stmt::Let { value, .. } => literals(value, &mut constants),
                Stmt::SinCos { arg, .. } => literals(arg, &mut constants),
            }
        }
        for o in &f.program.outputs {
            literals(o, &mut constants);
        }
        for c in constants {
            let why = if c.abs() > f64::from(f32::MAX) {
                format!(
                    "beyond f32's range (|x| <= {:e}): the literal does not compile",
                    f32::MAX
                )
            } else if c != 0.0 && c.abs() < f64::from(f32::MIN_POSITIVE) {
                format!(
                    "below f32's smallest normal number {:e}: it would become subnormal or 0",
                    f32::MIN_POSITIVE
                )
            } else {
                continue;
            };
            return Err(Failure {
                context: format!("function `{}`", f.function.name()),
                message: format!(
                    "its constant {c:e} is {why}; generate the scene in f64 or choose other units"
                ),
            });
        }
    }
    Ok(())
}
