//! Common-subexpression elimination: the reachable nodes of the graph in
//! order, every node used more than once (or a call, or nested too deep)
//! bound by one `let`, the others inlined into their single use; `sin` and
//! `cos` of one argument computed by one `sin_cos` statement.

use std::collections::{HashMap, HashSet};

use super::code::{Code, Stmt};
use crate::expr::{Func, Graph, Id, Node};

/// Deepest expression emitted inline before it is bound to a variable.
const MAX_INLINE_DEPTH: usize = 6;

/// Statements and output expressions computing `outputs`, and the number of
/// variables they bind.
pub(super) fn eliminate(graph: &Graph, outputs: &[Id]) -> (Vec<Stmt>, Vec<Code>, u32) {
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
    let outputs: Vec<Code> = outputs.iter().map(|&o| s.code(o)).collect();
    (s.stmts, outputs, s.next)
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
