//! Reverse-mode (adjoint) differentiation on the expression graph, and the
//! forward-mode Jacobian-vector product in the form the derivation uses.
//!
//! For `f` and variables `x`, the adjoint of a node `u` is `f_u = df/du`,
//! the sensitivity of `f` to `u` with every other path held. It starts at
//! `f_f = 1` and flows from parents to children in one sweep over the nodes
//! reachable from `f`, in decreasing id (reverse topological) order:
//!
//! * `u = k + sum c_i t_i` adds `c_i f_u` to `f_(t_i)`;
//! * `u = prod b_i^(e_i)` adds `f_u e_i b_i^(e_i - 1) prod_(j != i) b_j^(e_j)`
//!   to `f_(b_i)`;
//! * `u = g(a)` adds `f_u g'(a)` to `f_a` (`g'` away from the switch of
//!   `abs`, `sign` and `step`); `u = atan2(y, x)` adds
//!   `f_u x / r^2` to `f_y` and `-f_u y / r^2` to `f_x` (`r^2 = x^2 + y^2`).
//!
//! The contributions to a node are collected and summed once, when the sweep
//! reaches it; only nodes that depend on a variable of `x` take part. So the
//! whole gradient `df/dx` costs a small multiple of the size of `f`, however
//! many variables there are (forward mode costs that per variable).

use std::collections::{HashMap, HashSet};

use super::{Func, Graph, Id, Node, Symbol};

impl Graph {
    /// Gradient of `e` with respect to `vars` (`df/dx_i` for each `x_i`),
    /// by one reverse sweep.
    pub fn gradient(&mut self, e: Id, vars: &[Symbol]) -> Vec<Id> {
        let one = self.constant(1.0);
        self.vjp(&[e], &[one], vars)
    }

    /// Vector-Jacobian product: `sum_k w_k d(outputs_k)/dx_i` for each
    /// variable `x_i`, by one reverse sweep from the outputs, each seeded
    /// with its weight `w_k`. The weights are nodes held fixed: whatever
    /// they depend on, they are not differentiated.
    pub fn vjp(&mut self, outputs: &[Id], weights: &[Id], vars: &[Symbol]) -> Vec<Id> {
        assert_eq!(outputs.len(), weights.len(), "one weight per output");
        let wanted: HashSet<Symbol> = vars.iter().copied().collect();
        let order = self.reachable(outputs);
        // Nodes that depend on a wanted variable (children precede parents).
        let mut active: HashSet<Id> = HashSet::new();
        for &id in &order {
            let is_active = match self.node(id) {
                Node::Sym(s) => wanted.contains(s),
                _ => self.children(id).iter().any(|c| active.contains(c)),
            };
            if is_active {
                active.insert(id);
            }
        }
        let mut contributions: HashMap<Id, Vec<(Id, f64)>> = HashMap::new();
        let mut of_symbol: HashMap<Symbol, Id> = HashMap::new();
        for (&output, &weight) in outputs.iter().zip(weights) {
            if active.contains(&output) {
                contributions.entry(output).or_default().push((weight, 1.0));
            }
        }
        for &id in order.iter().rev() {
            let Some(terms) = contributions.remove(&id) else {
                continue;
            };
            let adjoint = self.linear(&terms, 0.0);
            if self.is_const(adjoint, 0.0) {
                continue;
            }
            let mut push = |child: Id, value: Id, coefficient: f64| {
                if active.contains(&child) {
                    contributions
                        .entry(child)
                        .or_default()
                        .push((value, coefficient));
                }
            };
            match self.node(id).clone() {
                Node::Const(_) => {}
                Node::Sym(s) => {
                    of_symbol.insert(s, adjoint);
                }
                Node::Sum(ts, _) => {
                    for &(t, c) in ts.iter() {
                        push(t, adjoint, c.get());
                    }
                }
                Node::Prod(fs) => {
                    for (i, &(b, ex)) in fs.iter().enumerate() {
                        if !active.contains(&b) {
                            continue;
                        }
                        let mut factors: Vec<(Id, i32)> = fs.to_vec();
                        factors[i].1 = ex - 1;
                        factors.push((adjoint, 1));
                        let partial = self.product(&factors);
                        push(b, partial, f64::from(ex));
                    }
                }
                Node::Call(f, a) => {
                    let outer = self.call_derivative(f, a, id);
                    let partial = self.mul(adjoint, outer);
                    push(a, partial, 1.0);
                }
                Node::Atan2(y, x) => {
                    let x2 = self.powi(x, 2);
                    let y2 = self.powi(y, 2);
                    let r2 = self.add(x2, y2);
                    let scaled = self.div(adjoint, r2);
                    let dy = self.mul(scaled, x);
                    let dx = self.mul(scaled, y);
                    push(y, dy, 1.0);
                    push(x, dx, -1.0);
                }
            }
        }
        let zero = self.constant(0.0);
        vars.iter()
            .map(|v| of_symbol.get(v).copied().unwrap_or(zero))
            .collect()
    }

    /// `f'(a)` for the node `node = f(a)`.
    pub(super) fn call_derivative(&mut self, f: Func, a: Id, node: Id) -> Id {
        match f {
            Func::Sin => self.cos(a),
            Func::Cos => {
                let s = self.sin(a);
                self.neg(s)
            }
            Func::Tan => {
                let t2 = self.powi(node, 2);
                self.linear(&[(t2, 1.0)], 1.0)
            }
            Func::Exp => node,
            Func::Ln => self.powi(a, -1),
            Func::Sqrt => {
                let inv = self.powi(node, -1);
                self.scale(inv, 0.5)
            }
            // Away from the switch at `a = 0` ([`Func`]).
            Func::Abs => self.call(Func::Sign, a),
            Func::Sign | Func::Step => self.constant(0.0),
        }
    }

    /// Jacobian-vector product: the directional derivatives of `outputs`
    /// along the tangent that gives symbol `s` the derivative `tangent[s]`
    /// (zero for symbols not listed), by one forward sweep shared between
    /// the outputs.
    pub fn jvp(&mut self, outputs: &[Id], tangent: &[(Symbol, Id)]) -> Vec<Id> {
        let map: HashMap<Symbol, Id> = tangent.iter().copied().collect();
        self.directional_many(outputs, &|s| map.get(&s).copied())
    }
}

#[cfg(test)]
mod tests {
    use crate::expr::{Func, Graph, Id, Symbol};

    fn env(p: &[f64; 5]) -> impl Fn(Symbol) -> f64 + '_ {
        |s| match s {
            Symbol::Q(i) => p[i as usize],
            Symbol::Qd(i) => p[2 + i as usize],
            Symbol::Time => p[4],
            _ => 1.3,
        }
    }

    /// A function of q0, q1, qd0, qd1 and t using every node kind, with
    /// shared subexpressions.
    fn sample(g: &mut Graph) -> Id {
        let (x, y, u, v) = (g.q(0), g.q(1), g.qd(0), g.qd(1));
        let t = g.symbol(Symbol::Time);
        let xy = g.mul(x, y);
        let s = g.sin(xy);
        let c = g.cos(x);
        let e = g.call(Func::Exp, c);
        let y2 = g.powi(y, 2);
        let r0 = g.linear(&[(y2, 1.0), (u, 0.2)], 2.0);
        let r = g.sqrt(r0);
        let l = g.call(Func::Ln, r);
        let at = g.atan2(y, x);
        let tn = g.call(Func::Tan, t);
        let uv = g.mul(u, v);
        let su = g.mul(s, uv);
        let sw = crate::expr::diff::tests::switches(g);
        let su_sign = g.call(Func::Sign, u);
        let ua = g.call(Func::Abs, u);
        let uv_abs = g.mul(ua, v);
        let num = g.sum(&[s, e, l, at, tn, su, sw, su_sign, uv_abs]);
        let den = g.linear(&[(xy, 0.3)], 2.0);
        let f = g.div(num, den);
        let x3v = g.product(&[(x, 3), (v, 2), (s, 1)]);
        g.add(f, x3v)
    }

    const VARS: [Symbol; 5] = [
        Symbol::Q(0),
        Symbol::Q(1),
        Symbol::Qd(0),
        Symbol::Qd(1),
        Symbol::Time,
    ];

    #[test]
    fn gradient_matches_central_differences() {
        let mut g = Graph::new();
        let f = sample(&mut g);
        let grad = g.gradient(f, &VARS);
        let p = [0.7, -0.4, 0.3, -1.1, 0.2];
        for (k, &d) in grad.iter().enumerate() {
            let h = 1e-6;
            let (mut a, mut b) = (p, p);
            a[k] += h;
            b[k] -= h;
            let fd = (g.eval(&[f], &env(&a))[0] - g.eval(&[f], &env(&b))[0]) / (2.0 * h);
            let exact = g.eval(&[d], &env(&p))[0];
            assert!(
                (fd - exact).abs() < 1e-7 * (1.0 + exact.abs()),
                "{:?}: {fd} vs {exact}",
                VARS[k]
            );
        }
    }

    #[test]
    fn gradient_agrees_with_forward_partials() {
        let mut g = Graph::new();
        let f = sample(&mut g);
        let grad = g.gradient(f, &VARS);
        let forward: Vec<Id> = VARS.iter().map(|&v| g.diff(f, v)).collect();
        for p in [[0.7, -0.4, 0.3, -1.1, 0.2], [-1.3, 0.8, 2.0, 0.4, 1.1]] {
            let a = g.eval(&grad, &env(&p));
            let b = g.eval(&forward, &env(&p));
            for (x, y) in a.iter().zip(&b) {
                assert!((x - y).abs() <= 1e-13 * (1.0 + y.abs()), "{x} vs {y}");
            }
        }
        // Variables the function does not depend on have a zero gradient.
        let none = g.gradient(f, &[Symbol::Q(7)]);
        assert!(g.is_const(none[0], 0.0));
    }

    /// The gradient of a chain `x_(k+1) = sin(x_k) * x_k` costs a bounded
    /// number of nodes per link, where forward mode per variable would not.
    #[test]
    fn gradient_of_chain_is_linear_in_its_length() {
        let size = |n: usize| {
            let mut g = Graph::new();
            let mut x = g.q(0);
            let mut vars = vec![Symbol::Q(0)];
            for k in 1..n {
                let s = g.sin(x);
                let qk = g.q(k);
                let p = g.mul(s, x);
                x = g.add(p, qk);
                vars.push(Symbol::Q(k as u32));
            }
            let before = g.len();
            g.gradient(x, &vars);
            g.len() - before
        };
        let (small, large) = (size(20), size(40));
        assert!(large <= 2 * small + 8, "{small} then {large}");
    }

    #[test]
    fn jvp_matches_central_differences() {
        let mut g = Graph::new();
        let f = sample(&mut g);
        let one = g.constant(1.0);
        let (u, v) = (g.qd(0), g.qd(1));
        let half = g.constant(0.5);
        let d = g.jvp(
            &[f],
            &[
                (Symbol::Q(0), u),
                (Symbol::Q(1), v),
                (Symbol::Qd(1), half),
                (Symbol::Time, one),
            ],
        )[0];
        let p = [0.3, 0.9, 0.25, -0.5, 0.1];
        let h = 1e-6;
        let shift = |s: f64| {
            [
                p[0] + s * p[2],
                p[1] + s * p[3],
                p[2],
                p[3] + 0.5 * s,
                p[4] + s,
            ]
        };
        let fd = (g.eval(&[f], &env(&shift(h)))[0] - g.eval(&[f], &env(&shift(-h)))[0]) / (2.0 * h);
        let exact = g.eval(&[d], &env(&p))[0];
        assert!(
            (fd - exact).abs() < 1e-7 * (1.0 + exact.abs()),
            "{fd} vs {exact}"
        );
    }
}
