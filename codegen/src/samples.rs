//! Sample states of a model, where the stages after the model check what
//! holds in the declared ranges: the pruning bound ([`crate::prune`]), the
//! signs of energies ([`crate::checks`]), redundant constraints
//! ([`crate::redundancy`]).

use crate::expr::{Graph, Id, Symbol};
use crate::model::{Coordinate, RuntimeParameter};

/// Number of sample states.
pub const SAMPLES: usize = 64;

/// Sample states: coordinates and velocities uniform in their
/// declared ranges, time in `[0, 10]` s, runtime parameters at their nominal
/// values; a fixed-seed generator, so generation is reproducible.
pub(crate) struct Samples {
    /// `values[s][symbol slot]`: slots `2 i` (q_i), `2 i + 1` (qd_i).
    values: Vec<Vec<f64>>,
    time: Vec<f64>,
}

impl Samples {
    pub(crate) fn new(coordinates: &[Coordinate]) -> Samples {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut uniform = |[a, b]: [f64; 2]| {
            // xorshift64*
            state ^= state >> 12;
            state ^= state << 25;
            state ^= state >> 27;
            let u = (state.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64;
            a + (b - a) * u
        };
        let mut values = Vec::with_capacity(SAMPLES);
        let mut time = Vec::with_capacity(SAMPLES);
        for _ in 0..SAMPLES {
            let mut v = Vec::with_capacity(2 * coordinates.len());
            for c in coordinates {
                v.push(uniform(c.range.unwrap_or([-1.0, 1.0])));
                v.push(uniform(c.velocity_range.unwrap_or([-1.0, 1.0])));
            }
            values.push(v);
            time.push(uniform([0.0, 10.0]));
        }
        Samples { values, time }
    }

    /// The coordinates and time of every sample.
    pub(crate) fn positions(&self) -> impl Iterator<Item = (Vec<f64>, f64)> + '_ {
        self.values
            .iter()
            .zip(&self.time)
            .map(|(v, &t)| (v.iter().step_by(2).copied().collect(), t))
    }

    /// Evaluate `roots` at every sample, handing each sample's values to `f`.
    pub(crate) fn each(
        &self,
        g: &Graph,
        roots: &[Id],
        params: &[RuntimeParameter],
        mut f: impl FnMut(Vec<f64>),
    ) {
        for (v, &t) in self.values.iter().zip(&self.time) {
            f(g.eval(roots, &|s| match s {
                Symbol::Q(i) => v[2 * i as usize],
                Symbol::Qd(i) => v[2 * i as usize + 1],
                Symbol::Time => t,
                Symbol::Param(i) => params[i as usize].value,
                // The pruned terms never read accelerations.
                Symbol::Qdd(_) => 0.0,
            }));
        }
    }

    /// Largest magnitude of each of `roots` over the samples (infinite where
    /// a value is not finite).
    pub(crate) fn max_abs(&self, g: &Graph, roots: &[Id], params: &[RuntimeParameter]) -> Vec<f64> {
        let mut out = vec![0.0f64; roots.len()];
        self.each(g, roots, params, |values| {
            for (o, x) in out.iter_mut().zip(values) {
                *o = o.max(if x.is_finite() {
                    x.abs()
                } else {
                    f64::INFINITY
                });
            }
        });
        out
    }
}
