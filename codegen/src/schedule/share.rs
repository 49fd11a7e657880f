//! Sharing of repeated pairs inside the n-ary products and sums of a
//! scheduled program.
//!
//! Hash-consing shares whole nodes only: `a b c` and `a b d` are different
//! products, and `-0.4 x - 0.1 y` and `-0.4 x - 0.1 y + z` different sums,
//! although the first two factors (terms) are common. This pass finds pairs
//! of factors, and pairs of terms with the same coefficient ratio, that
//! several products (sums) contain, and computes each such pair once:
//! `w = a b` then `w c` and `w d`; `s = x + 0.25 y` then `-0.4 s` and
//! `-0.4 s + z`.
//!
//! A shared pair never adds a multiplication or an addition where it is
//! used, so only pairs used at least twice are bound. Pairs are chosen
//! greedily, most frequent first, and the pass repeats so that shared pairs
//! can pair again (`a b c` in several products: `w = a b`, then `w c`).
//! Reassociation changes rounding in the last bits only; the CasADi
//! validation bounds the emitted terms at 1e-10 relative.

use super::code::{Code, Stmt};
use crate::expr::Symbol;
use crate::hash::{FastMap, FastSet};

/// Most passes over the program (each can pair the results of the
/// previous one; they stop when no pair repeats, which every robot and
/// scene measured reaches within 8: 16 factors common to several products
/// nest 4 deep).
const PASSES: usize = 16;

/// Products or sums with more leaf factors (terms) than this are left alone:
/// the pair enumeration is quadratic in their length.
const MAX_LEAVES: usize = 64;

/// A leaf operand: an input or a bound variable.
#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Debug)]
enum Leaf {
    Sym(Symbol),
    Var(u32),
}

impl Leaf {
    fn of(c: &Code) -> Option<Leaf> {
        match c {
            Code::Sym(s) => Some(Leaf::Sym(*s)),
            Code::Var(v) => Some(Leaf::Var(*v)),
            _ => None,
        }
    }

    fn code(self) -> Code {
        match self {
            Leaf::Sym(s) => Code::Sym(s),
            Leaf::Var(v) => Code::Var(v),
        }
    }
}

/// A pair inside a product (`a b`, `a <= b`), or inside a sum
/// (`x + r y`, `x < y`, `r` the coefficient of `y` over that of `x`, as bits).
#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Debug)]
enum Pair {
    Prod(Leaf, Leaf),
    Sum(Leaf, Leaf, u64),
}

impl Pair {
    /// The pair of factors `a b`.
    fn product(a: Leaf, b: Leaf) -> Pair {
        Pair::Prod(a.min(b), a.max(b))
    }

    /// The pair of terms `ca a + cb b`, with the coefficient it takes out
    /// (that of its first leaf); `None` when the ratio is not usable.
    fn sum(a: Leaf, ca: f64, b: Leaf, cb: f64) -> Option<(Pair, f64)> {
        let ((x, cx), (y, cy)) = if a < b {
            ((a, ca), (b, cb))
        } else {
            ((b, cb), (a, ca))
        };
        let r = cy / cx;
        (r.is_finite() && r != 0.0 && x != y).then_some((Pair::Sum(x, y, r.to_bits()), cx))
    }

    /// The shared expression.
    fn code(self) -> Code {
        match self {
            Pair::Prod(a, b) => Code::Prod {
                num: vec![a.code(), b.code()],
                den: Vec::new(),
            },
            Pair::Sum(x, y, r) => Code::Sum {
                constant: 0.0,
                terms: vec![(1.0, x.code()), (f64::from_bits(r), y.code())],
            },
        }
    }
}

/// The pairs of one product or sum, with the positions of their operands
/// and, for sums, the coefficient the shared pair takes there.
fn pairs_of(c: &Code) -> Vec<(Pair, usize, usize, f64)> {
    let mut out = Vec::new();
    match c {
        Code::Prod { num, .. } => {
            let leaves: Vec<(usize, Leaf)> = num
                .iter()
                .enumerate()
                .filter_map(|(i, f)| Leaf::of(f).map(|l| (i, l)))
                .collect();
            if leaves.len() < 3 || leaves.len() > MAX_LEAVES {
                return out;
            }
            for (k, &(i, a)) in leaves.iter().enumerate() {
                for &(j, b) in &leaves[k + 1..] {
                    out.push((Pair::product(a, b), i, j, 1.0));
                }
            }
        }
        Code::Sum { constant, terms } => {
            let leaves: Vec<(usize, f64, Leaf)> = terms
                .iter()
                .enumerate()
                .filter_map(|(i, (k, t))| Leaf::of(t).map(|l| (i, *k, l)))
                .collect();
            // A sum of exactly two leaf terms is itself the pair: sharing it
            // with a longer sum saves nothing there.
            let whole = leaves.len() == terms.len() && *constant == 0.0;
            if leaves.len() < 2 + usize::from(whole) || leaves.len() > MAX_LEAVES {
                return out;
            }
            for (k, &(i, ci, a)) in leaves.iter().enumerate() {
                for &(j, cj, b) in &leaves[k + 1..] {
                    if let Some((pair, cx)) = Pair::sum(a, ci, b, cj) {
                        out.push((pair, i, j, cx));
                    }
                }
            }
        }
        _ => {}
    }
    out
}

/// The pairs one product or sum takes, by decreasing `rank` (pairs with a
/// rank below 2 are not taken), each operand in at most one pair.
fn choose(c: &Code, rank: &dyn Fn(&Pair) -> usize) -> Vec<(Pair, usize, usize, f64)> {
    let mut candidates: Vec<(usize, (Pair, usize, usize, f64))> = pairs_of(c)
        .into_iter()
        .map(|p| (rank(&p.0), p))
        .filter(|(r, _)| *r >= 2)
        .collect();
    candidates.sort_by(|a, b| b.0.cmp(&a.0).then(a.1 .0.cmp(&b.1 .0)));
    let mut used = Vec::new();
    let mut chosen = Vec::new();
    for (_, p) in candidates {
        if !used.contains(&p.1) && !used.contains(&p.2) {
            used.extend([p.1, p.2]);
            chosen.push(p);
        }
    }
    chosen
}

fn stmt_code_mut(s: &mut Stmt) -> &mut Code {
    match s {
        Stmt::Let { value, .. } => value,
        Stmt::SinCos { arg, .. } => arg,
    }
}

/// The pairs that an existing `let` computes by itself (`let v = a b;`,
/// `let v = cx x + cy y;`), with the variable and, for sums, the
/// coefficient of the pair's first leaf in it.
fn existing_pairs(stmts: &[Stmt]) -> FastMap<Pair, (u32, f64)> {
    let mut found = FastMap::default();
    for s in stmts {
        let Stmt::Let { var, value } = s else {
            continue;
        };
        match value {
            Code::Prod { num, den } if den.is_empty() && num.len() == 2 => {
                if let (Some(a), Some(b)) = (Leaf::of(&num[0]), Leaf::of(&num[1])) {
                    found.entry(Pair::product(a, b)).or_insert((*var, 1.0));
                }
            }
            Code::Sum { constant, terms } if *constant == 0.0 && terms.len() == 2 => {
                let [(ca, a), (cb, b)] = [&terms[0], &terms[1]];
                if let (Some(a), Some(b)) = (Leaf::of(a), Leaf::of(b)) {
                    if let Some((pair, cx)) = Pair::sum(a, *ca, b, *cb) {
                        found.entry(pair).or_insert((*var, cx));
                    }
                }
            }
            _ => {}
        }
    }
    found
}

/// Rewrites the products and sums of a statement (children first) to use
/// the shared pairs: the variable of an existing `let` that computes the
/// pair, once it is defined, or else a new variable, whose `let` goes to
/// `lets` (placed before the statement using it).
struct Rewriter<'a> {
    /// Rank of the pairs to share (as when they were counted).
    rank: &'a FastMap<Pair, usize>,
    existing: &'a FastMap<Pair, (u32, f64)>,
    /// Variables defined so far, in program order.
    defined: FastSet<u32>,
    /// Variables bound by this pass, with their pair's coefficient 1.
    vars: FastMap<Pair, u32>,
    next: &'a mut u32,
}

impl Rewriter<'_> {
    fn rewrite(&mut self, c: &mut Code, lets: &mut Vec<Stmt>) {
        match c {
            Code::Var(_) | Code::Sym(_) | Code::Lit(_) => return,
            Code::Sum { terms, .. } => {
                for (_, t) in terms.iter_mut() {
                    self.rewrite(t, lets);
                }
            }
            Code::Prod { num, den } => {
                for t in num.iter_mut().chain(den.iter_mut()) {
                    self.rewrite(t, lets);
                }
            }
            Code::Call(_, a) => return self.rewrite(a, lets),
            Code::Atan2(y, x) => {
                self.rewrite(y, lets);
                return self.rewrite(x, lets);
            }
        }
        let rank = self.rank;
        let chosen = choose(c, &|p| rank.get(p).copied().unwrap_or(0));
        if chosen.is_empty() {
            return;
        }
        let mut gone = Vec::new();
        let mut added = Vec::new();
        for (pair, i, j, coef) in chosen {
            let (var, scale) = match self.existing.get(&pair) {
                Some(&(v, cv)) if self.defined.contains(&v) => (v, cv),
                _ => {
                    let next = &mut *self.next;
                    let defined = &mut self.defined;
                    let v = *self.vars.entry(pair).or_insert_with(|| {
                        let v = *next;
                        *next += 1;
                        lets.push(Stmt::Let {
                            var: v,
                            value: pair.code(),
                        });
                        defined.insert(v);
                        v
                    });
                    (v, 1.0)
                }
            };
            gone.extend([i, j]);
            added.push((coef / scale, Code::Var(var)));
        }
        let keep = |k: &mut usize| {
            *k += 1;
            !gone.contains(&(*k - 1))
        };
        match c {
            Code::Prod { num, .. } => {
                let mut k = 0;
                num.retain(|_| keep(&mut k));
                num.extend(added.into_iter().map(|(_, v)| v));
            }
            Code::Sum { terms, .. } => {
                let mut k = 0;
                terms.retain(|_| keep(&mut k));
                terms.extend(added);
            }
            _ => {}
        }
    }

    fn define(&mut self, s: &Stmt) {
        match s {
            Stmt::Let { var, .. } => {
                self.defined.insert(*var);
            }
            Stmt::SinCos { sin, cos, .. } => {
                self.defined.extend([*sin, *cos]);
            }
        }
    }
}

/// Shares the repeated pairs of the program `stmts` + `outputs`, binding new
/// variables numbered from `*next` (advanced past them).
pub(super) fn share_pairs(stmts: &mut Vec<Stmt>, outputs: &mut [Code], next: &mut u32) {
    for _ in 0..PASSES {
        let existing = existing_pairs(stmts);
        // How many products and sums contain each pair (an existing `let`
        // computing it counts as one).
        let mut contained: FastMap<Pair, usize> = existing.keys().map(|&p| (p, 1)).collect();
        let mut count = |c: &mut Code| {
            let mut seen: Vec<Pair> = pairs_of(c).into_iter().map(|p| p.0).collect();
            seen.sort();
            seen.dedup();
            for p in seen {
                *contained.entry(p).or_default() += 1;
            }
        };
        visit_all(stmts, outputs, &mut count);
        // How many would take each pair, choosing greedily by that count;
        // only pairs computed at least twice are worth sharing.
        let mut taken: FastMap<Pair, usize> = existing.keys().map(|&p| (p, 1)).collect();
        let mut tally = |c: &mut Code| {
            for p in choose(c, &|p| contained.get(p).copied().unwrap_or(0)) {
                *taken.entry(p.0).or_default() += 1;
            }
        };
        visit_all(stmts, outputs, &mut tally);
        let rank: FastMap<Pair, usize> = taken
            .into_iter()
            .filter(|&(_, n)| n >= 2)
            .map(|(p, _)| (p, contained[&p]))
            .collect();
        if rank.is_empty() {
            return;
        }
        let mut rewriter = Rewriter {
            rank: &rank,
            existing: &existing,
            defined: Default::default(),
            vars: FastMap::default(),
            next,
        };
        let mut out = Vec::with_capacity(stmts.len());
        for mut s in stmts.drain(..) {
            rewriter.rewrite(stmt_code_mut(&mut s), &mut out);
            rewriter.define(&s);
            out.push(s);
        }
        for o in outputs.iter_mut() {
            rewriter.rewrite(o, &mut out);
        }
        *stmts = out;
    }
}

/// Shares the reciprocals of the program's repeated divisors: a leaf that
/// divides two or more products is inverted once, `r = 1 / d`, and those
/// products multiply by `r` (a factorisation's `L_ij = x / D_j` down a
/// column): a division costs several multiplications on every target.
pub(super) fn share_reciprocals(stmts: &mut Vec<Stmt>, outputs: &mut [Code], next: &mut u32) {
    let mut count: FastMap<Leaf, usize> = FastMap::default();
    let mut tally = |c: &mut Code| {
        if let Code::Prod { num, den } = c {
            // `1 / d` itself gains nothing.
            if num.is_empty() && den.len() == 1 {
                return;
            }
            let mut seen: Vec<Leaf> = den.iter().filter_map(Leaf::of).collect();
            seen.sort();
            seen.dedup();
            for l in seen {
                *count.entry(l).or_default() += 1;
            }
        }
    };
    visit_all(stmts, outputs, &mut tally);
    count.retain(|_, n| *n >= 2);
    if count.is_empty() {
        return;
    }
    let mut inverse: FastMap<Leaf, u32> = FastMap::default();
    let mut invert = |c: &mut Code, lets: &mut Vec<Stmt>| {
        let Code::Prod { num, den } = c else {
            return;
        };
        if num.is_empty() && den.len() == 1 {
            return;
        }
        let mut k = 0;
        while k < den.len() {
            let Some(l) = Leaf::of(&den[k]).filter(|l| count.contains_key(l)) else {
                k += 1;
                continue;
            };
            let r = *inverse.entry(l).or_insert_with(|| {
                let v = *next;
                *next += 1;
                lets.push(Stmt::Let {
                    var: v,
                    value: Code::Prod {
                        num: Vec::new(),
                        den: vec![l.code()],
                    },
                });
                v
            });
            den.remove(k);
            num.push(Code::Var(r));
        }
    };
    let mut out = Vec::with_capacity(stmts.len());
    for mut s in stmts.drain(..) {
        visit_mut(stmt_code_mut(&mut s), &mut |c| invert(c, &mut out));
        out.push(s);
    }
    for o in outputs.iter_mut() {
        visit_mut(o, &mut |c| invert(c, &mut out));
    }
    *stmts = out;
}

/// Calls `f` on every product and sum of the statements and the outputs,
/// children first (the counting passes only read them).
fn visit_all(stmts: &mut [Stmt], outputs: &mut [Code], f: &mut dyn FnMut(&mut Code)) {
    for s in stmts.iter_mut() {
        visit_mut(stmt_code_mut(s), f);
    }
    for o in outputs.iter_mut() {
        visit_mut(o, f);
    }
}

/// Calls `f` on every product and sum of `c`, children first.
fn visit_mut(c: &mut Code, f: &mut dyn FnMut(&mut Code)) {
    match c {
        Code::Var(_) | Code::Sym(_) | Code::Lit(_) => return,
        Code::Sum { terms, .. } => {
            for (_, t) in terms.iter_mut() {
                visit_mut(t, f);
            }
        }
        Code::Prod { num, den } => {
            for t in num.iter_mut().chain(den.iter_mut()) {
                visit_mut(t, f);
            }
        }
        Code::Call(_, a) => return visit_mut(a, f),
        Code::Atan2(y, x) => {
            visit_mut(y, f);
            return visit_mut(x, f);
        }
    }
    f(c);
}
