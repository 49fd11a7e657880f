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
//!   trees are the same and every operand that belongs to a pair (an input
//!   of mirrored coordinates, a sine of one, a paired statement) is lane 0 of
//!   that pair in one and lane 1 in the other; other operands may be
//!   anything. Then the statements are ordered again (each pair where both
//!   its statements' operands are ready, otherwise the original order).

use std::cmp::Reverse;
use std::collections::{BinaryHeap, HashMap, HashSet};

use super::{Binary, Fused, Lowered, Op, Operand, Value};
use crate::expr::Symbol;

/// Per coordinate, its mirror image and its lane (`0` or `1`), if any.
pub type Mirror = Vec<Option<(u32, u8)>>;

/// The mirror images among the coordinates of a kinematic tree given by
/// each frame's parent, own coordinates and a description of its placement
/// (`nq` coordinates in all). Sibling subtrees pair first where their
/// frames' descriptions agree all the way down (mirror images written
/// alike), then, among the others, where only their coordinates per frame
/// and children do.
pub fn mirror_coordinates(
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

/// A token of a statement's shape for pairing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
enum Token {
    Binary(u8),
    Fused(u8),
    Neg,
    /// An operand of a pair (its number).
    Pair(u32),
    /// Another operand.
    Any,
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
        for u in units {
            let Op::Bind { value, .. } = ops[roots(plan, u)] else {
                continue;
            };
            let mut tokens = Vec::new();
            let mut lanes = Vec::new();
            let mut leaf = |o: Operand| match o.value {
                Value::Var(v) => var_pair.get(&v).copied(),
                Value::Input(s) => numbers.input(s, mirror),
                _ => None,
            };
            if !shape(
                lowered,
                &plan.writer,
                value,
                &mut leaf,
                &mut tokens,
                &mut lanes,
            ) {
                continue;
            }
            match lanes.first() {
                Some(&lane) if lanes.iter().all(|&l| l == lane) => {
                    candidates.entry(tokens).or_default()[lane as usize].push(u);
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
            pairs.push((a, b));
        }
    }
    pairs
}

/// The tokens of an operand's tree and the lanes of its operands that
/// belong to pairs (`leaf`); `false` where the tree has an operation that
/// has no two-lane form.
fn shape(
    lowered: &Lowered,
    writer: &[usize],
    o: Operand,
    leaf: &mut dyn FnMut(Operand) -> Option<(u32, u8)>,
    tokens: &mut Vec<Token>,
    lanes: &mut Vec<u8>,
) -> bool {
    if let Value::Temp(t) = o.value {
        let op = &lowered.ops[writer[t as usize]];
        let token = match op {
            Op::Binary { op, .. } => Token::Binary(binary_tag(*op)),
            Op::Fused { form, .. } => Token::Fused(fused_tag(*form)),
            Op::Neg { .. } => Token::Neg,
            _ => return false,
        };
        tokens.push(token);
        return op
            .operands()
            .into_iter()
            .all(|x| shape(lowered, writer, x, leaf, tokens, lanes));
    }
    match leaf(o) {
        Some((n, lane)) => {
            tokens.push(Token::Pair(n));
            lanes.push(lane);
        }
        None => tokens.push(Token::Any),
    }
    true
}

fn binary_tag(op: Binary) -> u8 {
    match op {
        Binary::Add => 0,
        Binary::Sub => 1,
        Binary::Mul => 2,
        Binary::Div => 3,
    }
}

fn fused_tag(form: Fused) -> u8 {
    match form {
        Fused::AddMul => 0,
        Fused::MulAdd => 1,
        Fused::SubMul => 2,
        Fused::MulSub => 3,
    }
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
            Step::Two(a, b, _) => {
                let (ra, rb) = (roots(plan, a), roots(plan, b));
                let mut stack =
                    vec![(lowered.ops[ra].operands()[0], lowered.ops[rb].operands()[0])];
                while let Some((x, y)) = stack.pop() {
                    match (x.value, y.value) {
                        (Value::Temp(s), Value::Temp(t)) => {
                            let (p, q) = (
                                &lowered.ops[plan.writer[s as usize]],
                                &lowered.ops[plan.writer[t as usize]],
                            );
                            stack.extend(p.operands().into_iter().zip(q.operands()));
                        }
                        _ => visit(x, Some(y), &mut scalar),
                    }
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
