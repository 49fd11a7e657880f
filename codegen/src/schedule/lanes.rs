//! Two lanes for mirror-image limbs: which statements of a lowered `f64`
//! program compute the same expression for two limbs of the same shape (a
//! humanoid's legs and arms, a hand's fingers), so that the Rust emitter
//! prints each such pair as one statement on two lanes (`math::F2`: one
//! SIMD instruction per operation on x86-64). Each lane performs exactly the
//! operations of its scalar statement, so the results are bitwise those of
//! the scalar program (and of the interpreter and the C back end, which do
//! not pair).
//!
//! * [`mirror_coordinates`]: sibling subtrees of the kinematic tree with the
//!   same shape (coordinates per frame, children) are paired, their
//!   coordinates matched frame by frame: lane 0 and lane 1.
//! * [`plan`]: statements are paired level by level (a statement's level is
//!   one more than the deepest statement it reads, so statements of one
//!   level never read each other): two statements pair when their operation
//!   trees are the same up to signs ([`View`]: a subtraction is a signed
//!   term, the four multiply-adds one form, a product's sign on its first
//!   factor, commuting operands in an order both share) and every operand
//!   that belongs to a pair (an input of mirrored coordinates, a sine of
//!   one, a paired statement) is lane 0 of that pair in one and lane 1 in
//!   the other; other operands may be anything. Each lane keeps its own
//!   signs ([`Lanes`]). Then the statements are ordered again (each pair
//!   where both its statements' operands are ready, otherwise the original
//!   order).
//! * [`printed`]: where a pair's signs go when it is printed (on a
//!   literal, in `minus`, `sub_mul` or `mul_sub`, else a negation of one
//!   lane or both), so that a back end only prints ([`Print`]).
//!
//! The lowering helps: in a mirrored scene it adds a sum's terms, and
//! picks the product it fuses, in an order both limbs share
//! ([`super::lower`]), so that their statements are written alike.

use std::cmp::Reverse;
use std::collections::{BinaryHeap, HashMap, HashSet};

use super::{Binary, Fused, Lowered, Op, Operand, Value};
use crate::expr::Symbol;
use crate::model::Model;

/// Per coordinate, its mirror image and its lane (`0` or `1`), if any.
pub type Mirror = Vec<Option<(u32, u8)>>;

/// The mirror images among a model's coordinates ([`mirror_coordinates`]
/// on its frames).
pub fn mirror_of(model: &Model) -> Mirror {
    let parents: Vec<Option<usize>> = model.placements.iter().map(|p| p.parent).collect();
    let coordinates: Vec<Vec<u32>> = model
        .placements
        .iter()
        .map(|p| p.own_coordinates(&model.graph))
        .collect();
    // A frame's placement as far as the programs' shapes go: which axes its
    // translation and turns have, and which turns are fixed.
    let descriptions: Vec<String> = model
        .placements
        .iter()
        .map(|p| {
            let pattern = |v: [f64; 3]| -> String {
                v.iter()
                    .map(|x| if *x == 0.0 { '0' } else { '1' })
                    .collect()
            };
            let translation = p
                .translation
                .map(|t| model.graph.as_const(t).unwrap_or(f64::NAN));
            let mut text = format!("t{}", pattern(translation));
            for (axis, angle) in &p.rotations {
                let fixed = model.graph.as_const(*angle).is_some();
                text += &format!("r{}{}", pattern(*axis), if fixed { 'c' } else { 'q' });
            }
            text
        })
        .collect();
    mirror_coordinates(&parents, &coordinates, &descriptions, model.nq())
}

/// The mirror images among the coordinates of a kinematic tree given by
/// each frame's parent, own coordinates and a description of its placement
/// (`nq` coordinates in all). Sibling subtrees pair first where their
/// frames' descriptions agree all the way down (mirror images written
/// alike), then, among the others, where only their coordinates per frame
/// and children do.
fn mirror_coordinates(
    parents: &[Option<usize>],
    coordinates: &[Vec<u32>],
    descriptions: &[String],
    nq: usize,
) -> Mirror {
    let n = parents.len();
    let mut children: Vec<Vec<usize>> = vec![Vec::new(); n];
    let mut roots = Vec::new();
    for (a, p) in parents.iter().enumerate() {
        match p {
            Some(p) => children[*p].push(a),
            None => roots.push(a),
        }
    }
    // Shapes from the leaves (children follow their parents): coarse
    // (coordinates and children) and detailed (descriptions too).
    let mut coarse: Vec<String> = vec![String::new(); n];
    let mut detailed: Vec<String> = vec![String::new(); n];
    for a in (0..n).rev() {
        for (shape, own) in [
            (&mut coarse, coordinates[a].len().to_string()),
            (
                &mut detailed,
                format!("{}{}", coordinates[a].len(), descriptions[a]),
            ),
        ] {
            let mut inner: Vec<&str> = children[a].iter().map(|&c| shape[c].as_str()).collect();
            inner.sort_unstable();
            let joined = inner.join(",");
            shape[a] = format!("{own}({joined})");
        }
    }
    let mut mirror: Mirror = vec![None; nq];
    let mut stack = vec![roots];
    while let Some(siblings) = stack.pop() {
        let mut left = siblings;
        for shape in [&detailed, &coarse] {
            let mut groups: Vec<Vec<usize>> = Vec::new();
            for &a in &left {
                match groups.iter_mut().find(|g| shape[g[0]] == shape[a]) {
                    Some(g) => g.push(a),
                    None => groups.push(vec![a]),
                }
            }
            left = Vec::new();
            for g in groups {
                let mut members = g.chunks_exact(2);
                for two in members.by_ref() {
                    match_subtrees(two[0], two[1], &children, shape, coordinates, &mut mirror);
                }
                left.extend(members.remainder());
            }
        }
        for a in left {
            stack.push(children[a].clone());
        }
    }
    mirror
}

/// Matches the coordinates of two subtrees of the same shape.
fn match_subtrees(
    a: usize,
    b: usize,
    children: &[Vec<usize>],
    shape: &[String],
    coordinates: &[Vec<u32>],
    mirror: &mut Mirror,
) {
    for (&i, &j) in coordinates[a].iter().zip(&coordinates[b]) {
        if (i as usize) < mirror.len() && (j as usize) < mirror.len() {
            mirror[i as usize] = Some((j, 0));
            mirror[j as usize] = Some((i, 1));
        }
    }
    let sorted = |x: usize| {
        let mut c = children[x].clone();
        c.sort_by(|p, q| shape[*p].cmp(&shape[*q]).then(p.cmp(q)));
        c
    };
    for (c, d) in sorted(a).into_iter().zip(sorted(b)) {
        match_subtrees(c, d, children, shape, coordinates, mirror);
    }
}

/// One step of the printed program.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Step {
    /// A unit printed as it is.
    One(usize),
    /// Two units (lane 0, lane 1) printed as pair number `n`.
    Two(usize, usize, u32),
}

/// How to print a lowered program: its units, their order, and where the
/// paired statements' variables live.
#[derive(Debug, Clone, Default)]
pub struct Plan {
    /// Each unit's operations (their indices in order, the statement that
    /// writes a variable or an output last).
    pub units: Vec<Vec<usize>>,
    /// The order in which units are printed.
    pub order: Vec<Step>,
    /// Variables held in a pair's lane: pair number and lane.
    pub resident: HashMap<u32, (u32, u8)>,
    /// Held variables that other statements also read as numbers.
    pub scalar: HashSet<u32>,
    /// The writer of each intermediate.
    pub writer: Vec<usize>,
    /// Each pair's two-lane expression, by pair number.
    pub trees: Vec<Lanes>,
}

impl Plan {
    /// The pair held in both lanes of two operands, lane 0 in `a`.
    pub fn held(&self, a: Operand, b: Operand) -> Option<u32> {
        match (a.value, b.value) {
            (Value::Var(x), Value::Var(y)) => {
                match (self.resident.get(&x), self.resident.get(&y)) {
                    (Some(&(n, 0)), Some(&(m, 1))) if n == m => Some(n),
                    _ => None,
                }
            }
            _ => None,
        }
    }
}

/// An operation of a statement in the form the two lanes share: an
/// addition or subtraction is a sum of two signed operands, a multiply-add
/// in any of its four forms is `x * y + c` with signed operands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Form {
    /// `a + b`.
    Plus,
    /// `a * b`.
    Times,
    /// `a / b`.
    Over,
    /// `x * y + c` (operands `x`, `y`, `c`).
    MulAdd,
}

/// One lane's statement as a tree of [`Form`]s whose signs sit where the
/// two lanes can agree on them: a negation or subtraction becomes a sign on
/// the negated operand, and within a product (or quotient) every sign moves
/// to its first factor. Each of these is exact in IEEE arithmetic: `a - b`
/// is `a + (-b)`, `-(a b) = (-a) b`, `-(a / b) = (-a) / b`, `c - x y = c +
/// (-x) y` (also fused), and negating a result flips its sign bit only. A
/// sum's sign stays on the sum (`-(a + b)` and `-a - b` differ in the sign
/// of a zero).
#[derive(Debug, Clone)]
enum View {
    /// An operand read as it is, negated or not.
    Leaf(Operand, bool),
    /// An operation, its result negated or not (never for products and
    /// quotients, whose sign is on the first factor), and how it was
    /// written.
    Node(Form, Vec<View>, bool, Written),
}

/// How a statement wrote an operation that [`View`] puts in its shared
/// form, so that a pair can be printed as its lane 0 was written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Written {
    /// Whether its first two operands were exchanged.
    pub swapped: bool,
    /// Whether a multiply-add was written product first (`x y + c`, `x y -
    /// c`).
    pub product_first: bool,
}

impl View {
    /// The view negated.
    fn negate(&mut self) {
        match self {
            View::Leaf(_, sign) | View::Node(Form::Plus | Form::MulAdd, _, sign, _) => {
                *sign = !*sign
            }
            View::Node(Form::Times | Form::Over, args, ..) => args[0].negate(),
        }
    }

    /// The sign where [`View::negate`] puts it.
    fn sign(&self) -> bool {
        match self {
            View::Leaf(_, sign) | View::Node(Form::Plus | Form::MulAdd, _, sign, _) => *sign,
            View::Node(Form::Times | Form::Over, args, ..) => args[0].sign(),
        }
    }
}

/// A token of a view's shape, for pairing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
enum Token {
    Form(u8),
    /// An operand of a pair (its number).
    Pair(u32),
    /// Another operand.
    Any,
}

/// The two lanes of a paired statement: the two views zipped.
#[derive(Debug, Clone)]
pub enum Lanes {
    /// Two operands (lane 0, lane 1), each negated where its flag says.
    Leaf([Operand; 2], [bool; 2]),
    /// An operation on both lanes, its result negated on the lanes whose
    /// flag says so, and how lane 0 wrote it.
    Node(Form, Vec<Lanes>, [bool; 2], Written),
}

impl Lanes {
    /// The signs on both lanes where [`View::sign`] reads them.
    pub fn signs(&self) -> [bool; 2] {
        match self {
            Lanes::Leaf(_, signs) | Lanes::Node(Form::Plus | Form::MulAdd, _, signs, _) => *signs,
            Lanes::Node(Form::Times | Form::Over, args, ..) => args[0].signs(),
        }
    }

    /// The same lanes with the signs that [`Lanes::signs`] reads flipped
    /// where `flip` says.
    pub fn flipped(&self, flip: [bool; 2]) -> Lanes {
        let xor = |s: [bool; 2]| [s[0] ^ flip[0], s[1] ^ flip[1]];
        match self {
            Lanes::Leaf(o, s) => Lanes::Leaf(*o, xor(*s)),
            Lanes::Node(f @ (Form::Plus | Form::MulAdd), args, s, w) => {
                Lanes::Node(*f, args.clone(), xor(*s), *w)
            }
            Lanes::Node(f, args, s, w) => {
                let mut args = args.clone();
                args[0] = args[0].flipped(flip);
                Lanes::Node(*f, args, *s, *w)
            }
        }
    }

    /// The operand pairs at its leaves.
    fn leaves(&self, out: &mut Vec<[Operand; 2]>) {
        match self {
            Lanes::Leaf(o, _) => out.push(*o),
            Lanes::Node(_, args, ..) => args.iter().for_each(|a| a.leaves(out)),
        }
    }
}

/// An operation of the runtime's two-lane type (`math::F2`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Call {
    /// `a + b`.
    Plus,
    /// `a - b`.
    Minus,
    /// `a b`.
    Times,
    /// `a / b`.
    Over,
    /// A multiply-add, its arguments in the order of its form's name.
    Fused(Fused),
}

impl Call {
    /// Its name in the runtime.
    pub fn name(self) -> &'static str {
        match self {
            Call::Plus => "plus",
            Call::Minus => "minus",
            Call::Times => "times",
            Call::Over => "over",
            Call::Fused(form) => form.name(),
        }
    }
}

/// A paired statement as the back end prints it, every sign where it costs
/// least ([`printed`]).
#[derive(Debug, Clone, PartialEq)]
pub enum Print {
    /// The variable of pair `n`.
    Pair(u32),
    /// Two operands packed into two lanes, each negated where its flag
    /// says (a literal's sign is free).
    Pack([Operand; 2], [bool; 2]),
    /// A two-lane operation on its arguments, in the order it takes them.
    Apply(Call, Vec<Print>),
    /// Its lanes negated where the flags say (one of them at least).
    Negated([bool; 2], Box<Print>),
}

/// How a pair's tree is printed: a literal's sign on the literal, `minus`
/// for a term negated on both lanes, `sub_mul` and `mul_sub` for a
/// multiply-add's signs on both lanes, else a negation of a lane or of
/// both.
pub fn printed(plan: &Plan, tree: &Lanes) -> Print {
    let (e, signs) = match tree {
        Lanes::Leaf([a, b], signs) => match plan.held(*a, *b) {
            Some(n) => (Print::Pair(n), *signs),
            None => (Print::Pack([*a, *b], *signs), [false; 2]),
        },
        Lanes::Node(form, args, signs, written) => {
            let mut args = args.clone();
            if written.swapped {
                args.swap(0, 1);
            }
            let both = |t: &Lanes| t.signs() == [true; 2];
            let go = |t: &Lanes| printed(plan, t);
            let e = match form {
                Form::Plus => {
                    let minus = |t: &Lanes| both(t).then(|| t.flipped([true; 2]));
                    match (minus(&args[0]), minus(&args[1])) {
                        (None, Some(b)) => Print::Apply(Call::Minus, vec![go(&args[0]), go(&b)]),
                        (Some(a), None) => Print::Apply(Call::Minus, vec![go(&args[1]), go(&a)]),
                        _ => Print::Apply(Call::Plus, vec![go(&args[0]), go(&args[1])]),
                    }
                }
                Form::Times | Form::Over => {
                    let call = if *form == Form::Times {
                        Call::Times
                    } else {
                        Call::Over
                    };
                    let (x, y, negated) = product_signs(plan, &args[0], &args[1], false);
                    let e = Print::Apply(call, vec![go(&x), go(&y)]);
                    if negated {
                        Print::Negated([true; 2], Box::new(e))
                    } else {
                        e
                    }
                }
                Form::MulAdd => {
                    let (x, y, negated) = product_signs(plan, &args[0], &args[1], true);
                    let (x, y) = (go(&x), go(&y));
                    if negated {
                        Print::Apply(Call::Fused(Fused::SubMul), vec![go(&args[2]), x, y])
                    } else if both(&args[2]) {
                        let c = go(&args[2].flipped([true; 2]));
                        Print::Apply(Call::Fused(Fused::MulSub), vec![x, y, c])
                    } else if written.product_first {
                        Print::Apply(Call::Fused(Fused::MulAdd), vec![x, y, go(&args[2])])
                    } else {
                        Print::Apply(Call::Fused(Fused::AddMul), vec![go(&args[2]), x, y])
                    }
                }
            };
            let signs = if matches!(form, Form::Plus | Form::MulAdd) {
                *signs
            } else {
                [false; 2]
            };
            (e, signs)
        }
    };
    if signs == [false; 2] {
        e
    } else {
        Print::Negated(signs, Box::new(e))
    }
}

/// The two factors of a product (or a quotient's numerator and
/// denominator) with their signs gathered where they cost least (exact:
/// `(-a) b = a (-b) = -(a b)`, and likewise for a quotient): on a factor
/// that is a literal on each lane the sign is on (a negated literal costs
/// nothing), else, where both lanes carry it, on the result (`true`: the
/// caller negates the product or writes `sub_mul`, which a multiply-add,
/// `fused`, prefers to a literal), else on the first factor (one lane
/// negated).
fn product_signs(plan: &Plan, x: &Lanes, y: &Lanes, fused: bool) -> (Lanes, Lanes, bool) {
    let (sx, sy) = (x.signs(), y.signs());
    let signs = [sx[0] ^ sy[0], sx[1] ^ sy[1]];
    let (x, y) = (x.flipped(sx), y.flipped(sy));
    let literal = |t: &Lanes| match t {
        Lanes::Leaf(o, _) => {
            plan.held(o[0], o[1]).is_none()
                && (0..2).all(|l| !signs[l] || matches!(o[l].value, Value::Literal(_)))
        }
        Lanes::Node(..) => false,
    };
    if signs == [false; 2] {
        (x, y, false)
    } else if fused && signs == [true; 2] {
        (x, y, true)
    } else if literal(&y) {
        let y = y.flipped(signs);
        (x, y, false)
    } else if literal(&x) {
        (x.flipped(signs), y, false)
    } else if signs == [true; 2] {
        (x, y, true)
    } else {
        (x.flipped(signs), y, false)
    }
}

/// The view of an operand of a statement (`None` where its tree has an
/// operation without a two-lane form), its operands that commute put in an
/// order both lanes share (by their shapes: `key`).
fn view(
    lowered: &Lowered,
    writer: &[usize],
    o: Operand,
    key: &mut dyn FnMut(&View) -> Vec<Token>,
) -> Option<View> {
    let Value::Temp(t) = o.value else {
        return Some(View::Leaf(o, false));
    };
    let go = |o: Operand, key: &mut dyn FnMut(&View) -> Vec<Token>| view(lowered, writer, o, key);
    let op = &lowered.ops[writer[t as usize]];
    let mut product_first = false;
    let (form, mut args) = match *op {
        Op::Neg { a, .. } => {
            let mut v = go(a, key)?;
            v.negate();
            return Some(v);
        }
        Op::Binary { op, a, b, .. } => {
            let (a, mut b) = (go(a, key)?, go(b, key)?);
            let form = match op {
                Binary::Add => Form::Plus,
                Binary::Sub => {
                    b.negate();
                    Form::Plus
                }
                Binary::Mul => Form::Times,
                Binary::Div => Form::Over,
            };
            (form, vec![a, b])
        }
        Op::Fused { form, x, y, c, .. } => {
            let (mut x, y, mut c) = (go(x, key)?, go(y, key)?, go(c, key)?);
            match form {
                Fused::AddMul => {}
                Fused::MulAdd => product_first = true,
                Fused::SubMul => x.negate(),
                Fused::MulSub => {
                    c.negate();
                    product_first = true;
                }
            }
            (Form::MulAdd, vec![x, y, c])
        }
        _ => return None,
    };
    // Operands that commute in an order of their shapes (exact: `a + b =
    // b + a`, `a b = b a`), then a product's signs on its first factor.
    let swapped = form != Form::Over && key(&args[1]) < key(&args[0]);
    if swapped {
        args.swap(0, 1);
    }
    if matches!(form, Form::Times | Form::Over | Form::MulAdd) && args[1].sign() {
        args[1].negate();
        args[0].negate();
    }
    let written = Written {
        swapped,
        product_first,
    };
    Some(View::Node(form, args, false, written))
}

/// The tokens of a view: its forms and operands, without signs.
fn tokens(
    v: &View,
    leaf: &mut dyn FnMut(Operand) -> Option<(u32, u8)>,
    out: &mut Vec<Token>,
    lanes: &mut Vec<u8>,
) {
    match v {
        View::Leaf(o, _) => match leaf(*o) {
            Some((n, lane)) => {
                out.push(Token::Pair(n));
                lanes.push(lane);
            }
            None => out.push(Token::Any),
        },
        View::Node(form, args, ..) => {
            out.push(Token::Form(*form as u8));
            for a in args {
                tokens(a, leaf, out, lanes);
            }
        }
    }
}

/// Two views of the same tokens as one two-lane tree.
fn zip(a: &View, b: &View) -> Lanes {
    match (a, b) {
        (View::Leaf(x, s), View::Leaf(y, t)) => Lanes::Leaf([*x, *y], [*s, *t]),
        (View::Node(form, xs, s, written), View::Node(_, ys, t, _)) => Lanes::Node(
            *form,
            xs.iter().zip(ys).map(|(x, y)| zip(x, y)).collect(),
            [*s, *t],
            *written,
        ),
        _ => unreachable!("paired views have the same tokens"),
    }
}

/// The units of `lowered`, paired (where `mirror` has pairs and the
/// program is `f64`) and ordered.
pub fn plan(lowered: &Lowered, mirror: &Mirror, double: bool) -> Plan {
    let ops = &lowered.ops;
    let mut writer = vec![usize::MAX; lowered.temps as usize];
    for (k, op) in ops.iter().enumerate() {
        if let Some(t) = temp_written(op) {
            writer[t as usize] = k;
        }
    }
    let mut units: Vec<Vec<usize>> = Vec::new();
    for (k, op) in ops.iter().enumerate() {
        if temp_written(op).is_some() {
            continue;
        }
        let mut members = vec![k];
        let mut next = 0;
        while next < members.len() {
            for o in ops[members[next]].operands() {
                if let Value::Temp(t) = o.value {
                    members.push(writer[t as usize]);
                }
            }
            next += 1;
        }
        members.sort_unstable();
        units.push(members);
    }
    let mut plan = Plan {
        units,
        writer,
        ..Plan::default()
    };
    let pairs = if double && mirror.iter().any(Option::is_some) {
        pair_units(lowered, &mut plan, mirror)
    } else {
        Vec::new()
    };
    if pairs.is_empty() {
        plan.order = (0..plan.units.len()).map(Step::One).collect();
    } else {
        plan.order = order(lowered, &plan, &pairs);
        plan.scalar = scalar_reads(lowered, &plan);
    }
    plan
}

/// The intermediate an operation writes, if it writes one.
fn temp_written(op: &Op) -> Option<u32> {
    match op {
        Op::Binary { dst, .. }
        | Op::Fused { dst, .. }
        | Op::Neg { dst, .. }
        | Op::Call { dst, .. }
        | Op::Atan2 { dst, .. } => Some(*dst),
        _ => None,
    }
}

/// The variables an operation defines.
fn defines(op: &Op) -> Vec<u32> {
    match op {
        Op::Bind { var, .. } => vec![*var],
        Op::SinCos { sin, cos, .. } => vec![*sin, *cos],
        Op::SinCosArray(batch) => batch.iter().flat_map(|(s, c, _)| [*s, *c]).collect(),
        _ => Vec::new(),
    }
}

/// The variables the operations of a unit read.
fn reads(lowered: &Lowered, unit: &[usize]) -> Vec<u32> {
    unit.iter()
        .flat_map(|&k| lowered.ops[k].operands())
        .filter_map(|o| match o.value {
            Value::Var(v) => Some(v),
            _ => None,
        })
        .collect()
}

/// Numbers of the pairs operands belong to.
#[derive(Default)]
struct Numbers {
    next: u32,
    /// Inputs (`0` positions, `1` velocities, `2` accelerations) by their
    /// lane-0 coordinate, sines (`3`) and cosines (`4`) by their angle's
    /// number.
    keyed: HashMap<(u8, u32), u32>,
}

impl Numbers {
    fn fresh(&mut self) -> u32 {
        self.next += 1;
        self.next - 1
    }

    fn keyed(&mut self, tag: u8, i: u32) -> u32 {
        if let Some(&n) = self.keyed.get(&(tag, i)) {
            return n;
        }
        let n = self.fresh();
        self.keyed.insert((tag, i), n);
        n
    }

    /// The pair and lane of an input of a mirrored coordinate.
    fn input(&mut self, s: Symbol, mirror: &Mirror) -> Option<(u32, u8)> {
        let (tag, i) = match s {
            Symbol::Q(i) => (0, i),
            Symbol::Qd(i) => (1, i),
            Symbol::Qdd(i) => (2, i),
            _ => return None,
        };
        let (j, lane) = (*mirror.get(i as usize)?)?;
        Some((self.keyed(tag, i.min(j)), lane))
    }
}

/// Pairs units level by level; returns the pairs (lane 0, lane 1) and
/// records where their variables live.
fn pair_units(lowered: &Lowered, plan: &mut Plan, mirror: &Mirror) -> Vec<(usize, usize)> {
    let ops = &lowered.ops;
    let mut numbers = Numbers::default();
    // The sines and cosines of mirrored angles pair like their angles.
    let mut var_pair: HashMap<u32, (u32, u8)> = HashMap::new();
    for op in ops {
        let angles: Vec<(u32, u32, Operand)> = match op {
            Op::SinCos { sin, cos, arg } => vec![(*sin, *cos, *arg)],
            Op::SinCosArray(batch) => batch.clone(),
            _ => continue,
        };
        for (sin, cos, arg) in angles {
            if let Value::Input(s @ Symbol::Q(_)) = arg.value {
                if let Some((n, lane)) = numbers.input(s, mirror) {
                    var_pair.insert(sin, (numbers.keyed(3, n), lane));
                    var_pair.insert(cos, (numbers.keyed(4, n), lane));
                }
            }
        }
    }
    // Levels.
    let mut definer: HashMap<u32, usize> = HashMap::new();
    for (u, unit) in plan.units.iter().enumerate() {
        for v in defines(&ops[*unit.last().expect("a unit has its statement")]) {
            definer.insert(v, u);
        }
    }
    let mut level = vec![0usize; plan.units.len()];
    for (u, unit) in plan.units.iter().enumerate() {
        level[u] = reads(lowered, unit)
            .iter()
            .filter_map(|v| definer.get(v))
            .map(|&w| level[w] + 1)
            .max()
            .unwrap_or(0);
    }
    let mut by_level: Vec<Vec<usize>> = vec![Vec::new(); level.iter().max().map_or(0, |m| m + 1)];
    for (u, &l) in level.iter().enumerate() {
        by_level[l].push(u);
    }
    let mut pairs = Vec::new();
    for units in by_level {
        let mut candidates: HashMap<Vec<Token>, [Vec<usize>; 2]> = HashMap::new();
        let mut views: HashMap<usize, View> = HashMap::new();
        for u in units {
            let Op::Bind { value, .. } = ops[roots(plan, u)] else {
                continue;
            };
            let mut leaf = |o: Operand| match o.value {
                Value::Var(v) => var_pair.get(&v).copied(),
                Value::Input(s) => numbers.input(s, mirror),
                _ => None,
            };
            let mut key = |v: &View| {
                let (mut out, mut lanes) = (Vec::new(), Vec::new());
                tokens(v, &mut leaf, &mut out, &mut lanes);
                out
            };
            let Some(v) = view(lowered, &plan.writer, value, &mut key) else {
                continue;
            };
            let (mut shape, mut lanes) = (Vec::new(), Vec::new());
            tokens(&v, &mut leaf, &mut shape, &mut lanes);
            match lanes.first() {
                Some(&lane) if lanes.iter().all(|&l| l == lane) => {
                    candidates.entry(shape).or_default()[lane as usize].push(u);
                    views.insert(u, v);
                }
                _ => {}
            }
        }
        let mut matched: Vec<(usize, usize)> = candidates
            .into_values()
            .flat_map(|[a, b]| a.into_iter().zip(b).collect::<Vec<_>>())
            .collect();
        matched.sort_unstable();
        for (a, b) in matched {
            let n = numbers.fresh();
            let held = pairs.len() as u32;
            for (u, lane) in [(a, 0u8), (b, 1u8)] {
                if let Op::Bind { var, .. } = ops[roots(plan, u)] {
                    var_pair.insert(var, (n, lane));
                    plan.resident.insert(var, (held, lane));
                }
            }
            plan.trees.push(zip(&views[&a], &views[&b]));
            pairs.push((a, b));
        }
    }
    pairs
}

/// The printing order: the original order where nothing is paired; a pair
/// when both its units' operands are ready. Statements that write outputs
/// keep their order among themselves.
fn order(lowered: &Lowered, plan: &Plan, pairs: &[(usize, usize)]) -> Vec<Step> {
    let ops = &lowered.ops;
    let units = &plan.units;
    // Nodes: units, a pair's two units as one node.
    let mut node_of = (0..units.len()).collect::<Vec<usize>>();
    let mut steps: Vec<Step> = (0..units.len()).map(Step::One).collect();
    for (n, &(a, b)) in pairs.iter().enumerate() {
        steps[a] = Step::Two(a, b, n as u32);
        node_of[b] = a;
    }
    let mut definer: HashMap<u32, usize> = HashMap::new();
    for (u, unit) in units.iter().enumerate() {
        for v in defines(&ops[*unit.last().expect("a unit has its statement")]) {
            definer.insert(v, node_of[u]);
        }
    }
    let mut waiting = vec![0usize; units.len()];
    let mut users: Vec<Vec<usize>> = vec![Vec::new(); units.len()];
    let mut previous_output: Option<usize> = None;
    for (u, unit) in units.iter().enumerate() {
        let node = node_of[u];
        let mut deps: Vec<usize> = reads(lowered, unit)
            .iter()
            .filter_map(|v| definer.get(v).copied())
            .collect();
        if !matches!(
            ops[*unit.last().expect("a unit has its statement")],
            Op::Bind { .. }
        ) {
            deps.extend(previous_output);
            previous_output = Some(node);
        }
        deps.sort_unstable();
        deps.dedup();
        for d in deps {
            if d != node {
                waiting[node] += 1;
                users[d].push(node);
            }
        }
    }
    let mut ready: BinaryHeap<Reverse<usize>> = (0..units.len())
        .filter(|&u| node_of[u] == u && waiting[u] == 0)
        .map(Reverse)
        .collect();
    let mut out = Vec::with_capacity(units.len());
    while let Some(Reverse(node)) = ready.pop() {
        out.push(steps[node]);
        for &w in &users[node] {
            waiting[w] -= 1;
            if waiting[w] == 0 {
                ready.push(Reverse(w));
            }
        }
    }
    out
}

/// The held variables that some statement reads as a number: outside a
/// pair, or in a pair whose other lane does not read its partner.
fn scalar_reads(lowered: &Lowered, plan: &Plan) -> HashSet<u32> {
    let mut scalar = HashSet::new();
    let visit = |a: Operand, b: Option<Operand>, scalar: &mut HashSet<u32>| {
        let held = b.and_then(|b| plan.held(a, b));
        if held.is_none() {
            for o in [Some(a), b].into_iter().flatten() {
                if let Value::Var(v) = o.value {
                    if plan.resident.contains_key(&v) {
                        scalar.insert(v);
                    }
                }
            }
        }
    };
    for step in &plan.order {
        match *step {
            Step::One(u) => {
                for &k in &plan.units[u] {
                    for o in lowered.ops[k].operands() {
                        visit(o, None, &mut scalar);
                    }
                }
            }
            Step::Two(_, _, n) => {
                let mut leaves = Vec::new();
                plan.trees[n as usize].leaves(&mut leaves);
                for [x, y] in leaves {
                    visit(x, Some(y), &mut scalar);
                }
            }
        }
    }
    scalar
}

/// A unit's last operation (its statement).
fn roots(plan: &Plan, u: usize) -> usize {
    *plan.units[u].last().expect("a unit has its statement")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::schedule::Function;

    /// Statements of two mirrored coordinates (`q0`, `qd0` and `q1`, `qd1`)
    /// that differ only where their signs sit pair, each lane keeping its
    /// own signs: a sum negated whole on one lane and term by term on the
    /// other too (its lanes then differ in a zero's sign, as their
    /// statements do).
    #[test]
    fn statements_that_differ_in_signs_pair() {
        let o = |value| Operand {
            value,
            paren: false,
        };
        let (q, qd) = (
            |i| o(Value::Input(Symbol::Q(i))),
            |i| o(Value::Input(Symbol::Qd(i))),
        );
        let (t, k) = (|i| o(Value::Temp(i)), |x| o(Value::Literal(x)));
        let fused = |dst, form, x, y, c| Op::Fused { dst, form, x, y, c };
        let binary = |dst, op, a, b| Op::Binary { dst, op, a, b };
        let bind = |var, value| Op::Bind { var, value };
        let ops = vec![
            // qd0 + 2 q0 and qd1 - q1 2: a sign on a factor, factors swapped.
            fused(0, Fused::AddMul, k(2.0), q(0), qd(0)),
            bind(0, t(0)),
            fused(1, Fused::SubMul, q(1), k(2.0), qd(1)),
            bind(1, t(1)),
            // -(q0 qd0) and (-q1) qd1: a negation moved onto a factor.
            binary(2, Binary::Mul, q(0), qd(0)),
            Op::Neg { dst: 3, a: t(2) },
            bind(2, t(3)),
            Op::Neg { dst: 4, a: q(1) },
            binary(5, Binary::Mul, t(4), qd(1)),
            bind(3, t(5)),
            // q0 - qd0 and q1 + qd1: a sign on a term.
            binary(6, Binary::Sub, q(0), qd(0)),
            bind(4, t(6)),
            binary(7, Binary::Add, q(1), qd(1)),
            bind(5, t(7)),
            // -(q0 + qd0) and (-q1) - qd1: the sum's sign on lane 0 only.
            binary(8, Binary::Add, q(0), qd(0)),
            Op::Neg { dst: 9, a: t(8) },
            bind(6, t(9)),
            Op::Neg { dst: 10, a: q(1) },
            binary(11, Binary::Sub, t(10), qd(1)),
            bind(7, t(11)),
        ];
        let lowered = Lowered {
            function: Function::ALL[0],
            shapes: Vec::new(),
            ops,
            temps: 12,
        };
        let mirror: Mirror = vec![Some((1, 0)), Some((0, 1))];
        let plan = plan(&lowered, &mirror, true);
        let var = |u: usize| match lowered.ops[roots(&plan, u)] {
            Op::Bind { var, .. } => var,
            _ => unreachable!(),
        };
        let pairs: Vec<(u32, u32)> = plan
            .order
            .iter()
            .filter_map(|s| match *s {
                Step::Two(a, b, _) => Some((var(a), var(b))),
                Step::One(_) => None,
            })
            .collect();
        assert_eq!(pairs, vec![(0, 1), (2, 3), (4, 5), (6, 7)]);
        // Every pair keeps a sign on one lane: the factor `q1`, `-q0`, the
        // term `-qd0`, the sum on lane 0 and both terms on lane 1.
        let signs: Vec<Vec<[bool; 2]>> = plan
            .trees
            .iter()
            .map(|tree| {
                let mut out = Vec::new();
                fn walk(t: &Lanes, out: &mut Vec<[bool; 2]>) {
                    match t {
                        Lanes::Leaf(_, s) => out.push(*s),
                        Lanes::Node(_, args, s, _) => {
                            out.push(*s);
                            args.iter().for_each(|a| walk(a, out));
                        }
                    }
                }
                walk(tree, &mut out);
                out
            })
            .collect();
        assert!(
            signs.iter().all(|s| s.iter().any(|&l| l != [false; 2])),
            "{signs:?}"
        );
    }

    /// A base (frame 0, no coordinate) with two arms of two joints each
    /// (frames 1-2 and 3-4) and a one-joint head (5); a second pair of
    /// one-joint arms on the head's frame would pair too.
    #[test]
    fn sibling_limbs_of_the_same_shape_are_mirror_images() {
        let parents = [
            None,
            Some(0),
            Some(1),
            Some(0),
            Some(3),
            Some(0),
            Some(5),
            Some(5),
        ];
        let coordinates = [
            vec![],
            vec![0],
            vec![1],
            vec![2],
            vec![3],
            vec![4],
            vec![5],
            vec![6],
        ];
        let mut descriptions = vec![String::new(); 8];
        let mirror = mirror_coordinates(&parents, &coordinates, &descriptions, 7);
        assert_eq!(
            mirror,
            vec![
                Some((2, 0)),
                Some((3, 0)),
                Some((0, 1)),
                Some((1, 1)),
                None,
                Some((6, 0)),
                Some((5, 1)),
            ]
        );
        // Described differently, the arms still pair, after the frames
        // described alike: a third arm on the base like the second pairs
        // with it, the first stays alone.
        let parents = [None, Some(0), Some(0), Some(0)];
        let coordinates = [vec![], vec![0], vec![1], vec![2]];
        descriptions = vec!["".into(), "x".into(), "y".into(), "y".into()];
        let mirror = mirror_coordinates(&parents, &coordinates, &descriptions[..4], 3);
        assert_eq!(mirror, vec![None, Some((2, 0)), Some((1, 1))]);
        // And two arms described differently pair by their coarse shape.
        descriptions = vec!["".into(), "x".into(), "y".into(), "z".into()];
        let mirror = mirror_coordinates(&parents[..3], &coordinates[..3], &descriptions[..3], 2);
        assert_eq!(mirror, vec![Some((1, 0)), Some((0, 1))]);
    }
}
