//! Hash-consed expression graph over `f64`.
//!
//! Every expression is a node in one [`Graph`]; structurally equal expressions
//! are the same node ([`Id`]). Nodes are kept in a canonical form while they
//! are built:
//!
//! * sums are lists of `coefficient * term` plus a constant, sorted by
//!   term, with like terms collected and zero terms dropped; a short sum
//!   added to another is merged into it, a long one (more than
//!   `FLATTEN_MAX_TERMS`, 8, terms) stays one term, a shared partial sum,
//!   and so does a sum of more than `SCALED_MAX_TERMS`, 2, added with a
//!   coefficient other than `+-1`, unless it has a term in common with the
//!   rest (then it is opened, so that `a + b - a` is still `b`) or is the
//!   only term, unscaled;
//! * products are flat lists of `base ^ integer exponent`, sorted by base,
//!   with equal bases merged; numeric factors move to the enclosing sum;
//! * operations on constants are folded.
//!
//! Children always have smaller ids than their parents, so increasing id order
//! is a topological order of the graph.

mod diff;
pub mod exact;
mod reverse;

use std::collections::{HashMap, HashSet};
use std::fmt;

/// Sums of at most this many terms are merged into a sum they are added to
/// (with a coefficient of `+-1`; see [`SCALED_MAX_TERMS`] for others);
/// longer ones stay one term of it (a partial sum), unless they share a
/// term with it or are its only term. A chain of partial
/// sums (the angular velocity of link `k` of a planar chain,
/// `qd_0 + ... + qd_k`, built from that of link `k - 1`) then takes a
/// bounded number of terms per link instead of growing by one each time,
/// and so do its derivatives. (Measured: with 6 the rigid parallel
/// robot's `dynamics_terms` took 804 operations instead of 705, with 12
/// the planar chain's bias forces grew as `n^1.21`; 8 keeps the small
/// scenes' counts and the chain linear.)
const FLATTEN_MAX_TERMS: usize = 8;

/// A sum added with a coefficient other than `+-1` is merged only when it
/// has at most this many terms (or shares a term with the rest, to cancel):
/// opening `c (a + b + d)` costs a multiplication per term where keeping it
/// costs one, and where several such sums share their terms (the
/// components of a twist or a force carried from link to link, of a
/// vector turned by a tilt) opening them all spreads each term into every
/// user. Measured against opening every short sum (and a scaled sum of any
/// length on its own): TALOS's inverse dynamics 4,627 to 4,213 operations,
/// `M + h` 6,953 to 6,700, the UR5's 547 and 732 to 532 and 717, the Panda's
/// inverse-dynamics derivatives 7,732 to 7,562; the Solo12's 2 % more; the
/// small scenes' counts unchanged. With 1 instead of 2 the double
/// pendulum's inverse dynamics takes 72 operations instead of 42.
const SCALED_MAX_TERMS: usize = 2;

/// Adds `c` times the sum `k + sum(ts)` to a sum being built: its terms to
/// `terms`, its constant to `constant` and that constant's magnitude to
/// `magnitude` (for [`exact::cancel`]).
fn open_sum(
    ts: &[(Id, Real)],
    k: Real,
    c: f64,
    constant: &mut f64,
    magnitude: &mut f64,
    terms: &mut Vec<(Id, f64)>,
) {
    *constant += c * k.get();
    *magnitude += (c * k.get()).abs();
    terms.extend(ts.iter().map(|&(t, ct)| (t, c * ct.get())));
}

/// Index of a node in a [`Graph`].
#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Debug)]
pub struct Id(u32);

impl Id {
    /// Position of the node in the graph's node list.
    pub fn index(self) -> usize {
        self.0 as usize
    }
}

/// A leaf variable of an expression.
#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Debug)]
pub enum Symbol {
    /// Generalized coordinate `q[i]`.
    Q(u32),
    /// Generalized velocity `qd[i]`.
    Qd(u32),
    /// Generalized acceleration `qdd[i]` (only in the inverse dynamics).
    Qdd(u32),
    /// Time `t`.
    Time,
    /// Parameter left as a runtime input (index into the scene's runtime parameters).
    Param(u32),
}

/// Elementary functions of one argument.
///
/// `Abs`, `Sign` and `Step` are the switches: `sign` is `1`, `-1` or `0`
/// (at `+-0`), `step` is Heaviside's `(1 + sign x) / 2`, so `1/2` at `0`
/// and `step(x) + step(-x) = 1` everywhere; both propagate NaN
/// ([`flexdyn_runtime::math::sign`], which every back end computes).
/// Their derivatives are those away from the switch: `abs' = sign`,
/// `sign' = step' = 0`; the impulse at the switch is not represented.
#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Debug)]
pub enum Func {
    Sin,
    Cos,
    Tan,
    Exp,
    Ln,
    Sqrt,
    Abs,
    Sign,
    Step,
}

impl Func {
    /// Every function, in the order of the enum.
    pub const ALL: [Func; 9] = [
        Func::Sin,
        Func::Cos,
        Func::Tan,
        Func::Exp,
        Func::Ln,
        Func::Sqrt,
        Func::Abs,
        Func::Sign,
        Func::Step,
    ];

    /// The function called `name` in scene files ([`Func::name`]).
    pub fn from_name(name: &str) -> Option<Func> {
        Func::ALL.into_iter().find(|f| f.name() == name)
    }

    /// Evaluate the function at a constant being folded: sines, cosines and
    /// tangents of multiples of `pi/12` exactly ([`exact`]).
    pub fn fold(self, x: f64) -> f64 {
        match self {
            Func::Sin => exact::sin_cos(x).0,
            Func::Cos => exact::sin_cos(x).1,
            Func::Tan => {
                let (s, c) = exact::sin_cos(x);
                s / c
            }
            _ => self.apply(x),
        }
    }

    /// Evaluate the function.
    pub fn apply(self, x: f64) -> f64 {
        match self {
            Func::Sin => x.sin(),
            Func::Cos => x.cos(),
            Func::Tan => x.tan(),
            Func::Exp => x.exp(),
            Func::Ln => x.ln(),
            Func::Sqrt => x.sqrt(),
            Func::Abs => x.abs(),
            Func::Sign => flexdyn_runtime::math::sign(x),
            Func::Step => flexdyn_runtime::math::step(x),
        }
    }

    /// The name used in scene files and in generated code.
    pub fn name(self) -> &'static str {
        match self {
            Func::Sin => "sin",
            Func::Cos => "cos",
            Func::Tan => "tan",
            Func::Exp => "exp",
            Func::Ln => "ln",
            Func::Sqrt => "sqrt",
            Func::Abs => "abs",
            Func::Sign => "sign",
            Func::Step => "step",
        }
    }
}

/// A finite `f64` stored by its bits so that nodes can be hashed (`-0.0` is
/// normalised to `0.0`).
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub struct Real(u64);

impl Real {
    fn new(x: f64) -> Real {
        debug_assert!(x.is_finite());
        Real(if x == 0.0 { 0 } else { x.to_bits() })
    }

    /// The value.
    pub fn get(self) -> f64 {
        f64::from_bits(self.0)
    }
}

/// One node of the graph.
#[derive(Clone, PartialEq, Eq, Hash, Debug)]
pub enum Node {
    /// A finite constant.
    Const(Real),
    /// A variable.
    Sym(Symbol),
    /// `constant + sum(coefficient * term)`: at least one term; terms sorted,
    /// distinct, not constants; a term that is a sum (a partial sum) has
    /// more than 8 terms, none of them a term of the enclosing sum;
    /// coefficients nonzero. A single term has a coefficient other than one
    /// or a nonzero constant.
    Sum(Box<[(Id, Real)]>, Real),
    /// `prod(base ^ exponent)`: bases sorted, distinct, neither constants,
    /// products nor single-term sums without constant; exponents nonzero; not
    /// a single base with exponent one.
    Prod(Box<[(Id, i32)]>),
    /// `f(argument)` with a non-constant argument.
    Call(Func, Id),
    /// `atan2(y, x)`.
    Atan2(Id, Id),
}

/// The expression graph.
#[derive(Default, Clone)]
pub struct Graph {
    nodes: Vec<Node>,
    index: HashMap<Node, Id>,
    overflow: bool,
}

impl fmt::Debug for Graph {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Graph({} nodes)", self.nodes.len())
    }
}

impl Graph {
    /// An empty graph.
    pub fn new() -> Graph {
        Graph::default()
    }

    /// Number of nodes.
    pub fn len(&self) -> usize {
        self.nodes.len()
    }

    /// Whether the graph has no nodes.
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    /// The node behind an id.
    pub fn node(&self, id: Id) -> &Node {
        &self.nodes[id.index()]
    }

    fn intern(&mut self, node: Node) -> Id {
        if let Some(&id) = self.index.get(&node) {
            return id;
        }
        let id = Id(u32::try_from(self.nodes.len()).expect("expression graph exceeds 2^32 nodes"));
        self.nodes.push(node.clone());
        self.index.insert(node, id);
        id
    }

    /// The id of an existing node, if the graph has it.
    pub fn lookup(&self, node: &Node) -> Option<Id> {
        self.index.get(node).copied()
    }

    /// The node of a constant, if the graph has it.
    pub fn find_constant(&self, value: f64) -> Option<Id> {
        value
            .is_finite()
            .then(|| self.lookup(&Node::Const(Real::new(value))))
            .flatten()
    }

    /// Whether a constant overflowed (a non-finite value, folded or given
    /// to [`Graph::constant`], was saturated) since the last call; resets
    /// the flag.
    pub fn take_overflow(&mut self) -> bool {
        std::mem::take(&mut self.overflow)
    }

    /// The value of a constant node.
    pub fn as_const(&self, id: Id) -> Option<f64> {
        match self.node(id) {
            Node::Const(c) => Some(c.get()),
            _ => None,
        }
    }

    /// Whether `id` is the constant `value`.
    pub fn is_const(&self, id: Id, value: f64) -> bool {
        self.as_const(id) == Some(value)
    }

    /// A constant. Non-finite values are not representable: one is
    /// saturated like an overflowing fold (NaN to 0) and recorded in the
    /// overflow flag, which the stages check after each component,
    /// constraint and derivation ([`Graph::take_overflow`]); callers that
    /// report the value itself use [`Graph::try_constant`].
    pub fn constant(&mut self, value: f64) -> Id {
        if !value.is_finite() {
            self.overflow = true;
        }
        self.intern(Node::Const(Real::new(clamp_finite(value))))
    }

    /// A constant, or `None` when `value` is not finite.
    pub fn try_constant(&mut self, value: f64) -> Option<Id> {
        value
            .is_finite()
            .then(|| self.intern(Node::Const(Real::new(value))))
    }

    /// A variable.
    pub fn symbol(&mut self, s: Symbol) -> Id {
        self.intern(Node::Sym(s))
    }

    /// `q[i]`.
    pub fn q(&mut self, i: usize) -> Id {
        self.symbol(Symbol::Q(i as u32))
    }

    /// `qd[i]`.
    pub fn qd(&mut self, i: usize) -> Id {
        self.symbol(Symbol::Qd(i as u32))
    }

    /// Linear combination `constant + sum(c * term)` in canonical form.
    pub fn linear(&mut self, terms: &[(Id, f64)], constant: f64) -> Id {
        // Constants added up, with the sum of their magnitudes for the
        // cancellation rule ([`exact::cancel`]).
        let mut constant = constant;
        let mut magnitude = constant.abs();
        let mut flat: Vec<(Id, f64)> = Vec::with_capacity(terms.len());
        // A sum that is the only term is opened when its coefficient is +-1.
        let single = terms
            .iter()
            .filter(|&&(id, c)| c != 0.0 && !matches!(self.node(id), Node::Const(_)))
            .count()
            == 1;
        for &(id, c) in terms {
            if c == 0.0 {
                continue;
            }
            match self.node(id) {
                Node::Const(k) => {
                    constant += c * k.get();
                    magnitude += (c * k.get()).abs();
                }
                Node::Sum(ts, k)
                    if (c.abs() == 1.0 && (single || ts.len() <= FLATTEN_MAX_TERMS))
                        || ts.len() <= SCALED_MAX_TERMS =>
                {
                    open_sum(ts, *k, c, &mut constant, &mut magnitude, &mut flat);
                }
                _ => flat.push((id, c)),
            }
        }
        // Partial sums that share a term with the rest are opened, so that
        // like terms collect and cancel as in a flat sum.
        while let Some(open) = self.overlapping_partial_sums(&flat) {
            let mut kept = Vec::with_capacity(flat.len());
            for (id, c) in flat {
                match self.node(id) {
                    Node::Sum(ts, k) if open.contains(&id) => {
                        open_sum(ts, *k, c, &mut constant, &mut magnitude, &mut kept);
                    }
                    _ => kept.push((id, c)),
                }
            }
            flat = kept;
        }
        constant = exact::cancel(constant, magnitude);
        flat.sort_by_key(|&(id, _)| id);
        let mut merged: Vec<(Id, f64, f64)> = Vec::with_capacity(flat.len());
        for (id, c) in flat {
            match merged.last_mut() {
                Some((last, lc, lm)) if *last == id => {
                    *lc += c;
                    *lm += c.abs();
                }
                _ => merged.push((id, c, c.abs())),
            }
        }
        let mut merged: Vec<(Id, f64)> = merged
            .into_iter()
            .map(|(id, c, m)| (id, exact::cancel(c, m)))
            .filter(|&(_, c)| c != 0.0)
            .collect();
        self.pythagorean(&mut merged, &mut constant);
        if !constant.is_finite() || merged.iter().any(|(_, c)| !c.is_finite()) {
            // Overflow while folding: keep the operation unfolded is not
            // possible in canonical form, so saturate to the largest finite
            // value and record it: the stages refuse the scene, naming the
            // component, constraint or derivation ([`Graph::take_overflow`]).
            self.overflow = true;
            constant = clamp_finite(constant);
            for (_, c) in merged.iter_mut() {
                *c = clamp_finite(*c);
            }
        }
        match merged.as_slice() {
            [] => self.constant(constant),
            [(id, c)] if *c == 1.0 && constant == 0.0 => *id,
            _ => {
                let terms = merged
                    .into_iter()
                    .map(|(id, c)| (id, Real::new(c)))
                    .collect();
                self.intern(Node::Sum(terms, Real::new(constant)))
            }
        }
    }

    /// The partial sums among `terms` (sums kept as one term) that share a
    /// term with another of `terms`, or `None` if there are none.
    fn overlapping_partial_sums(&self, terms: &[(Id, f64)]) -> Option<HashSet<Id>> {
        let is_partial = |id: Id| matches!(self.node(id), Node::Sum(..));
        if !terms.iter().any(|&(id, _)| is_partial(id)) {
            return None;
        }
        let mut items: Vec<Id> = terms.iter().map(|&(id, _)| id).collect();
        items.sort_unstable();
        items.dedup();
        // How many of the items have each id as themselves or as a term.
        let mut count: HashMap<Id, u32> = HashMap::new();
        for &id in &items {
            *count.entry(id).or_default() += 1;
            if let Node::Sum(ts, _) = self.node(id) {
                for &(t, _) in ts.iter() {
                    *count.entry(t).or_default() += 1;
                }
            }
        }
        let open: HashSet<Id> = items
            .into_iter()
            .filter(|&id| match self.node(id) {
                Node::Sum(ts, _) => ts.iter().any(|(t, _)| count[t] > 1),
                _ => false,
            })
            .collect();
        (!open.is_empty()).then_some(open)
    }

    /// `c * sin(u)^2 * F + c * cos(u)^2 * F = c * F`, applied to the terms of
    /// one sum (both squares must carry the same rest `F` and coefficient).
    fn pythagorean(&mut self, terms: &mut Vec<(Id, f64)>, constant: &mut f64) {
        if terms.len() < 2 {
            return;
        }
        let mut i = 0;
        while i < terms.len() {
            let (id, c) = terms[i];
            let Some((rest, arg)) = self.split_square(id, Func::Sin) else {
                i += 1;
                continue;
            };
            let cos = self.call(Func::Cos, arg);
            let cos2 = self.intern_prod_raw(vec![(cos, 2)]);
            let partner = self.mul(rest, cos2);
            if let Some(j) = terms.iter().position(|&(t, ct)| t == partner && ct == c) {
                // Remove both, add c * rest.
                let (hi, lo) = if i > j { (i, j) } else { (j, i) };
                terms.remove(hi);
                terms.remove(lo);
                match self.node(rest).clone() {
                    Node::Const(k) => *constant += c * k.get(),
                    _ => {
                        if let Some(pos) = terms.iter().position(|&(t, _)| t == rest) {
                            terms[pos].1 += c;
                            if terms[pos].1 == 0.0 {
                                terms.remove(pos);
                            }
                        } else {
                            let pos = terms.partition_point(|&(t, _)| t < rest);
                            terms.insert(pos, (rest, c));
                        }
                    }
                }
                i = 0;
            } else {
                i += 1;
            }
        }
    }

    /// If `id` is `F * f(u)^k` with `k >= 2`, return `(F * f(u)^(k-2), u)`.
    fn split_square(&mut self, id: Id, func: Func) -> Option<(Id, Id)> {
        let factors: Vec<(Id, i32)> = match self.node(id) {
            Node::Prod(fs) => fs.to_vec(),
            _ => return None,
        };
        let pos = factors
            .iter()
            .position(|&(b, e)| e >= 2 && matches!(self.node(b), Node::Call(f, _) if *f == func))?;
        let Node::Call(_, arg) = *self.node(factors[pos].0) else {
            return None;
        };
        let mut rest = factors;
        rest[pos].1 -= 2;
        let rest = self.product(&rest);
        Some((rest, arg))
    }

    /// `a + b`.
    pub fn add(&mut self, a: Id, b: Id) -> Id {
        self.linear(&[(a, 1.0), (b, 1.0)], 0.0)
    }

    /// `a - b`.
    pub fn sub(&mut self, a: Id, b: Id) -> Id {
        self.linear(&[(a, 1.0), (b, -1.0)], 0.0)
    }

    /// `-a`.
    pub fn neg(&mut self, a: Id) -> Id {
        self.linear(&[(a, -1.0)], 0.0)
    }

    /// `c * a`.
    pub fn scale(&mut self, a: Id, c: f64) -> Id {
        self.linear(&[(a, c)], 0.0)
    }

    /// Sum of many expressions.
    pub fn sum(&mut self, items: &[Id]) -> Id {
        let terms: Vec<(Id, f64)> = items.iter().map(|&id| (id, 1.0)).collect();
        self.linear(&terms, 0.0)
    }

    /// `a * b`.
    pub fn mul(&mut self, a: Id, b: Id) -> Id {
        self.product(&[(a, 1), (b, 1)])
    }

    /// `a / b`.
    pub fn div(&mut self, a: Id, b: Id) -> Id {
        self.product(&[(a, 1), (b, -1)])
    }

    /// `a ^ n` for an integer `n`.
    pub fn powi(&mut self, a: Id, n: i32) -> Id {
        self.product(&[(a, n)])
    }

    /// Product `prod(base ^ exponent)` in canonical form.
    pub fn product(&mut self, factors: &[(Id, i32)]) -> Id {
        let mut coeff = 1.0f64;
        let mut flat: Vec<(Id, i64)> = Vec::with_capacity(factors.len());
        let mut stack: Vec<(Id, i64)> = factors.iter().map(|&(b, e)| (b, e as i64)).collect();
        while let Some((id, e)) = stack.pop() {
            if e == 0 {
                continue;
            }
            match self.node(id) {
                Node::Const(k) => coeff *= powi_f64(k.get(), e),
                Node::Prod(fs) => stack.extend(fs.iter().map(|&(b, be)| (b, be as i64 * e))),
                Node::Sum(ts, k) if ts.len() == 1 && k.get() == 0.0 => {
                    let (t, c) = ts[0];
                    coeff *= powi_f64(c.get(), e);
                    stack.push((t, e));
                }
                _ => flat.push((id, e)),
            }
        }
        if coeff == 0.0 {
            return self.constant(0.0);
        }
        if !coeff.is_finite() {
            self.overflow = true;
        }
        flat.sort_by_key(|&(id, _)| id);
        let mut merged: Vec<(Id, i64)> = Vec::with_capacity(flat.len());
        for (id, e) in flat {
            match merged.last_mut() {
                Some((last, le)) if *last == id => *le += e,
                _ => merged.push((id, e)),
            }
        }
        // sqrt(u)^(2k) = u^k.
        let mut rewritten = false;
        for (b, e) in merged.iter_mut() {
            if let Node::Call(Func::Sqrt, u) = *self.node(*b) {
                if *e % 2 == 0 {
                    *b = u;
                    *e /= 2;
                    rewritten = true;
                }
            }
        }
        if rewritten {
            let again: Vec<(Id, i32)> = merged.iter().map(|&(b, e)| (b, clamp_exp(e))).collect();
            let p = self.product(&again);
            return self.scale(p, clamp_finite(coeff));
        }
        merged.retain(|&(_, e)| e != 0);
        let merged: Vec<(Id, i32)> = merged.into_iter().map(|(b, e)| (b, clamp_exp(e))).collect();
        let base = match merged.as_slice() {
            [] => return self.constant(clamp_finite(coeff)),
            [(b, 1)] => *b,
            _ => self.intern_prod_raw(merged),
        };
        self.scale(base, clamp_finite(coeff))
    }

    fn intern_prod_raw(&mut self, factors: Vec<(Id, i32)>) -> Id {
        if let [(b, 1)] = factors.as_slice() {
            return *b;
        }
        self.intern(Node::Prod(factors.into_boxed_slice()))
    }

    /// `f(a)`, folded when `a` is a constant and the result finite.
    pub fn call(&mut self, f: Func, a: Id) -> Id {
        if let Some(x) = self.as_const(a) {
            let y = f.fold(x);
            if y.is_finite() {
                return self.constant(y);
            }
        }
        if f == Func::Ln {
            if let Node::Call(Func::Exp, u) = *self.node(a) {
                return u;
            }
        }
        self.intern(Node::Call(f, a))
    }

    /// `sin(a)`.
    pub fn sin(&mut self, a: Id) -> Id {
        self.call(Func::Sin, a)
    }

    /// `cos(a)`.
    pub fn cos(&mut self, a: Id) -> Id {
        self.call(Func::Cos, a)
    }

    /// `sqrt(a)`.
    pub fn sqrt(&mut self, a: Id) -> Id {
        self.call(Func::Sqrt, a)
    }

    /// `min(a, b)`, built from steps as `a step(b - a) + b step(a - b)`:
    /// exactly `a` where `a < b`, `b` where `b < a` (a product by `1` plus
    /// a product by `0`: no rounding, however different their sizes, where
    /// `(a + b - |a - b|) / 2` would lose the smaller one) and their mean
    /// where they are equal; NaN when either is NaN or infinite. Its
    /// derivative is `da step(b - a) + db step(a - b)`, at the switch the
    /// mean of the two sides'. Constants fold to the exact minimum.
    pub fn min(&mut self, a: Id, b: Id) -> Id {
        match (self.as_const(a), self.as_const(b)) {
            (Some(x), Some(y)) => self.constant(x.min(y)),
            _ => self.weighted_by_steps(a, b, false),
        }
    }

    /// `max(a, b) = a step(a - b) + b step(b - a)`, as [`Graph::min`].
    pub fn max(&mut self, a: Id, b: Id) -> Id {
        match (self.as_const(a), self.as_const(b)) {
            (Some(x), Some(y)) => self.constant(x.max(y)),
            _ => self.weighted_by_steps(a, b, true),
        }
    }

    /// `a step(a - b) + b step(b - a)` for the larger of `a` and `b`, with
    /// the steps' arguments swapped for the smaller.
    fn weighted_by_steps(&mut self, a: Id, b: Id, larger: bool) -> Id {
        let (a_minus_b, b_minus_a) = (self.sub(a, b), self.sub(b, a));
        let (of_a, of_b) = if larger {
            (a_minus_b, b_minus_a)
        } else {
            (b_minus_a, a_minus_b)
        };
        let weight_a = self.call(Func::Step, of_a);
        let weight_b = self.call(Func::Step, of_b);
        let x = self.mul(a, weight_a);
        let y = self.mul(b, weight_b);
        self.add(x, y)
    }

    /// `atan2(y, x)`.
    pub fn atan2(&mut self, y: Id, x: Id) -> Id {
        if let (Some(a), Some(b)) = (self.as_const(y), self.as_const(x)) {
            return self.constant(a.atan2(b));
        }
        self.intern(Node::Atan2(y, x))
    }

    /// Direct children of a node.
    pub fn children(&self, id: Id) -> Vec<Id> {
        match self.node(id) {
            Node::Const(_) | Node::Sym(_) => vec![],
            Node::Sum(ts, _) => ts.iter().map(|&(t, _)| t).collect(),
            Node::Prod(fs) => fs.iter().map(|&(b, _)| b).collect(),
            Node::Call(_, a) => vec![*a],
            Node::Atan2(y, x) => vec![*y, *x],
        }
    }

    /// All nodes reachable from `roots`, in increasing id (topological) order.
    /// Costs time proportional to the reachable part, not the whole graph.
    pub fn reachable(&self, roots: &[Id]) -> Vec<Id> {
        let mut seen: std::collections::HashSet<Id> = std::collections::HashSet::new();
        let mut stack: Vec<Id> = roots.to_vec();
        while let Some(id) = stack.pop() {
            if seen.insert(id) {
                stack.extend(self.children(id));
            }
        }
        let mut out: Vec<Id> = seen.into_iter().collect();
        out.sort_unstable();
        out
    }

    /// The symbols an expression depends on, sorted.
    pub fn symbols(&self, roots: &[Id]) -> Vec<Symbol> {
        let mut out: Vec<Symbol> = self
            .reachable(roots)
            .into_iter()
            .filter_map(|id| match self.node(id) {
                Node::Sym(s) => Some(*s),
                _ => None,
            })
            .collect();
        out.sort();
        out.dedup();
        out
    }

    /// Evaluate expressions numerically, with `env` giving each symbol's value.
    pub fn eval(&self, roots: &[Id], env: &dyn Fn(Symbol) -> f64) -> Vec<f64> {
        let order = self.reachable(roots);
        let mut value: HashMap<Id, f64> = HashMap::with_capacity(order.len());
        for id in order {
            let v = match self.node(id) {
                Node::Const(c) => c.get(),
                Node::Sym(s) => env(*s),
                Node::Sum(ts, k) => ts
                    .iter()
                    .fold(k.get(), |acc, &(t, c)| acc + c.get() * value[&t]),
                Node::Prod(fs) => fs
                    .iter()
                    .fold(1.0, |acc, &(b, e)| acc * powi_f64(value[&b], e as i64)),
                Node::Call(f, a) => f.apply(value[a]),
                Node::Atan2(y, x) => value[y].atan2(value[x]),
            };
            value.insert(id, v);
        }
        roots.iter().map(|r| value[r]).collect()
    }

    /// Rebuild `roots` with every symbol replaced by `map(symbol)` (kept where
    /// it gives `None`), through the canonical constructors, so that the
    /// results fold and simplify as if they had been written that way.
    pub fn substitute(&mut self, roots: &[Id], map: &dyn Fn(Symbol) -> Option<Id>) -> Vec<Id> {
        let order = self.reachable(roots);
        let mut new: HashMap<Id, Id> = HashMap::with_capacity(order.len());
        for id in order {
            let v = match self.node(id).clone() {
                Node::Const(_) => id,
                Node::Sym(s) => map(s).unwrap_or(id),
                Node::Sum(ts, k) => {
                    let terms: Vec<(Id, f64)> =
                        ts.iter().map(|&(t, c)| (new[&t], c.get())).collect();
                    self.linear(&terms, k.get())
                }
                Node::Prod(fs) => {
                    let factors: Vec<(Id, i32)> = fs.iter().map(|&(b, e)| (new[&b], e)).collect();
                    self.product(&factors)
                }
                Node::Call(f, a) => self.call(f, new[&a]),
                Node::Atan2(y, x) => self.atan2(new[&y], new[&x]),
            };
            new.insert(id, v);
        }
        roots.iter().map(|r| new[r]).collect()
    }

    /// Render an expression as text (for diagnostics and tests).
    pub fn display(&self, id: Id) -> String {
        match self.node(id) {
            Node::Const(c) => format!("{}", c.get()),
            Node::Sym(Symbol::Q(i)) => format!("q[{i}]"),
            Node::Sym(Symbol::Qd(i)) => format!("qd[{i}]"),
            Node::Sym(Symbol::Qdd(i)) => format!("qdd[{i}]"),
            Node::Sym(Symbol::Time) => "t".into(),
            Node::Sym(Symbol::Param(i)) => format!("p{i}"),
            Node::Sum(ts, k) => {
                let mut s = String::from("(");
                if k.get() != 0.0 {
                    s += &format!("{}", k.get());
                }
                for (i, &(t, c)) in ts.iter().enumerate() {
                    if i > 0 || k.get() != 0.0 {
                        s += " + ";
                    }
                    if c.get() != 1.0 {
                        s += &format!("{}*", c.get());
                    }
                    s += &self.display(t);
                }
                s + ")"
            }
            Node::Prod(fs) => fs
                .iter()
                .map(|&(b, e)| {
                    if e == 1 {
                        self.display(b)
                    } else {
                        format!("{}^{e}", self.display(b))
                    }
                })
                .collect::<Vec<_>>()
                .join("*"),
            Node::Call(f, a) => format!("{}({})", f.name(), self.display(*a)),
            Node::Atan2(y, x) => format!("atan2({}, {})", self.display(*y), self.display(*x)),
        }
    }
}

fn clamp_finite(x: f64) -> f64 {
    if x.is_nan() {
        0.0
    } else {
        x.clamp(f64::MIN, f64::MAX)
    }
}

fn clamp_exp(e: i64) -> i32 {
    e.clamp(i32::MIN as i64 + 1, i32::MAX as i64) as i32
}

/// `x^n` for an integer `n` by repeated squaring.
pub fn powi_f64(x: f64, n: i64) -> f64 {
    let mut base = if n < 0 { 1.0 / x } else { x };
    let mut n = n.unsigned_abs();
    let mut acc = 1.0;
    while n > 0 {
        if n & 1 == 1 {
            acc *= base;
        }
        base *= base;
        n >>= 1;
    }
    acc
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(g: &Graph, id: Id, q: &[f64]) -> f64 {
        g.eval(&[id], &|s| match s {
            Symbol::Q(i) => q[i as usize],
            _ => 0.0,
        })[0]
    }

    #[test]
    fn equal_expressions_share_one_node() {
        let mut g = Graph::new();
        let (x, y) = (g.q(0), g.q(1));
        let a = g.mul(x, y);
        let b = g.mul(y, x);
        assert_eq!(a, b);
        let s1 = g.add(a, x);
        let s2 = g.add(x, b);
        assert_eq!(s1, s2);
    }

    #[test]
    fn identities_fold() {
        let mut g = Graph::new();
        let x = g.q(0);
        let zero = g.constant(0.0);
        let one = g.constant(1.0);
        assert_eq!(g.mul(x, zero), zero);
        assert_eq!(g.mul(x, one), x);
        assert_eq!(g.add(x, zero), x);
        assert_eq!(g.sub(x, x), zero);
        let nx = g.neg(x);
        assert_eq!(g.neg(nx), x);
        assert_eq!(g.div(x, x), one);
        let two = g.constant(2.0);
        let three = g.constant(3.0);
        let six = g.mul(two, three);
        assert_eq!(g.as_const(six), Some(6.0));
    }

    #[test]
    fn like_terms_collect() {
        let mut g = Graph::new();
        let (x, y) = (g.q(0), g.q(1));
        let xy = g.mul(x, y);
        let a = g.scale(xy, 2.0);
        let yx = g.mul(y, x);
        let b = g.scale(yx, 3.0);
        let s = g.add(a, b);
        assert_eq!(s, g.scale(xy, 5.0));
        let xx = g.mul(x, x);
        assert_eq!(xx, g.powi(x, 2));
    }

    #[test]
    fn pythagorean_identity() {
        let mut g = Graph::new();
        let (x, y) = (g.q(0), g.q(1));
        let s = g.sin(x);
        let c = g.cos(x);
        let s2 = g.powi(s, 2);
        let c2 = g.powi(c, 2);
        let s2y = g.mul(s2, y);
        let c2y = g.mul(c2, y);
        let a = g.scale(s2y, 0.5);
        let b = g.scale(c2y, 0.5);
        let sum = g.add(a, b);
        assert_eq!(sum, g.scale(y, 0.5));
        let plain = g.add(s2, c2);
        assert!(g.is_const(plain, 1.0));
    }

    /// Operands of every node reachable from `roots` (terms, factors,
    /// arguments): the size of the program that evaluates them.
    fn operands(g: &Graph, roots: &[Id]) -> usize {
        g.reachable(roots)
            .iter()
            .map(|&id| g.children(id).len())
            .sum()
    }

    #[test]
    fn partial_sums_stay_terms_of_longer_sums() {
        let n = 100;
        let mut g = Graph::new();
        let x: Vec<Id> = (0..=n).map(|i| g.q(i)).collect();
        // s_k = s_(k-1) + x_k: a running sum, flattened it would take
        // n^2 / 2 operands.
        let mut s = vec![x[0]];
        for k in 1..=n {
            let next = g.add(s[k - 1], x[k]);
            s.push(next);
        }
        let size = operands(&g, &s);
        assert!(size < 10 * n, "{size} operands");
        let value: Vec<f64> = (0..=n).map(|i| (i as f64 * 0.37).sin()).collect();
        let got = g.eval(&s[n..], &|sym| match sym {
            Symbol::Q(i) => value[i as usize],
            _ => 0.0,
        })[0];
        let want: f64 = value.iter().sum();
        assert!((got - want).abs() < 1e-12 * want.abs().max(1.0));
        // Cancellation is as exact as in a flat sum.
        assert_eq!(g.sub(s[n], s[n - 1]), x[n]);
        let flat = g.sum(&x);
        let zero = g.sub(s[n], flat);
        assert!(g.is_const(zero, 0.0), "{}", g.display(zero));
        let y = g.q(n + 1);
        let sy = g.add(s[n], y);
        assert_eq!(g.sub(sy, s[n]), y);
        let back = g.linear(&[(sy, 2.0), (flat, -2.0), (y, -1.0)], 0.0);
        assert_eq!(back, y);
    }

    #[test]
    fn sqrt_squared_is_argument() {
        let mut g = Graph::new();
        let x = g.q(0);
        let r = g.sqrt(x);
        assert_eq!(g.powi(r, 2), x);
        assert_eq!(g.mul(r, r), x);
    }

    #[test]
    fn switches_of_constants_fold_exactly() {
        let mut g = Graph::new();
        let folded = |g: &mut Graph, f: Func, x: f64| {
            let c = g.constant(x);
            let id = g.call(f, c);
            g.as_const(id)
        };
        assert_eq!(folded(&mut g, Func::Abs, -2.5), Some(2.5));
        assert_eq!(folded(&mut g, Func::Sign, -3.0), Some(-1.0));
        assert_eq!(folded(&mut g, Func::Sign, 1e-300), Some(1.0));
        assert_eq!(folded(&mut g, Func::Sign, 0.0), Some(0.0));
        assert_eq!(folded(&mut g, Func::Step, 0.0), Some(0.5));
        assert_eq!(folded(&mut g, Func::Step, -1e-300), Some(0.0));
        assert_eq!(folded(&mut g, Func::Step, 7.0), Some(1.0));
        // (0.1 + 0.3 - |0.1 - 0.3|) / 2 is 0.10000000000000002.
        let (a, b) = (g.constant(0.1), g.constant(0.3));
        let lo = g.min(a, b);
        let hi = g.max(a, b);
        assert_eq!((g.as_const(lo), g.as_const(hi)), (Some(0.1), Some(0.3)));
        // A constant difference decides the switch symbolically.
        let x = g.q(0);
        let x1 = g.linear(&[(x, 1.0)], 1.0);
        assert_eq!(g.min(x, x1), x);
        assert_eq!(g.max(x1, x), x1);
        assert_eq!(g.min(x, x), x);
    }

    #[test]
    fn min_and_max_are_exact_however_different_the_sizes() {
        let mut g = Graph::new();
        let (x, y) = (g.q(0), g.q(1));
        let small = g.scale(x, 1e-20);
        let large = g.scale(y, 1e20);
        let lo = g.min(small, large);
        let hi = g.max(small, large);
        let (lo_xy, hi_xy) = (g.min(x, y), g.max(x, y));
        assert_eq!(g.eval(&[lo, hi], &|_| 1.0), [1e-20, 1e20]);
        let v = |g: &Graph, id: Id, q: &[f64]| at(g, id, q);
        assert_eq!(v(&g, lo, &[-1.0, -1.0]), -1e20);
        assert_eq!(v(&g, hi, &[-1.0, -1.0]), -1e-20);
        // Ties give the common value; NaN propagates (f64::min would drop it).
        assert_eq!(v(&g, lo_xy, &[0.3, 0.3]), 0.3);
        assert_eq!(v(&g, hi_xy, &[-0.7, -0.7]), -0.7);
        assert!(v(&g, lo_xy, &[f64::NAN, 1.0]).is_nan());
        assert!(v(&g, hi_xy, &[1.0, f64::NAN]).is_nan());
    }

    #[test]
    fn eval_matches_direct_computation() {
        let mut g = Graph::new();
        let (x, y) = (g.q(0), g.q(1));
        let s = g.sin(x);
        let num = g.mul(s, y);
        let den = g.add(x, y);
        let e = g.div(num, den);
        let e = g.atan2(e, x);
        let v = at(&g, e, &[0.3, 1.7]);
        let want = ((0.3f64.sin() * 1.7) / (0.3 + 1.7)).atan2(0.3);
        assert!((v - want).abs() < 1e-15);
    }

    #[test]
    fn substitution_folds_like_fresh_construction() {
        let mut g = Graph::new();
        let (x, y) = (g.q(0), g.q(1));
        // x*y + sin(y) + cos(x)^2 + sin(x)^2 with y := 0 is 1 (sin(0) folds, x*0 vanishes).
        let xy = g.mul(x, y);
        let sy = g.sin(y);
        let (sx, cx) = (g.sin(x), g.cos(x));
        let (s2, c2) = (g.powi(sx, 2), g.powi(cx, 2));
        let e = g.sum(&[xy, sy, s2, c2]);
        let zero = g.constant(0.0);
        let out = g.substitute(&[e, x], &|s| (s == Symbol::Q(1)).then_some(zero));
        assert!(g.is_const(out[0], 1.0), "{}", g.display(out[0]));
        assert_eq!(out[1], x);
        // Renaming q1 -> q0 turns x*y into x^2, the same node as built directly.
        let out = g.substitute(&[xy], &|s| (s == Symbol::Q(1)).then_some(x));
        assert_eq!(out[0], g.powi(x, 2));
        // Values agree with evaluating the original at the substituted point.
        let w = g.atan2(sy, xy);
        let half = g.constant(0.5);
        let out = g.substitute(&[w], &|s| (s == Symbol::Q(0)).then_some(half));
        assert!((at(&g, out[0], &[9.0, 1.3]) - at(&g, w, &[0.5, 1.3])).abs() < 1e-15);
    }

    #[test]
    fn children_precede_parents() {
        let mut g = Graph::new();
        let (x, y) = (g.q(0), g.q(1));
        let a = g.mul(x, y);
        let b = g.sin(a);
        let c = g.add(b, x);
        for id in g.reachable(&[c]) {
            for ch in g.children(id) {
                assert!(ch < id);
            }
        }
    }
}
