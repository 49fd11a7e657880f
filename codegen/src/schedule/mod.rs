//! Stage 6, schedule: the table of emitted functions ([`Function`]: name,
//! inputs, outputs, which derived terms each computes) and each function of
//! a scene as a straight-line program ([`functions()`]) from the expression
//! nodes of its outputs, in two passes: common-subexpression elimination
//! ([`cse`]: every node used more than once gets one `let`, `sin` and `cos`
//! of one argument one `sin_cos` call, only nodes reachable from the outputs
//! are kept), then sharing of the reciprocals of repeated divisors and of
//! repeated pairs of factors and terms, in that order, so that a reciprocal
//! pairs like any factor ([`share`]); a program carries its
//! operation count ([`code`]). Each
//! program is then lowered once ([`lower()`]) into operations in evaluation
//! order, which the emitter prints and the interpreter runs; [`plan`]
//! pairs the statements of mirror-image limbs, which the Rust emitter prints
//! on two lanes ([`lanes`]).

mod code;
mod cse;
mod functions;
mod lanes;
mod lower;
mod share;

pub use code::{Code, OpCount, Program, Stmt};
#[cfg(test)]
pub use functions::Terms;
pub use functions::{functions, Dim, Function, Inputs, OutputSpec, Scheduled, Shape, Spec};
pub use lanes::{mirror_of, plan, printed, Mirror, Plan, Print, Step};
pub use lower::{lower, Binary, Fused, Lowered, Op, Operand, Value};

use crate::expr::{Graph, Id};

/// Schedule the computation of `outputs`.
pub fn schedule(graph: &Graph, outputs: &[Id]) -> Program {
    let (mut stmts, mut outputs, mut next) = cse::eliminate(graph, outputs);
    share::share_reciprocals(&mut stmts, &mut outputs, &mut next);
    share::share_pairs(&mut stmts, &mut outputs, &mut next);
    Program::new(stmts, outputs)
}

#[cfg(test)]
mod tests {
    use std::collections::HashMap;

    use super::*;
    use crate::expr::Symbol;

    /// Evaluate a program with the same semantics the emitter gives it.
    pub(crate) fn run(p: &Program, env: &dyn Fn(Symbol) -> f64) -> Vec<f64> {
        let mut vars: HashMap<u32, f64> = HashMap::new();
        fn ev(c: &Code, vars: &HashMap<u32, f64>, env: &dyn Fn(Symbol) -> f64) -> f64 {
            match c {
                Code::Var(v) => vars[v],
                Code::Sym(s) => env(*s),
                Code::Lit(x) => *x,
                Code::Sum { constant, terms } => terms
                    .iter()
                    .fold(*constant, |a, (k, t)| a + k * ev(t, vars, env)),
                Code::Prod { num, den } => {
                    let n: f64 = num.iter().map(|f| ev(f, vars, env)).product();
                    let d: f64 = den.iter().map(|f| ev(f, vars, env)).product();
                    n / d
                }
                Code::Call(f, a) => f.apply(ev(a, vars, env)),
                Code::Atan2(y, x) => ev(y, vars, env).atan2(ev(x, vars, env)),
            }
        }
        for st in &p.stmts {
            match st {
                Stmt::Let { var, value } => {
                    let v = ev(value, &vars, env);
                    vars.insert(*var, v);
                }
                Stmt::SinCos { sin, cos, arg } => {
                    let a = ev(arg, &vars, env);
                    vars.insert(*sin, a.sin());
                    vars.insert(*cos, a.cos());
                }
            }
        }
        p.outputs.iter().map(|o| ev(o, &vars, env)).collect()
    }

    #[test]
    fn program_computes_the_graph_values() {
        let mut g = Graph::new();
        let (x, y) = (g.q(0), g.q(1));
        let s = g.sin(x);
        let c = g.cos(x);
        let sy = g.mul(s, y);
        let cy = g.mul(c, y);
        let r = g.div(sy, cy);
        let y3 = g.powi(y, 3);
        let o1 = g.add(r, y3);
        let o2 = g.atan2(sy, cy);
        let outs = [o1, o2, sy, x];
        let p = schedule(&g, &outs);
        let env = |s: Symbol| match s {
            Symbol::Q(0) => 0.4,
            Symbol::Q(1) => -1.3,
            _ => 0.0,
        };
        let want = g.eval(&outs, &env);
        let got = run(&p, &env);
        for (a, b) in want.iter().zip(&got) {
            assert!((a - b).abs() < 1e-14, "{a} vs {b}");
        }
        // sin and cos of x computed by one call; sy used twice is bound once.
        let sincos = p
            .stmts
            .iter()
            .filter(|s| matches!(s, Stmt::SinCos { .. }))
            .count();
        assert_eq!(sincos, 1);
        assert_eq!(p.ops.calls, 2, "{:?}", p.ops); // sin_cos + atan2
    }

    /// Repeated pairs of factors and of terms are computed once: three
    /// products `a b c`, `a b d`, `a b e` take 1 + 3 multiplications instead
    /// of 6; the sums `2x + y + z`, `2x + y - z`, `2x + y + 3w` share
    /// `s = x + 0.5 y` (1 multiplication, 1 addition), then take `2s + z`,
    /// `2s - z`, `2s + 3w`: 5 multiplications and 4 additions instead of 4
    /// and 6. The values are unchanged (to rounding).
    #[test]
    fn repeated_pairs_are_shared() {
        let mut g = Graph::new();
        let q: Vec<Id> = (0..6).map(|i| g.q(i)).collect();
        let ab = g.mul(q[0], q[1]);
        let products: Vec<Id> = (2..5).map(|i| g.mul(ab, q[i])).collect();
        let p = schedule(&g, &products);
        assert_eq!((p.ops.muls, p.ops.adds), (4, 0), "{:?}", p.ops);
        let (x, y, z, w) = (q[0], q[1], q[2], q[3]);
        let x2 = g.scale(x, 2.0);
        let base = g.add(x2, y);
        let s1 = g.add(base, z);
        let s2 = g.sub(base, z);
        let w3 = g.scale(w, 3.0);
        let s3 = g.add(base, w3);
        let sums = [s1, s2, s3];
        let p2 = schedule(&g, &sums);
        assert_eq!((p2.ops.muls, p2.ops.adds), (5, 4), "{:?}", p2.ops);
        let env = |s: Symbol| match s {
            Symbol::Q(i) => 0.3 + 0.7 * f64::from(i) - 0.05 * f64::from(i * i),
            _ => 0.0,
        };
        for (program, outs) in [(&p, &products[..]), (&p2, &sums[..])] {
            let want = g.eval(outs, &env);
            let got = run(program, &env);
            for (a, b) in want.iter().zip(&got) {
                assert!((a - b).abs() <= 1e-15 * a.abs().max(1.0), "{a} vs {b}");
            }
        }
    }

    /// A factorisation's updates `x y / d`, `x z / d`, `x w / d` (a
    /// multiplier `x / d` times each entry of a row): the divisor inverted
    /// once, `r = 1 / d`, and then the pair `x r` shared by the three
    /// products: 1 division and 4 multiplications, where sharing the pairs
    /// before the reciprocals saw only two-factor numerators and left 6.
    #[test]
    fn reciprocals_join_the_shared_pairs() {
        let mut g = Graph::new();
        let q: Vec<Id> = (0..5).map(|i| g.q(i)).collect();
        let updates: Vec<Id> = (2..5)
            .map(|i| {
                let p = g.mul(q[1], q[i]);
                g.div(p, q[0])
            })
            .collect();
        let p = schedule(&g, &updates);
        assert_eq!((p.ops.divs, p.ops.muls), (1, 4), "{:?}", p.ops);
        assert_computes(&g, &p, &updates);
    }

    /// Three products of the same 20 factors, each times one factor of its
    /// own: the passes pair pairs until nothing repeats (20 factors nest
    /// five deep), 19 multiplications for the common product and one for
    /// each, where 4 passes left 2 more.
    #[test]
    fn pairs_nest_until_nothing_repeats() {
        let mut g = Graph::new();
        let q: Vec<Id> = (0..23).map(|i| g.q(i)).collect();
        let common: Vec<(Id, i32)> = q[..20].iter().map(|&x| (x, 1)).collect();
        let products: Vec<Id> = (20..23)
            .map(|k| {
                let mut f = common.clone();
                f.push((q[k], 1));
                g.product(&f)
            })
            .collect();
        let p = schedule(&g, &products);
        assert_eq!(p.ops.muls, 22, "{:?}", p.ops);
        assert_computes(&g, &p, &products);
    }

    /// The program computes the graph's values of `outputs` (to rounding)
    /// at `q_i = 1 + 0.01 i`.
    fn assert_computes(g: &Graph, p: &Program, outputs: &[Id]) {
        let env = |s: Symbol| match s {
            Symbol::Q(i) => 1.0 + 0.01 * f64::from(i),
            _ => 0.0,
        };
        let want = g.eval(outputs, &env);
        for (a, b) in want.iter().zip(&run(p, &env)) {
            assert!((a - b).abs() <= 1e-15 * a.abs(), "{a} vs {b}");
        }
    }

    #[test]
    fn unused_nodes_are_dropped() {
        let mut g = Graph::new();
        let x = g.q(0);
        let _unused = g.sin(x);
        let y = g.mul(x, x);
        let p = schedule(&g, &[y]);
        assert!(p.stmts.is_empty());
        assert_eq!(p.ops.calls, 0);
        assert_eq!(p.ops.muls, 1);
    }
}
