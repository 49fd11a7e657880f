//! Stage 7, emit: one Rust module per scene, built with `quote` from the
//! functions of the schedule stage, one program each
//! ([`crate::schedule::functions`]; never from scene text), and formatted
//! with `prettyplease`. The module names the runtime crate (its `Model`
//! trait, `math` and `nalgebra` re-export) by the path the builder was given.

use proc_macro2::{Literal, TokenStream};
use quote::{format_ident, quote};

use crate::expr::Symbol;
use crate::model::{Model, Precision};
use crate::schedule::{
    lower, mirror_of, plan, printed, Binary, Code, Fused, Inputs, Lowered, Mirror, Op, OpCount,
    Operand, OutputSpec, Plan, Print, Program, Scheduled, Shape, Step, Stmt, Value,
};

/// Operation counts of one emitted function.
#[derive(Debug, Clone, PartialEq)]
pub struct FunctionReport {
    /// Function name.
    pub name: &'static str,
    /// The marker, for a per-marker function's program.
    pub marker: Option<String>,
    /// Its operations.
    pub ops: OpCount,
}

/// The emitted module of one scene.
#[derive(Debug, Clone)]
pub struct Emitted {
    /// Formatted source, `@generated` header first.
    pub source: String,
    /// Per-function operation counts.
    pub functions: Vec<FunctionReport>,
}

/// Name of the model struct for a scene name: `double_pendulum` -> `DoublePendulum`.
pub fn struct_name(scene: &str) -> String {
    scene
        .split('_')
        .filter(|p| !p.is_empty())
        .map(|p| {
            let mut c = p.chars();
            c.next()
                .map(|f| f.to_ascii_uppercase().to_string() + c.as_str())
                .unwrap_or_default()
        })
        .collect()
}

struct Emitter<'a> {
    model: &'a Model,
    /// The coordinates of mirror-image limbs, computed on two lanes.
    mirror: Mirror,
    reports: Vec<FunctionReport>,
    perturbation: Option<&'a CoefficientPerturbation>,
    perturbed: bool,
}

/// A deliberate error in one emitted coefficient, for tests only: it proves
/// that the validation against CasADi catches a wrong term in the generated
/// code itself (see `Builder::perturb_coefficient`).
#[derive(Debug, Clone, PartialEq)]
pub struct CoefficientPerturbation {
    /// Scene whose module is perturbed.
    pub scene: String,
    /// Emitted function (`mass_matrix`, `bias`, ...).
    pub function: String,
    /// Which coefficient of that function's program: the `index`-th
    /// coefficient of a sum, counting statements in order, then outputs.
    pub index: usize,
    /// The coefficient is multiplied by `1 + relative`.
    pub relative: f64,
}

/// Multiply the `index`-th sum coefficient of `p` by `factor`; `false` when
/// the program has fewer coefficients.
fn scale_coefficient(p: &mut Program, index: usize, factor: f64) -> bool {
    fn visit(c: &mut Code, left: &mut usize, factor: f64) -> bool {
        match c {
            Code::Sum { terms, .. } => terms.iter_mut().any(|(k, t)| {
                if *left == 0 {
                    *k *= factor;
                    return true;
                }
                *left -= 1;
                visit(t, left, factor)
            }),
            Code::Prod { num, den } => num
                .iter_mut()
                .chain(den.iter_mut())
                .any(|f| visit(f, left, factor)),
            Code::Call(_, x) => visit(x, left, factor),
            Code::Atan2(y, x) => visit(y, left, factor) || visit(x, left, factor),
            Code::Var(_) | Code::Sym(_) | Code::Lit(_) => false,
        }
    }
    let mut left = index;
    p.stmts
        .iter_mut()
        .map(|s| match s {
            Stmt::Let { value, .. } => value,
            Stmt::SinCos { arg, .. } => arg,
        })
        .chain(p.outputs.iter_mut())
        .any(|c| visit(c, &mut left, factor))
}

/// The literal `x` in `precision`: for `f32` the shortest text of the
/// nearest `f32`, so that the compiler rounds once.
fn lit(x: f64, precision: Precision) -> TokenStream {
    let text = match precision {
        Precision::F64 => format!("{:?}", x.abs()),
        Precision::F32 => format!("{:?}", x.abs() as f32),
    };
    let l: Literal = text
        .parse()
        .unwrap_or_else(|_| Literal::f64_unsuffixed(x.abs()));
    if x.is_sign_negative() && x != 0.0 {
        quote!(-#l)
    } else {
        quote!(#l)
    }
}

fn usize_lit(i: usize) -> Literal {
    Literal::usize_unsuffixed(i)
}

/// Programs with at most this many statements are emitted as one `let` per
/// statement (see `Emitter::function`).
const FLAT_STATEMENTS: usize = 512;

/// Variables per declaration in longer programs.
const DECLARATION_GROUP: usize = 64;

/// Functions with at least this many operations run their statements
/// through the runtime's `math::dispatch` (compiled twice on x86-64, the
/// copy for the processor chosen at run time): below it the call that
/// selects the copy costs about what AVX saves.
const DISPATCHED_OPERATIONS: usize = 128;

/// Binding strength of printed Rust expressions, for the parentheses that
/// the association of the lowered operations needs (on top of those the
/// lowering asks for).
const SUM: u8 = 1;
const PRODUCT: u8 = 2;
const UNARY: u8 = 3;
const ATOM: u8 = 4;

/// An argument's name, `_name` where the function does not use it.
fn argument(name: &str, used: bool) -> proc_macro2::Ident {
    if used {
        format_ident!("{}", name)
    } else {
        format_ident!("_{}", name)
    }
}

/// `v<n>`.
fn var(v: u32) -> proc_macro2::Ident {
    format_ident!("v{}", v)
}

/// Prints the operations of one lowered function as Rust.
struct Printer<'e, 'a> {
    emitter: &'e Emitter<'a>,
    /// The function's outputs.
    outputs: &'static [OutputSpec],
    /// What it reads.
    inputs: Inputs,
    /// Output names.
    names: Vec<proc_macro2::Ident>,
    /// The text of each intermediate (taken by its one reader) and its
    /// binding strength.
    texts: Vec<Option<(TokenStream, u8)>>,
    /// `let ` in flat programs, nothing where variables are declared first.
    bind: TokenStream,
}

impl Printer<'_, '_> {
    /// An operand's text, parenthesised where the lowering asks for it or
    /// where it binds less strongly than `need`.
    fn operand(&mut self, o: Operand, need: u8) -> TokenStream {
        let (text, strength) = match o.value {
            Value::Var(v) => {
                let v = var(v);
                (quote!(#v), ATOM)
            }
            Value::Input(s) => (self.emitter.input(s, self.inputs), ATOM),
            Value::Literal(x) => {
                let strength = if x < 0.0 { UNARY } else { ATOM };
                (self.emitter.lit(x), strength)
            }
            Value::Temp(t) => self.texts[t as usize]
                .take()
                .expect("an intermediate is read once, after it is written"),
        };
        if o.paren || strength < need {
            quote!((#text))
        } else {
            text
        }
    }

    fn set(&mut self, dst: u32, text: TokenStream, strength: u8) {
        self.texts[dst as usize] = Some((text, strength));
    }

    /// The statement an operation prints, if any (intermediates are printed
    /// where they are read), and the value a returned output ends with.
    fn op(&mut self, op: &Op, out: &mut TokenStream, tail: &mut TokenStream) {
        let bind = self.bind.clone();
        match op {
            Op::Fused { dst, form, x, y, c } => {
                let x = self.operand(*x, PRODUCT);
                let y = self.operand(*y, PRODUCT + 1);
                let c = self.operand(*c, SUM);
                let name = format_ident!("{}", form.name());
                let args = match form {
                    Fused::AddMul | Fused::SubMul => quote!(#c, #x, #y),
                    Fused::MulAdd | Fused::MulSub => quote!(#x, #y, #c),
                };
                self.set(*dst, quote!(math::#name(#args)), ATOM);
            }
            Op::Binary { dst, op, a, b } => {
                let (level, sign) = match op {
                    Binary::Add => (SUM, quote!(+)),
                    Binary::Sub => (SUM, quote!(-)),
                    Binary::Mul => (PRODUCT, quote!(*)),
                    Binary::Div => (PRODUCT, quote!(/)),
                };
                let x = self.operand(*a, level);
                let y = self.operand(*b, level + 1);
                self.set(*dst, quote!(#x #sign #y), level);
            }
            Op::Neg { dst, a } => {
                let a = self.operand(*a, UNARY);
                self.set(*dst, quote!(-#a), UNARY);
            }
            Op::Call { dst, f, a } => {
                let name = format_ident!("{}", f.name());
                let a = self.operand(*a, SUM);
                self.set(*dst, quote!(math::#name(#a)), ATOM);
            }
            Op::Atan2 { dst, y, x } => {
                let (y, x) = (self.operand(*y, SUM), self.operand(*x, SUM));
                self.set(*dst, quote!(math::atan2(#y, #x)), ATOM);
            }
            Op::Bind { var: v, value } => {
                let (v, e) = (var(*v), self.operand(*value, SUM));
                out.extend(quote!(#bind #v = #e;));
            }
            Op::SinCos { sin, cos, arg } => {
                let (s, c) = (var(*sin), var(*cos));
                let a = self.operand(*arg, SUM);
                out.extend(quote!(#bind (#s, #c) = math::sin_cos(#a);));
            }
            Op::SinCosArray(batch) => {
                let pairs = batch.iter().map(|(s, c, _)| {
                    let (s, c) = (var(*s), var(*c));
                    quote!((#s, #c))
                });
                let pairs: Vec<TokenStream> = pairs.collect();
                let args: Vec<TokenStream> = batch
                    .iter()
                    .map(|(_, _, a)| self.operand(*a, SUM))
                    .collect();
                out.extend(quote!(#bind [#(#pairs),*] = math::sin_cos_array([#(#args),*]);));
            }
            Op::Zero { output } => {
                let name = &self.names[*output];
                out.extend(quote!(*#name = SMatrix::zeros();));
            }
            Op::Store {
                output,
                row,
                col,
                value,
            } => {
                let e = self.operand(*value, SUM);
                let name = &self.names[*output];
                let (i, j) = (usize_lit(*row), usize_lit(*col));
                match self.outputs[*output].shape {
                    Shape::Scalar => *tail = e,
                    Shape::Vector(_) => out.extend(quote!(#name[#i] = #e;)),
                    Shape::Matrix { .. } => out.extend(quote!(#name[(#i, #j)] = #e;)),
                }
            }
            Op::Mirror { output, row, col } => {
                let name = &self.names[*output];
                let (i, j) = (usize_lit(*row), usize_lit(*col));
                out.extend(quote!(#name[(#j, #i)] = #name[(#i, #j)];));
            }
        }
    }
}
impl Printer<'_, '_> {
    /// Two units' statements as one, on two lanes: `p<n> = ...;`, then the
    /// lanes that other statements read as numbers.
    fn pair(
        &mut self,
        lowered: &Lowered,
        plan: &Plan,
        (a, b): (usize, usize),
        n: u32,
        out: &mut TokenStream,
    ) {
        let bind = self.bind.clone();
        let p = pair(n);
        let [ra, rb] = [a, b].map(|u| &lowered.ops[*plan.units[u].last().expect("a statement")]);
        let (Op::Bind { var: va, .. }, Op::Bind { var: vb, .. }) = (ra, rb) else {
            unreachable!("only statements that bind a variable are paired");
        };
        let e = self.lanes(&printed(plan, &plan.trees[n as usize]));
        out.extend(quote!(#bind #p = #e;));
        for (v, lane) in [(*va, quote!(lo)), (*vb, quote!(hi))] {
            if plan.scalar.contains(&v) {
                let v = var(v);
                out.extend(quote!(#bind #v = #p.#lane();));
            }
        }
    }

    /// The two-lane expression of a paired statement, printed as
    /// [`printed`] resolved its signs.
    fn lanes(&mut self, e: &Print) -> TokenStream {
        match e {
            Print::Pair(n) => {
                let p = pair(*n);
                quote!(#p)
            }
            Print::Pack([a, b], signs) => {
                let [x, y] = [(*a, signs[0]), (*b, signs[1])].map(|(o, negated)| match o.value {
                    Value::Literal(x) if negated => self.emitter.lit(-x),
                    _ if negated => {
                        let x = self.operand(o, ATOM);
                        quote!(-#x)
                    }
                    _ => self.operand(o, SUM),
                });
                quote!(math::F2::new(#x, #y))
            }
            Print::Apply(call, args) => {
                let f = format_ident!("{}", call.name());
                let args: Vec<TokenStream> = args.iter().map(|a| self.lanes(a)).collect();
                quote!(math::F2::#f(#(#args),*))
            }
            Print::Negated(signs, e) => {
                let e = self.lanes(e);
                match signs {
                    [true, false] => quote!(math::F2::negated_lo(#e)),
                    [false, true] => quote!(math::F2::negated_hi(#e)),
                    _ => quote!(math::F2::negated(#e)),
                }
            }
        }
    }
}

/// The two-lane variable of pair `n`.
fn pair(n: u32) -> proc_macro2::Ident {
    format_ident!("p{}", n)
}

impl Emitter<'_> {
    fn lit(&self, x: f64) -> TokenStream {
        lit(x, self.model.precision)
    }

    /// The scalar type, `f64` or `f32`.
    fn real(&self) -> proc_macro2::Ident {
        format_ident!("{}", self.model.precision.rust_type())
    }

    /// An input as a function reading `inputs` reads it (`Symbol::Qdd` is
    /// the forces `f` of a function of [`Inputs::Forces`] and the actuator
    /// inputs `tau` of one of [`Inputs::Actuation`]).
    fn input(&self, s: Symbol, inputs: Inputs) -> TokenStream {
        match s {
            Symbol::Q(i) => {
                let i = usize_lit(i as usize);
                quote!(q[#i])
            }
            Symbol::Qd(i) => {
                let i = usize_lit(i as usize);
                quote!(qd[#i])
            }
            Symbol::Qdd(i) => {
                let i = usize_lit(i as usize);
                match inputs {
                    Inputs::Forces => quote!(f[#i]),
                    Inputs::Actuation => quote!(tau[#i]),
                    _ => quote!(qdd[#i]),
                }
            }
            Symbol::Time => quote!(t),
            Symbol::Param(i) => {
                let p = format_ident!("{}", self.model.runtime_parameters[i as usize].name);
                quote!(self.#p)
            }
        }
    }

    /// Record the operation count of function `name` (of one marker's
    /// program), and apply the test-only perturbation when it targets this
    /// function.
    fn record(&mut self, name: &'static str, marker: Option<String>, p: &mut Program) {
        self.reports.push(FunctionReport {
            name,
            marker,
            ops: p.ops,
        });
        if let Some(c) = self.perturbation.filter(|c| c.function == name) {
            self.perturbed |= scale_coefficient(p, c.index, 1.0 + c.relative);
        }
    }

    /// The function of `group` (one scheduled function, or a per-marker
    /// function's programs in marker order, selected by a `match` on the
    /// marker index): its lowered operations printed, in a signature with
    /// the inputs it takes (named `_x` where unread) and its outputs (`&mut`
    /// arguments, or the returned value).
    fn function(&mut self, group: &mut [Scheduled]) -> TokenStream {
        let spec = group[0].spec();
        let mut lowered = Vec::with_capacity(group.len());
        let operations: usize = group.iter().map(|f| f.program.ops.total()).sum();
        for f in group.iter_mut() {
            if spec.inputs != Inputs::Constant {
                let marker = f.marker.map(|k| self.model.markers[k].name.clone());
                self.record(spec.name, marker, &mut f.program);
            }
            let double = self.model.precision == Precision::F64;
            let mirrored = double && self.mirror.iter().any(Option::is_some);
            lowered.push(lower(f, double, mirrored));
        }
        let touched = |k: usize| {
            lowered.iter().flat_map(|l| &l.ops).any(
                |op| matches!(op, Op::Zero { output } | Op::Store { output, .. } if *output == k),
            )
        };
        let names: Vec<proc_macro2::Ident> = spec
            .outputs
            .iter()
            .enumerate()
            .map(|(k, o)| argument(o.name, touched(k)))
            .collect();
        let mut tail = TokenStream::new();
        let bodies: Vec<TokenStream> = lowered
            .iter()
            .map(|l| self.body(l, &names, &mut tail))
            .collect();
        let body = if spec.per_marker {
            let arms = bodies.iter().enumerate().map(|(k, b)| {
                let k = usize_lit(k);
                quote!(#k => { #b })
            });
            quote! {
                match marker {
                    #(#arms)*
                    _ => return false,
                }
            }
        } else {
            bodies.into_iter().collect()
        };
        let real = self.real();
        let mut args = TokenStream::new();
        let mut ret = TokenStream::new();
        for ((o, name), &(rows, cols)) in spec.outputs.iter().zip(&names).zip(&lowered[0].shapes) {
            let (r, c) = (usize_lit(rows), usize_lit(cols));
            match o.shape {
                Shape::Scalar => ret = quote!(-> #real),
                Shape::Vector(_) => args.extend(quote!(#name: &mut SVector<#real, #r>,)),
                Shape::Matrix { .. } => args.extend(quote!(#name: &mut SMatrix<#real, #r, #c>,)),
            }
        }
        if spec.optional {
            (ret, tail) = (quote!(-> bool), quote!(true));
        }
        let read: Vec<Symbol> = lowered.iter().flat_map(Lowered::reads).collect();
        let nq = usize_lit(self.model.nq());
        let vector = quote!(&SVector<#real, #nq>);
        let q = argument("q", read.iter().any(|s| matches!(s, Symbol::Q(_))));
        let qd = argument("qd", read.iter().any(|s| matches!(s, Symbol::Qd(_))));
        let qdd = argument("qdd", read.iter().any(|s| matches!(s, Symbol::Qdd(_))));
        let t = argument("t", read.contains(&Symbol::Time));
        let marker = if spec.per_marker {
            quote!(marker: usize,)
        } else {
            quote!()
        };
        let nu = usize_lit(self.model.actuators.len());
        let inputs = match spec.inputs {
            Inputs::Constant => quote!(),
            Inputs::Actuation => {
                let tau = argument("tau", read.iter().any(|s| matches!(s, Symbol::Qdd(_))));
                quote!(#tau: &SVector<#real, #nu>,)
            }
            Inputs::Positions => quote!(#q: #vector, #t: #real,),
            Inputs::Velocities => quote!(#q: #vector, #qd: #vector, #t: #real,),
            Inputs::Accelerations => quote!(#q: #vector, #qd: #vector, #qdd: #vector, #t: #real,),
            Inputs::Forces => quote!(#q: #vector, #qd: #vector, f: #vector, #t: #real,),
        };

        let fname = format_ident!("{}", spec.name);
        let doc = spec.doc;
        let statements = if operations >= DISPATCHED_OPERATIONS {
            quote!(math::dispatch(#[inline(always)] || { #body #tail }))
        } else {
            quote!(#body #tail)
        };
        quote! {
            #[doc = #doc]
            #[inline]
            fn #fname(&self, #marker #inputs #args) #ret {
                #statements
            }
        }
    }

    /// The statements of one lowered program writing to the outputs
    /// `names`, and in `tail` the value a returned output ends with.
    /// Programs longer than [`FLAT_STATEMENTS`] declare their variables up
    /// front in groups of [`DECLARATION_GROUP`] (`let [v0, v1, ...]: [f64;
    /// 64];`) and then assign them: every `let` opens a lexical scope nested
    /// in the previous one, and LLVM builds the debug information of nested
    /// scopes recursively (a 4282-statement function overflowed rustc's
    /// stack in debug builds).
    fn body(
        &self,
        lowered: &Lowered,
        names: &[proc_macro2::Ident],
        tail: &mut TokenStream,
    ) -> TokenStream {
        let real = self.real();
        let plan = plan(
            lowered,
            &self.mirror,
            self.model.precision == Precision::F64,
        );
        let pairs = plan
            .order
            .iter()
            .filter(|s| matches!(s, Step::Two(..)))
            .count();
        let vars: Vec<proc_macro2::Ident> = lowered
            .ops
            .iter()
            .flat_map(|op| match op {
                Op::Bind { var, .. } => vec![*var],
                Op::SinCos { sin, cos, .. } => vec![*sin, *cos],
                Op::SinCosArray(batch) => batch.iter().flat_map(|(s, c, _)| [*s, *c]).collect(),
                _ => Vec::new(),
            })
            .filter(|v| !plan.resident.contains_key(v) || plan.scalar.contains(v))
            .map(var)
            .collect();
        let statements = lowered
            .ops
            .iter()
            .map(|op| match op {
                Op::Bind { .. } | Op::SinCos { .. } => 1,
                Op::SinCosArray(batch) => batch.len(),
                _ => 0,
            })
            .sum::<usize>();
        let mut body = TokenStream::new();
        let flat = statements <= FLAT_STATEMENTS;
        if !flat {
            for group in vars.chunks(DECLARATION_GROUP) {
                let n = usize_lit(group.len());
                body.extend(quote!(let [#(#group),*]: [#real; #n];));
            }
            let lanes: Vec<proc_macro2::Ident> = (0..pairs as u32).map(pair).collect();
            for group in lanes.chunks(DECLARATION_GROUP) {
                let n = usize_lit(group.len());
                body.extend(quote!(let [#(#group),*]: [math::F2; #n];));
            }
        }
        let mut printer = Printer {
            emitter: self,
            outputs: lowered.function.spec().outputs,
            inputs: lowered.function.spec().inputs,
            names: names.to_vec(),
            texts: vec![None; lowered.temps as usize],
            bind: if flat { quote!(let) } else { quote!() },
        };
        for step in &plan.order {
            match *step {
                Step::One(u) => {
                    for &k in &plan.units[u] {
                        printer.op(&lowered.ops[k], &mut body, tail);
                    }
                }
                Step::Two(a, b, n) => printer.pair(lowered, &plan, (a, b), n, &mut body),
            }
        }
        body
    }
}

/// Emit the module of a scene, naming the runtime crate by `runtime`, with
/// an optional test-only perturbation of one coefficient; also says whether
/// the perturbation found its coefficient.
pub fn emit(
    model: &Model,
    functions: Vec<Scheduled>,
    runtime: &syn::Path,
    perturbation: Option<&CoefficientPerturbation>,
) -> (Emitted, bool) {
    let mut e = Emitter {
        model,
        mirror: mirror_of(model),
        reports: Vec::new(),
        perturbation,
        perturbed: false,
    };
    let n = model.nq();
    let nc = model.constraints.len();
    let nu = model.actuators.len();
    let (nq_l, nc_l, nu_l) = (usize_lit(n), usize_lit(nc), usize_lit(nu));
    let nm_l = usize_lit(model.markers.len());
    let sname = format_ident!("{}", struct_name(&model.name));
    let real = e.real();
    let scene = model.name.as_str();

    // The trait's functions, then the runtime parameters, then the optional
    // outputs (the trait's methods default to "not generated").
    let (mut required, mut optional) = (TokenStream::new(), TokenStream::new());
    let mut functions = functions;
    for group in functions.chunk_by_mut(|a, b| a.function == b.function) {
        if group[0].spec().optional {
            optional.extend(e.function(group));
        } else {
            required.extend(e.function(group));
        }
    }

    let coords = model.coordinates.iter().map(|c| c.name.as_str());
    let acts = model.actuators.iter().map(|a| a.name.as_str());
    let fields = model.runtime_parameters.iter().map(|p| {
        let id = format_ident!("{}", p.name);
        let doc = format!("Runtime parameter (nominal value {:?}).", p.value);
        quote!(#[doc = #doc] pub #id: #real,)
    });
    let defaults = model.runtime_parameters.iter().map(|p| {
        let id = format_ident!("{}", p.name);
        let v = lit(p.value, model.precision);
        quote!(#id: #v,)
    });
    let struct_doc = format!(
        "Equations of motion of scene `{scene}`: {n} coordinates, {nc} constraints, {nu} actuators. Fields are the runtime parameters."
    );
    let parameters = if model.runtime_parameters.is_empty() {
        quote!()
    } else {
        let names = model.runtime_parameters.iter().map(|p| p.name.as_str());
        let arms = model.runtime_parameters.iter().map(|p| {
            let id = format_ident!("{}", p.name);
            let name = p.name.as_str();
            quote!(#name => self.#id = value,)
        });
        quote! {
            const PARAMETERS: &'static [&'static str] = &[#(#names),*];
            fn set_parameter(&mut self, name: &str, value: #real) -> bool {
                match name {
                    #(#arms)*
                    _ => return false,
                }
                true
            }
        }
    };
    let struct_def = if model.runtime_parameters.is_empty() {
        quote! {
            #[doc = #struct_doc]
            #[derive(Debug, Clone, Copy, Default, PartialEq)]
            pub struct #sname;
        }
    } else {
        quote! {
            #[doc = #struct_doc]
            #[derive(Debug, Clone, Copy, PartialEq)]
            pub struct #sname { #(#fields)* }

            impl Default for #sname {
                fn default() -> Self {
                    Self { #(#defaults)* }
                }
            }
        }
    };
    let lints = quote! {
        #[allow(
            clippy::approx_constant,
            clippy::excessive_precision,
            clippy::too_many_lines,
            clippy::unreadable_literal,
            clippy::neg_multiply,
            clippy::identity_op,
            clippy::suspicious_operation_groupings,
            clippy::too_many_arguments,
            unused_parens
        )]
    };
    let marker_names = model.markers.iter().map(|m| m.name.as_str());
    let markers = if model.markers.is_empty() {
        quote!()
    } else {
        quote!(const MARKERS: &'static [&'static str] = &[#(#marker_names),*];)
    };
    let consts = quote! {
        const NAME: &'static str = #scene;
        const COORDINATES: [&'static str; #nq_l] = [#(#coords),*];
        const ACTUATORS: [&'static str; #nu_l] = [#(#acts),*];
        #markers
    };
    let members = quote! {
        #consts
        #required
        #parameters
        #optional
    };
    // The runtime's trait, in the model's scalar type (`f64`, the trait's
    // default, left out).
    let (math, implementation) = match model.precision {
        Precision::F64 => (
            quote!(use #runtime::math;),
            quote!(impl #runtime::Model<#nq_l, #nc_l, #nu_l> for #sname { #members }),
        ),
        Precision::F32 => (
            quote!(use #runtime::math::f32 as math;),
            quote!(impl #runtime::Model<#nq_l, #nc_l, #nu_l, f32> for #sname { #members }),
        ),
    };
    let tokens = quote! {
        #math
        use #runtime::nalgebra::{SMatrix, SVector};

        /// Number of generalized coordinates.
        pub const NQ: usize = #nq_l;
        /// Number of constraints.
        pub const NC: usize = #nc_l;
        /// Number of actuator inputs.
        pub const NU: usize = #nu_l;
        /// Number of markers.
        pub const NM: usize = #nm_l;

        #struct_def

        #lints
        #implementation
    };
    let file: syn::File = syn::parse2(tokens).expect("emitted tokens form a valid Rust file");
    let body = prettyplease::unparse(&file);
    let mut total = OpCount::default();
    let mut header = format!(
        "// @generated by flexdyn-codegen {} from scene `{scene}`. Do not edit: edit the scene and rebuild.\n\
         // Operation counts (add / mul / div / call):\n",
        env!("CARGO_PKG_VERSION")
    );
    for r in &e.reports {
        total += r.ops;
        let name = match &r.marker {
            Some(m) => format!("{} ({m})", r.name),
            None => r.name.to_owned(),
        };
        header.push_str(&format!(
            "//   {:<40} {:>6} {:>6} {:>6} {:>6}\n",
            name, r.ops.adds, r.ops.muls, r.ops.divs, r.ops.calls
        ));
    }
    header.push_str(&format!(
        "//   {:<40} {:>6} {:>6} {:>6} {:>6}\n\
         // (constraints_and_jacobian computes constraints and constraint_jacobian in one program,\n\
         // dynamics_terms mass_matrix, bias, constraint_jacobian and constraint_rhs)\n\n",
        "total", total.adds, total.muls, total.divs, total.calls
    ));
    if model.precision == Precision::F32 {
        header.push_str("// Precision f32: implements the runtime's `Model<.., f32>`.\n\n");
    }
    if let (Some(c), true) = (perturbation, e.perturbed) {
        header.push_str(&format!(
            "// TEST ONLY: coefficient {} of `{}` deliberately multiplied by 1 + {:e}.\n\n",
            c.index, c.function, c.relative
        ));
    }
    let perturbed = e.perturbed;
    (
        Emitted {
            source: header + &body,
            functions: e.reports,
        },
        perturbed,
    )
}
