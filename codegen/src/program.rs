//! From expression nodes to a straight-line program: common-subexpression
//! elimination (every node used more than once gets one `let`), sharing of
//! `sin` and `cos` of one argument (one `sin_cos` call), dead-code
//! elimination (only nodes reachable from the outputs are kept) and an
//! operation count of the result.

use std::collections::{HashMap, HashSet};
use std::fmt;
use std::ops::AddAssign;

use crate::expr::{Func, Graph, Id, Node, Symbol};

/// Deepest expression emitted inline before it is bound to a variable.
const MAX_INLINE_DEPTH: usize = 6;

/// Arithmetic operations of a program.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct OpCount {
    /// Additions, subtractions and negations.
    pub adds: usize,
    /// Multiplications.
    pub muls: usize,
    /// Divisions.
    pub divs: usize,
    /// Calls of `sin`, `cos`, `sin_cos`, `tan`, `exp`, `ln`, `sqrt`, `atan2`.
    pub calls: usize,
}

impl OpCount {
    /// All operations.
    pub fn total(&self) -> usize {
        self.adds + self.muls + self.divs + self.calls
    }
}

impl AddAssign for OpCount {
    fn add_assign(&mut self, o: OpCount) {
        self.adds += o.adds;
        self.muls += o.muls;
        self.divs += o.divs;
        self.calls += o.calls;
    }
}

impl fmt::Display for OpCount {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} add, {} mul, {} div, {} call",
            self.adds, self.muls, self.divs, self.calls
        )
    }
}

/// An expression of the emitted program.
#[derive(Debug, Clone, PartialEq)]
pub enum Code {
    /// A local variable.
    Var(u32),
    /// An input.
    Sym(Symbol),
    /// A literal.
    Lit(f64),
    /// `constant + sum(coefficient * term)`.
    Sum {
        /// Constant part.
        constant: f64,
        /// Terms with their coefficients.
        terms: Vec<(f64, Code)>,
    },
    /// `prod(num) / prod(den)`.
    Prod {
        /// Numerator factors.
        num: Vec<Code>,
        /// Denominator factors.
        den: Vec<Code>,
    },
    /// `f(x)`.
    Call(Func, Box<Code>),
    /// `atan2(y, x)`.
    Atan2(Box<Code>, Box<Code>),
}

/// A statement of the emitted program.
#[derive(Debug, Clone, PartialEq)]
pub enum Stmt {
    /// `let var = value;`
    Let {
        /// Variable number.
        var: u32,
        /// Its value.
        value: Code,
    },
    /// `let (sin, cos) = sin_cos(arg);`
    SinCos {
        /// Variable receiving the sine.
        sin: u32,
        /// Variable receiving the cosine.
        cos: u32,
        /// The argument.
        arg: Code,
    },
}

/// A straight-line program computing a list of outputs.
#[derive(Debug, Clone, PartialEq)]
pub struct Program {
    /// Statements in order.
    pub stmts: Vec<Stmt>,
    /// One expression per output.
    pub outputs: Vec<Code>,
    /// Operations the program performs.
    pub ops: OpCount,
}

/// Schedule the computation of `outputs`.
pub fn schedule(graph: &Graph, outputs: &[Id]) -> Program {
    let order = graph.reachable(outputs);
    let mut uses: HashMap<Id, usize> = HashMap::new();
    for &id in &order {
        match graph.node(id) {
            Node::Prod(fs) => {
                for &(b, e) in fs.iter() {
                    // A power is emitted as repeated multiplication: bind its base.
                    *uses.entry(b).or_default() += if e.abs() >= 2 { 2 } else { 1 };
                }
            }
            _ => {
                for c in graph.children(id) {
                    *uses.entry(c).or_default() += 1;
                }
            }
        }
    }
    for &o in outputs {
        *uses.entry(o).or_default() += 1;
    }
    // Arguments whose sine and cosine are both needed.
    let mut sines = HashSet::new();
    let mut cosines = HashSet::new();
    for &id in &order {
        match graph.node(id) {
            Node::Call(Func::Sin, a) => {
                sines.insert(*a);
            }
            Node::Call(Func::Cos, a) => {
                cosines.insert(*a);
            }
            _ => {}
        }
    }
    let paired: HashSet<Id> = sines.intersection(&cosines).copied().collect();

    let mut s = Scheduler {
        graph,
        var: HashMap::new(),
        inline: HashMap::new(),
        depth: HashMap::new(),
        stmts: Vec::new(),
        next: 0,
    };
    for &id in &order {
        match graph.node(id) {
            Node::Const(_) | Node::Sym(_) => continue,
            Node::Call(f @ (Func::Sin | Func::Cos), a) if paired.contains(a) => {
                if s.var.contains_key(&id) {
                    continue;
                }
                let (sin_id, cos_id) = match f {
                    Func::Sin => (id, s.find(Node::Call(Func::Cos, *a))),
                    _ => (s.find(Node::Call(Func::Sin, *a)), id),
                };
                let arg = s.code(*a);
                let (sv, cv) = (s.fresh(), s.fresh());
                s.var.insert(sin_id, sv);
                s.var.insert(cos_id, cv);
                s.stmts.push(Stmt::SinCos {
                    sin: sv,
                    cos: cv,
                    arg,
                });
                continue;
            }
            _ => {}
        }
        let code = s.build(id);
        let depth = s.depth_of(id);
        let bind = uses.get(&id).copied().unwrap_or(0) >= 2
            || matches!(graph.node(id), Node::Call(..) | Node::Atan2(..))
            || depth > MAX_INLINE_DEPTH;
        if bind {
            let v = s.fresh();
            s.var.insert(id, v);
            s.stmts.push(Stmt::Let {
                var: v,
                value: code,
            });
        } else {
            s.inline.insert(id, code);
        }
    }
    let mut outputs: Vec<Code> = outputs.iter().map(|&o| s.code(o)).collect();
    crate::share::share_pairs(&mut s.stmts, &mut outputs, &mut s.next);
    let mut ops = OpCount::default();
    for st in &s.stmts {
        match st {
            Stmt::Let { value, .. } => count(value, &mut ops),
            Stmt::SinCos { arg, .. } => {
                ops.calls += 1;
                count(arg, &mut ops);
            }
        }
    }
    for o in &outputs {
        count(o, &mut ops);
    }
    Program {
        stmts: s.stmts,
        outputs,
        ops,
    }
}

struct Scheduler<'a> {
    graph: &'a Graph,
    var: HashMap<Id, u32>,
    inline: HashMap<Id, Code>,
    depth: HashMap<Id, usize>,
    stmts: Vec<Stmt>,
    next: u32,
}

impl Scheduler<'_> {
    fn fresh(&mut self) -> u32 {
        self.next += 1;
        self.next - 1
    }

    /// The id of a node known to exist.
    fn find(&self, node: Node) -> Id {
        self.graph
            .lookup(&node)
            .expect("paired sin/cos node exists")
    }

    fn depth_of(&self, id: Id) -> usize {
        self.depth.get(&id).copied().unwrap_or(0)
    }

    /// Code referring to an already scheduled node.
    fn code(&mut self, id: Id) -> Code {
        if let Some(&v) = self.var.get(&id) {
            return Code::Var(v);
        }
        match self.graph.node(id) {
            Node::Const(c) => Code::Lit(c.get()),
            Node::Sym(s) => Code::Sym(*s),
            _ => self
                .inline
                .remove(&id)
                .expect("node scheduled before its single use"),
        }
    }

    fn child_depth(&self, id: Id) -> usize {
        if self.var.contains_key(&id) {
            0
        } else {
            self.depth_of(id)
        }
    }

    /// Code for a node from its children, recording its inline depth.
    fn build(&mut self, id: Id) -> Code {
        let children = self.graph.children(id);
        let depth = 1 + children
            .iter()
            .map(|&c| self.child_depth(c))
            .max()
            .unwrap_or(0);
        self.depth.insert(id, depth);
        match self.graph.node(id).clone() {
            Node::Sum(ts, k) => Code::Sum {
                constant: k.get(),
                terms: ts.iter().map(|&(t, c)| (c.get(), self.code(t))).collect(),
            },
            Node::Prod(fs) => {
                let mut num = Vec::new();
                let mut den = Vec::new();
                for &(b, e) in fs.iter() {
                    let c = self.code(b);
                    let target = if e > 0 { &mut num } else { &mut den };
                    for _ in 0..e.unsigned_abs() {
                        target.push(c.clone());
                    }
                }
                Code::Prod { num, den }
            }
            Node::Call(f, a) => Code::Call(f, Box::new(self.code(a))),
            Node::Atan2(y, x) => {
                let yc = self.code(y);
                let xc = self.code(x);
                Code::Atan2(Box::new(yc), Box::new(xc))
            }
            Node::Const(_) | Node::Sym(_) => unreachable!("leaves are not scheduled"),
        }
    }
}

/// Count the operations of an expression as it is emitted.
fn count(c: &Code, ops: &mut OpCount) {
    match c {
        Code::Var(_) | Code::Sym(_) | Code::Lit(_) => {}
        Code::Sum { constant, terms } => {
            ops.adds += terms.len() - 1 + usize::from(*constant != 0.0);
            if terms.iter().all(|(c, _)| *c < 0.0) && *constant == 0.0 {
                ops.adds += 1; // leading negation
            }
            for (coef, t) in terms {
                if coef.abs() != 1.0 {
                    ops.muls += 1;
                }
                count(t, ops);
            }
        }
        Code::Prod { num, den } => {
            ops.muls += num.len().saturating_sub(1) + den.len().saturating_sub(1);
            if !den.is_empty() {
                ops.divs += 1;
            }
            for f in num.iter().chain(den) {
                count(f, ops);
            }
        }
        Code::Call(_, a) => {
            ops.calls += 1;
            count(a, ops);
        }
        Code::Atan2(y, x) => {
            ops.calls += 1;
            count(y, ops);
            count(x, ops);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
