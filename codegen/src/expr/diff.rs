//! Exact symbolic differentiation on the expression graph, forward mode:
//! partial and directional derivatives, Jacobians and Hessians (gradients by
//! reverse mode are in `reverse`).

use std::collections::HashMap;

use super::{Graph, Id, Node, Symbol};

impl Graph {
    /// Directional derivative of `e`: the derivative of every symbol `s` is
    /// `seed(s)` (`None` meaning zero). Shared subexpressions are
    /// differentiated once.
    pub fn directional(&mut self, e: Id, seed: &dyn Fn(Symbol) -> Option<Id>) -> Id {
        self.directional_many(&[e], seed)[0]
    }

    /// Directional derivatives of several expressions along one direction,
    /// sharing the work between them.
    pub fn directional_many(&mut self, es: &[Id], seed: &dyn Fn(Symbol) -> Option<Id>) -> Vec<Id> {
        // Children have smaller ids than parents: differentiate every
        // reachable node in increasing id order, no recursion needed.
        let mut memo: HashMap<Id, Id> = HashMap::new();
        for id in self.reachable(es) {
            let d = self.derivative_of_node(id, seed, &memo);
            memo.insert(id, d);
        }
        es.iter().map(|e| memo[e]).collect()
    }

    fn derivative_of_node(
        &mut self,
        id: Id,
        seed: &dyn Fn(Symbol) -> Option<Id>,
        memo: &HashMap<Id, Id>,
    ) -> Id {
        let zero = self.constant(0.0);
        match self.node(id).clone() {
            Node::Const(_) => zero,
            Node::Sym(s) => seed(s).unwrap_or(zero),
            Node::Sum(ts, _) => {
                let terms: Vec<(Id, f64)> = ts.iter().map(|&(t, c)| (memo[&t], c.get())).collect();
                self.linear(&terms, 0.0)
            }
            Node::Prod(fs) => {
                let mut terms = Vec::new();
                for (i, &(b, e)) in fs.iter().enumerate() {
                    let db = memo[&b];
                    if self.is_const(db, 0.0) {
                        continue;
                    }
                    let mut factors: Vec<(Id, i32)> = fs.to_vec();
                    factors[i].1 = e - 1;
                    factors.push((db, 1));
                    let t = self.product(&factors);
                    terms.push((t, e as f64));
                }
                self.linear(&terms, 0.0)
            }
            Node::Call(f, a) => {
                let da = memo[&a];
                if self.is_const(da, 0.0) {
                    return zero;
                }
                let outer = self.call_derivative(f, a, id);
                self.mul(outer, da)
            }
            Node::Atan2(y, x) => {
                let (dy, dx) = (memo[&y], memo[&x]);
                // d atan2(y, x) = (x dy - y dx) / (x^2 + y^2)
                let xdy = self.mul(x, dy);
                let ydx = self.mul(y, dx);
                let num = self.sub(xdy, ydx);
                let x2 = self.powi(x, 2);
                let y2 = self.powi(y, 2);
                let den = self.add(x2, y2);
                self.div(num, den)
            }
        }
    }

    /// Partial derivative `de/ds`.
    pub fn diff(&mut self, e: Id, s: Symbol) -> Id {
        let one = self.constant(1.0);
        self.directional(e, &|x| (x == s).then_some(one))
    }

    /// Partial derivatives of several expressions with respect to one symbol.
    pub fn diff_many(&mut self, es: &[Id], s: Symbol) -> Vec<Id> {
        let one = self.constant(1.0);
        self.directional_many(es, &|x| (x == s).then_some(one))
    }

    /// Jacobian `J[i][j] = d es[i] / d vars[j]`.
    pub fn jacobian(&mut self, es: &[Id], vars: &[Symbol]) -> Vec<Vec<Id>> {
        let columns: Vec<Vec<Id>> = vars.iter().map(|&v| self.diff_many(es, v)).collect();
        (0..es.len())
            .map(|i| columns.iter().map(|col| col[i]).collect())
            .collect()
    }

    /// Hessian `H[i][j] = d^2 e / d vars[i] d vars[j]` (symmetric).
    pub fn hessian(&mut self, e: Id, vars: &[Symbol]) -> Vec<Vec<Id>> {
        let grad = self.gradient(e, vars);
        let n = vars.len();
        let mut h = vec![vec![self.constant(0.0); n]; n];
        for i in 0..n {
            for j in i..n {
                let d = self.diff(grad[i], vars[j]);
                h[i][j] = d;
                h[j][i] = d;
            }
        }
        h
    }

    /// Total time derivative of `e` along `q' = qd`, `t' = 1`, holding `qd`
    /// fixed (the accelerations are not part of the result).
    pub fn time_derivative_at_zero_acceleration(&mut self, es: &[Id]) -> Vec<Id> {
        let one = self.constant(1.0);
        let mut velocity = HashMap::new();
        for s in self.symbols(es) {
            if let Symbol::Q(i) = s {
                velocity.insert(s, self.qd(i as usize));
            }
        }
        self.directional_many(es, &|s| match s {
            Symbol::Time => Some(one),
            Symbol::Q(_) => velocity.get(&s).copied(),
            _ => None,
        })
    }
}

#[cfg(test)]
pub(super) mod tests {
    use crate::expr::{Graph, Id, Symbol};

    fn eval(g: &Graph, e: Id, q: &[f64]) -> f64 {
        g.eval(&[e], &|s| match s {
            Symbol::Q(i) => q[i as usize],
            Symbol::Qd(i) => q[2 + i as usize],
            Symbol::Time => q[4],
            Symbol::Param(_) | Symbol::Qdd(_) => 1.3,
        })[0]
    }

    /// Build a test function using every node kind.
    fn sample(g: &mut Graph) -> Id {
        let (x, y) = (g.q(0), g.q(1));
        let t = g.symbol(Symbol::Time);
        let xy = g.mul(x, y);
        let s = g.sin(xy);
        let c = g.cos(x);
        let e = g.call(crate::expr::Func::Exp, c);
        let y2 = g.powi(y, 2);
        let r0 = g.linear(&[(y2, 1.0)], 2.0);
        let r = g.sqrt(r0);
        let l = g.call(crate::expr::Func::Ln, r);
        let at = g.atan2(y, x);
        let tn = g.call(crate::expr::Func::Tan, t);
        let sw = switches(g);
        let num = g.sum(&[s, e, l, at, tn, sw]);
        let den = g.linear(&[(xy, 0.3)], 2.0);
        let f = g.div(num, den);
        let x3 = g.powi(x, 3);
        g.add(f, x3)
    }

    /// `abs(x - y) + sign(y) x^2 + step(x + y) y + min(x, y^2) + max(t, x)`,
    /// whose switches are away from the states the tests sample.
    pub(crate) fn switches(g: &mut Graph) -> Id {
        use crate::expr::Func;
        let (x, y) = (g.q(0), g.q(1));
        let t = g.symbol(Symbol::Time);
        let x_minus_y = g.sub(x, y);
        let a = g.call(Func::Abs, x_minus_y);
        let sy = g.call(Func::Sign, y);
        let x2 = g.powi(x, 2);
        let b = g.mul(sy, x2);
        let x_plus_y = g.add(x, y);
        let st = g.call(Func::Step, x_plus_y);
        let c = g.mul(st, y);
        let y2 = g.powi(y, 2);
        let d = g.min(x, y2);
        let e = g.max(t, x);
        g.sum(&[a, b, c, d, e])
    }

    #[test]
    fn partials_match_central_differences() {
        let mut g = Graph::new();
        let f = sample(&mut g);
        let p = [0.7, -0.4, 0.0, 0.0, 0.2];
        for (k, s) in [(0usize, Symbol::Q(0)), (1, Symbol::Q(1)), (4, Symbol::Time)] {
            let d = g.diff(f, s);
            let h = 1e-6;
            let mut a = p;
            a[k] += h;
            let mut b = p;
            b[k] -= h;
            let fd = (eval(&g, f, &a) - eval(&g, f, &b)) / (2.0 * h);
            let exact = eval(&g, d, &p);
            assert!(
                (fd - exact).abs() < 1e-7 * (1.0 + exact.abs()),
                "{s:?}: {fd} vs {exact}"
            );
        }
    }

    #[test]
    fn hessian_is_symmetric_and_matches_differences() {
        let mut g = Graph::new();
        let f = sample(&mut g);
        let vars = [Symbol::Q(0), Symbol::Q(1)];
        let h = g.hessian(f, &vars);
        let grad = g.gradient(f, &vars);
        let p = [0.3, 0.9, 0.0, 0.0, 0.1];
        for i in 0..2 {
            for j in 0..2 {
                let step = 1e-6;
                let mut a = p;
                a[j] += step;
                let mut b = p;
                b[j] -= step;
                let fd = (eval(&g, grad[i], &a) - eval(&g, grad[i], &b)) / (2.0 * step);
                let exact = eval(&g, h[i][j], &p);
                assert!((fd - exact).abs() < 1e-6 * (1.0 + exact.abs()));
            }
        }
    }

    #[test]
    fn time_derivative_follows_chain_rule() {
        let mut g = Graph::new();
        let f = sample(&mut g);
        let df = g.time_derivative_at_zero_acceleration(&[f])[0];
        let p = [0.3, 0.9, 0.25, -0.5, 0.1];
        let h = 1e-6;
        let shift = |s: f64| [p[0] + s * p[2], p[1] + s * p[3], p[2], p[3], p[4] + s];
        let fd = (eval(&g, f, &shift(h)) - eval(&g, f, &shift(-h))) / (2.0 * h);
        let exact = eval(&g, df, &p);
        assert!((fd - exact).abs() < 1e-7 * (1.0 + exact.abs()));
    }

    #[test]
    fn derivative_of_polynomial_is_exact() {
        let mut g = Graph::new();
        let x = g.q(0);
        let x3 = g.powi(x, 3);
        let f = g.scale(x3, 2.0);
        let d = g.diff(f, Symbol::Q(0));
        let x2 = g.powi(x, 2);
        assert_eq!(d, g.scale(x2, 6.0));
    }
}
