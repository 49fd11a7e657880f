//! The expression grammar of scene files, parsed with `syn` into the graph.
//!
//! Accepted: number literals; `+ - * /` and unary minus; parentheses;
//! coordinates by name or as `q[i]`; velocities as `qd[i]` or `dot(name)`;
//! time `t`; `pi`; parameters by name; the functions `sin cos tan exp ln
//! sqrt abs sign step atan2(y, x) min(a, b) max(a, b) powi(x, n)` (also as
//! methods: `x.sin()`, `x.powi(2)`, `y.atan2(x)`, `a.min(b)`). Anything else is rejected with a message and a position.
//! Input is bounded in length, nesting and operator count before `syn` sees
//! it, so hostile input cannot exhaust the stack.

use std::collections::BTreeMap;

use proc_macro2::Span;
use syn::spanned::Spanned;
use syn::{BinOp, Expr, Lit, UnOp};

use crate::expr::{Func, Graph, Id, Node, Symbol};

/// Longest expression accepted, in bytes.
pub const MAX_LEN: usize = 16 * 1024;
/// Deepest bracket nesting accepted.
pub const MAX_DEPTH: usize = 48;
/// Most operators (and unary minus signs) in one expression.
pub const MAX_OPERATORS: usize = 500;
/// Largest integer power an expression may build up (by nesting `powi` or
/// by repeated products): the generated code multiplies powers out, so
/// `x^n` costs `n` multiplications (`powi(powi(x, 64), 64)` would be 4096).
pub const MAX_POWER: i64 = 256;

/// What a name in an expression stands for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Binding {
    /// A folded constant.
    Value(f64),
    /// A runtime parameter, by index.
    Runtime(u32),
}

/// The names an expression may use.
#[derive(Debug, Clone, Default)]
pub struct Scope {
    /// Coordinate names in order.
    pub coordinates: Vec<String>,
    /// Parameters.
    pub parameters: BTreeMap<String, Binding>,
    /// Whether velocities (`qd[i]`, `dot(x)`) may appear.
    pub allow_velocity: bool,
    /// Named points (markers) whose world coordinates an expression reads
    /// as `name.x`, `name.y`, `name.z`.
    pub points: BTreeMap<String, [Id; 3]>,
}

/// A parse error at a byte offset within the expression.
#[derive(Debug, Clone, PartialEq)]
pub struct ParseError {
    /// Byte offset in the expression text.
    pub offset: usize,
    /// What is wrong.
    pub message: String,
}

fn err<T>(offset: usize, message: impl Into<String>) -> Result<T, ParseError> {
    Err(ParseError {
        offset,
        message: message.into(),
    })
}

/// Reserved words that cannot name coordinates or parameters.
pub const RESERVED: &[&str] = &[
    "q", "qd", "t", "pi", "PI", "dot", "sin", "cos", "tan", "exp", "ln", "sqrt", "abs", "sign",
    "step", "atan2", "min", "max", "powi", "pow",
];

/// Parse `text` into the graph.
pub fn parse_expr(graph: &mut Graph, text: &str, scope: &Scope) -> Result<Id, ParseError> {
    precheck(text)?;
    let expr: Expr = syn::parse_str(text).map_err(|e| {
        let mut what = e.to_string();
        if what == "cannot parse string into token stream" {
            // syn's wording for a failure to split the text into tokens.
            what =
                "unbalanced brackets, an unclosed quote or a character outside the grammar".into();
        }
        // At the end of the whole text syn reports no position (the call
        // site); point just past the last token instead of at the start.
        let offset = if e.span().byte_range() == (0..0) && what.starts_with("unexpected end") {
            text.trim_end().len()
        } else {
            offset_of(text, e.span())
        };
        ParseError {
            offset,
            message: format!("syntax error: {what}"),
        }
    })?;
    let mut conv = Converter { graph, text, scope };
    conv.convert(&expr)
}

/// Bound the input before handing it to `syn`.
fn precheck(text: &str) -> Result<(), ParseError> {
    if text.len() > MAX_LEN {
        return err(0, format!("expression longer than {MAX_LEN} bytes"));
    }
    if text.trim().is_empty() {
        return err(0, "empty expression");
    }
    let mut depth = 0usize;
    let mut unary_run = 0usize;
    let mut operators = 0usize;
    let mut after_operand = false;
    for (i, ch) in text.char_indices() {
        if ch.is_whitespace() {
            continue;
        }
        match ch {
            '(' | '[' | '{' => {
                depth += 1;
                after_operand = false;
            }
            ')' | ']' | '}' => {
                depth = depth.saturating_sub(1);
                unary_run = 0;
                after_operand = true;
            }
            '+' | '-' | '*' | '/' | '!' | '&' | '|' | '^' | '%' | '<' | '>' | '=' | '.' | ',' => {
                operators += 1;
                if operators > MAX_OPERATORS {
                    return err(i, format!("more than {MAX_OPERATORS} operators"));
                }
                if !after_operand && (ch == '-' || ch == '!') {
                    unary_run += 1;
                }
                after_operand = false;
            }
            _ => {
                unary_run = 0;
                after_operand = true;
            }
        }
        if depth + unary_run > MAX_DEPTH {
            return err(
                i,
                format!("brackets and signs nested deeper than {MAX_DEPTH}"),
            );
        }
    }
    Ok(())
}

/// Byte offset in `text` of a span produced by parsing `text`.
fn offset_of(text: &str, span: Span) -> usize {
    let lc = span.start();
    let mut line = 1;
    let mut offset = 0;
    for (i, l) in text.split_inclusive('\n').enumerate() {
        if i + 1 == lc.line {
            return offset + l.char_indices().nth(lc.column).map_or(l.len(), |(b, _)| b);
        }
        offset += l.len();
        line += 1;
    }
    let _ = line;
    text.len()
}

fn suffix_error<T>(at: usize, suffix: &str) -> Result<T, ParseError> {
    err(
        at,
        format!("malformed number: `{suffix}` directly after the digits (write `*` to multiply)"),
    )
}

struct Converter<'a> {
    graph: &'a mut Graph,
    text: &'a str,
    scope: &'a Scope,
}

impl Converter<'_> {
    fn at(&self, node: &impl Spanned) -> usize {
        offset_of(self.text, node.span())
    }

    fn constant(&mut self, value: f64, at: usize) -> Result<Id, ParseError> {
        match self.graph.try_constant(value) {
            Some(id) => Ok(id),
            None => err(at, format!("constant is not finite ({value})")),
        }
    }

    /// Check that folding did not produce a non-finite constant.
    fn checked(&mut self, id: Id, at: usize) -> Result<Id, ParseError> {
        if self.graph.take_overflow() {
            return err(
                at,
                "constant subexpression is not finite (division by zero or overflow)",
            );
        }
        // A product, possibly scaled by a constant.
        let product = match self.graph.node(id) {
            Node::Sum(ts, k) if ts.len() == 1 && k.get() == 0.0 => ts[0].0,
            _ => id,
        };
        if let Node::Prod(fs) = self.graph.node(product) {
            let power = fs.iter().map(|&(_, e)| i64::from(e).abs()).max();
            if let Some(p) = power.filter(|&p| p > MAX_POWER) {
                return err(
                    at,
                    format!(
                        "the powers here combine to an exponent of {p}; at most {MAX_POWER} is allowed"
                    ),
                );
            }
        }
        Ok(id)
    }

    fn convert(&mut self, e: &Expr) -> Result<Id, ParseError> {
        let at = self.at(e);
        match e {
            Expr::Lit(l) => match &l.lit {
                // Rust reads `2pi` or `1e` as a number with a suffix.
                Lit::Float(f) if !f.suffix().is_empty() => suffix_error(at, f.suffix()),
                Lit::Int(i) if !i.suffix().is_empty() => suffix_error(at, i.suffix()),
                Lit::Float(f) => {
                    let v: f64 = f.base10_parse().or_else(|_| err(at, "malformed number"))?;
                    self.constant(v, at)
                }
                Lit::Int(i) => {
                    let v: f64 = i
                        .base10_digits()
                        .parse()
                        .or_else(|_| err(at, "malformed number"))?;
                    self.constant(v, at)
                }
                _ => err(at, "only numbers are allowed as literals"),
            },
            Expr::Paren(p) => self.convert(&p.expr),
            Expr::Group(g) => self.convert(&g.expr),
            Expr::Unary(u) => match u.op {
                UnOp::Neg(_) => {
                    let a = self.convert(&u.expr)?;
                    Ok(self.graph.neg(a))
                }
                _ => err(at, "unsupported unary operator (only `-` is allowed)"),
            },
            Expr::Binary(b) => {
                let l = self.convert(&b.left)?;
                let r = self.convert(&b.right)?;
                let op_at = self.at(&b.op);
                let id = match b.op {
                    BinOp::Add(_) => self.graph.add(l, r),
                    BinOp::Sub(_) => self.graph.sub(l, r),
                    BinOp::Mul(_) => self.graph.mul(l, r),
                    BinOp::Div(_) => {
                        if self.graph.is_const(r, 0.0) {
                            return err(op_at, "division by zero");
                        }
                        self.graph.div(l, r)
                    }
                    BinOp::BitXor(_) => {
                        return err(
                            op_at,
                            "`^` is not a power here: write `powi(x, n)` or `x.powi(n)`",
                        )
                    }
                    _ => return err(op_at, "unsupported operator (allowed: + - * /)"),
                };
                self.checked(id, op_at)
            }
            Expr::Path(p) => {
                let Some(ident) = p.path.get_ident() else {
                    return err(at, "expected a name");
                };
                self.name(&ident.to_string(), at)
            }
            Expr::Index(ix) => self.index(ix, at),
            Expr::Field(f) => self.point_coordinate(f, at),
            Expr::Call(c) => {
                let Expr::Path(p) = &*c.func else {
                    return err(at, "only named functions can be called");
                };
                let Some(ident) = p.path.get_ident() else {
                    return err(at, "expected a function name");
                };
                let args: Vec<&Expr> = c.args.iter().collect();
                self.call(&ident.to_string(), &args, at)
            }
            Expr::MethodCall(m) => {
                if m.turbofish.is_some() {
                    return err(at, "generic arguments are not allowed");
                }
                let mut args: Vec<&Expr> = vec![&m.receiver];
                args.extend(m.args.iter());
                self.call(&m.method.to_string(), &args, self.at(&m.method))
            }
            _ => err(at, "unsupported syntax in expression"),
        }
    }

    fn name(&mut self, name: &str, at: usize) -> Result<Id, ParseError> {
        if let Some(i) = self.scope.coordinates.iter().position(|c| c == name) {
            return Ok(self.graph.q(i));
        }
        if let Some(b) = self.scope.parameters.get(name) {
            return match *b {
                Binding::Value(v) => self.constant(v, at),
                Binding::Runtime(i) => Ok(self.graph.symbol(Symbol::Param(i))),
            };
        }
        match name {
            "t" => Ok(self.graph.symbol(Symbol::Time)),
            "pi" | "PI" => self.constant(std::f64::consts::PI, at),
            "q" | "qd" => err(at, format!("`{name}` must be indexed, as in `{name}[0]`")),
            _ => err(at, format!("undefined symbol `{name}`")),
        }
    }

    /// `marker.x` (`.y`, `.z`): a world coordinate of a marker.
    fn point_coordinate(&mut self, f: &syn::ExprField, at: usize) -> Result<Id, ParseError> {
        let base = match &*f.base {
            Expr::Path(p) => p.path.get_ident().map(|i| i.to_string()),
            _ => None,
        };
        let Some(base) = base else {
            return err(
                at,
                "only a marker's coordinates can be read with `.`, as in `tip.x`",
            );
        };
        let Some(point) = self.scope.points.get(&base) else {
            let known: Vec<&str> = self.scope.points.keys().map(String::as_str).collect();
            return err(
                at,
                format!(
                    "no marker `{base}` above (markers: {})",
                    if known.is_empty() {
                        "none".to_owned()
                    } else {
                        known.join(", ")
                    }
                ),
            );
        };
        let axis = match &f.member {
            syn::Member::Named(m) => m.to_string(),
            syn::Member::Unnamed(i) => i.index.to_string(),
        };
        match axis.as_str() {
            "x" => Ok(point[0]),
            "y" => Ok(point[1]),
            "z" => Ok(point[2]),
            other => err(
                at,
                format!("a marker has coordinates `x`, `y` and `z`, not `{other}`"),
            ),
        }
    }

    fn velocity(&mut self, i: usize, at: usize) -> Result<Id, ParseError> {
        if !self.scope.allow_velocity {
            return err(
                at,
                "velocities are not allowed here (only in kinetic energy and dissipation)",
            );
        }
        Ok(self.graph.qd(i))
    }

    fn index(&mut self, ix: &syn::ExprIndex, at: usize) -> Result<Id, ParseError> {
        let Expr::Path(p) = &*ix.expr else {
            return err(at, "only `q[i]` and `qd[i]` can be indexed");
        };
        let base = p
            .path
            .get_ident()
            .map(|i| i.to_string())
            .unwrap_or_default();
        let idx_at = self.at(&ix.index);
        let i = match &*ix.index {
            Expr::Lit(syn::ExprLit {
                lit: Lit::Int(n), ..
            }) if n.suffix().is_empty() => n
                .base10_parse::<usize>()
                .or_else(|_| err(idx_at, "bad index"))?,
            _ => return err(idx_at, "index must be an integer literal"),
        };
        let n = self.scope.coordinates.len();
        if i >= n {
            return err(
                idx_at,
                format!("coordinate {base}[{i}] is not declared (the scene has {n} coordinates)"),
            );
        }
        match base.as_str() {
            "q" => Ok(self.graph.q(i)),
            "qd" => self.velocity(i, at),
            _ => err(at, "only `q[i]` and `qd[i]` can be indexed"),
        }
    }

    fn call(&mut self, name: &str, args: &[&Expr], at: usize) -> Result<Id, ParseError> {
        let arity = match name {
            "atan2" | "min" | "max" | "powi" | "pow" => 2,
            "dot" => 1,
            _ if Func::from_name(name).is_some() => 1,
            _ => return err(at, format!("unknown function `{name}`")),
        };
        if args.len() != arity {
            return err(
                at,
                format!("`{name}` takes {arity} argument(s), found {}", args.len()),
            );
        }
        if name == "dot" {
            let a_at = self.at(args[0]);
            let coord = match args[0] {
                Expr::Path(p) => p.path.get_ident().map(|i| i.to_string()),
                _ => None,
            };
            let Some(i) = coord.and_then(|c| self.scope.coordinates.iter().position(|x| *x == c))
            else {
                return err(a_at, "`dot` takes the name of a coordinate");
            };
            return self.velocity(i, at);
        }
        if name == "powi" || name == "pow" {
            let base = self.convert(args[0])?;
            let e_at = self.at(args[1]);
            let exponent = self.convert(args[1])?;
            let Some(n) = self.graph.as_const(exponent) else {
                return err(e_at, "the exponent must be a constant integer");
            };
            if n.fract() != 0.0 || n.abs() > 64.0 {
                return err(e_at, "the exponent must be an integer between -64 and 64");
            }
            if n < 0.0 && self.graph.is_const(base, 0.0) {
                return err(at, "zero raised to a negative power");
            }
            let id = self.graph.powi(base, n as i32);
            return self.checked(id, at);
        }
        if arity == 2 {
            let a = self.convert(args[0])?;
            let b = self.convert(args[1])?;
            return Ok(match name {
                "min" => self.graph.min(a, b),
                "max" => self.graph.max(a, b),
                // `powi` and `pow` returned above.
                _ => self.graph.atan2(a, b),
            });
        }
        let Some(f) = Func::from_name(name) else {
            return err(at, format!("unknown function `{name}`"));
        };
        let a = self.convert(args[0])?;
        if let Some(x) = self.graph.as_const(a) {
            if !f.apply(x).is_finite() {
                return err(at, format!("`{name}({x})` is not finite"));
            }
        }
        Ok(self.graph.call(f, a))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scope() -> Scope {
        let mut parameters = BTreeMap::new();
        parameters.insert("m".to_string(), Binding::Value(2.0));
        parameters.insert("k".to_string(), Binding::Runtime(0));
        Scope {
            coordinates: vec!["x".into(), "y".into()],
            parameters,
            allow_velocity: true,
            points: BTreeMap::new(),
        }
    }

    fn value(text: &str, q: [f64; 2], qd: [f64; 2]) -> f64 {
        let mut g = Graph::new();
        let id = parse_expr(&mut g, text, &scope()).unwrap();
        g.eval(&[id], &|s| match s {
            Symbol::Q(i) => q[i as usize],
            Symbol::Qd(i) => qd[i as usize],
            Symbol::Time => 0.5,
            Symbol::Param(_) => 3.0,
            Symbol::Qdd(_) => f64::NAN,
        })[0]
    }

    #[test]
    fn evaluates_the_grammar() {
        let (x, y, xd) = (0.3f64, -1.2f64, 0.7f64);
        let got = value(
            "0.5*m*dot(x)*qd[0] - k*cos(q[1]) + x.powi(3)/y + atan2(y, x) + sqrt(2.0) * t + pi + y.sin() + exp(ln(2))",
            [x, y],
            [xd, 0.0],
        );
        let want = 0.5 * 2.0 * xd * xd - 3.0 * y.cos()
            + x.powi(3) / y
            + y.atan2(x)
            + 2f64.sqrt() * 0.5
            + std::f64::consts::PI
            + y.sin()
            + 2.0;
        assert!((got - want).abs() < 1e-13, "{got} vs {want}");
    }

    #[test]
    fn evaluates_the_switches() {
        for (x, y) in [(0.3f64, -1.2f64), (-2.5, 0.4), (1.5, 1.5), (0.0, -0.0)] {
            let got = value(
                "abs(x) + 2*sign(y) + 3*step(x - y) + 5*min(x, y) + 7*max(x, y) + 11*y.abs() + 13*y.min(x) + 17*x.max(-1)",
                [x, y],
                [0.0, 0.0],
            );
            // Rust's signum is 1 at +0, the grammar's sign 0.
            let sign = |v: f64| if v == 0.0 { 0.0 } else { v.signum() };
            let want = x.abs()
                + 2.0 * sign(y)
                + 3.0 * (1.0 + sign(x - y)) / 2.0
                + 5.0 * x.min(y)
                + 7.0 * x.max(y)
                + 11.0 * y.abs()
                + 13.0 * y.min(x)
                + 17.0 * x.max(-1.0);
            assert!((got - want).abs() < 1e-13, "at ({x}, {y}): {got} vs {want}");
        }
        // At the switch: sign 0, step 1/2 (so step(x) + step(-x) = 1).
        assert_eq!(value("sign(x)", [0.0, 1.0], [0.0; 2]), 0.0);
        assert_eq!(value("step(x)", [0.0, 1.0], [0.0; 2]), 0.5);
        assert_eq!(
            value("step(x - y) + step(y - x)", [0.25, 0.25], [0.0; 2]),
            1.0
        );
    }

    /// Central differences of the parsed expression against its symbolic
    /// partial derivative in `x`, away from the switches.
    #[test]
    fn derivatives_of_the_switches_match_central_differences() {
        let mut g = Graph::new();
        let f = parse_expr(
            &mut g,
            "abs(x*y - 0.1)*sin(x) + sign(y)*x*x + step(x - 0.5)*x*x*x + min(x*x, y) + max(exp(x), y*y) + x.abs().sqrt()",
            &scope(),
        )
        .unwrap();
        let dfx = g.diff(f, Symbol::Q(0));
        let dfy = g.diff(f, Symbol::Q(1));
        let at = |g: &Graph, id: Id, x: f64, y: f64| {
            g.eval(&[id], &|s| match s {
                Symbol::Q(0) => x,
                Symbol::Q(_) => y,
                _ => 0.0,
            })[0]
        };
        let h = 1e-6;
        // Points on either side of every switch.
        for (x, y) in [
            (0.7, -0.4),
            (-0.9, 1.3),
            (0.2, 0.9),
            (1.4, 3.0),
            (-1.1, -2.0),
        ] {
            let fd_x = (at(&g, f, x + h, y) - at(&g, f, x - h, y)) / (2.0 * h);
            let fd_y = (at(&g, f, x, y + h) - at(&g, f, x, y - h)) / (2.0 * h);
            let (ex, ey) = (at(&g, dfx, x, y), at(&g, dfy, x, y));
            assert!(
                (fd_x - ex).abs() < 1e-7 * (1.0 + ex.abs()),
                "d/dx at ({x}, {y}): {fd_x} vs {ex}"
            );
            assert!(
                (fd_y - ey).abs() < 1e-7 * (1.0 + ey.abs()),
                "d/dy at ({x}, {y}): {fd_y} vs {ey}"
            );
        }
        // At a tie, min's derivative is the mean of the two sides'.
        let m = parse_expr(&mut g, "min(x, 2*y)", &scope()).unwrap();
        let dm = g.diff(m, Symbol::Q(0));
        assert_eq!(at(&g, dm, 1.0, 0.5), 0.5);
    }

    #[test]
    fn switches_of_constants_fold() {
        let mut g = Graph::new();
        let mut folded = |text: &str| {
            let id = parse_expr(&mut g, text, &scope()).unwrap();
            g.as_const(id)
        };
        assert_eq!(folded("abs(-m)"), Some(2.0));
        assert_eq!(folded("sign(m - 2)"), Some(0.0));
        assert_eq!(folded("step(m - 2) + sign(-1e-300)"), Some(-0.5));
        assert_eq!(
            folded("min(0.1, 0.3) + max(-1e20, 1e-20)"),
            Some(0.1 + 1e-20)
        );
        assert_eq!(folded("m.max(3)"), Some(3.0));
        assert_eq!(folded("min(x, y)"), None);
    }

    fn error(text: &str) -> ParseError {
        let mut g = Graph::new();
        let mut s = scope();
        s.allow_velocity = false;
        parse_expr(&mut g, text, &s).unwrap_err()
    }

    #[test]
    fn errors_point_at_the_problem() {
        let e = error("m * zz + 1");
        assert_eq!(e.offset, 4, "{e:?}");
        assert!(e.message.contains("undefined symbol `zz`"));
        let e = error("x + q[7]");
        assert_eq!(e.offset, 6);
        assert!(e.message.contains("not declared"), "{e:?}");
        let e = error("x + qd[0]");
        assert!(e.message.contains("velocities are not allowed"));
        let e = error("x ^ 2");
        assert_eq!(e.offset, 2);
        let e = error("1e999 * x");
        assert!(e.message.contains("not finite"));
        let e = error("x / (m - 2)");
        assert!(e.message.contains("division by zero"));
        let e = error("ln(0.0)");
        assert!(e.message.contains("not finite"));
        let e = error("foo(x)");
        assert!(e.message.contains("unknown function"));
        let e = error("min(x)");
        assert!(e.message.contains("`min` takes 2 argument(s)"), "{e:?}");
        let e = error("x.step(1)");
        assert!(e.message.contains("`step` takes 1 argument(s)"), "{e:?}");
        let e = error("{ x }");
        assert!(e.message.contains("unsupported"));
        let e = error("x +");
        assert!(e.message.contains("syntax error"));
    }

    #[test]
    fn hostile_input_is_bounded() {
        let deep = format!("{}x{}", "(".repeat(1000), ")".repeat(1000));
        assert!(error(&deep).message.contains("nested"));
        let long = "x+".repeat(5000) + "x";
        assert!(error(&long).message.contains("operators"));
        let negs = "-".repeat(300) + "x";
        assert!(error(&negs).message.contains("nested"));
    }
}
