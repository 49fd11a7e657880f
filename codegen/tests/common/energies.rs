//! Total energies of a model at a state, for the integration tests that
//! compare a component with the same physics written another way.

use flexdyn_codegen::{Model, Symbol};

/// Total T and V of a model at (q, qd), runtime parameters at `params`.
pub fn energies(model: &Model, q: &[f64], qd: &[f64], params: &[f64]) -> (f64, f64) {
    let ids: Vec<_> = model
        .components
        .iter()
        .flat_map(|c| [c.kinetic, c.potential])
        .collect();
    let values = model.graph.eval(&ids, &|s| match s {
        Symbol::Q(i) => q[i as usize],
        Symbol::Qd(i) => qd[i as usize],
        Symbol::Param(i) => params[i as usize],
        Symbol::Time => 0.0,
        Symbol::Qdd(_) => f64::NAN, // energies do not depend on accelerations
    });
    values
        .chunks(2)
        .fold((0.0, 0.0), |(t, v), c| (t + c[0], v + c[1]))
}
